"""``embodied-adhoc`` console script.

Each subcommand lives in its own module under ``embodied_adhoc.commands`` and exposes
``register(subparsers)``; command modules import heavy libraries (mujoco, torch, ...) only inside their
handlers so that ``--help`` stays instant.

Exit statuses: bad input (an argparse error or an ``EmbodiedAdhocError``) is one line on stderr and status 2;
Ctrl-C (SIGINT) exits 130 and SIGTERM 143, both after the command's cleanup ran (worker pools terminated,
finished results kept); a closed stdout (``embodied-adhoc envs --json | head``) ends quietly with 141, as a
SIGPIPE would.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import threading

from embodied_adhoc import __version__
from embodied_adhoc.errors import EmbodiedAdhocError

# Order = order in --help. A module listed here that is missing is a packaging bug, not a user error.
COMMAND_MODULES = ("run", "trials", "envs", "pomdp", "speech", "render", "train", "live", "teamster", "bench")


class OneLineParser(argparse.ArgumentParser):
    """argparse's parser with one-line errors (no usage block): ``PROG: error: MESSAGE (see PROG --help)``.

    Sub-command parsers inherit the class (``add_subparsers`` uses the parent's type)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread so that cleanup (``finally`` blocks, pool termination) runs."""


def _raise_terminated(signum, frame):
    raise Terminated()


def build_parser(commands: tuple[str, ...] = COMMAND_MODULES) -> argparse.ArgumentParser:
    """The parser with the sub-commands of ``commands`` (modules of :data:`COMMAND_MODULES`) registered."""
    parser = OneLineParser(
        prog="embodied-adhoc",
        description="Ad hoc teamwork testbed: embodied (MuJoCo) and abstract (POMDP) worlds, agents and trials.",
    )
    parser.add_argument("--version", action="version", version=f"embodied-adhoc {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in commands:
        try:
            module = importlib.import_module(f"embodied_adhoc.commands.{name}")
        except ModuleNotFoundError as error:
            if error.name == f"embodied_adhoc.commands.{name}":
                continue  # command not built yet in this checkout
            raise
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    # A command line naming a command imports that command's module alone: the others' imports (and what they
    # pull in) would be part of every command's memory, e.g. of a solver's peak that is compared with SARSOP's.
    words = sys.argv[1:] if argv is None else argv
    parser = build_parser((words[0],) if words and words[0] in COMMAND_MODULES else COMMAND_MODULES)
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        # A command group without a subcommand (or no command at all): show its help.
        (getattr(args, "_parser", None) or parser).print_help()
        return 2
    in_main_thread = threading.current_thread() is threading.main_thread()  # only it may set signal handlers
    previous_sigterm = signal.signal(signal.SIGTERM, _raise_terminated) if in_main_thread else None
    try:
        status = int(args.func(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, not at interpreter exit
        return status
    except EmbodiedAdhocError as error:
        print(f"embodied-adhoc: error: {error}", file=sys.stderr)
        return 2
    except Terminated:
        print("embodied-adhoc: terminated (finished work was kept)", file=sys.stderr)
        return 143
    except KeyboardInterrupt:
        print("embodied-adhoc: interrupted (finished work was kept)", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (``| head``): nothing more can be shown. Point stdout at /dev/null so that the
        # interpreter's final flush does not fail again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    finally:
        if in_main_thread:
            signal.signal(signal.SIGTERM, previous_sigterm)


if __name__ == "__main__":
    sys.exit(main())
