"""argparse value types shared by the commands: checked when the command line is parsed, before any work starts.

A bad value makes argparse exit with status 2 and one line ``embodied-adhoc ...: error: argument --flag: what is
wrong and what to give instead`` (the one-line parser is :class:`embodied_adhoc.cli.OneLineParser`).

* :func:`seed`: a non-negative integer (numpy's ``SeedSequence`` and Gymnasium's ``reset(seed=)`` refuse negatives).
* :func:`positive_int`: an integer >= 1 (sizes and counts).
* :func:`bounded`: a type for a finite int or float at least some minimum (``nan`` and ``inf`` refused).
* :func:`output_folder` / :func:`output_file`: a path the command can create and write, probed without leaving
  anything behind: not an existing file where a folder is wanted (or the reverse), no file among its parents, and
  a writable nearest existing folder (tested by creating and removing a temporary folder there, which also catches
  read-only file systems and permissions that ``os.access`` misreports for root).
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

from embodied_adhoc.checks import bounded, positive_int  # noqa: F401  (argparse types, re-exported)


def seed(text: str) -> int:
    """``--seed``: an integer >= 0."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer; give a seed >= 0") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value} is negative; give a seed >= 0")
    return value


def _nearest_existing(path: Path) -> Path:
    for candidate in (path, *path.parents):
        if os.path.lexists(candidate):
            return candidate
    return Path(".")


def _check_writable(folder: Path, target: Path) -> None:
    """Raise ArgumentTypeError unless ``folder`` exists or can be created, and files can be written in it."""
    existing = _nearest_existing(folder)
    if not existing.is_dir():
        raise argparse.ArgumentTypeError(
            f"{target}: {existing} is a file, not a folder; choose a path outside it"
        )
    try:
        with tempfile.TemporaryDirectory(dir=existing, prefix=".embodied-adhoc-probe-"):
            pass
    except OSError as error:
        raise argparse.ArgumentTypeError(
            f"{target}: cannot write in {existing} ({error.strerror or error}); choose a writable location"
        ) from None


def output_folder(text: str) -> Path:
    """A folder to write results into: existing (and writable) or creatable."""
    path = Path(text).expanduser()
    if os.path.lexists(path) and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{path} exists and is not a folder; give a folder name")
    _check_writable(path, path)
    return path


def output_file(text: str) -> Path:
    """A file to write: not an existing folder, in a folder that exists or can be created, and is writable."""
    path = Path(text).expanduser()
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{path} is a folder; give a file name")
    _check_writable(path.parent, path)
    return path
