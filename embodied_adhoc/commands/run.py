"""``embodied-adhoc run toxic-waste``: one physically simulated episode, with a progress bar and a summary.

With ``--record DIR`` it writes ``episode.mp4`` (overhead camera), ``episode.rrd`` (rerun) and ``metrics.json``;
an interrupted run keeps what it finished. Episode 0 of ``trials toxic-waste --backend mujoco --seed S`` for the
same agent is the same episode (same seeds, same draw).
"""

from __future__ import annotations

import argparse
import json
import sys

from embodied_adhoc.commands.arguments import output_folder, seed
from embodied_adhoc.domains.confusion import DEFAULT_CONFUSION
from embodied_adhoc.gl import choose_gl_platform

AGENTS = ("hotspot", "known-task", "oracle", "random", "atpo", "bopa")
EPILOG = """\
examples:
  embodied-adhoc run toxic-waste --agent hotspot --seed 0 --record runs/demo
  embodied-adhoc run toxic-waste --agent known-task --task 1 --speech audio --record runs/audio
  rerun runs/demo/episode.rrd        # inspect the recording (the viewer ships in the rerun-sdk wheel)
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "run",
        help="run one physically simulated episode (MuJoCo), optionally recorded (mp4, rerun, metrics)",
        description="Run one episode of an embodied domain on MuJoCo physics.",
    )
    domains = parser.add_subparsers(dest="domain", metavar="DOMAIN")
    toxic = domains.add_parser(
        "toxic-waste",
        help="HOTSPOT lab: a robot container helps a human clean three toxic-waste balls (thesis ch. 7)",
        description="One episode of EmbodiedAdhoc/ToxicWaste-v0: the agent drives the container robot until the "
        "three balls are in its container or --max-steps macro steps pass.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    toxic.add_argument(
        "--agent",
        default="hotspot",
        metavar="NAME|MODULE:CALLABLE|FILE.py:CALLABLE",
        help=f"decision agent: {', '.join(AGENTS)} (default hotspot), or a plug-in (docs/plugins.md)",
    )
    toxic.add_argument("--seed", type=seed, default=0, help="seed of the episode, >= 0 (default 0)")
    toxic.add_argument("--task", type=int, default=None, metavar="K", help="true task index (default: drawn)")
    toxic.add_argument(
        "--robot-node", type=int, default=None, metavar="N", help="robot start node (default: drawn)"
    )
    toxic.add_argument(
        "--human-node", type=int, default=None, metavar="N", help="human start node (default: drawn)"
    )
    toxic.add_argument(
        "--human-epsilon", type=float, default=0.05, metavar="E", help="human failure rate (0.05)"
    )
    toxic.add_argument(
        "--human",
        default=None,
        metavar="scripted|MODULE:CALLABLE",
        help="the world's human teammate (default: the scripted cleaner the agents' models assume), or a plug-in "
        "(docs/plugins.md)",
    )
    toxic.add_argument(
        "--no-communication",
        action="store_true",
        help="no 'locate human'; the human is seen only when co-located",
    )
    toxic.add_argument(
        "--speech",
        choices=("channel", "audio", "perfect"),
        default="channel",
        help="how the human's reply is heard: confusion-matrix channel (default), full offline audio pipeline, perfect",
    )
    toxic.add_argument(
        "--confusion",
        default=DEFAULT_CONFUSION,
        metavar="measured|thesis|PATH",
        help=f"speech confusion matrix of the channel and of the agent's model (default: {DEFAULT_CONFUSION})",
    )
    toxic.add_argument(
        "--max-steps", type=int, default=100, help="macro-step cap (default 100, as the thesis)"
    )
    from embodied_adhoc.experiments.domains.toxic_waste import add_fault_arguments

    add_fault_arguments(toxic.add_argument_group("faults and localisation"))
    toxic.add_argument(
        "--record",
        type=output_folder,
        default=None,
        metavar="DIR",
        help="write episode.mp4/.rrd, metrics.json",
    )
    from embodied_adhoc.experiments.recorded import EpisodeConfig

    toxic.add_argument(
        "--video-fps",
        type=float,
        default=EpisodeConfig.video_fps,
        help=f"frames per second of the video ({EpisodeConfig.video_fps:g})",
    )
    toxic.add_argument(
        "--video-speed",
        type=float,
        default=EpisodeConfig.video_speed,
        help=f"simulated seconds per video second ({EpisodeConfig.video_speed:g} = {EpisodeConfig.video_speed:g}x "
        "time-lapse)",
    )
    toxic.add_argument("--width", type=int, default=640, help="video width in pixels, even (640)")
    toxic.add_argument("--height", type=int, default=480, help="video height in pixels, even (480)")
    toxic.add_argument(
        "--render-quality",
        choices=("fast", "high"),
        default="fast",
        help="'high' adds shadows, reflections, floor texture (slower)",
    )
    toxic.add_argument(
        "--no-overlay",
        action="store_true",
        help="no heads-up text (step, action, observation, belief) on the video",
    )
    toxic.add_argument(
        "--json", action="store_true", help="print metrics.json's summary as JSON instead of text"
    )
    toxic.add_argument("--no-progress", action="store_true", help="no progress bar")
    toxic.set_defaults(func=handle_toxic_waste)
    from embodied_adhoc.commands.run_arenas import register_arena_runs

    register_arena_runs(domains)  # run pursuit (Fig. 7.12 on physics), run foraging
    parser.set_defaults(_parser=parser)


def handle_toxic_waste(args: argparse.Namespace) -> int:
    choose_gl_platform()  # headless by default: MuJoCo picks its GL platform when first imported
    from embodied_adhoc.errors import ConfigError
    from embodied_adhoc.experiments.domains.toxic_waste import fault_options
    from embodied_adhoc.experiments.recorded import EpisodeConfig, run_episode

    if args.max_steps < 1:
        raise ConfigError(f"--max-steps must be >= 1, got {args.max_steps}")
    from embodied_adhoc.sim.lab_render import check_render_size

    try:  # the frames are drawn on another thread, so the renderer's own refusal would come after the episode
        check_render_size(args.width, args.height)
    except ConfigError as error:
        raise ConfigError(f"--width {args.width} --height {args.height}: {error}") from None
    if (
        args.record is not None
    ):  # the video writer opens after the world is built: its refusals come first here
        from embodied_adhoc.record.video import check_video_settings

        check_video_settings(args.width, args.height, args.video_fps)
    from embodied_adhoc.experiments.domains.toxic_waste import DOMAIN
    from embodied_adhoc.experiments.registry import agent_plugin

    agent_plugin(
        DOMAIN, args.agent, "--agent"
    )  # an unknown name or a broken plug-in stops here, before any model
    from embodied_adhoc.envs.lab_humans import human_option

    config = EpisodeConfig(
        env_kwargs=human_option(args.human),
        agent=args.agent,
        seed=args.seed,
        task=args.task,
        robot_node=args.robot_node,
        human_node=args.human_node,
        human_epsilon=args.human_epsilon,
        communication=not args.no_communication,
        speech=args.speech,
        confusion=args.confusion,
        faults=fault_options(args),
        localisation=not args.no_localisation,
        localisation_model=args.localisation_model,
        model_rfid_miss=args.model_rfid_miss,
        max_steps=args.max_steps,
        record_dir=args.record,
        video_fps=args.video_fps,
        video_speed=args.video_speed,
        render_quality=args.render_quality,
        video_overlay=not args.no_overlay,
        width=args.width,
        height=args.height,
    )

    def postfix(info: dict) -> str:
        done = sum(1 for status in info["ball_status"] if status == 2)
        return f"balls {done}/{len(info['ball_status'])}, sim {info['sim_time']:.0f}s"

    summary = play(args, "toxic-waste", lambda progress: run_episode(config, progress), postfix)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(format_summary(summary))
    return 0


def play(args: argparse.Namespace, domain: str, run, postfix) -> dict:
    """``run(progress)`` (one recorded run) under a progress bar (``postfix(info)`` beside it, unless
    ``--no-progress``); returns the metrics summary without the per-step rows, with the files written. Shared by
    ``run toxic-waste``, ``run pursuit`` and ``run foraging``."""
    bar = None
    if not args.no_progress:
        from tqdm import tqdm

        bar = tqdm(total=args.max_steps, desc=f"{domain} {args.agent}", unit="step", file=sys.stderr)

    def progress(step: int, info: dict) -> None:
        if bar is not None:
            bar.set_postfix_str(postfix(info))
            bar.update(1)

    try:
        outcome = run(progress)
        if bar is not None and outcome.metrics["success"]:
            finish_progress(bar)
    finally:
        if bar is not None:
            bar.close()
    summary = {k: v for k, v in outcome.metrics.items() if k != "per_step"}
    summary["files"] = {name: str(path) for name, path in outcome.files.items()}
    return summary


def finish_progress(bar) -> None:
    """An episode that succeeded before the step cap: the bar's total becomes the steps taken, so it closes as
    done ("12/12, 100%") instead of "12/100, 12%" with an ETA."""
    bar.total = bar.n
    bar.refresh()


def format_summary(
    summary: dict,
    outcomes: tuple[str, str] = ("all balls in the container", "not finished"),
    truth: str | None = None,
    belief: str = "task-belief",
    extra: tuple[str, ...] = (),
    per_step_time: bool = True,
) -> str:
    """The text summary of a ``run`` episode: outcome (``outcomes``: what success and the rest are), steps,
    identification against ``truth`` (default the true task), final ``belief`` entropy, ``extra`` lines, times,
    the lab's localisation, faults and cap reason where the summary has them, and the files written."""
    step_time = summary["macro_step_time_s"]["mean"]
    identify = summary["identify_step"]
    entropy = summary["final_entropy"]
    truth = f"true task {summary['true_task']}" if truth is None else truth
    time_line = (
        f"time:           {summary['wall_time_s']:.1f} s wall, {summary['sim_time_s']:.1f} s simulated"
    )
    if per_step_time:
        time_line += f", {float('nan') if step_time is None else step_time:.2f} s wall per macro step"
    lines = [
        f"outcome:        {summary['outcome']} ({outcomes[0] if summary['success'] else outcomes[1]})",
        f"steps:          {summary['steps']}",
        f"identified:     {'never' if identify is None else f'at step {identify}'} ({truth})",
        f"final entropy:  {'-' if entropy is None else format(entropy, '.3f')} (normalised {belief} entropy)",
        *extra,
        time_line,
    ]
    localisation = summary.get("localisation")
    if localisation is not None:
        blocked = localisation["blocked_steps"]
        lines.append(
            f"localisation:   {'/'.join(localisation['modes'])}; worst pose error "
            f"{localisation['worst_pose_error_m']:.2f} m (odometry {localisation['worst_odometry_error_m']:.2f} m); "
            f"blocked {'never' if not blocked else 'at steps ' + ','.join(map(str, blocked))}; "
            f"{localisation['kidnaps']} re-localisation(s); readings unknown {localisation['unknown_readings']}, "
            f"wrong {localisation['wrong_readings']}"
        )
    if summary.get("faults") is not None:
        from embodied_adhoc.experiments.domains.toxic_waste import fault_line

        lines.append(f"faults:         {fault_line(summary['faults'])}")
    if summary.get("cap_reason"):
        lines.append(f"cap:            {summary['cap_reason']['detail']} [{summary['cap_reason']['code']}]")
    for name, path in summary.get("files", {}).items():
        lines.append(f"{name + ':':<16}{path}")
    return "\n".join(lines)
