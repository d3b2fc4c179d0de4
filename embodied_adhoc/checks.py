"""Checks of user-given values (env kwargs, reset options, config fields), shared by every layer that takes input.

Each check returns the value in its canonical Python type or raises one :class:`~embodied_adhoc.errors.ConfigError`
that names the input and says what is accepted. Nothing is coerced silently: ``2.7`` is not the integer 2,
``"no"`` is not ``False``, ``True`` is not the integer 1. numpy only (usable below ``envs/``, e.g. in ``domains/``).
"""

from __future__ import annotations

import argparse
import difflib
import math
import os
import stat
from collections.abc import Iterable, Mapping

import numpy as np

from embodied_adhoc.errors import ConfigError

__all__ = [
    "bounded",
    "choice",
    "flag",
    "integer",
    "number",
    "positive_int",
    "probability_rows",
    "read_text",
    "refuse_unknown",
]


def _is_integer(value) -> bool:
    if isinstance(value, (bool, np.bool_)):
        return False
    if isinstance(value, (int, np.integer)):
        return True
    return isinstance(value, np.ndarray) and value.shape == () and np.issubdtype(value.dtype, np.integer)


def integer(name: str, value, low: int | None = None, high: int | None = None) -> int:
    """An integer (Python ``int``, a numpy integer of any width, or a 0-d integer array) in ``low..high``.

    Refused: bools, floats (even ``2.0``), strings, ``None`` and arrays with a shape (``np.array([2])``).
    """
    bounds = _range_text(low, high)
    if not _is_integer(value):
        where = f" in {bounds}" if ".." in bounds else f" {bounds}" if bounds else ""
        raise ConfigError(
            f"{name}={value!r} ({type(value).__name__}): must be an integer{where} "
            "(a Python or numpy int, or a 0-d integer array)"
        )
    result = int(value)
    if (low is not None and result < low) or (high is not None and result > high):
        raise ConfigError(
            f"{name}={result}: " + (f"outside {bounds}" if ".." in bounds else f"must be {bounds}")
        )
    return result


def _range_text(low, high) -> str:
    if low is not None and high is not None:
        return f"{low}..{high}"
    if low is not None:
        return f">= {low}"
    if high is not None:
        return f"<= {high}"
    return ""


