"""Reproduce thesis Fig. 7.12 (HOTSPOT's scale-up to two-predator pursuit) on the grid twin and in physics.

The same sweep (``trials pursuit --pairs``: the pursuit-task POMDP as the world, 32 episodes, cap 150, tasks and
start states drawn once from --seed) on ``--backends`` (default abstract and mujoco, same episodes), then:

* steps to capture per agent and backend (mean ± sd, 95 % bootstrap CI) beside the thesis (optimal 6.75 ± 4.55,
  known task 10.22 ± 6.12, TEBOPA 12.84 ± 7.29, random 76.1 ± 52.6), also in our count (the thesis counts the step
  taken from the capture state: one more per captured trial), and the Welch test abstract vs physics;
* how many episodes took exactly the same steps on both backends (same seeds: the backends differ only where
  physics does not execute a move the POMDP drew);
* the thesis's statistical claims with our Welch p-values (on each backend);
* ``fig7_12.png``: bars per agent, abstract / physics / thesis, 95 % CIs (the thesis's from its mean and sd).

    MUJOCO_GL=egl .venv/bin/python scripts/reproduce_fig7_12.py --out runs/fig7_12 [--workers 1 --markdown]

The runs are resumable (``--out``): ``trials pursuit --pairs --backend abstract,mujoco --agents ... --out
runs/fig7_12`` writes the same folders.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from embodied_adhoc.experiments.domains.pursuit_pairs import (
    THESIS_FIG_7_12,
    THESIS_TRIALS,
    pomdp_options,
    thesis_in_our_count,
)
from embodied_adhoc.experiments.runner import SweepConfig, SweepResult, run_sweep
from embodied_adhoc.experiments.script_args import parse_dataclass_args
from embodied_adhoc.experiments.stats import welch_test
from embodied_adhoc.experiments.tables import CI_HEADER, fmt, format_table, interval, mean_sd, p_value

AGENTS = ("oracle", "perseus", "known-task", "hotspot", "atpo", "bopa", "random")
THESIS = {agent: (mean, sd) for agent, (mean, sd, _) in THESIS_FIG_7_12.items()}  # population sds
CAP = 150


@dataclass(frozen=True)
class Args:
    out: Path = Path("runs/fig7_12")
    """folder of the runs (one per backend, resumable) and the plot"""
    episodes: int = 32
    """episodes per agent and backend (the thesis ran 32)"""
    seed: int = 0
    """seed of the sweeps (same episodes on every backend)"""
    backends: str = "abstract,mujoco"
    """comma-separated backends"""
    agents: str = ",".join(AGENTS)
    """comma-separated agents (default all; atpo and perseus solve their Perseus policies first, ~45 s CPU per task)"""
    workers: int = 1
    """worker processes (results do not depend on it)"""
    markdown: bool = False
    """print Markdown tables (for the docs)"""


def _agents(results: dict[str, SweepResult]) -> list[str]:
    return [a for a in AGENTS if all(a in r.summary().agents for r in results.values())]


def _steps(result: SweepResult, agent: str) -> list[int]:
    return [r.steps for r in sorted(result.records, key=lambda r: r.episode) if r.agent == agent]


def results_table(results: dict[str, SweepResult], markdown: bool) -> str:
    backends = list(results)
    rows = []
    for agent in _agents(results):
        row = [agent]
        for backend in backends:
            s = results[backend].summary().agents[agent]
            row += [mean_sd(s.steps), interval(s.steps), fmt(s.success_rate)]
        if len(backends) == 2:
            first, second = (_steps(results[b], agent) for b in backends)
            _, p = welch_test(first, second)
            same = sum(a == b for a, b in zip(first, second, strict=True))
            row += [p_value(p), f"{same}/{len(first)}"]
        thesis = THESIS.get(agent)
        row.append(f"{thesis[0]:.2f} ± {thesis[1]:.2f}" if thesis else "-")
        row.append(fmt(thesis_in_our_count(agent)) if thesis else "-")
        rows.append(row)
    headers = ["agent"]
    for backend in backends:
        headers += [f"{backend} steps", f"{backend} {CI_HEADER}", f"{backend} success"]
    if len(backends) == 2:
        headers += [f"Welch p ({backends[0]} vs {backends[1]})", "same steps"]
    headers += ["thesis (its count)", "thesis, our count"]
    return format_table(headers, rows, markdown)


def claims_table(results: dict[str, SweepResult], markdown: bool) -> str:
    """The thesis's statements about Fig. 7.12 with our Welch p-values on each backend."""
    claims = [  # (claim, first, second, thesis p, expect a difference first < second)
        ("optimal < known task", "oracle", "known-task", "0.007", True),
        ("optimal < TEBOPA", "oracle", "hotspot", "0.00012", True),
        ("known task = TEBOPA", "known-task", "hotspot", "> 0.05", False),
        ("known task < random", "known-task", "random", "4e-8", True),
        ("TEBOPA < random", "hotspot", "random", "8.8e-8", True),
    ]
    rows = []
    present = _agents(results)
    for claim, first, second, thesis_p, expect_difference in claims:
        if first not in present or second not in present:
            continue
        row = [claim, thesis_p]
        for result in results.values():
            t, p = welch_test(_steps(result, first), _steps(result, second))
            significant = not math.isnan(p) and p < 0.05
            holds = (significant and t < 0) if expect_difference else not significant
            row += [p_value(p), "yes" if holds else "no"]
        rows.append(row)
    headers = ["thesis claim (Welch, alpha 0.05)", "p (thesis)"]
    for backend in results:
        headers += [f"p ({backend})", "holds"]
    return format_table(headers, rows, markdown)


