"""Atomic file finalisation shared by the recorders: write to a temporary sibling, then rename over the target.

A reader (or an interrupted run) therefore never sees a half-written ``episode.mp4``/``episode.rrd``/
``metrics.json``: the final name exists only once its content is complete.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any


def temporary_sibling(path: Path) -> Path:
    """A temporary name next to ``path`` that keeps its suffix (ffmpeg picks the container from it)."""
    return path.with_name(f".{path.stem}.partial-{os.getpid()}{path.suffix}")


def publish(temporary: Path, path: Path) -> Path:
    """Atomically move a finished ``temporary`` file to ``path`` (same folder, so ``os.replace`` is atomic)."""
    os.replace(temporary, path)
    return path


def write_json_atomic(path: Path, payload: Any) -> Path:
    """Write ``payload`` as indented JSON to ``path`` atomically (temp file + fsync + rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = temporary_sibling(path)
    with open(temporary, "w", encoding="utf-8") as handle:
        json.dump(payload, handle, indent=2, sort_keys=False, allow_nan=False)
        handle.write("\n")
        handle.flush()
        os.fsync(handle.fileno())
    return publish(temporary, path)