def number(
    name: str, value, low: float | None = None, high: float | None = None, low_open: bool = False
) -> float:
    """A finite real number (int or float, Python or numpy; not a bool or a string) in ``[low, high]``
    (``(low, high]`` with ``low_open``)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ConfigError(f"{name}={value!r} ({type(value).__name__}): must be a number")
    result = float(value)
    below = low is not None and (result <= low if low_open else result < low)
    if not math.isfinite(result) or below or (high is not None and result > high):
        bound = (
            f"{'(' if low_open else '['}{'-inf' if low is None else low}, {'inf' if high is None else high}]"
        )
        raise ConfigError(f"{name}={value!r}: must be a finite number in {bound}")
    return result


def flag(name: str, value) -> bool:
    """``True`` or ``False`` (a Python or numpy bool); ``"no"``, ``0`` or ``None`` are refused."""
    if not isinstance(value, (bool, np.bool_)):
        raise ConfigError(f"{name}={value!r} ({type(value).__name__}): must be True or False")
    return bool(value)


def choice(name: str, value, choices: Iterable):
    """One of ``choices`` (compared by equality; bools and arrays never match)."""
    options = tuple(choices)
    if isinstance(value, (bool, np.bool_, np.ndarray)) or not any(_equal(value, o) for o in options):
        raise ConfigError(f"{name}={value!r}: use one of {', '.join(repr(o) for o in options)}")
    return value


def _equal(value, option) -> bool:
    try:
        return bool(value == option)
    except (TypeError, ValueError):
        return False


def refuse_unknown(
    where: str, given: Mapping | Iterable[str], accepted: Iterable[str], what: str = "keyword"
) -> None:
    """Refuse names in ``given`` that are not ``accepted`` (typos get a suggestion)."""
    accepted = tuple(accepted)
    unknown = sorted(set(given) - set(accepted))
    if not unknown:
        return
    hints = []
    for name in unknown:
        close = difflib.get_close_matches(str(name), accepted, n=1)
        hints.append(f"{name!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
    raise ConfigError(
        f"{where}: unknown {what}{'s' if len(unknown) > 1 else ''} {', '.join(hints)}; accepted: {', '.join(accepted)}"
    )


def read_text(
    path: str | os.PathLike,
    limit: int,
    what: str,
    error: type[Exception] = ConfigError,
    replace: bool = False,
) -> str:
    """The UTF-8 text of the file ``path``, read up to ``limit`` characters (a path such as ``/dev/zero`` or a
    huge file is refused after ``limit + 1``, never read whole); ``error`` names the path and ``what`` it holds.
    ``replace``: undecodable bytes become U+FFFD instead of an error. Newlines are universal, as in
    ``Path.read_text``."""
    try:
        with open(path, encoding="utf-8", errors="replace" if replace else "strict") as stream:
            # a read of n characters reserves room for n, so a regular file reads its own size, not the limit
            size = os.fstat(stream.fileno())
            count = limit + 1 if not stat.S_ISREG(size.st_mode) else min(limit, size.st_size) + 1
            text = stream.read(count)
    except FileNotFoundError:
        raise error(f"{path}: no such file ({what})") from None
    except OSError as failure:
        raise error(f"{path}: cannot read the {what} ({failure.strerror or failure})") from None
    except UnicodeDecodeError as failure:
        raise error(f"{path}: the {what} is not UTF-8 text (byte {failure.start})") from None
    if len(text) > limit:
        raise error(f"{path}: larger than the {limit:,}-character limit of a {what}")
    return text


def probability_rows(name: str, values, shape: tuple[int, int], tolerance: float) -> np.ndarray:
    """``values`` as a float (rows, columns) array of finite, non-negative entries whose rows each sum to 1
    within ``tolerance``; ``name`` says where the matrix comes from (e.g. ``"FILE: field 'matrix'"``)."""
    try:
        matrix = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{name}: must be {shape[0]} rows of {shape[1]} numbers") from None
    if matrix.shape != tuple(shape):
        raise ConfigError(f"{name}: has shape {matrix.shape}, expected {tuple(shape)}")
    bad = np.argwhere(~np.isfinite(matrix))
    if bad.size:
        row, column = (int(v) for v in bad[0])
        raise ConfigError(
            f"{name}: entry [{row}][{column}] is {float(matrix[row, column])}; every entry must be a finite number"
        )
    bad = np.argwhere(matrix < 0)
    if bad.size:
        row, column = (int(v) for v in bad[0])
        raise ConfigError(
            f"{name}: entry [{row}][{column}] is negative ({matrix[row, column]:g}); probabilities are >= 0"
        )
    sums = matrix.sum(axis=1)
    bad = np.flatnonzero(np.abs(sums - 1.0) > tolerance)
    if bad.size:
        raise ConfigError(f"{name}: row {int(bad[0])} sums to {sums[bad[0]]:.6g}, expected 1")
    return matrix


# Command-line types (argparse ``type=``), used by commands/ and by the trial plug-ins in experiments/.


def bounded(kind: type, minimum: float, what: str):
    """An argparse type: a finite ``kind`` (int or float) >= ``minimum``; ``what`` names what to give
    (e.g. ``bounded(float, math.ulp(0.0), "a finite number of seconds > 0")``)."""

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {what}") from None
        if not math.isfinite(value) or value < minimum:
            raise argparse.ArgumentTypeError(f"{text} is not {what}")
        return value

    parse.__name__ = what  # argparse names the type in its messages
    return parse


def positive_int(text: str) -> int:
    """A count or size: an integer >= 1 (e.g. ``--width``: 0 would silently fall back to a default size)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer; give an integer >= 1") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value}: give an integer >= 1")
    return value
