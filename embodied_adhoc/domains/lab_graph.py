"""The topological map of the HOTSPOT lab (thesis section 7.1, Fig. 7.4) and the waste-ball vocabulary.

Nodes are areas, edges are passages. Robot and human moves are phrased as "move to the k-th lowest-index
neighbour" (k = 1..max degree); a k beyond a node's degree falls back to the lowest-index neighbour, as in the
original implementation. Distances are shortest-path hop counts (breadth-first search).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from embodied_adhoc import checks
from embodied_adhoc.domains.lab_facts import EDGES, N_AREAS, NODE_NAMES
from embodied_adhoc.errors import ConfigError

__all__ = [
    "DEFAULT_GRAPH",
    "DEFAULT_TASKS",
    "DISPOSED",
    "GROUND",
    "HELD",
    "MAX_STATE_CODES",
    "MAX_TASKS",
    "LabGraph",
    "validate_tasks",
]

GROUND, HELD, DISPOSED = 0, 1, 2
"""Ball status values: on the ground, held by the human, disposed in the robot's container."""


@dataclass(frozen=True)
class LabGraph:
    """An undirected connected graph of ``n_nodes`` areas with ``edges`` (pairs of node indices) and ``names``;
    the default is the lab's map (:mod:`embodied_adhoc.domains.lab_facts`)."""

    n_nodes: int = N_AREAS
    edges: tuple[tuple[int, int], ...] = EDGES
    names: tuple[str, ...] = NODE_NAMES
    neighbours: tuple[tuple[int, ...], ...] = field(init=False, repr=False, compare=False)
    distances: np.ndarray = field(init=False, repr=False, compare=False)
    max_degree: int = field(init=False, repr=False, compare=False)
    """Number of "move to the k-th neighbour" actions (3 for the default lab)."""

    def __post_init__(self) -> None:
        if self.n_nodes < 1:
            raise ConfigError(f"LabGraph.n_nodes must be >= 1, got {self.n_nodes}")
        edges = tuple((int(a), int(b)) for a, b in self.edges)
        names = tuple(str(n) for n in self.names)
        if len(names) != self.n_nodes:
            raise ConfigError(
                f"LabGraph.names has {len(names)} entries for {self.n_nodes} nodes; give one name per node"
            )
        adjacency: list[set[int]] = [set() for _ in range(self.n_nodes)]
        for a, b in edges:
            if not (0 <= a < self.n_nodes and 0 <= b < self.n_nodes) or a == b:
                raise ConfigError(
                    f"LabGraph.edges: edge ({a}, {b}) must join two different nodes in 0..{self.n_nodes - 1}"
                )
            adjacency[a].add(b)
            adjacency[b].add(a)
        neighbours = tuple(tuple(sorted(s)) for s in adjacency)
        distances = np.full((self.n_nodes, self.n_nodes), -1, dtype=np.int64)
        for source in range(self.n_nodes):
            distances[source, source] = 0
            queue = deque([source])
            while queue:
                node = queue.popleft()
                for nxt in neighbours[node]:
                    if distances[source, nxt] < 0:
                        distances[source, nxt] = distances[source, node] + 1
                        queue.append(nxt)
        if self.n_nodes > 1 and (distances < 0).any():
            a, b = np.argwhere(distances < 0)[0]
            raise ConfigError(f"LabGraph is not connected: no path from node {a} to node {b}; add an edge")
        if self.n_nodes > 1 and min(len(n) for n in neighbours) == 0:
            raise ConfigError("LabGraph: every node needs at least one neighbour")
        distances.setflags(write=False)
        object.__setattr__(self, "edges", edges)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "neighbours", neighbours)
        object.__setattr__(self, "distances", distances)
        object.__setattr__(self, "max_degree", max((len(n) for n in neighbours), default=0))

    def move_target(self, node: int, k: int) -> int:
        """Node reached by "move to the (k+1)-th lowest-index neighbour" (0-based ``k``); fallback: the lowest."""
        options = self.neighbours[node]
        return options[k] if k < len(options) else options[0]


DEFAULT_GRAPH = LabGraph()
DEFAULT_TASKS: tuple[tuple[int, ...], ...] = ((0, 1, 2), (1, 2, 3))
"""The two evaluated ball placements (thesis Fig. 7.6): balls at nodes [0, 1, 2] and [1, 2, 3]."""

MAX_TASKS = 64
"""At most this many ball placements: each task adds a POMDP over the shared states."""
MAX_STATE_CODES = 200_000
"""The shared state space enumerates ``n_nodes^2 * 3^balls * 2`` candidate states before keeping the valid ones;
above this count (e.g. more than 7 balls on the 5-node lab) the enumeration alone would take gigabytes."""


def validate_tasks(graph: LabGraph, tasks: Sequence[Sequence[int]]) -> tuple[tuple[int, ...], ...]:
    """Check a task library (ball nodes per task): non-empty, same number of balls, nodes inside the graph."""
    if isinstance(tasks, np.ndarray):
        tasks = tasks.tolist()
    placements = (Sequence, np.ndarray)
    if (
        not isinstance(tasks, Sequence)
        or isinstance(tasks, str)
        or not all(isinstance(t, placements) and not isinstance(t, str) for t in tasks)
    ):
        raise ConfigError(
            f"tasks={tasks!r}: give a list of ball placements (node lists), e.g. [[0, 1, 2], [1, 2, 3]]"
        )
    _check_sizes(graph, tasks)
    result = tuple(
        tuple(checks.integer(f"tasks[{i}][{j}]", node) for j, node in enumerate(task))
        for i, task in enumerate(tasks)
    )
    if not result:
        raise ConfigError("tasks: give at least one ball placement, e.g. [[0, 1, 2], [1, 2, 3]]")
    sizes = {len(task) for task in result}
    if len(sizes) != 1 or 0 in sizes:
        raise ConfigError(
            f"tasks: every task must place the same (non-zero) number of balls, got sizes {sorted(sizes)}"
        )
    for index, task in enumerate(result):
        for node in task:
            if not 0 <= node < graph.n_nodes:
                raise ConfigError(
                    f"tasks[{index}] places a ball at node {node}, outside 0..{graph.n_nodes - 1}"
                )
    return result


def _check_sizes(graph: LabGraph, tasks: Sequence) -> None:
    """Refuse a library whose states would not fit, from the lengths alone (before any element is read)."""
    if len(tasks) > MAX_TASKS:
        raise ConfigError(f"tasks: {len(tasks)} ball placements given; at most {MAX_TASKS} are accepted")
    for index, task in enumerate(tasks):
        codes = graph.n_nodes**2 * 2 * 3 ** min(len(task), 64)  # 3^64 already exceeds any limit
        if codes > MAX_STATE_CODES:
            raise ConfigError(
                f"tasks[{index}]: {len(task)} balls on {graph.n_nodes} nodes give "
                f"{graph.n_nodes}^2 x 3^{len(task)} x 2 "
                f"candidate states, more than the limit of {MAX_STATE_CODES:,}; place fewer balls"
            )
