"""``embodied-adhoc evaluate``: every agent on every member of a suite, scored between the member's bounds.

For each domain and member the trial runner (``experiments.runner.run_sweep``) runs every agent for the same
episodes (specs drawn from ``(seed, episode)``, shared by the agents) with the member as the world's teammate,
stored under ``OUT/<domain>/<member>/`` and resumable there. Each return is normalised by the member's bounds
(:mod:`embodied_adhoc.bench.bounds`); per domain and over all domains the summary holds each agent's IQM and mean
with stratified-bootstrap intervals, the probability of improvement of every pair and the performance profile
(:mod:`embodied_adhoc.bench.scores`), written to ``OUT/summary.json`` (with the suite's name and version) and
plotted to ``OUT/<scope>-intervals.png`` and ``OUT/<scope>-profiles.png``.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.teammates.populations import (
    BENCH_DOMAINS,
    GRID,
    SUITE_VERSION,
    load_population,
    members,
)

__all__ = ["SUITES", "Suite", "backend_difference", "evaluate", "resolve_suite"]

SUITES = ("heldout", "validation", "train")
PROFILE_TAUS = np.round(np.linspace(-0.25, 1.25, 31), 4)


@dataclass(frozen=True)
class Suite:
    name: str
    version: str
    members: dict  # domain -> tuple of TeammateSpec


def resolve_suite(suite: str, domains: tuple[str, ...] | None = None) -> Suite:
    """A built-in split (``heldout``, ``validation``, ``train``) or a population file, restricted to ``domains``."""
    if suite in SUITES:
        chosen = tuple(domains or BENCH_DOMAINS)
        return Suite(suite, SUITE_VERSION, {d: members(d, suite) for d in chosen})
    if not suite.endswith(".json"):
        raise ConfigError(
            f"--suite {suite!r}: choose from {', '.join(SUITES)} or give a population file (.json)"
        )
    name, version, specs = load_population(suite)
    found = tuple(dict.fromkeys(spec.domain for spec in specs))
    chosen = tuple(domains or found)
    selected = {d: tuple(s for s in specs if s.domain == d) for d in chosen}
    empty = [d for d, group in selected.items() if not group]
    if empty:
        raise ConfigError(
            f"--domains {','.join(empty)}: {suite} has no member there (it has {', '.join(found)})"
        )
    return Suite(name, version, selected)


def domain_defaults(domain_name: str) -> tuple[dict, int]:
    """The options and step cap ``trials DOMAIN`` uses with no flag (its own parser, so they stay one definition)."""
    from embodied_adhoc.experiments.registry import get_trial_domain
    from embodied_adhoc.experiments.runner import DEFAULT_MAX_STEPS

    domain = get_trial_domain(domain_name)
    parser = argparse.ArgumentParser(add_help=False)
    domain.add_arguments(parser)
    args = parser.parse_args([])
    return domain.options_from_args(args), int(getattr(args, "max_steps", None) or DEFAULT_MAX_STEPS)


def _agents_for(domain_name: str, agents: tuple[str, ...]) -> tuple[str, ...]:
    from embodied_adhoc.experiments.registry import get_trial_domain
    from embodied_adhoc.plugins import names_plugin

    known = get_trial_domain(domain_name).agent_names
    return tuple(a for a in agents if a in known or names_plugin("agent", a))


def check_agents(agents: tuple[str, ...], domains) -> dict:
    """The agents run per domain (a name a domain does not know is left out there); ConfigError for a name no domain
    knows, before any work."""
    from embodied_adhoc.experiments.registry import get_trial_domain

    per_domain = {d: _agents_for(d, agents) for d in domains}
    unknown = [a for a in agents if not any(a in run for run in per_domain.values())]
    if unknown:
        names = sorted({n for d in domains for n in get_trial_domain(d).agent_names})
        raise ConfigError(
            f"--agents {','.join(unknown)}: no selected domain knows it; choose from {', '.join(names)} or give "
            "MODULE:CALLABLE"
        )
    if len(set(agents)) != len(agents):
        raise ConfigError(f"--agents lists an agent twice: {','.join(agents)}")
    return per_domain


def _scope_summary(matrices: dict, reps: int) -> dict:
    """IQM, mean, pairwise probability of improvement and profiles of ``{agent: (episodes x members)}``."""
    from embodied_adhoc.bench.scores import aggregate, improvement, profile

    names = list(matrices)
    return {
        "members": int(next(iter(matrices.values())).shape[1]) if matrices else 0,
        "aggregate": {a: aggregate(matrices[a], reps) for a in names},
        "probability_of_improvement": {
            f"{a} > {b}": improvement(matrices[a], matrices[b], reps) for a in names for b in names if a != b
        },
        "profiles": {a: profile(matrices[a], PROFILE_TAUS, reps) for a in names},
    }


def evaluate(
    agents: tuple[str, ...],
    suite: Suite,
    out: str | Path,
    episodes: int = 32,
    seed: int = 0,
    backend: str = "abstract",
    workers: int = 1,
    executor: str = "local",
    progress: bool = False,
    reps: int | None = None,
    plots: bool = True,
    scores: dict | None = None,
    bound_episodes: int | None = None,
) -> dict:
    """Run (or resume) the suite for ``agents`` and write ``OUT/summary.json`` (returned) and the plots.

    ``executor`` is the trial runner's (``local`` or ``ray``); the members of a population file given by
    ``params`` are known to this process and its forked workers only, so they need ``local``. ``scores``, if
    given, receives per domain ``{agent: normalised scores (episodes x members)}``, the per-episode data the
    summary aggregates (e.g. for :func:`backend_difference`). On the grid arenas a return is minus the steps and
    the bounds are simulated (``bench.bounds.simulated_bounds``, ``bound_episodes`` each, default
    ``GRID_BOUND_EPISODES``), stored under ``OUT/<domain>/<member>/bounds/``."""
    from embodied_adhoc.atomic import atomic_write_text
    from embodied_adhoc.bench.bounds import (
        GRID_BOUND_EPISODES,
        grid_return,
        member_bounds,
        normalise,
        simulated_bounds,
        start_state,
    )
    from embodied_adhoc.bench.scores import BENCH_REPS
    from embodied_adhoc.experiments.executors import close_sessions
    from embodied_adhoc.experiments.registry import get_trial_domain
    from embodied_adhoc.experiments.runner import SweepConfig, run_sweep
    from embodied_adhoc.experiments.stats import summarise_sample

    reps = BENCH_REPS if reps is None else int(reps)
    if episodes < 2:
        raise ConfigError(f"--episodes {episodes}: at least 2 per member (the intervals resample episodes)")
    per_domain = check_agents(tuple(agents), suite.members)
    for domain_name in suite.members:
        if backend not in get_trial_domain(domain_name).backends:
            raise ConfigError(
                f"--backend {backend}: {domain_name} has {', '.join(get_trial_domain(domain_name).backends)}"
            )
    out = Path(out)
    summary = {
        "suite": suite.name,
        "version": suite.version,
        "backend": backend,
        "episodes": int(episodes),
        "seed": int(seed),
        "agents": list(agents),
        "bootstrap": {"reps": reps, "confidence": 0.95, "method": "stratified percentile bootstrap"},
        "domains": {},
    }
    overall: dict[str, list[np.ndarray]] = {}
    for domain_name, specs in suite.members.items():
        options, max_steps = domain_defaults(domain_name)
        library = get_trial_domain(domain_name).open_session(backend, options).library
        run_agents = per_domain[domain_name]
        rows, matrices = [], {a: [] for a in run_agents}
        grid = domain_name in GRID
        for spec in specs:
            member_options = {**spec.trial_options(options), "bench_member": spec.describe()}
            if grid:
                bounds = simulated_bounds(
                    domain_name,
                    member_options,
                    max_steps,
                    out / domain_name / spec.name / "bounds",
                    episodes=bound_episodes or GRID_BOUND_EPISODES,
                    workers=workers,
                    executor=executor,
                    progress=progress,
                )
            else:
                bounds = member_bounds(spec, library, max_steps)
            config = SweepConfig(domain_name, backend, member_options, run_agents, episodes, seed, max_steps)
            result = run_sweep(
                config,
                out=out / domain_name / spec.name,
                workers=workers,
                executor=executor,
                progress=progress,
            )
            returns = {a: np.zeros(episodes) for a in run_agents}
            solved = {a: np.zeros(episodes) for a in run_agents}
            belief = {a: np.full(episodes, np.nan) for a in run_agents}
            starts = {}
            for record in result.records:
                returns[record.agent][record.episode] = grid_return(record) if grid else record.total_reward
                solved[record.agent][record.episode] = float(record.success)
                belief[record.agent][record.episode] = record.true_task_probability
                if not grid:
                    starts[record.episode] = start_state(domain_name, library, record.spec)
            row = {
                **spec.describe(),
                "bounds": {
                    "random": bounds.random,
                    "best": bounds.best,
                    "horizon": max_steps,
                    "upper": bounds.upper,
                    **({"episodes": bounds.episodes} if bounds.episodes else {}),
                    # both simulated candidates for the upper bound, so a reader sees what the max chose between
                    **({"original": bounds.original} if bounds.original is not None else {}),
                    **({"trained": bounds.trained} if bounds.trained is not None else {}),
                },
                # the best response's expected return from these episodes' own starts, normalised: what no agent's
                # mean over the same episodes exceeds in expectation (none where the bounds are simulated)
                "best_on_episodes": None
                if grid
                else float(normalise(bounds.on_starts(list(starts.values()))[0], bounds)),
            }
            row["agents"] = {}
            for agent in run_agents:
                normalised = normalise(returns[agent], bounds)
                matrices[agent].append(normalised)
                sample = summarise_sample(normalised)
                row["agents"][agent] = {
                    "mean_return": float(returns[agent].mean()),
                    "normalised_mean": sample.mean,
                    "normalised_sd": sample.sd,
                    "normalised_ci": [sample.ci_low, sample.ci_high],
                    "success": float(solved[agent].mean()),
                    # the agent's final posterior on the true task (NaN for agents without one): low where the
                    # member made it identify the wrong task
                    "true_task_probability": float(np.nanmean(belief[agent]))
                    if np.isfinite(belief[agent]).any()
                    else math.nan,
                }
            rows.append(row)
            close_sessions()  # one member's worlds and policies at a time in memory
        stacked = {a: np.stack(columns, axis=1) for a, columns in matrices.items()}
        if scores is not None:
            scores[domain_name] = stacked
        summary["domains"][domain_name] = {
            "agents": list(run_agents),
            "teammates": rows,
            **_scope_summary(stacked, reps),
        }
        for agent, matrix in stacked.items():
            overall.setdefault(agent, []).append(matrix)
    everywhere = [a for a in agents if all(a in per_domain[d] for d in suite.members)]
    summary["overall"] = {
        "agents": everywhere,
        **_scope_summary({a: np.concatenate(overall[a], axis=1) for a in everywhere}, reps),
    }
    summary = _finite(summary)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=1) + "\n")
    if plots:
        from embodied_adhoc.bench.plots import plot_summary

        plot_summary(summary, out)
    return summary


def backend_difference(first: dict, second: dict, members: list[str]) -> dict:
    """Per agent of both ``{agent: normalised scores (episodes x members)}`` (the same members, e.g. the abstract
    and the physics lab): each side's mean, their difference (second - first) and Welch's unequal-variances t-test
    (two-sided, ``experiments.stats.welch_test``, ``t`` of second - first) on the per-episode scores, pooled over
    the members and per member."""
    from embodied_adhoc.experiments.stats import welch_test

    def compare(a: np.ndarray, b: np.ndarray) -> dict:
        t, p = welch_test(b, a)  # t has the sign of the difference
        return {
            "first_mean": float(a.mean()),
            "second_mean": float(b.mean()),
            "difference": float(b.mean() - a.mean()),
            "t": t,
            "p": p,
            "n": [int(a.size), int(b.size)],
        }

    result = {}
    for agent in (a for a in first if a in second):
        a, b = np.asarray(first[agent]), np.asarray(second[agent])
        result[agent] = {
            **compare(a.ravel(), b.ravel()),
            "per_member": {name: compare(a[:, k], b[:, k]) for k, name in enumerate(members)},
        }
    return _finite(
        {"method": "Welch's unequal-variances t-test, two-sided, on per-episode normalised scores"}
        | {"agents": result}
    )


def _finite(value):
    """JSON without NaN (``null`` instead), so that every reader parses the summary."""
    if isinstance(value, float):
        return None if math.isnan(value) else value
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value
