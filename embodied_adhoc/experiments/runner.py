"""The trial runner shared by every domain and backend: a sweep = agents x episodes, same episodes for all agents.

Usage from Python (what ``embodied-adhoc trials`` and ``scripts/reproduce_hotspot.py`` do)::

    from embodied_adhoc.experiments.runner import SweepConfig, run_sweep
    config = SweepConfig("toxic-waste", "abstract", {"human_epsilon": 0.05, "communication": True, ...},
                         agents=("hotspot", "known-task", "oracle", "random"), episodes=32, seed=7)
    result = run_sweep(config, out="runs/fig7_8", workers=2)
    print(summary_table(result.summary()))

Episode specs (task, start positions) are drawn once from ``(seed, episode)``; each trial's env and agent
randomness from ``(seed, episode, agent)`` (:mod:`embodied_adhoc.experiments.seeding`), so a result does not
depend on the executor, the number of workers, or on which other trials a run contains. With ``out`` the run is
stored and resumable (:mod:`embodied_adhoc.experiments.storage`): the run's identity holds the content of its
input files, plug-in agents' sources and, where a domain's results depend on it, the BLAS kernel class
(:mod:`embodied_adhoc.experiments.identity`); resuming with any of them changed is refused, and ``new_run`` then
writes a fresh sibling folder instead. One process at a time writes a folder (its lock).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments import seeding
from embodied_adhoc.experiments.executors import execute, open_session
from embodied_adhoc.experiments.identity import blas_note, input_digest, run_inputs
from embodied_adhoc.experiments.registry import agent_plugin, build_agent, get_trial_domain
from embodied_adhoc.experiments.storage import (
    ResultStore,
    TrialRecord,
    fresh_sibling,
    record_from_row,
    trial_row,
)
from embodied_adhoc.experiments.summary import RunSummary, summarise_records
from embodied_adhoc.experiments.trial import TrialJob

DEFAULT_MAX_STEPS = 100
"""The thesis's cap on simulated episodes (Sec. 7.2)."""


@dataclass(frozen=True)
class SweepConfig:
    """One sweep. ``options`` are the domain's own options (JSON scalars), e.g. ``human_epsilon``."""

    domain: str
    backend: str
    options: Mapping = field(default_factory=dict)
    agents: tuple[str, ...] = ()
    episodes: int = 32
    seed: int = 0
    max_steps: int = DEFAULT_MAX_STEPS

    def identity(self) -> dict:
        """What determines every trial's outcome (agents and episodes only choose which trials run)."""
        return {
            "domain": self.domain,
            "backend": self.backend,
            "options": dict(self.options),
            "seed": int(self.seed),
            "max_steps": int(self.max_steps),
        }

    def describe(self) -> dict:
        return {**self.identity(), "agents": list(self.agents), "episodes": int(self.episodes)}


@dataclass(frozen=True)
class SweepResult:
    config: SweepConfig
    task_names: tuple[str, ...]
    records: list[TrialRecord]  # requested trials, ordered by (agent as requested, episode)
    entropy_curves: dict[tuple[str, int], list[float]]  # (agent, episode) -> normalised entropy per step
    new_trials: int  # trials run by this call (the others were resumed from ``out``)
    wall_time_s: float
    out: Path | None = None  # the folder written: ``out``, or its fresh sibling under ``new_run``

    def summary(self) -> RunSummary:
        return summarise_records(self.records, self.config.agents)

    def curves_by_agent(self) -> dict[str, list[list[float]]]:
        curves: dict[str, list[list[float]]] = {name: [] for name in self.config.agents}
        for record in self.records:
            curve = self.entropy_curves.get((record.agent, record.episode))
            if curve:
                curves[record.agent].append(curve)
        return {name: c for name, c in curves.items() if c}


def _validate(config: SweepConfig, domain) -> None:
    if config.backend not in domain.backends:
        raise ConfigError(
            f"domain '{config.domain}' has no backend '{config.backend}'; choose one of {', '.join(domain.backends)}"
        )
    if not config.agents:
        raise ConfigError(
            f"no agent given for '{config.domain}'; choose from {', '.join(domain.agent_names)}"
        )
    for (
        name
    ) in config.agents:  # a built-in name or a plug-in spec (embodied_adhoc.plugins); refused here if neither
        agent_plugin(domain, name)
    if len(set(config.agents)) != len(config.agents):
        raise ConfigError(f"agents listed twice in {list(config.agents)}")
    if config.episodes < 1:
        raise ConfigError(f"--episodes must be >= 1, got {config.episodes}")
    if config.max_steps < 1:
        raise ConfigError(f"--max-steps must be >= 1, got {config.max_steps}")


