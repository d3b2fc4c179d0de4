"""Fig. 7.12's gap to the thesis, measured: our model and protocol against the original experiment's, one switch at
a time (see :mod:`embodied_adhoc.experiments.domains.pursuit_pairs_ablation` for what each switch is and where it comes
from in the original code).

Every row runs oracle, known-task, HOTSPOT (TEBOPA) and random on the same episode draws of its library (``--seed``,
``--episodes``; cap 150) and counts steps the original's way (to the capture reward: ours + 1). Beside each mean:
the Welch p-value against the thesis's 32 trials (from their mean and sd).

    .venv/bin/python scripts/ablate_fig7_12.py [--episodes 32 --seed 0 --markdown]
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass

import numpy as np
from scipy import stats

from embodied_adhoc.envs.pursuit_pomdp import pursuit_pair_library
from embodied_adhoc.experiments.domains.pursuit_pairs import THESIS_FIG_7_12, THESIS_TRIALS
from embodied_adhoc.experiments.domains.pursuit_pairs_ablation import (
    ABLATION_AGENTS,
    ablation_steps,
    original_library,
    with_locate,
)
from embodied_adhoc.experiments.script_args import parse_dataclass_args
from embodied_adhoc.experiments.tables import format_table, p_value

ROWS = (  # (label, torus wrap, tasks, "locate" action for HOTSPOT and known-task, HOTSPOT reward gain)
    ("ours (Fig. 7.12 as built)", "modular", 4, False, "conditional"),
    ("ours, 2 tasks (N+S, W+E)", "modular", 2, False, "conditional"),
    ("original wrap, 4 tasks", "original", 4, False, "conditional"),
    ("original wrap, 2 tasks", "original", 2, False, "conditional"),
    ("original wrap, 2 tasks, + locate", "original", 2, True, "conditional"),
    ("original wrap, 2 tasks, gain 'thesis'", "original", 2, False, "thesis"),
    ("original wrap, 2 tasks, + locate, gain 'thesis'", "original", 2, True, "thesis"),
    ("original wrap, 2 tasks, gain 'none' (original code)", "original", 2, False, "none"),
)
"""The original ran oracle and random on its 5-action models and TEBOPA / known task on the 6-action ones."""


@dataclass(frozen=True)
class Args:
    episodes: int = 32
    """episodes per agent and row (the thesis ran 32)"""
    seed: int = 0
    """seed of the episode draws and the agents"""
    markdown: bool = False
    """print a Markdown table"""


def thesis_p(sample: np.ndarray, agent: str) -> float:
    """Welch p-value of ``sample`` against the thesis's 32 trials (population sd converted to ddof 1)."""
    mean, sd, _ = THESIS_FIG_7_12[agent]
    sd = sd * math.sqrt(THESIS_TRIALS / (THESIS_TRIALS - 1))
    return float(
        stats.ttest_ind_from_stats(
            sample.mean(), sample.std(ddof=1), sample.size, mean, sd, THESIS_TRIALS, equal_var=False
        ).pvalue
    )


def main() -> None:
    args = parse_dataclass_args(Args, __doc__)
    if args.episodes < 2:
        print(f"--episodes {args.episodes}: at least 2 (a standard deviation)", file=sys.stderr)
        raise SystemExit(2)
    library = pursuit_pair_library()
    rows = []
    for label, wrap, n_tasks, locate, gain in ROWS:
        variant = original_library(library, wrap, n_tasks)
        steps = ablation_steps(variant, ABLATION_AGENTS, args.episodes, args.seed, reward_gain=gain)
        if locate:
            steps.update(
                ablation_steps(
                    with_locate(variant),
                    ("known-task", "hotspot"),
                    args.episodes,
                    args.seed,
                    reward_gain=gain,
                )
            )
        row = [label]
        for agent in ABLATION_AGENTS:
            sample = steps[agent]
            row.append(
                f"{sample.mean():.2f} ± {sample.std(ddof=1):.2f} (p {p_value(thesis_p(sample, agent))})"
            )
        rows.append(row)
        print(f"done: {label}", flush=True)
    rows.append(
        ["thesis (original's result files)"]
        + [
            f"{THESIS_FIG_7_12[a][0]:.2f} ± "
            f"{THESIS_FIG_7_12[a][1] * math.sqrt(THESIS_TRIALS / (THESIS_TRIALS - 1)):.2f}"
            for a in ABLATION_AGENTS
        ]
    )
    print(
        f"\nFig. 7.12 ablation: {args.episodes} episodes per cell, seed {args.seed}, cap 150, steps to the capture "
        "reward (mean ± sd, Welch p vs the thesis)\n"
    )
    print(format_table(["model and protocol", *ABLATION_AGENTS], rows, args.markdown))


if __name__ == "__main__":
    main()
