"""``embodied-adhoc run pursuit`` (Fig. 7.12 on physics, recorded) and ``run foraging`` (the ATLPO agent's arena).

Registered under ``run`` by :mod:`embodied_adhoc.commands.run` (one call, :func:`register_arena_runs`).
"""

from __future__ import annotations

import argparse
import json

from embodied_adhoc.commands.arguments import output_folder, seed
from embodied_adhoc.gl import choose_gl_platform

__all__ = ["ATLPO_TRAIN_COMMAND", "register_arena_runs"]

FORAGING_EPILOG = """\
examples:
  embodied-adhoc run foraging --seed 0 --record runs/foraging        # ATLPO-MF, shipped library
  embodied-adhoc run foraging --task 3 --team tau2 --library runs/atlpo/foraging --record runs/f3
  rerun runs/foraging/episode.rrd
"""

PURSUIT_AGENTS = ("hotspot", "known-task", "oracle", "atpo", "bopa", "perseus", "random")
ATLPO_TRAIN_COMMAND = "embodied-adhoc train atlpo --domain foraging --set task --out DIR"
EPILOG = """\
examples:
  embodied-adhoc run pursuit --agent hotspot --seed 0 --record runs/pursuit
  embodied-adhoc run pursuit --agent atpo --task 3 --record runs/pursuit-atpo
  rerun runs/pursuit/episode.rrd
"""


def register_arena_runs(domains: argparse._SubParsersAction) -> None:
    pursuit = domains.add_parser(
        "pursuit",
        help="Fig. 7.12: a decision-layer agent (HOTSPOT, ATPO, ...) as a predator robot in the MuJoCo arena",
        description="One episode of EmbodiedAdhoc/PursuitPairPomdp-v0: the agent's robot and a greedy teammate "
        "robot must capture the prey robot at the task's pair of cells (N+S, W+E, SW+NE, NW+SE), which the agent "
        "does not know. Episode 0 of 'trials pursuit --pairs --backend mujoco --seed S' for the same agent.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    pursuit.add_argument(
        "--agent",
        default="hotspot",
        metavar="NAME|MODULE:CALLABLE",
        help=f"decision agent: {', '.join(PURSUIT_AGENTS)} (default hotspot), or a plug-in (docs/plugins.md)",
    )
    pursuit.add_argument("--seed", type=seed, default=0, help="seed of the episode, >= 0 (default 0)")
    pursuit.add_argument(
        "--task",
        type=int,
        default=None,
        metavar="K",
        help="true task 1..4 (N+S, W+E, SW+NE, NW+SE; default: drawn)",
    )
    pursuit.add_argument("--max-steps", type=int, default=150, help="step cap (default 150, Fig. 7.12's)")
    _recording_arguments(pursuit)
    pursuit.set_defaults(func=handle_pursuit)

    from embodied_adhoc.experiments.recorded import FORAGING_AGENTS

    foraging = domains.add_parser(
        "foraging",
        help="level-based foraging in the MuJoCo arena with the ATLPO agent "
        "(thesis ch. 6; pre-trained library shipped)",
        description="One episode of EmbodiedAdhoc/Foraging-v0: the ad hoc robot and three scripted teammate robots "
        "(team drawn from --team) must forage the apple from the task's N/S/W/E positions, which the agent does "
        "not know. ATLPO-MF reads the egocentric grid the arena computes from the robots' physical positions. "
        "Episode 0 of 'trials foraging --backend mujoco --seed S' for the same agent.",
        epilog=FORAGING_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    foraging.add_argument(
        "--agent",
        default="atlpo-mf",
        metavar="NAME|MODULE:CALLABLE",
        help=f"ad hoc agent: {', '.join(FORAGING_AGENTS)} (default atlpo-mf), or a plug-in (docs/plugins.md)",
    )
    foraging.add_argument("--seed", type=seed, default=0, help="seed of the episode, >= 0 (default 0)")
    foraging.add_argument(
        "--task", type=int, default=None, metavar="K", help="true task 1..4 (default: drawn)"
    )
    foraging.add_argument(
        "--team",
        default="tau0,tau1,tau2",
        metavar="NAME[,NAME]",
        help="team type(s) the episode's team is drawn from (default tau0,tau1,tau2)",
    )
    foraging.add_argument(
        "--library",
        default=None,
        metavar="DIR",
        help="atlpo-mf: a folder written by `embodied-adhoc train atlpo --domain foraging` "
        "(default: the pre-trained task+team library shipped with the package)",
    )
    foraging.add_argument("--max-steps", type=int, default=200, help="step cap (default 200, the grid envs')")
    _recording_arguments(foraging)
    foraging.set_defaults(func=handle_foraging)


def _frame_size(text: str) -> int:
    """``--size``: even (H.264 yuv420p) and within the arenas' offscreen framebuffer, known before the episode."""
    from embodied_adhoc.sim.grid_arena import OFFSCREEN_SIZE

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not an integer; give an even size 2..{OFFSCREEN_SIZE}"
        ) from None
    if not 2 <= value <= OFFSCREEN_SIZE or value % 2:
        raise argparse.ArgumentTypeError(
            f"{value}: give an even size 2..{OFFSCREEN_SIZE} (the arenas' offscreen framebuffer)"
        )
    return value


