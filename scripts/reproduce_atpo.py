"""Reproduce thesis Tables 5.5 and 5.6, Fig. 5.9 and the belief dynamics of ATPO (section 5.2) in one command.

For each of the eleven domains of Table 5.2, one sweep of 32 episodes (true model and start state drawn once per
episode from --seed, shared by the six agents) over Table 5.2's horizon h: value-iteration, perseus, atpo,
random-picker, bopa (not on the power plant) and random. Perseus policies (Table 5.2's belief-set sizes unless
--beliefs, tolerance 0.01, at most the domain's ``SOLVE_STAGES`` stages per model unless --solve-stages: a budget
that does not depend on the machine's load, so two runs give the same table) are cached on disk, so a second run
costs only the trials. Prints:

* Table 5.5: accumulated reward, ours (mean ± sd, 95 % seeded percentile-bootstrap interval of the mean,
  ``experiments.stats``) beside the thesis's (mean ± sd), with the Welch p-value of ours against the thesis's
  (summary statistics, n = 32 both sides);
* Table 5.6: ATPO normalised between random (0 %) and value iteration (100 %), ours and the thesis's;
* the original's model bugs (``--with-bugs``): ntu, mit and overcooked rebuilt with the bug, beside the fix;
* Fig. 5.9: ATPO's normalised score on gridworld for library sizes --library-sizes (normalised by this run's
  4-model gridworld value-iteration and random, as the thesis did with Table 5.5's), with the bootstrap interval
  of ATPO's mean reward through the same normalisation and whether the thesis's "above 70 %" holds;
* belief dynamics: how often ATPO's most likely model is the true one after 5, 10 and 20 steps.

Writes every run (resumable) under --out, and ``table5_5.png`` and ``fig5_9.png``::

    .venv/bin/python scripts/reproduce_atpo.py --out runs/reproduce_atpo [--episodes 32 --with-bugs --markdown]
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from embodied_adhoc.experiments.domains.chapter5 import (
    CHAPTER5_AGENTS,
    SOLVE_STAGES,
    TABLE_5_5_DOMAINS,
    sweep_config,
    table_agents,
)
from embodied_adhoc.experiments.runner import SweepResult, run_sweep
from embodied_adhoc.experiments.script_args import parse_dataclass_args
from embodied_adhoc.experiments.stats import welch_test_from_stats
from embodied_adhoc.experiments.tables import CI_HEADER, bounds, fmt, format_table, interval, mean_sd, p_value

DOMAINS = TABLE_5_5_DOMAINS
THESIS = {  # Table 5.5: (mean, sd) per agent, in CHAPTER5_AGENTS order (None: n/a)
    "gridworld": ((95.62, 1.54), (93.44, 3.13), (86.53, 9.12), (39.91, 61.34), (93.38, 3.14), (5.88, 64.13)),
    "pursuit-both": (
        (90.19, 8.32),
        (84.44, 11.76),
        (82.72, 12.81),
        (35.34, 63.18),
        (90.06, 7.47),
        (20.72, 69.47),
    ),
    "pursuit-task": (
        (92.72, 4.87),
        (88.03, 7.51),
        (82.59, 11.18),
        (47.59, 55.46),
        (92.81, 3.48),
        (14.59, 71.34),
    ),
    "pursuit-teammate": (
        (89.88, 8.38),
        (86.97, 12.04),
        (86.41, 14.52),
        (81.34, 31.56),
        (91.38, 6.13),
        (-7.66, 78.7),
    ),
    "power-plant": ((94.91, 1.99), (95.12, 2.1), (94.75, 2.35), (93.81, 4.97), None, (47.44, 62.31)),
    "ntu": ((98.0, 0.0), (97.25, 0.43), (97.19, 0.53), (97.28, 0.51), (98.0, 0.0), (88.0, 7.42)),
    "overcooked": (
        (39.12, 60.73),
        (39.0, 60.63),
        (25.31, 66.43),
        (27.94, 64.58),
        (24.81, 66.19),
        (-46.75, 18.1),
    ),
    "isr": ((92.41, 2.68), (91.16, 4.68), (82.62, 12.19), (60.59, 59.15), (91.66, 4.22), (-23.31, 68.05)),
    "mit": ((84.5, 0.87), (84.09, 0.58), (83.72, 0.57), (83.75, 0.75), (84.31, 0.88), (-71.41, 20.01)),
    "pentagon": ((91.0, 0.0), (90.62, 0.6), (81.19, 11.04), (53.28, 56.53), (85.5, 6.71), (-45.94, 55.14)),
    "cit": ((86.22, 2.27), (85.09, 2.53), (75.66, 9.52), (69.91, 14.46), (84.88, 2.94), (-81.25, 20.88)),
}
THESIS_TRIALS = 32
BUGGY = ("ntu", "mit", "overcooked")
BELIEF_STEPS = (5, 10, 20)


@dataclass(frozen=True)
class Args:
    out: Path = Path("runs/reproduce_atpo")
    """folder of the runs (resumable) and the plots"""
    episodes: int = 32
    """episodes per agent and domain (the thesis ran 32)"""
    seed: int = 0
    """seed of every sweep"""
    domains: tuple[str, ...] = DOMAINS
    """domains of Table 5.5"""
    solve_stages: int = 0
    """Perseus stages per model at most (0: each domain's SOLVE_STAGES)"""
    solve_seconds: float = 0.0
    """also a wall-clock limit per model (0: none; with one the table depends on the machine's load)"""
    beliefs: int = 0
    """Perseus belief-set size (0: Table 5.2's)"""
    library_sizes: tuple[int, ...] = (2, 4, 8, 16, 32)
    """Fig. 5.9: gridworld library sizes (the thesis's 2 to 32); none with --skip-fig59"""
    skip_fig59: bool = False
    """do not run Fig. 5.9"""
    with_bugs: bool = False
    """also run ntu, mit and overcooked with the original's model bugs"""
    workers: int = 1
    """worker processes (each solves the policies it needs, or reads them from the cache)"""
    executor: str = "local"
    """local (this process or a process pool) or ray (RAY_ADDRESS: that cluster; else a private one)"""
    markdown: bool = False
    """print Markdown tables (for the README)"""


def sweep(args: Args, domain: str, library: dict, agents: tuple[str, ...], folder: str) -> SweepResult:
    config = sweep_config(
        domain, library, agents, args.episodes, args.seed, args.solve_stages or None, args.beliefs or None,
        args.solve_seconds or None,
    )  # fmt: skip
    return run_sweep(
        config, out=args.out / folder, workers=args.workers, executor=args.executor, progress=True
    )


def returns(result: SweepResult, agent: str) -> list[float]:
    return [r.total_reward for r in result.records if r.agent == agent]


def normalised(
    result: SweepResult, agent: str = "atpo", low: float | None = None, high: float | None = None
) -> float:
    """Table 5.6: ``(agent - random) / (value-iteration - random)`` on mean accumulated reward."""
    low = np.mean(returns(result, "random")) if low is None else low
    high = np.mean(returns(result, "value-iteration")) if high is None else high
    return float((np.mean(returns(result, agent)) - low) / (high - low)) if high != low else math.nan


def table_5_5(results: dict[str, SweepResult], markdown: bool) -> str:
    rows = []
    for label, result in results.items():
        domain = label.split(" ")[0]
        summary = result.summary().agents
        for k, agent in enumerate(CHAPTER5_AGENTS):
            if agent not in summary:
                continue
            sample = summary[agent].total_reward
            thesis = THESIS[domain][k]
            p = math.nan
            if thesis is not None:  # the "(bug)" rows too: the thesis's numbers came from the buggy models
                _, p = welch_test_from_stats(sample.mean, sample.sd, sample.n, *thesis, THESIS_TRIALS)
            thesis_text = "n/a" if thesis is None else f"{thesis[0]:.2f} ± {thesis[1]:.2f}"
            rows.append(
                [
                    label,
                    agent,
                    mean_sd(sample),
                    interval(sample),
                    thesis_text,
                    p_value(p) if not math.isnan(p) else "-",
                ]
            )
    headers = ("domain", "agent", "reward (ours)", CI_HEADER, "reward (thesis)", "Welch p vs thesis")
    return format_table(headers, rows, markdown)


def thesis_normalised(domain: str) -> float:
    vi, _, atpo, _, _, random = THESIS[domain]
    return (atpo[0] - random[0]) / (vi[0] - random[0])


def table_5_6(results: dict[str, SweepResult], markdown: bool) -> str:
    rows = []
    for label, result in results.items():
        domain = label.split(" ")[0]
        ours = normalised(result)
        picker = normalised(result, "random-picker")
        perseus = normalised(result, "perseus")
        rows.append([label, f"{100 * ours:.1f} %", f"{100 * perseus:.1f} %", f"{100 * picker:.1f} %",
                     f"{100 * thesis_normalised(domain):.1f} %", "yes" if ours >= 0.8 else "no"])  # fmt: skip
    headers = ("domain", "ATPO (ours)", "Perseus (ours)", "random-picker (ours)", "ATPO (thesis)", ">= 80 %")
    return format_table(headers, rows, markdown)


def belief_dynamics(args: Args, results: dict[str, SweepResult], markdown: bool) -> str:
    """Share of ATPO trials whose most likely model is the true one after 5, 10, 20 steps (from steps.csv; a trial
    that ended earlier counts with its last posterior)."""
    rows = []
    for label, result in results.items():
        folder = args.out / label.replace(" ", "-")
        true_task = {r.episode: int(r.spec["task"]) for r in result.records if r.agent == "atpo"}
        posteriors: dict[int, list[list[float]]] = {}
        with open(folder / "steps.csv", encoding="utf-8", newline="") as stream:
            for row in csv.DictReader(stream):
                if row["agent"] == "atpo" and int(row["episode"]) in true_task:
                    values = [float(row[key]) for key in row if key.startswith("posterior_")]
                    posteriors.setdefault(int(row["episode"]), []).append(values)
        shares = []
        for step in BELIEF_STEPS:
            hits = [
                int(np.argmax(trace[min(step, len(trace) - 1)]) == true_task[episode])
                for episode, trace in posteriors.items()
            ]
            shares.append(f"{100 * np.mean(hits):.0f} %" if hits else "-")
        identify = [
            r.identify_step for r in result.records if r.agent == "atpo" and r.identify_step is not None
        ]
        rows.append([label, *shares, fmt(float(np.mean(identify))) if identify else "-"])
    headers = ("domain", *(f"true model most likely after {s}" for s in BELIEF_STEPS), "identify step (mean)")
    return (
        format_table(headers, rows, markdown)
        + "\n(thesis: ~5 steps on average, ~70 % after 10, ~90 % after 20)"
    )


def figure_5_9(args: Args, reference: SweepResult) -> tuple[str, Path | None]:
    low = float(np.mean(returns(reference, "random")))
    high = float(np.mean(returns(reference, "value-iteration")))
    scores, intervals, rows = {}, {}, []
    span = 100 / (high - low) if high != low else math.nan
    for size in args.library_sizes:
        result = sweep(args, "gridworld", {"n_models": size}, ("atpo",), f"fig5_9-{size}")
        scores[size] = normalised(result, "atpo", low, high)
        # the interval of ATPO's mean reward through the same normalisation, the reference's means held fixed
        sample = result.summary().agents["atpo"].total_reward
        intervals[size] = ((sample.ci_low - low) * span, (sample.ci_high - low) * span)
        ci = bounds(*intervals[size], 1)
        rows.append(
            [f"{size} models", f"{100 * scores[size]:.1f} %", ci, "yes" if scores[size] > 0.7 else "no"]
        )
    headers = ("library size", "ATPO normalised (ours)", f"{CI_HEADER}, %", "> 70 %")
    table = format_table(headers, rows, args.markdown)
    from embodied_adhoc.experiments.plots import _pyplot, _save

    plt = _pyplot()
    figure, axes = plt.subplots(figsize=(6, 3.5))
    sizes = list(scores)
    axes.fill_between(
        sizes, [intervals[k][0] for k in sizes], [intervals[k][1] for k in sizes], alpha=0.2, label=CI_HEADER
    )
    axes.plot(sizes, [100 * s for s in scores.values()], marker="o", label="ATPO (ours)")
    axes.axhline(70, color="grey", linestyle="--", label="thesis: stays above 70 %")
    axes.set_xlabel("library size |M|")
    axes.set_ylabel("normalised score (%)")
    axes.set_title("Fig. 5.9 analogue: gridworld")
    axes.legend()
    return table, _save(figure, args.out / "fig5_9.png")


def plot_table(results: dict[str, SweepResult], path: Path) -> Path:
    from embodied_adhoc.experiments.plots import _pyplot, _save

    plt = _pyplot()
    labels = list(results)
    figure, axes = plt.subplots(figsize=(max(8, len(labels)), 4))
    width = 0.8 / len(CHAPTER5_AGENTS)
    for k, agent in enumerate(CHAPTER5_AGENTS):
        means = [np.mean(returns(r, agent)) if returns(r, agent) else np.nan for r in results.values()]
        axes.bar(np.arange(len(labels)) + k * width, means, width, label=agent)
    axes.set_xticks(np.arange(len(labels)) + 0.4 - width / 2, labels, rotation=30, ha="right")
    axes.set_ylabel("accumulated reward")
    axes.set_title("Table 5.5 analogue")
    axes.legend(fontsize="small", ncol=3)
    return _save(figure, path)


def main() -> None:
    args = parse_dataclass_args(Args, __doc__)
    results = {domain: sweep(args, domain, {}, table_agents(domain), domain) for domain in args.domains}
    if args.with_bugs:
        for domain in BUGGY:
            label = f"{domain} (bug)"
            results[label] = sweep(
                args, domain, {"bug_compatible": True}, table_agents(domain), label.replace(" ", "-")
            )
    stages = args.solve_stages or ", ".join(f"{d} {SOLVE_STAGES[d]}" for d in args.domains)
    limit = f", <= {args.solve_seconds:g} s" if args.solve_seconds else ""
    print(f"Table 5.5: {args.episodes} episodes per agent and domain, seed {args.seed}; Perseus stages per model at "
          f"most: {stages}{limit}")  # fmt: skip
    print()
    print(table_5_5(results, args.markdown))
    print()
    print("Table 5.6: ATPO normalised between random (0 %) and value iteration (100 %)")
    print(table_5_6(results, args.markdown))
    print()
    print(belief_dynamics(args, results, args.markdown))
    paths = [plot_table(results, args.out / "table5_5.png")]
    if not args.skip_fig59 and "gridworld" in results:
        table, path = figure_5_9(args, results["gridworld"])
        print()
        print("Fig. 5.9: ATPO normalised on gridworld by library size (0 % random, 100 % value iteration of the "
              "4-model run; the thesis: stays above 70 %)")  # fmt: skip
        print(table)
        paths.append(path)
    wall = sum(r.wall_time_s for r in results.values())
    print(f"\nTable 5.5 sweeps: {sum(r.new_trials for r in results.values())} new trials, {wall:.1f} s (building, "
          f"solving and trials); wrote {', '.join(str(p) for p in paths)}")  # fmt: skip


if __name__ == "__main__":
    main()
