"""Per-agent summaries of a sweep (thesis Metrics 1-3) and Welch tests between agents; the ``--json`` document."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from embodied_adhoc.experiments.stats import (
    SampleSummary,
    WelchTest,
    pairwise_welch,
    summarise_sample,
    welch_test,
)
from embodied_adhoc.experiments.storage import TrialRecord


@dataclass(frozen=True)
class AgentSummary:
    agent: str
    trials: int
    steps: SampleSummary  # Metric 1: steps to finish (capped trials count with the steps they took)
    success_rate: float
    identify: SampleSummary  # Metric 2 over the trials that identified the task
    identified_rate: float  # NaN for agents that keep no task posterior
    final_entropy: SampleSummary  # Metric 3 at the end of the trial
    total_reward: SampleSummary


@dataclass(frozen=True)
class RunSummary:
    agents: dict[str, AgentSummary]
    welch: list[WelchTest]  # steps to finish, every pair of agents


def summarise_records(records: Sequence[TrialRecord], agents: Sequence[str]) -> RunSummary:
    by_agent: dict[str, list[TrialRecord]] = {name: [] for name in agents}
    for record in records:
        if record.agent in by_agent:
            by_agent[record.agent].append(record)
    summaries = {}
    for name, rows in by_agent.items():
        keeps_posterior = any(not math.isnan(r.final_entropy) for r in rows)
        identified = [r.identify_step for r in rows if r.identify_step is not None]
        summaries[name] = AgentSummary(
            agent=name,
            trials=len(rows),
            steps=summarise_sample([r.steps for r in rows]),
            success_rate=float(np.mean([r.success for r in rows])) if rows else math.nan,
            identify=summarise_sample(identified),
            identified_rate=len(identified) / len(rows) if rows and keeps_posterior else math.nan,
            final_entropy=summarise_sample(
                [r.final_entropy for r in rows if not math.isnan(r.final_entropy)]
            ),
            total_reward=summarise_sample([r.total_reward for r in rows]),
        )
    welch = pairwise_welch({name: [r.steps for r in rows] for name, rows in by_agent.items()}, "steps")
    return RunSummary(summaries, welch)


def welch_between_runs(runs: dict[str, Sequence[TrialRecord]], agents: Sequence[str]) -> list[WelchTest]:
    """Per agent, Welch tests on steps between runs of the same episodes under different settings or backends
    (e.g. abstract vs physics, the thesis's simulation-vs-reality comparison); ``runs`` maps a label to records."""
    labels = list(runs)
    tests = []
    for agent in agents:
        for i, first in enumerate(labels):
            for second in labels[i + 1 :]:
                statistic, p_value = welch_test(
                    [r.steps for r in runs[first] if r.agent == agent],
                    [r.steps for r in runs[second] if r.agent == agent],
                )
                tests.append(
                    WelchTest(f"{agent} ({first})", f"{agent} ({second})", "steps", statistic, p_value)
                )
    return tests


def welch_json(tests: Sequence[WelchTest]) -> list[dict]:
    return [
        {
            "a": test.first,
            "b": test.second,
            "metric": test.metric,
            "t": _number(test.statistic),
            "p": _number(test.p_value),
            "significant": None if math.isnan(test.p_value) else test.significant(),
        }
        for test in tests
    ]


def _number(value: float) -> float | None:
    """JSON has no NaN: undefined statistics become null."""
    return None if value is None or math.isnan(value) else float(value)


def _interval(sample: SampleSummary) -> list[float | None]:
    return [_number(sample.ci_low), _number(sample.ci_high)]


def summary_json(summary: RunSummary, config: dict) -> dict:
    """The ``--json`` document: ``{"agents": {NAME: {...}}, "welch": [...], "config": {...}}``.

    ``steps_ci95`` and ``identify_steps_ci95`` are ``[low, high]`` 95 % t-intervals of the mean.
    """
    agents = {}
    for name, s in summary.agents.items():
        agents[name] = {
            "trials": s.trials,
            "steps_mean": _number(s.steps.mean),
            "steps_sd": _number(s.steps.sd),
            "steps_ci95": _interval(s.steps),
            "success_rate": _number(s.success_rate),
            "identify_steps_mean": _number(s.identify.mean),
            "identify_steps_sd": _number(s.identify.sd),
            "identify_steps_ci95": _interval(s.identify),
            "identified_rate": _number(s.identified_rate),
            "final_entropy_mean": _number(s.final_entropy.mean),
            "return_mean": _number(s.total_reward.mean),
        }
    return {"agents": agents, "welch": welch_json(summary.welch), "config": config}
