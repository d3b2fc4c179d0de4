"""Atomic file finalisation shared by the recorders: write to a temporary sibling, then rename over the target.

A reader (or an interrupted run) therefore never sees a half-written ``episode.mp4``/``episode.rrd``/
``metrics.json``: the final name exists only once its content is complete (whole-text files such as
``metrics.json`` go through ``experiments.storage.atomic_write_text``).
"""

from __future__ import annotations

import os
from pathlib import Path


def temporary_sibling(path: Path) -> Path:
    """A temporary name next to ``path`` that keeps its suffix (ffmpeg picks the container from it)."""
    return path.with_name(f".{path.stem}.partial-{os.getpid()}{path.suffix}")


def publish(temporary: Path, path: Path) -> Path:
    """Atomically move a finished ``temporary`` file to ``path`` (same folder, so ``os.replace`` is atomic)."""
    os.replace(temporary, path)
    return path
