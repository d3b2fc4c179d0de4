"""``embodied-adhoc live toxic-waste``: a person plays the human teammate in a browser, in real time.

Serves the live page (``embodied_adhoc.live.server``) on 127.0.0.1 unless ``--host`` opens it (then with a token
printed at start-up), runs the real-time lab with the participant as the human and the chosen agent as the robot,
and writes the study log under ``--out`` (docs/live.md).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from embodied_adhoc.commands.arguments import bounded, output_folder, positive_int, seed
from embodied_adhoc.gl import choose_gl_platform

AGENTS = ("hotspot", "known-task", "oracle", "random", "atpo", "bopa")
EPILOG = """\
examples:
  embodied-adhoc live toxic-waste                       # then open http://127.0.0.1:8000/
  embodied-adhoc live toxic-waste --agent hotspot --seed 3 --out runs/study
  embodied-adhoc live toxic-waste --host 0.0.0.0 --port 8000   # other machines, with the printed token
"""


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer; give a port 0..65535") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"{value} is outside 0..65535 (0: any free port)")
    return value


POSITIVE = bounded(float, math.ulp(0.0), "a finite number > 0")
NON_NEGATIVE = bounded(float, 0.0, "a finite number >= 0")


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "live",
        help="a person plays the human teammate in a browser, in real time (keyboard, typed or spoken replies)",
        description="Serve the live page: the overhead view streamed, the keyboard walks the human, the robot's "
        "agent decides in real time and asks 'Where are you?', the participant answers by typing or speaking.",
    )
    domains = parser.add_subparsers(dest="domain", metavar="DOMAIN")
    toxic = domains.add_parser(
        "toxic-waste",
        help="the HOTSPOT lab with a participant as the human",
        description="Real-time toxic-waste lab in the browser; writes the recording, metrics, inputs and reply "
        "audio under --out/<participant>_<time>/.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    toxic.add_argument(
        "--agent",
        default="hotspot",
        metavar="NAME|MODULE:CALLABLE",
        help=f"the robot's agent: {', '.join(AGENTS)} (default hotspot), or a plug-in (docs/plugins.md)",
    )
    toxic.add_argument("--seed", type=seed, default=0, help="episode seed: task and start nodes (default 0)")
    toxic.add_argument("--port", type=_port, default=8000, help="TCP port (default 8000; 0: any free port)")
    toxic.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to listen on (default 127.0.0.1: this machine only); any other needs the printed token",
    )
    toxic.add_argument(
        "--out",
        type=output_folder,
        default=Path("runs/live"),
        help="study folder of the run folders (runs/live)",
    )
    toxic.add_argument(
        "--participant",
        default=None,
        metavar="ID",
        help="anonymous participant code, 1-32 letters/digits/'-' (default: the next P### in --out)",
    )
    toxic.add_argument(
        "--speed",
        type=POSITIVE,
        default=1.0,
        help="simulated seconds per wall second (default 1: real time)",
    )
    toxic.add_argument(
        "--reply-timeout",
        type=POSITIVE,
        default=30.0,
        metavar="S",
        help="seconds the robot waits for an answer before it hears none (default 30)",
    )
    toxic.add_argument(
        "--max-steps", type=positive_int, default=100, metavar="N", help="step cap (default 100)"
    )
    toxic.add_argument(
        "--stream-fps", type=POSITIVE, default=10.0, help="frames per second sent to the page (default 10)"
    )
    toxic.add_argument(
        "--question-interval",
        type=NON_NEGATIVE,
        default=8.0,
        metavar="S",
        help="simulated seconds after an answer before the robot asks again, unless its belief moved (default 8)",
    )
    toxic.add_argument(
        "--study",
        type=Path,
        default=None,
        metavar="PLAN.json",
        help="run a study: the plan's episodes in counterbalanced order, instructions, a questionnaire after each "
        "episode; one folder per participant under --out (docs/live.md, study mode)",
    )
    toxic.set_defaults(func=handle_toxic_waste)
    summarise = domains.add_parser(
        "summarise",
        help="per-agent statistics of a study folder across participants, with bootstrap intervals",
        description="Read every P###/study.csv of STUDY_DIR (written by `live toxic-waste --study`) and print "
        "per-agent means over participants with 95 % percentile-bootstrap intervals.",
    )
    summarise.add_argument("study_dir", type=Path, metavar="STUDY_DIR", help="the --out folder of the study")
    summarise.set_defaults(func=handle_summarise)
    parser.set_defaults(_parser=parser)


def handle_summarise(args: argparse.Namespace) -> int:
    from embodied_adhoc.live.study import summarise_study

    print(summarise_study(args.study_dir))
    return 0


def handle_toxic_waste(args: argparse.Namespace) -> int:
    from embodied_adhoc.live.study import StudyRun, load_plan

    plan = None if args.study is None else load_plan(args.study)  # a bad plan stops here, before any work
    from embodied_adhoc.experiments.domains.toxic_waste import DOMAIN
    from embodied_adhoc.experiments.registry import agent_plugin

    agent_plugin(
        DOMAIN, args.agent, "--agent"
    )  # so does an unknown agent or a plug-in that cannot be imported
    choose_gl_platform()  # headless by default: MuJoCo picks its GL platform when first imported
    from embodied_adhoc.live.server import serve
    from embodied_adhoc.live.session import LiveSettings

    settings = LiveSettings(
        agent=args.agent,
        seed=args.seed,
        out=args.out,
        participant=args.participant,
        speed=args.speed,
        reply_timeout=args.reply_timeout,
        max_steps=args.max_steps,
        stream_fps=args.stream_fps,
        question_interval=args.question_interval,
    )
    study = None if plan is None else StudyRun(plan, args.out, args.participant)
    server = serve(settings, args.host, args.port, announce=lambda line: print(line, flush=True), study=study)
    folder = server.session.folder if study is None else study.folder
    print(f"live: session ended; files in {folder}", flush=True)
    return 0
