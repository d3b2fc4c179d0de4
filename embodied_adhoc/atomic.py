"""Atomic file output, the one mechanism every writer uses (results, recordings, policies, models, matrices).

A file appears under its final name only once it is complete: content goes to a temporary sibling in the same
folder (so the rename is atomic), which is renamed over the target on success and deleted on failure. Finished
files get ordinary permissions (0666 minus the umask), not the private mode of a temporary file.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def temporary_sibling(path: str | os.PathLike) -> Path:
    """A temporary name next to ``path`` that keeps its suffix (ffmpeg, matplotlib pick the format from it)."""
    path = Path(path)
    return path.with_name(f".{path.stem}.partial-{os.getpid()}{path.suffix}")


def publish(temporary: str | os.PathLike, path: str | os.PathLike) -> Path:
    """Give a finished ``temporary`` ordinary permissions and move it over ``path`` atomically.

    For writers that keep a file open across many calls (video, rerun); one-shot writers use :func:`atomic_path`.
    """
    os.chmod(temporary, 0o666 & ~_umask())
    os.replace(temporary, path)
    return Path(path)


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary sibling of ``path`` (same suffix, so tools that pick a format from it still work).

    Write to it inside the ``with`` block; on normal exit it replaces ``path``; on any exception it is removed
    and ``path`` is left as it was. Parent folders are created.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = temporary_sibling(path)
    try:
        yield temporary
        publish(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (flushed and fsynced before the rename)."""
    with atomic_path(path) as temporary:
        with open(temporary, "wb") as stream:
            stream.write(data)
            stream.flush()
            os.fsync(stream.fileno())
    return Path(path)


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically (newlines written as given)."""
    return atomic_write_bytes(path, text.encode("utf-8"))
