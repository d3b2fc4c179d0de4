"""Atomic file output, the one mechanism every writer uses (results, recordings, policies, models, matrices).

A file appears under its final name only once it is complete: content goes to a temporary sibling in the same
folder (so the rename is atomic), which is renamed over the target on success and deleted on failure. The
temporary file is created by ``tempfile.mkstemp`` in the target's folder: ``O_CREAT | O_EXCL`` with an
unpredictable name, so nothing planted in advance (a file, or a symlink pointing elsewhere) is ever opened or
followed. Finished files get ordinary permissions (0666 minus the umask), not the private mode of a temporary
file.

* :func:`atomic_open` gives an open binary stream (the safest: nothing reopens the file by name); writers that
  take a file object (``numpy.savez``, ``json.dump`` on bytes) use it, and then write exactly the path asked.
* :func:`atomic_path` gives the name of the (already created, empty) temporary file, for tools that open a path
  themselves (matplotlib, soundfile); :func:`temporary_sibling` and :func:`publish` are its two halves, for
  writers that keep a file open across many calls (ffmpeg, rerun).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _create_temporary(path: Path) -> tuple[int, Path]:
    """Create (O_EXCL) a fresh temporary file next to ``path`` that keeps its suffix; return (fd, name)."""
    descriptor, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.partial-", suffix=path.suffix)
    return descriptor, Path(name)


def temporary_sibling(path: str | os.PathLike) -> Path:
    """Create an empty temporary file next to ``path`` and return its name.

    The name keeps ``path``'s suffix (ffmpeg and matplotlib pick the format from it) and is unpredictable; the
    file exists from this call on (created with ``O_EXCL``), so a tool that then opens it by name writes our own
    file. The caller publishes it with :func:`publish` or removes it. The folder must exist.
    """
    descriptor, temporary = _create_temporary(Path(path))
    os.close(descriptor)
    return temporary


def publish(temporary: str | os.PathLike, path: str | os.PathLike) -> Path:
    """Give a finished ``temporary`` ordinary permissions and move it over ``path`` atomically.

    For writers that keep a file open across many calls (video, rerun); one-shot writers use :func:`atomic_path`.
    """
    os.chmod(temporary, 0o666 & ~_umask())
    os.replace(temporary, path)
    return Path(path)


@contextmanager
def atomic_open(path: str | os.PathLike) -> Iterator[BinaryIO]:
    """Yield a binary stream whose content replaces ``path`` on normal exit (flushed and fsynced first).

    On any exception the temporary file is removed and ``path`` is left as it was. Parent folders are created.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor, temporary = _create_temporary(path)
    try:
        with os.fdopen(descriptor, "wb") as stream:
            yield stream
            stream.flush()
            os.fsync(stream.fileno())
        publish(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield the name of a fresh temporary sibling of ``path`` (same suffix, so tools that pick a format from it
    still work).

    Write to it inside the ``with`` block; on normal exit it replaces ``path``; on any exception it is removed
    and ``path`` is left as it was. Parent folders are created. A writer that appends its own extension to the
    name it is given (``numpy.savez`` on a name not ending in ``.npz``) must use :func:`atomic_open` instead.
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
    with atomic_open(path) as stream:
        stream.write(data)
    return Path(path)


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically (newlines written as given)."""
    return atomic_write_bytes(path, text.encode("utf-8"))
