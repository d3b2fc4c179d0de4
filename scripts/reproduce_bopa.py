"""Reproduce thesis Table 5.1: BOPA on Panic Buttons (3x3, 4x4, 5x5; optimal, sub-optimal and random teammates).

For every grid size and teammate, one sweep of 32 episodes (button configuration and start state drawn once per
episode from --seed, the same for the three agents) of:

* ``greedy``: the agent that knows the task and sees the state (``value-iteration`` in the trial runner);
* ``bopa``: BOPA over the three button configurations (section 5.1, Eqs. 5.1-5.2);
* ``random``: uniform actions.

Prints steps to finish, ours (mean ± sd, 95 % seeded percentile-bootstrap interval of the mean) beside the
thesis's (mean ± the thesis's spread,
taken as a standard deviation of 32 trials), the Welch p-value of ours against the thesis's (from summary
statistics) and, per setting, the Welch test of BOPA against greedy. Our episodes end on entering the absorbing
state, one step after the buttons are pressed (the step that collects the +100), so "ours - 1" is the thesis's
count of steps to press and the one compared. Writes the runs (resumable) and a plot::

    .venv/bin/python scripts/reproduce_bopa.py --out runs/reproduce_bopa [--episodes 32 --seed 0]
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from embodied_adhoc.experiments.runner import SweepConfig, SweepResult, run_sweep
from embodied_adhoc.experiments.script_args import parse_dataclass_args
from embodied_adhoc.experiments.stats import welch_test, welch_test_from_stats
from embodied_adhoc.experiments.tables import CI_HEADER, fmt, format_table, interval, mean_sd, p_value

AGENTS = {"greedy": "value-iteration", "bopa": "bopa", "random": "random"}
TEAMMATES = ("optimal", "suboptimal", "random")
THESIS = {  # Table 5.1: (grid, agent) -> (mean, spread) of steps per teammate (optimal, sub-optimal, random)
    (3, "greedy"): ((2.7, 0.5), (3.4, 1.2), (24.2, 23.3)),
    (3, "bopa"): ((3.3, 0.8), (4.3, 2.3), (35.9, 37.7)),
    (3, "random"): ((25.2, 27.4), (26.7, 28.2), (144.8, 154.1)),
    (4, "greedy"): ((4.0, 0.8), (5.2, 1.9), (54.0, 56.1)),
    (4, "bopa"): ((4.7, 0.8), (6.0, 2.4), (61.0, 67.0)),
    (4, "random"): ((47.3, 50.6), (56.8, 59.2), (497.4, 426.3)),
    (5, "greedy"): ((5.3, 0.9), (6.7, 1.6), (85.7, 97.4)),
    (5, "bopa"): ((5.8, 0.8), (8.5, 3.7), (168.8, 169.5)),
    (5, "random"): ((104.7, 106.9), (103.3, 109.0), (1120.4, 1003.1)),
}
THESIS_TRIALS = 32


@dataclass(frozen=True)
class Args:
    out: Path = Path("runs/reproduce_bopa")
    """folder of the runs (resumable) and the plot"""
    episodes: int = 32
    """episodes per agent and setting (the thesis ran 32)"""
    seed: int = 0
    """seed of every sweep"""
    sizes: tuple[int, ...] = (3, 4, 5)
    """grid sizes"""
    max_steps: int = 5000
    """step cap per episode (the thesis gives none; random teams on 5x5 need ~1,000 steps)"""
    workers: int = 1
    """worker processes (results do not depend on it)"""
    markdown: bool = False
    """print Markdown tables (for the README)"""


def run_setting(args: Args, size: int, teammate: str) -> SweepResult:
    options = {
        "library": {"size": size, "teammate": teammate},
        "task": None,
        "beliefs": None,
        "solve_stages": None,  # no Perseus here: greedy, BOPA and random use value iteration
        "solve_seconds": None,
        "cache": True,
    }
    config = SweepConfig(
        "panic-buttons", "abstract", options, tuple(AGENTS.values()), args.episodes, args.seed, args.max_steps
    )
    return run_sweep(config, out=args.out / f"{size}x{size}-{teammate}", workers=args.workers, progress=True)


def table(results: dict[tuple[int, str], SweepResult], markdown: bool) -> str:
    rows = []
    for (size, teammate), result in results.items():
        summary = result.summary().agents
        for label, agent in AGENTS.items():
            steps = summary[agent].steps
            thesis_mean, thesis_sd = THESIS[(size, label)][TEAMMATES.index(teammate)]
            _, p = welch_test_from_stats(
                steps.mean - 1, steps.sd, steps.n, thesis_mean, thesis_sd, THESIS_TRIALS
            )
            rows.append([
                f"{size}x{size}", teammate, label, mean_sd(steps), interval(steps), fmt(steps.mean - 1),
                fmt(summary[agent].success_rate), f"{thesis_mean:.1f} ± {thesis_sd:.1f}", p_value(p),
            ])  # fmt: skip
    headers = ("grid", "teammate", "agent", "steps (ours)", CI_HEADER, "ours - 1", "success", "steps (thesis)",
               "Welch p (ours - 1 vs thesis)")  # fmt: skip
    return format_table(headers, rows, markdown)


def bopa_vs_greedy(results: dict[tuple[int, str], SweepResult], markdown: bool) -> str:
    rows = []
    for (size, teammate), result in results.items():
        greedy = [r.steps for r in result.records if r.agent == "value-iteration"]
        bopa = [r.steps for r in result.records if r.agent == "bopa"]
        identified = [
            r.identify_step for r in result.records if r.agent == "bopa" and r.identify_step is not None
        ]
        t, p = welch_test(bopa, greedy)
        share = len(identified) / max(1, len(bopa))
        mean_identify = fmt(sum(identified) / len(identified)) if identified else "-"
        rows.append([f"{size}x{size}", teammate, fmt(t), p_value(p), fmt(share), mean_identify])
    headers = ("grid", "teammate", "Welch t (bopa - greedy)", "Welch p", "identified", "identify step")
    return format_table(headers, rows, markdown)


def plot(results: dict[tuple[int, str], SweepResult], path: Path) -> Path:
    from embodied_adhoc.experiments.plots import plot_settings

    summaries = {f"{s}x{s} {t}": r.summary() for (s, t), r in results.items()}
    return plot_settings(summaries, path, "Table 5.1 analogue: Panic Buttons, steps to finish")


def main() -> None:
    args = parse_dataclass_args(Args, __doc__)
    results = {
        (size, teammate): run_setting(args, size, teammate) for size in args.sizes for teammate in TEAMMATES
    }
    print(f"Table 5.1, Panic Buttons: {args.episodes} episodes per agent and setting, seed {args.seed}")
    print()
    print(table(results, args.markdown))
    print()
    print(bopa_vs_greedy(results, args.markdown))
    path = plot(results, args.out / "table5_1_steps.png")
    wall = sum(r.wall_time_s for r in results.values())
    print(f"\n{sum(r.new_trials for r in results.values())} new trials in {wall:.1f} s; wrote {path}")


if __name__ == "__main__":
    main()
