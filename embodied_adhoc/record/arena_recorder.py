"""Rerun recording of a grid-arena episode (``run pursuit``): the lab recorder's stream, timelines, belief bars,
entropy, text logs and cameras, plus the arena's own entities.

=========================  ===========  ==========================================================
entity                     archetype    content
=========================  ===========  ==========================================================
``world/arena/cells``      LineStrips3D the cell grid (static)
``world/arena/robots``     Points3D     every robot's true position, labelled and coloured, per frame
``world/arena/headings``   Arrows3D     every robot's heading, per frame
=========================  ===========  ==========================================================

Everything else (``belief/task``, ``belief/entropy``, ``log/*``, ``camera/*``, the ``step`` and ``sim_time``
timelines) is :class:`~embodied_adhoc.record.rerun_recorder.RerunRecorder`'s.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from embodied_adhoc.record.rerun_recorder import RerunRecorder

__all__ = ["ARENA_ENTITY_PATHS", "ArenaRerunRecorder"]

ARENA_ENTITY_PATHS = ("world/arena/cells", "world/arena/robots", "world/arena/headings")


class ArenaRerunRecorder(RerunRecorder):
    """A :class:`RerunRecorder` that also logs the arena's cells and robots (see the module docstring)."""

    def log_cells(self, rows: int, cols: int, cell: float) -> None:
        """The ``rows x cols`` grid of ``cell``-metre cells centred on the origin, once (static)."""
        width, height = cols * cell, rows * cell
        lines = [
            np.array([[x, -height / 2, 0.0], [x, height / 2, 0.0]])
            for x in np.linspace(-width / 2, width / 2, cols + 1)
        ]
        lines += [
            np.array([[-width / 2, y, 0.0], [width / 2, y, 0.0]])
            for y in np.linspace(-height / 2, height / 2, rows + 1)
        ]
        self._stream.log(
            "world/arena/cells",
            self._rr.LineStrips3D(lines, colors=[(170, 170, 170)], radii=0.004),
            static=True,
        )

    def log_robots(
        self, poses: np.ndarray, labels: Sequence[str], colors: Sequence[tuple[int, int, int]]
    ) -> None:
        """Robot positions and headings (``poses``: (n, 3) x, y, yaw) at the current time."""
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        points = np.column_stack([poses[:, :2], np.full(len(poses), 0.05)])
        arrows = 0.1 * np.column_stack([np.cos(poses[:, 2]), np.sin(poses[:, 2]), np.zeros(len(poses))])
        rr = self._rr
        self._stream.log(
            "world/arena/robots", rr.Points3D(points, labels=list(labels), colors=list(colors), radii=0.06)
        )
        self._stream.log(
            "world/arena/headings", rr.Arrows3D(origins=points, vectors=arrows, colors=list(colors))
        )
