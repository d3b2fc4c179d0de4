"""Reproduce thesis chapter 4 on 5x5 pursuit: the PLASTIC reference and the sequential-teams protocol.

    .venv/bin/python scripts/reproduce_teamster.py [--trials 8] [--steps 5000] [--eval-steps 500] [--points 10]
        [--agents ...] [--changed fail:0.25|mirror] [--changed-steps N] [--out runs/teamster-pursuit] [--skip-protocol]
        [--size 5] [--wave N]

The mirrored-environment study (docs/teamster.md, Part B3): ``--agents teamster,plastic-model,learns-team,
plastic-policy --trials 8 --steps 500 --eval-steps 50 --points 5 --changed mirror --changed-steps 2500 --out
runs/teamster-mirror-t500`` (each (agent, trial) record depends only on the seed, the trial and the agent).

Part A, the PLASTIC reference (results-to-reproduce.md): prey captures per 500 steps with the teammate-aware
team for the ad hoc seat filled by a teammate-aware, greedy or probabilistic-destinations agent, by a random
agent and by PLASTIC-Model that already knows the three teams (exact models, as in Barrett et al.); ``--trials``
runs of 500 steps each, printed beside the reference (64, 32, 35, 11; PLASTIC-Policy 43); with ``--markdown``
as the pipe table that ``scripts/render_results.py run teamster-reference`` publishes, with its provenance.

Part B, section 4.1.4: ``embodied-adhoc teamster pursuit`` with the given options (resumable in ``--out``); the
table of captures per 500 steps after learning each team (Table 4.4's layout) and PLASTIC-Policy / TEAMSTER
evaluated on the teammate-aware team after learning it, beside the reference's PLASTIC-Policy.
The thesis's scale (8 trials, T = 5000) takes hours on two CPU cores; smaller options give a smaller study.
``--size 10`` runs part B on section 4.1.5's 10x10 world (part A stays the reference's 5x5 world).

Part C, the navigation maps (``--maps ntu,isr,pentagon``; ``--skip-pursuit`` leaves out A and B): with each team,
the team's own policy in the ad hoc seat ("Original Teammate"), a random agent and PLASTIC-Model that knows the
three teams, ``--episodes`` episodes of at most 100 steps each: the mean accumulated episode reward (-100 for an
episode that does not end), the share of episodes that end, and the mean over those (the original's final
evaluation re-ran an episode that did not end, so Tables 4.5-4.7 are means over ended episodes), beside the
thesis's rows. Unless ``--skip-protocol``, ``embodied-adhoc teamster MAP`` with the given options follows
(``--eval-episodes`` per evaluation, resumable in ``OUT-MAP``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from embodied_adhoc.cli import main as cli_main
from embodied_adhoc.domains.pursuit4 import TEAMS, ExactTeam, Pursuit4
from embodied_adhoc.experiments.domains.teamster_protocol import make_world, play, play_episodes
from embodied_adhoc.experiments.stats import summarise_sample
from embodied_adhoc.experiments.tables import format_table
from embodied_adhoc.learning.teamster_agents import build_agent

REFERENCE = {
    "teammate-aware": 64,
    "greedy": 32,
    "probabilistic-destinations": 35,
    "plastic-policy": 43,
    "random": 11,
}


def _cell(values) -> str:
    return _cells(summarise_sample(values), markdown=False)[0]


def _cells(s, markdown: bool) -> list[str]:
    """A sample's mean and interval: one cell for the terminal; two for the pipe tables, which
    render_results.py reads (the interval beside its mean)."""
    if markdown:
        return [f"{s.mean:.2f}", f"[{s.ci_low:.2f}, {s.ci_high:.2f}]"]
    return [f"{s.mean:.1f} [{s.ci_low:.1f}, {s.ci_high:.1f}]" if s.n > 1 else f"{s.mean:.1f}"]


def part_a(trials: int, seed: int) -> dict[str, list[int]]:
    world = Pursuit4()
    team = ExactTeam(world, "teammate-aware")
    out: dict[str, list[int]] = {}
    for name in ("teammate-aware", "greedy", "probabilistic-destinations", "random", "plastic-model"):
        counts = []
        for trial in range(trials):
            rng = np.random.default_rng([seed, trial, 7])
            agent = build_agent(name, world, np.random.default_rng([seed, trial, 8]), horizon=500)
            for known in TEAMS:
                agent.finish_team(known)  # PLASTIC-Model knows the three teams' exact models
            agent.start_team(np.random.default_rng([seed, trial, 9]))
            agent.set_evaluation(True)
            counts.append(play(agent, world, team, 500, rng))
        out[name] = counts
    return out


# Tables 4.5-4.7 (mean over 8 trials; eval on tau1, tau2, tau3): Original Teammate, Random Policy, and
# PLASTIC-Model after learning the three teams.
THESIS_MAPS = {
    "ntu": {
        "original": (98.0, 98.0, 97.83),
        "random": (79.58, 69.0, 69.12),
        "plastic-model": (98.0, 97.96, 97.67),
    },
    "isr": {
        "original": (94.0, 94.0, 94.0),
        "random": (60.0, 69.17, 64.04),
        "plastic-model": (92.71, 92.62, 93.62),
    },
    "pentagon": {
        "original": (91.67, 88.0, 91.83),
        "random": (66.17, 61.92, 80.79),
        "plastic-model": (91.54, 84.08, 91.21),
    },
}


def part_c(map_name: str, episodes: int, seed: int, markdown: bool = False) -> list[list[str]]:
    """Rows (agent, team, mean [CI], ended share, mean over ended episodes, thesis) of the map baselines; with
    ``markdown`` the mean and its interval take a column each (render_results.py compares the one to the other)."""
    world = make_world(map_name)
    rows = []
    for name in ("original", "random", "plastic-model"):
        agent = build_agent(name, world, np.random.default_rng([seed, 8]), horizon=episodes)
        for known in world.teams:
            agent.finish_team(known)  # PLASTIC-Model knows the three teams' exact models
        agent.start_team(np.random.default_rng([seed, 9]))
        agent.set_evaluation(True)
        for k, team in enumerate(world.teams):
            returns = np.array(
                play_episodes(
                    agent, world, ExactTeam(world, team), episodes, np.random.default_rng([seed, k, 7])
                )
            )
            ended = returns > -world.episode_cap
            rows.append(
                [
                    name,
                    team,
                    *_cells(summarise_sample(returns), markdown),
                    f"{ended.mean():.2f}",
                    f"{returns[ended].mean():.2f}" if ended.any() else "-",
                    f"{THESIS_MAPS.get(map_name, {}).get(name, ('-',) * 3)[k]}",
                ]
            )
    return rows


def _changed(args: argparse.Namespace) -> list[str]:
    """The command's changed-phase options (none when --changed is 0)."""
    if args.changed.strip() in ("0", "0.0", "fail:0"):
        return []
    steps = [] if args.changed_steps is None else ["--changed-steps", str(args.changed_steps)]
    return ["--changed", args.changed] + steps