def run_sweep(
    config: SweepConfig,
    out: str | Path | None = None,
    workers: int = 1,
    executor: str = "local",
    progress: bool = False,
    new_run: bool = False,
) -> SweepResult:
    """Run (or resume, with ``out``) every (agent, episode) trial of ``config``; see the module docstring.

    ``new_run``: where ``out`` holds a run of another identity, write to the first sibling ``out-2``, ``out-3``, ...
    that is new or holds this run (a note names it) instead of refusing.

    An interrupt (Ctrl-C, or SIGTERM under the CLI) propagates after the trials that finished were written to
    ``out`` and the worker processes were terminated.
    """
    started = time.perf_counter()
    domain = get_trial_domain(config.domain)
    _validate(config, domain)
    options = dict(config.options)
    specs = [
        domain.episode_spec(options, seeding.episode_rng(config.seed, e)) for e in range(config.episodes)
    ]
    spec_fields = tuple(specs[0])
    if "task" not in spec_fields:
        raise ConfigError(
            f"domain '{config.domain}' episode specs lack the required key 'task' (got {spec_fields})"
        )
    session = open_session(config.domain, config.backend, options)
    task_names = tuple(session.task_names)
    for name in (
        config.agents
    ):  # a plug-in agent is built once here, so a broken one stops the sweep before any trial
        if not agent_plugin(domain, name).builtin:
            build_agent(domain, session, name, specs[0], seeding.agent_seed(config.seed, 0, name))

    store = None
    rows: dict[tuple[str, int], dict[str, str]] = {}
    if out is not None:
        identity = {**config.identity(), **run_inputs(domain, options)}
        out = Path(out)
        if new_run:
            chosen = fresh_sibling(out, identity)
            if chosen != out:
                note = f"embodied-adhoc: note: {out} holds another run; writing this one to {chosen}"
                print(note, file=sys.stderr)
            out = chosen
        extra_fields = tuple(getattr(session, "trial_columns", ()))  # e.g. fault counts
        notes = {"blas": blas_note(), "agent_sources": _agent_sources(domain, config.agents)}
        store = ResultStore(out, identity, task_names, spec_fields, extra_fields, notes)
        for row in store.open({"agents": list(config.agents), "episodes": config.episodes}):
            rows[(row["agent"], int(row["episode"]))] = row
    try:
        return _run_trials(config, specs, spec_fields, options, task_names, store, rows, workers, executor,
                           progress, started, out)  # fmt: skip
    finally:
        if store is not None:
            store.close()


def _agent_sources(domain, agents) -> dict[str, str]:
    """sha256 of each plug-in agent's source file (built-in agents are the package's own code)."""
    sources = {}
    for name in agents:
        source = agent_plugin(domain, name).source
        if source is not None:
            sources[name] = input_digest(source, f"--agents {name}")
    return sources


def _run_trials(config, specs, spec_fields, options, task_names, store, rows, workers, executor, progress, started,
                out) -> SweepResult:  # fmt: skip
    if store is not None:
        _check_stored_specs(rows, specs, spec_fields, store)
    jobs = [
        TrialJob(config.domain, config.backend, options, config.seed, config.max_steps, agent, e, specs[e])
        for agent in config.agents
        for e in range(config.episodes)
        if (agent, e) not in rows
    ]
    curves: dict[tuple[str, int], list[float]] = {}
    bar = _progress_bar(len(jobs), config) if progress and jobs else None
    results = execute(jobs, workers=workers, executor=executor)
    try:
        for result in results:
            rows[(result.agent, result.episode)] = (
                store.append(result) if store else trial_row(result, spec_fields)
            )
            if result.entropies is not None:
                curves[(result.agent, result.episode)] = [float(h) for h in result.entropies]
            if bar is not None:
                bar.update(1)
    finally:
        results.close()  # stopped early: the executor terminates its workers now, not when garbage-collected
        if bar is not None:
            bar.close()
    if store is not None:
        curves = store.entropy_curves()
    records = [
        record_from_row(rows[(agent, e)], spec_fields)
        for agent in config.agents
        for e in range(config.episodes)
    ]
    requested = {(r.agent, r.episode) for r in records}
    return SweepResult(
        config=config,
        task_names=task_names,
        records=records,
        entropy_curves={key: curve for key, curve in curves.items() if key in requested},
        new_trials=len(jobs),
        wall_time_s=time.perf_counter() - started,
        out=out,
    )


def _check_stored_specs(rows, specs, spec_fields, store) -> None:
    for (agent, episode), row in rows.items():
        if episode < len(specs) and any(row[key] != str(specs[episode][key]) for key in spec_fields):
            raise ConfigError(
                f"{store.trials_path}: episode {episode} of '{agent}' was run with spec "
                f"{ {k: row[k] for k in spec_fields} }, but this version draws {specs[episode]}; "
                "the domain's episode draw changed: use a new --out folder"
            )


def _progress_bar(total: int, config: SweepConfig):
    from tqdm import tqdm

    return tqdm(
        total=total,
        desc=f"{config.domain}/{config.backend} trials",
        unit="trial",
        file=sys.stderr,
        leave=False,
        disable=None,
    )
