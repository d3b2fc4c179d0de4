"""``embodied-adhoc teamster DOMAIN``: the sequential-teams protocol of thesis section 4.1.4 (TEAMSTER and its
baselines, chapter 4) on DOMAIN (pursuit: 5x5 toroidal, four predators; ntu, isr, pentagon: 4, 3, 3 agents
leaving a facility by its exits, teams altruistic, selfish, weighted-altruistic, evaluated by the mean reward of
``--eval-episodes`` episodes; all fully observable).

Each agent is paired with the teammate-aware, greedy and probabilistic-destinations teams in turn for ``--steps``
steps each, learning, evaluated (``--eval-steps`` steps, learning paused) before and after every 10 % of the
interaction and, after each team, on all three. ``--changed fail:P`` adds the changed-environment phase
(predator moves fail with probability P; a bare P means the same), ``--changed mirror`` one where the ad hoc
agent's moves are mirrored (up <-> down, left <-> right), for ``--changed-steps`` steps (default ``--steps``).
``--mixed-steps N`` (pursuit) adds section 4.1.5's Performance Convergence Experiment instead: N steps with the
Mixed team (one teammate-aware, one greedy, one probabilistic-destinations teammate), its curve beside the teams'.
With ``--out`` every (agent, trial) is stored as it finishes and a rerun resumes
from them; the folder gets ``summary.json``, ``table.md`` and ``curves.png``. ``--json`` prints the summary
(accumulated reward = prey captures, mean and 95 % CI, at each evaluation point, and per 500 steps).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from embodied_adhoc.atomic import atomic_write_text
from embodied_adhoc.commands.arguments import output_folder, positive_int, seed
from embodied_adhoc.decision.agents.teamwork import CHAPTER4_AGENTS as AGENTS
from embodied_adhoc.decision.uct import UctConfig
from embodied_adhoc.errors import ConfigError

DEFAULT_AGENTS = AGENTS[:7]


def _agents(text: str, domain: str = "pursuit") -> list[str]:
    from embodied_adhoc.domains.navigation4 import TEAMS as NAVIGATION_TEAMS

    allowed = AGENTS if domain == "pursuit" else DEFAULT_AGENTS + NAVIGATION_TEAMS
    names = [name.strip() for name in text.split(",") if name.strip()]
    from embodied_adhoc.plugins import names_plugin, resolve

    unknown = [name for name in names if name not in allowed and not names_plugin("agent", name)]
    if unknown or not names:
        raise ConfigError(
            f"--agents {text!r}: unknown {', '.join(unknown) or '(none given)'} on {domain}; choose "
            f"from {', '.join(allowed)}, or a plug-in MODULE:CALLABLE (docs/plugins.md)"
        )
    for name in names:  # a plug-in that cannot be imported stops here, before any learning
        if name not in allowed:
            resolve("agent", name, builtin=allowed, flag="--agents")
    return list(dict.fromkeys(names))


def handle(args: argparse.Namespace) -> int:
    agents = _agents(args.agents, args.domain)
    if args.steps % args.points:
        raise ConfigError(f"--steps {args.steps}: must be a multiple of --points {args.points}")
    if args.changed_steps is not None and args.changed_steps % args.points:
        raise ConfigError(
            f"--changed-steps {args.changed_steps}: must be a multiple of --points {args.points}"
        )
    from embodied_adhoc.experiments.domains.teamster import final_table, summarise, write_outputs
    from embodied_adhoc.experiments.domains.teamster_protocol import ProtocolConfig, parse_change, run_trial
    from embodied_adhoc.learning.teamster_agents import TABLE_4_1

    changed = parse_change(args.changed)
    if args.changed_steps is not None and not changed:
        raise ConfigError(f"--changed-steps {args.changed_steps}: only with a changed phase (--changed)")
    if args.mixed_steps is not None:
        if args.domain != "pursuit":
            raise ConfigError(f"--mixed-steps: the Mixed team is pursuit's; drop it for {args.domain}")
        if changed:
            raise ConfigError("--mixed-steps with --changed: each is its own last phase; give one per --out")
        if args.mixed_steps % (args.steps // args.points):
            raise ConfigError(
                f"--mixed-steps {args.mixed_steps}: must be a multiple of --steps / --points = "
                f"{args.steps // args.points} (the phase is evaluated as often as each team's interaction)"
            )

    if args.size != 5 and args.domain != "pursuit":
        raise ConfigError(f"--size {args.size}: only pursuit has a size (a map's is its file's)")
    if args.size < 3:
        raise ConfigError(f"--size {args.size}: pursuit's torus needs a side >= 3")
    iterations, depth = TABLE_4_1[args.domain]
    config = ProtocolConfig(
        steps=args.steps,
        eval_steps=args.eval_steps,
        points=args.points,
        changed=changed,
        changed_steps=args.changed_steps,
        mixed_steps=args.mixed_steps,
        seed=args.seed,
        iterations=args.iterations or iterations,
        depth=args.depth or depth,
        domain=args.domain,
        eval_episodes=args.eval_episodes,
        wave=args.wave,
        size=args.size,
    )
    out = args.out
    records = []
    jobs = [(agent, trial) for agent in agents for trial in range(args.trials)]
    from tqdm import tqdm

    phases = 3 + bool(config.changed) + bool(config.mixed_steps)
    bar = tqdm(
        total=len(jobs) * phases,
        desc="teamster",
        unit="team",
        disable=args.json or args.quiet,
        file=sys.stderr,
    )
    try:
        for agent, trial in jobs:
            path = Path(out, "runs", agent, f"trial-{trial}.json") if out else None
            if path is not None and path.is_file():
                record = json.loads(path.read_text())
                if record.get("config") != config.as_dict():
                    raise ConfigError(
                        f"{path}: written with other settings ({record.get('config')}); use another "
                        "--out or the same options"
                    )
                bar.update(phases)
            else:
                bar.set_postfix_str(f"{agent} trial {trial}")
                record = run_trial(agent, trial, config, tick=lambda: bar.update(1))
                if path is not None:
                    atomic_write_text(path, json.dumps(record) + "\n")
            records.append(record)
    finally:
        bar.close()
    summary = summarise(records)
    if out is not None:
        write_outputs(summary, out)
    if args.json:
        print(
            json.dumps(
                {"domain": args.domain, "config": config.as_dict(), "trials": args.trials, "agents": summary},
                indent=2,
            )
        )
    else:
        print(final_table(summary))
        if out is not None:
            print(f"summary.json, table.md and curves.png in {out}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "teamster", help="chapter 4: TEAMSTER, PLASTIC-Model/-Policy, sequential teams", description=__doc__
    )
    parser.add_argument(
        "domain",
        choices=("pursuit", "ntu", "isr", "pentagon"),
        help="pursuit (5x5, 4 predators) or a navigation map (ntu, isr, pentagon)",
    )
    parser.add_argument(
        "--agents",
        default=",".join(DEFAULT_AGENTS),
        metavar="A,B,...",
        help=f"comma-separated from {{{', '.join(AGENTS)}}} (default {','.join(DEFAULT_AGENTS)}), or "
        "plug-ins: factory(world, rng=, horizon=) -> a chapter-4 agent (docs/plugins.md)",
    )
    parser.add_argument(
        "--steps",
        type=positive_int,
        default=5000,
        help="interaction steps per team, a multiple of --points (default 5000)",
    )
    parser.add_argument("--trials", type=positive_int, default=8, help="trials per agent (default 8)")
    parser.add_argument(
        "--eval-steps", type=positive_int, default=500, help="pursuit: steps per evaluation (default 500)"
    )
    parser.add_argument(
        "--eval-episodes",
        type=positive_int,
        default=8,
        help="navigation: episodes (of at most 100 steps) per evaluation (default 8)",
    )
    parser.add_argument(
        "--points",
        type=positive_int,
        default=10,
        help="evaluations per interaction (default 10: every 10 %%)",
    )
    parser.add_argument(
        "--changed",
        default="0",
        metavar="fail:P|mirror",
        help="add the changed-environment phase: fail:P, predator moves fail with probability P "
        "(a bare P: the same); mirror, the ad hoc agent's moves mirrored (default none)",
    )
    parser.add_argument(
        "--changed-steps",
        type=positive_int,
        default=None,
        help="interaction steps of the changed phase, a multiple of --points (default --steps)",
    )
    parser.add_argument(
        "--mixed-steps",
        type=positive_int,
        default=None,
        help="add section 4.1.5's Mixed-team phase (seats teammate-aware, greedy, probabilistic destinations) "
        "of this many steps after the three teams, evaluated every --steps / --points steps (the thesis: "
        "15000); pursuit only, not with --changed",
    )
    parser.add_argument(
        "--iterations",
        type=positive_int,
        default=None,
        help="UCT iterations (default Table 4.1's: pursuit and ntu 100, isr and pentagon 300)",
    )
    parser.add_argument(
        "--depth",
        type=positive_int,
        default=None,
        help="UCT rollout depth (default Table 4.1's: pursuit 5, ntu 10, isr 50, pentagon 25)",
    )
    parser.add_argument(
        "--wave",
        type=positive_int,
        default=UctConfig.wave,
        help=f"UCT simulations that descend the tree together, one batched model call per depth (default "
        f"{UctConfig.wave}; 1: the sequential UCT; more: fewer, larger calls)",
    )
    parser.add_argument(
        "--size",
        type=positive_int,
        default=5,
        help="pursuit: the torus's side (default 5; section 4.1.5's larger world: 10), >= 3",
    )
    parser.add_argument("--seed", type=seed, default=0, help="seed, >= 0 (default 0)")
    parser.add_argument(
        "--out",
        type=output_folder,
        default=None,
        metavar="DIR",
        help="store (and resume) the trials in DIR, with summary.json, table.md, curves.png",
    )
    parser.add_argument("--json", action="store_true", help="print only the JSON summary on stdout")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(func=handle)