def plot(results: dict[str, SweepResult], path: Path) -> Path:
    """Fig. 7.12 analogue: per agent, one bar per backend and the thesis's, with 95 % CIs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = _agents(results)
    series = {}
    for backend, result in results.items():
        agents = result.summary().agents
        series[backend] = [
            (agents[a].steps.mean, agents[a].steps.ci_low, agents[a].steps.ci_high) for a in names
        ]
    half = [1.96 * THESIS[a][1] / math.sqrt(THESIS_TRIALS) if a in THESIS else math.nan for a in names]
    ours = {a: thesis_in_our_count(a) for a in THESIS}
    series["thesis (our count)"] = [
        (ours[a], ours[a] - h, ours[a] + h) if a in THESIS else (math.nan,) * 3
        for a, h in zip(names, half, strict=True)
    ]
    x = np.arange(len(names))
    width = 0.8 / len(series)
    figure, axes = plt.subplots(figsize=(11, 4.2))
    for index, (label, values) in enumerate(series.items()):
        values = np.array(values, dtype=float)
        errors = np.vstack([values[:, 0] - values[:, 1], values[:, 2] - values[:, 0]])
        axes.bar(
            x + (index - (len(series) - 1) / 2) * width,
            values[:, 0],
            width,
            yerr=errors,
            capsize=3,
            label={"abstract": "grid twin", "mujoco": "MuJoCo arena"}.get(label, label),
        )
    axes.set_xticks(x, names)
    axes.set_yscale("log")
    axes.set_ylabel("steps to capture (mean, 95% CI; log)")
    axes.set_title(f"Fig. 7.12 analogue: two-predator pursuit, {THESIS_TRIALS} trials, cap {CAP}")
    axes.legend()
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def main() -> None:
    args = parse_dataclass_args(Args, __doc__)
    backends = [b.strip() for b in args.backends.split(",") if b.strip()]
    agents = tuple(a.strip() for a in args.agents.split(",") if a.strip())
    unknown = sorted(set(agents) - set(AGENTS))
    if unknown or not agents:
        print(f"--agents {args.agents}: choose from {','.join(AGENTS)}", file=sys.stderr)
        raise SystemExit(2)
    if "mujoco" in backends:
        from embodied_adhoc.gl import choose_gl_platform

        choose_gl_platform()
    results = {}
    for backend in backends:
        config = SweepConfig("pursuit", backend, pomdp_options(), agents, args.episodes, args.seed, CAP)
        results[backend] = run_sweep(config, out=args.out / backend, workers=args.workers, progress=True)
    print(
        f"Fig. 7.12, two-predator pursuit (pursuit-task POMDP as the world): {args.episodes} episodes per agent, "
        f"seed {args.seed}, cap {CAP}"
    )
    print()
    print(results_table(results, args.markdown))
    print()
    print(claims_table(results, args.markdown))
    path = plot(results, args.out / "fig7_12.png")
    timing = ", ".join(f"{b} {r.new_trials} new trials in {r.wall_time_s:.1f} s" for b, r in results.items())
    print(f"\n{timing}; wrote {path}")


if __name__ == "__main__":
    main()