def _recording_arguments(parser: argparse.ArgumentParser) -> None:
    """The recording and output flags shared by ``run pursuit`` and ``run foraging``."""
    parser.add_argument(
        "--record",
        type=output_folder,
        default=None,
        metavar="DIR",
        help="write episode.mp4/.rrd, metrics.json",
    )
    parser.add_argument("--video-fps", type=float, default=12.0, help="frames per second of the video (12)")
    parser.add_argument(
        "--video-speed", type=float, default=2.0, help="simulated seconds per video second (2)"
    )
    parser.add_argument(
        "--size",
        type=_frame_size,
        default=480,
        help="video width and height in pixels, even, at most the arenas' 640 (480)",
    )
    parser.add_argument("--no-overlay", action="store_true", help="no heads-up text on the video")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _arena_episode(args: argparse.Namespace, domain: str, config_type, run, postfix, **fields) -> dict | None:
    """One ``run pursuit`` / ``run foraging`` episode: its config from the shared flags (and ``fields``), run
    under the progress bar; the summary, or None once printed as JSON (``--json``)."""
    from embodied_adhoc.commands.run import play

    config = config_type(
        agent=args.agent,
        seed=args.seed,
        task=args.task,
        max_steps=args.max_steps,
        record_dir=args.record,
        video_fps=args.video_fps,
        video_speed=args.video_speed,
        size=args.size,
        video_overlay=not args.no_overlay,
        **fields,
    )
    summary = play(args, domain, lambda progress: run(config, progress), postfix)
    if args.json:
        print(json.dumps(summary, indent=2))
        return None
    return summary


def handle_pursuit(args: argparse.Namespace) -> int:
    choose_gl_platform()
    from embodied_adhoc.commands.run import format_summary
    from embodied_adhoc.experiments.recorded import PursuitEpisodeConfig, run_pursuit_episode

    summary = _arena_episode(
        args,
        "pursuit",
        PursuitEpisodeConfig,
        run_pursuit_episode,
        lambda info: f"sim {info['sim_time']:.0f}s",
    )
    if summary is not None:
        mismatches = summary["physics_mismatches"]
        physics = f"physics:        {mismatches} step(s) where physics did not execute the drawn move"
        print(format_summary(summary, ("prey captured", "not captured"), extra=(physics,)))
    return 0


def handle_foraging(args: argparse.Namespace) -> int:
    """One ATLPO (or original-teammate, random) episode in the foraging arena; the library defaults to the one
    shipped in the package (``learning.atlpo.shipped_library``)."""
    choose_gl_platform()
    from pathlib import Path

    from embodied_adhoc.commands.run import format_summary
    from embodied_adhoc.experiments.recorded import ForagingEpisodeConfig, run_foraging_episode

    summary = _arena_episode(
        args,
        "foraging",
        ForagingEpisodeConfig,
        run_foraging_episode,
        lambda info: f"apples left {info['remaining']}",
        teams=tuple(t.strip() for t in args.team.split(",")),
        library=None if args.library is None else Path(args.library),
    )
    if summary is not None:
        truth = f"true task {summary['true_task'] + 1}, team {summary['true_team']}"
        outcomes = ("apple foraged", "not foraged")
        print(format_summary(summary, outcomes, truth, "task-posterior", per_step_time=False))
    return 0
