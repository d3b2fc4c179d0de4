"""The abstract lab's ``rgb_array`` picture (numpy only, about a millisecond): the graph's nodes on a circle
(node 0 at the top, then clockwise), its passages, the robot (orange, left of its node), the human (blue, right
of its node) and the balls: green on the ground at their node, red in the human's hands, grey in the robot's
container."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from embodied_adhoc.domains.lab_graph import DISPOSED, GROUND, LabGraph

BACKGROUND, PASSAGE, NODE = (245, 245, 245), (170, 170, 170), (210, 210, 210)
ROBOT, HUMAN = (240, 140, 20), (40, 90, 220)
BALL = {GROUND: (40, 170, 40), DISPOSED: (120, 120, 120)}
HELD_BALL = (220, 40, 40)


class LabPicture:
    """Draws one lab graph at ``size x size`` pixels."""

    def __init__(self, graph: LabGraph, size: int = 256) -> None:
        self.graph, self.size = graph, size
        angles = 2 * np.pi * np.arange(graph.n_nodes) / graph.n_nodes
        self.nodes = size / 2 + 0.36 * size * np.stack(
            [-np.cos(angles), np.sin(angles)], axis=1
        )  # (row, col)
        self.rows, self.cols = np.mgrid[0:size, 0:size]
        self.background = np.empty((size, size, 3), dtype=np.uint8)
        self.background[:] = BACKGROUND
        t = np.linspace(0.0, 1.0, 2 * size)[:, None]
        for a, b in graph.edges:
            points = np.rint(self.nodes[a] + t * (self.nodes[b] - self.nodes[a])).astype(int)
            for offset in (-1, 0, 1):
                self.background[np.clip(points[:, 0] + offset, 0, size - 1), points[:, 1]] = PASSAGE
        for centre in self.nodes:
            self._disc(self.background, centre, 0.08 * size, NODE)

    def _disc(self, image: np.ndarray, centre, radius: float, colour) -> None:
        mask = (self.rows - centre[0]) ** 2 + (self.cols - centre[1]) ** 2 <= radius**2
        image[mask] = colour

    def draw(self, robot: int, human: int, balls: Sequence[int], status: Sequence[int]) -> np.ndarray:
        """The picture of one state: node indices of robot and human, each ball's node and status."""
        image = self.background.copy()
        unit = self.size / 100
        robot_at = self.nodes[robot] + (0, -3.5 * unit)
        human_at = self.nodes[human] + (0, 3.5 * unit)
        self._disc(image, robot_at, 3 * unit, ROBOT)
        self._disc(image, human_at, 3 * unit, HUMAN)
        for index, (node, state) in enumerate(zip(balls, status, strict=True)):
            spread = (index - (len(balls) - 1) / 2) * 2.4 * unit
            if state == GROUND:
                centre, colour = self.nodes[node] + (5 * unit, spread), BALL[GROUND]
            elif state == DISPOSED:
                centre, colour = robot_at + (4.5 * unit, spread), BALL[DISPOSED]
            else:
                centre, colour = human_at + (-4.5 * unit, 0), HELD_BALL
            self._disc(image, centre, 1.6 * unit, colour)
        return image
