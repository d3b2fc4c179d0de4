"""Per-agent summaries of a sweep (thesis Metrics 1-3 with IQM and bootstrap intervals), pairwise comparisons (Welch
tests and probability of improvement) between agents; the ``--json`` document."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from embodied_adhoc.experiments.stats import (
    BOOTSTRAP_REPS,
    BOOTSTRAP_SEED,
    CI_METHOD,
    CONFIDENCE,
    IDENTIFY_MARGIN,
    PairComparison,
    SampleSummary,
    compare_pairs,
    compare_samples,
    summarise_sample,
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
    # the sessions' extra per-trial columns: numeric ones as their mean per episode, codes as counts per value
    extras_mean: dict[str, float] = field(default_factory=dict)
    extras_counts: dict[str, dict[str, int]] = field(default_factory=dict)


@dataclass(frozen=True)
class RunSummary:
    agents: dict[str, AgentSummary]
    comparisons: list[PairComparison]  # steps to finish, every pair of agents


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
            **_extras(rows),
        )
    comparisons = compare_pairs({name: [r.steps for r in rows] for name, rows in by_agent.items()}, "steps")
    return RunSummary(summaries, comparisons)


def _extras(rows: Sequence[TrialRecord]) -> dict:
    """Per extra column of ``rows``: the mean per episode of a numeric one, the count per value of a code (empty
    cells are not counted)."""
    means, counts = {}, {}
    for key in dict.fromkeys(key for r in rows for key in r.extras):
        values = [r.extras.get(key, "") for r in rows]
        if all(isinstance(v, (int, float)) for v in values):
            means[key] = float(np.mean(values))
        else:
            counts[key] = dict(Counter(str(v) for v in values if v != ""))
    return {"extras_mean": means, "extras_counts": counts}


def extras_table(summary: RunSummary) -> str:
    """The extra per-trial columns (e.g. fault counts) per agent: means per episode, then the codes counted; empty
    when the sweep has none."""
    from embodied_adhoc.experiments.tables import format_table

    agents = list(summary.agents.values())
    keys = list(dict.fromkeys(key for s in agents for key in s.extras_mean))
    codes = list(dict.fromkeys(key for s in agents for key in s.extras_counts))
    if not keys and not codes:
        return ""
    rows = [[key, *(_cell(s.extras_mean.get(key)) for s in agents)] for key in keys]
    notes = []
    for key in codes:
        if all(len(v) <= CODE_WIDTH for s in agents for v in s.extras_counts.get(key, {})):
            rows.append([key, *(_codes(s.extras_counts.get(key, {})) for s in agents)])
        else:  # sentences: one line each, under the table
            notes += [
                f"{s.agent} {key}: {v} (x{n})"
                for s in agents
                for v, n in s.extras_counts.get(key, {}).items()
            ]
    return "\n".join([format_table(["per episode (mean)", *(s.agent for s in agents)], rows), *notes])


CODE_WIDTH = 24
"""Longer values of a code column are sentences: listed under the extras table, not in a cell."""


def _cell(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3f}".rstrip("0").rstrip(".")


def _codes(counts: dict[str, int]) -> str:
    return ", ".join(f"{code} x{n}" for code, n in sorted(counts.items())) or "-"


def comparisons_between_runs(
    runs: dict[str, Sequence[TrialRecord]], agents: Sequence[str]
) -> list[PairComparison]:
    """Per agent, comparisons of steps between runs of the same episodes under different settings or backends
    (e.g. abstract vs physics, the thesis's simulation-vs-reality comparison); ``runs`` maps a label to records."""
    labels = list(runs)
    return [
        compare_samples(
            [r.steps for r in runs[first] if r.agent == agent],
            [r.steps for r in runs[second] if r.agent == agent],
            (f"{agent} ({first})", f"{agent} ({second})"),
            "steps",
        )
        for agent in agents
        for i, first in enumerate(labels)
        for second in labels[i + 1 :]
    ]


def comparisons_json(comparisons: Sequence[PairComparison]) -> list[dict]:
    return [
        {
            "a": c.first,
            "b": c.second,
            "metric": c.metric,
            "t": _number(c.statistic),
            "p": _number(c.p_value),
            "significant": None if math.isnan(c.p_value) else c.significant(),
            "p_improvement": _number(c.improvement),
            "p_improvement_ci95": [_number(c.improvement_low), _number(c.improvement_high)],
        }
        for c in comparisons
    ]


def statistics_json() -> dict:
    """How the document's numbers were computed (so a reader never has to guess the interval)."""
    return {
        "ci": f"{CI_METHOD} of the statistic, {CONFIDENCE:.0%}",
        "bootstrap_resamples": BOOTSTRAP_REPS,
        "bootstrap_seed": BOOTSTRAP_SEED,
        "iqm": "interquartile mean: mean of the middle 50 % (25 % trimmed each side), as rliable",
        "p_improvement": "P(a takes fewer steps than b) + P(tie) / 2 over trial pairs (rliable's probability of "
        "improvement; Mann-Whitney U / (n m))",
        "welch": "two-sided Welch t-test, scipy.stats.ttest_ind(equal_var=False)",
        "identify_margin": IDENTIFY_MARGIN,
    }


def _number(value: float) -> float | None:
    """JSON has no NaN: undefined statistics become null."""
    return None if value is None or math.isnan(value) else float(value)


def _sample_json(prefix: str, sample: SampleSummary) -> dict:
    return {
        f"{prefix}_mean": _number(sample.mean),
        f"{prefix}_sd": _number(sample.sd),
        f"{prefix}_ci95": [_number(sample.ci_low), _number(sample.ci_high)],
        f"{prefix}_iqm": _number(sample.iqm),
        f"{prefix}_iqm_ci95": [_number(sample.iqm_ci_low), _number(sample.iqm_ci_high)],
    }


def summary_json(summary: RunSummary, config: dict) -> dict:
    """The ``--json`` document: ``{"agents": {NAME: {...}}, "comparisons": [...], "statistics": {...},
    "config": {...}}``.

    ``*_ci95`` are ``[low, high]`` 95 % percentile-bootstrap intervals (``statistics`` says how they were made).
    """
    agents = {}
    for name, s in summary.agents.items():
        agents[name] = {
            "trials": s.trials,
            **_sample_json("steps", s.steps),
            "success_rate": _number(s.success_rate),
            **_sample_json("identify_steps", s.identify),
            "identified_rate": _number(s.identified_rate),
            "final_entropy_mean": _number(s.final_entropy.mean),
            "final_entropy_ci95": [_number(s.final_entropy.ci_low), _number(s.final_entropy.ci_high)],
            **_sample_json("return", s.total_reward),  # accumulated reward (Table 5.5)
        }
        if s.extras_mean or s.extras_counts:  # the session's extra columns, e.g. fault counts per episode
            agents[name]["per_episode_mean"] = {key: _number(v) for key, v in s.extras_mean.items()}
            agents[name]["counts"] = s.extras_counts
    return {
        "agents": agents,
        "comparisons": comparisons_json(summary.comparisons),
        "statistics": statistics_json(),
        "config": config,
    }
