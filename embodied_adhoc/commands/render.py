"""``embodied-adhoc render lab``: a still image of the MuJoCo lab (robot, human, balls) from a named camera.

Example: ``embodied-adhoc render lab --out docs/images/lab_overhead.png --task 0,1,2 --pick 1``.
Rendering is offscreen; on Linux without a display it uses EGL unless ``MUJOCO_GL`` says otherwise (e.g.
``osmesa``): :func:`embodied_adhoc.gl.choose_gl_platform`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from embodied_adhoc.commands.arguments import output_file, positive_int, seed
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.gl import choose_gl_platform

CAMERAS = ("overhead", "perspective", "robot")


def _node_list(text: str) -> tuple[int, ...]:
    try:
        nodes = tuple(int(part) for part in text.split(","))
    except ValueError as error:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated node ids like 0,1,2, got {text!r}"
        ) from error
    if len(nodes) != 3 or not all(0 <= n <= 4 for n in nodes):
        raise argparse.ArgumentTypeError(f"expected three node ids in 0..4 (one per ball), got {text!r}")
    return nodes


def handle_lab(args: argparse.Namespace) -> int:
    choose_gl_platform()  # before mujoco is imported (by lab_world)
    import imageio.v3 as iio

    from embodied_adhoc.atomic import publish, temporary_sibling
    from embodied_adhoc.sim.lab_world import HumanCommand, LabWorld, LabWorldConfig

    out = Path(args.out)
    if out.suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise ConfigError(f"--out {out}: use a .png or .jpg file name")
    if not out.parent.is_dir():
        raise ConfigError(f"--out {out}: folder {out.parent} does not exist; create it first")
    if args.pick is not None and args.task[args.pick] != args.human_node:
        raise ConfigError(
            f"--pick {args.pick}: that ball lies at node {args.task[args.pick]}, the human is at node "
            f"{args.human_node}; pick a ball in the human's area"
        )
    config = LabWorldConfig(render_quality="fast" if args.fast else "high")
    with LabWorld(config) as world:
        world.reset(
            seed=args.seed, robot_node=args.robot_node, human_node=args.human_node, ball_nodes=args.task
        )
        if args.pick is not None:
            world.step_macro(None, HumanCommand.pick(args.pick))
        image = world.render(args.camera, width=args.width, height=args.height)
    temporary = temporary_sibling(out)
    iio.imwrite(temporary, image)
    publish(temporary, out)
    print(f"wrote {out} ({args.width}x{args.height}, camera {args.camera})")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    group = subparsers.add_parser(
        "render",
        help="render still images of the MuJoCo scenes",
        description="Render still images of the MuJoCo scenes offscreen (EGL when there is no display, unless "
        "MUJOCO_GL is set).",
    )
    scenes = group.add_subparsers(dest="scene", metavar="SCENE")
    lab = scenes.add_parser(
        "lab",
        help="the HOTSPOT lab with robot, human and the three balls",
        description="Render the HOTSPOT lab (scenes/lab.xml) with the robot, the human and the balls of a task.",
    )
    lab.add_argument("--out", type=output_file, required=True, help="output image (.png or .jpg)")
    lab.add_argument("--camera", choices=CAMERAS, default="overhead", help="camera (default: overhead)")
    lab.add_argument(
        "--task", type=_node_list, default=(0, 1, 2), help="ball nodes, e.g. 0,1,2 (default) or 1,2,3"
    )
    lab.add_argument(
        "--robot-node", type=int, choices=range(5), default=0, help="robot's node (default 0, door)"
    )
    lab.add_argument("--human-node", type=int, choices=range(5), default=1, help="human's node (default 1)")
    lab.add_argument(
        "--pick", type=int, choices=range(3), default=None, help="the human first picks this ball"
    )
    lab.add_argument("--width", type=positive_int, default=1280, help="image width in pixels (default 1280)")
    lab.add_argument(
        "--height", type=positive_int, default=1024, help="image height in pixels (default 1024)"
    )
    lab.add_argument(
        "--fast",
        action="store_true",
        help='render quality "fast" (what videos use): no shadows, reflections or floor texture',
    )
    lab.add_argument("--seed", type=seed, default=0, help="seed of the world, >= 0 (default 0)")
    lab.set_defaults(func=handle_lab)
    group.set_defaults(_parser=group)