def _wave(args: argparse.Namespace) -> list[str]:
    return [] if args.wave is None else ["--wave", str(args.wave)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=8)
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument("--eval-steps", type=int, default=500)
    parser.add_argument("--points", type=int, default=10)
    parser.add_argument(
        "--changed", default="0", help="the changed phase: fail:P (or P) or mirror (default none)"
    )
    parser.add_argument(
        "--changed-steps", type=int, default=None, help="its interaction steps (default --steps)"
    )
    parser.add_argument(
        "--agents",
        default="teamster,plastic-model,learns-team,learns-environment,plastic-policy,random,original",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="runs/teamster-pursuit")
    parser.add_argument("--skip-protocol", action="store_true", help="part A only (part C only on the maps)")
    parser.add_argument(
        "--maps", default="", help="comma-separated navigation maps for part C (ntu,isr,pentagon)"
    )
    parser.add_argument("--episodes", type=int, default=40, help="part C: episodes per (agent, team)")
    parser.add_argument(
        "--eval-episodes", type=int, default=8, help="maps' protocol: episodes per evaluation"
    )
    parser.add_argument("--skip-pursuit", action="store_true", help="parts A and B left out")
    parser.add_argument(
        "--size", type=int, default=5, help="part B: pursuit's torus side (section 4.1.5's larger world: 10)"
    )
    parser.add_argument(
        "--wave", type=int, default=None, help="UCT simulations per wave (default the planner's)"
    )
    parser.add_argument(
        "--markdown",
        action="store_true",
        help="parts A and C as pipe tables with the mean and its interval in columns of their own "
        "(render_results.py)",
    )
    args = parser.parse_args()

    for map_name in [m for m in args.maps.split(",") if m]:
        rows = part_c(map_name, args.episodes, args.seed, markdown=args.markdown)
        if args.markdown:
            print(
                f"Part C: {map_name}, {args.episodes} episodes per row of seed {args.seed} (accumulated episode "
                "reward, mean and 95 % percentile-bootstrap interval over the episodes)"
            )
            headers = ["ad hoc agent", "team", "mean", "95 % CI", "ended", "mean of ended", "thesis"]
            print(format_table(headers, rows, markdown=True))
        else:
            print(f"Part C: {map_name}, {args.episodes} episodes per row (accumulated episode reward)")
            headers = ["ad hoc agent", "team", "mean [95% CI]", "ended", "mean of ended", "thesis"]
            print(format_table(headers, rows))
        if not args.skip_protocol:
            out = f"{args.out}-{map_name}"
            command = [
                "teamster",
                map_name,
                "--agents",
                args.agents,
                "--steps",
                str(args.steps),
                "--trials",
                str(args.trials),
                "--eval-episodes",
                str(args.eval_episodes),
                "--points",
                str(args.points),
                "--seed",
                str(args.seed),
                "--out",
                out,
                "--quiet",
            ]
            command += _changed(args) + _wave(args)
            if cli_main(command) != 0:
                raise SystemExit(2)
            print("\n" + Path(out, "table.md").read_text())
    if args.skip_pursuit:
        return

    counts = part_a(args.trials, args.seed)
    if args.markdown:
        rows = []
        for name, values in counts.items():
            rows.append([name, *_cells(summarise_sample(values), True), str(REFERENCE.get(name, "-"))])
        print(
            f"Part A: prey captures per 500 steps with the teammate-aware team ({args.trials} runs of seed "
            f"{args.seed} on, mean and 95 % percentile-bootstrap interval over the runs)"
        )
        print(format_table(["ad hoc agent", "captures", "95 % CI", "PLASTIC reference"], rows, markdown=True))
    else:
        rows = [[name, _cell(values), str(REFERENCE.get(name, "-"))] for name, values in counts.items()]
        print(
            f"Part A: prey captures per 500 steps with the teammate-aware team ({args.trials} runs, mean [95% CI])"
        )
        print(format_table(["ad hoc agent", "ours", "PLASTIC reference"], rows))

    if args.skip_protocol:
        return
    print(
        f"\nPart B: sequential teams (T={args.steps}, {args.trials} trials, evaluations of {args.eval_steps} steps)"
    )
    command = [
        "teamster",
        "pursuit",
        "--agents",
        args.agents,
        "--steps",
        str(args.steps),
        "--trials",
        str(args.trials),
        "--eval-steps",
        str(args.eval_steps),
        "--points",
        str(args.points),
        "--seed",
        str(args.seed),
        "--out",
        args.out,
        "--quiet",
    ]
    command += _changed(args) + ["--size", str(args.size)] + _wave(args)
    if cli_main(command) != 0:
        raise SystemExit(2)
    summary = json.loads(Path(args.out, "summary.json").read_text())
    print("\n" + Path(args.out, "table.md").read_text())
    rows = []
    for agent in ("plastic-policy", "teamster", "plastic-model", "learns-team", "learns-environment"):
        if agent in summary:
            cell = summary[agent]["after"]["teammate-aware"]["teammate-aware"]["per_500"]
            rows.append(
                [
                    agent,
                    f"{cell['mean']:.1f} [{cell['ci'][0]:.1f}, {cell['ci'][1]:.1f}]",
                    str(REFERENCE.get(agent, "-")),
                ]
            )
    print("After learning the teammate-aware team, evaluated on it (captures per 500 steps)")
    print(format_table(["ad hoc agent", "ours", "PLASTIC reference"], rows))


if __name__ == "__main__":
    main()
