"""``embodied-adhoc`` console script.

Each subcommand lives in its own module under ``embodied_adhoc.commands`` and exposes
``register(subparsers)``; command modules import heavy libraries (mujoco, torch, ...) only inside their
handlers so that ``--help`` stays instant. Project errors (``EmbodiedAdhocError``) are printed as one line
and exit with status 2; interrupts exit with 130.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from embodied_adhoc import __version__
from embodied_adhoc.errors import EmbodiedAdhocError

# Order = order in --help. A module listed here that is missing is a packaging bug, not a user error.
COMMAND_MODULES = ("run", "trials", "envs", "pomdp", "speech", "render", "train")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="embodied-adhoc",
        description="Ad hoc teamwork testbed: embodied (MuJoCo) and abstract (POMDP) worlds, agents and trials.",
    )
    parser.add_argument("--version", action="version", version=f"embodied-adhoc {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(f"embodied_adhoc.commands.{name}")
        except ModuleNotFoundError as error:
            if error.name == f"embodied_adhoc.commands.{name}":
                continue  # command not built yet in this checkout
            raise
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        # A command group without a subcommand (or no command at all): show its help.
        (getattr(args, "_parser", None) or parser).print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except EmbodiedAdhocError as error:
        print(f"embodied-adhoc: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("embodied-adhoc: interrupted (finished work was kept)", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
