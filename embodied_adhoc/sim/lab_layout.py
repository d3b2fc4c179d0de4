"""Map metadata of the HOTSPOT lab arena, in the style of dm_control's ``locomotion/arenas/mazes.py``.

The one place that says where the five areas of the toxic-waste lab are (thesis section 7.1, Fig. 7.4):
0 door, 1 open space, 2 robot station, 3 single workbench, 4 double workbench, with passages (graph edges)
0-1, 1-2, 1-3, 3-4; their names and the passages themselves come from :mod:`embodied_adhoc.domains.lab_facts`,
which the abstract model's graph reads too. The waypoint controller, the odometry-to-node mapping, the human
walker and recordings read the geometry from here; ``scenes/lab.xml`` builds the walls and furniture at these
coordinates (a test checks that every route keeps its clearance from every wall geom of the scene).

World frame: metres, x east, y north, origin at the centre of a 10 m x 8 m room (x in [-5, 5], y in [-4, 4]).
Partition walls lie on the area borders; a passage is a 1.2 m gap in a partition.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from embodied_adhoc.domains.lab_facts import EDGES, N_AREAS, NODE_NAMES
from embodied_adhoc.errors import SceneError

XY = tuple[float, float]


@dataclass(frozen=True)
class Passage:
    """A gap in a partition wall joining two areas: ``midpoint`` on the wall centre line, ``normal`` a unit
    vector pointing from area ``nodes[0]`` to area ``nodes[1]``, ``width`` the clear gap in metres."""

    nodes: tuple[int, int]
    midpoint: XY
    normal: XY
    width: float


def _rectangle(x0: float, x1: float, y0: float, y1: float) -> tuple[XY, ...]:
    return ((x0, y0), (x1, y0), (x1, y1), (x0, y1))


@dataclass(frozen=True)
class LabLayout:
    """Topological map of the lab: nodes, edges, area polygons and the waypoints that realise each node.

    Attributes:
        nodes: node ids 0..4 (index into ``node_names``).
        edges: undirected passages between areas (``domains.lab_facts.EDGES``, the abstract model's too).
        area_polygons: per node, a simple polygon (counter-clockwise xy vertices) covering that area.
        node_waypoints: per node, where the robot parks (area centre, clear of furniture and props).
        human_spots: per node, where the human stands while in that area.
        ball_spots: per node, where a waste ball placed at that node lies on the floor.
        passages: one :class:`Passage` per edge.
        passage_offset: distance (m) before/after a wall at which a route crosses straight through a passage.
        human_clearance: the human's routes detour to keep this distance (m) from the robot waypoints of the
            areas they cross, so that a person never walks through the parked robot.
        room_extent: (x_min, x_max, y_min, y_max) of the room interior.
    """

    nodes: tuple[int, ...] = tuple(range(N_AREAS))
    node_names: tuple[str, ...] = NODE_NAMES
    edges: tuple[tuple[int, int], ...] = EDGES
    area_polygons: tuple[tuple[XY, ...], ...] = (
        _rectangle(-2.5, 5.0, -4.0, -2.0),  # 0 door: entrance corridor along the south wall
        _rectangle(-2.5, 5.0, -2.0, 1.0),  # 1 open space
        _rectangle(-5.0, -2.5, -4.0, 1.0),  # 2 robot station (west wing)
        _rectangle(-5.0, 0.0, 1.0, 4.0),  # 3 single workbench (north-west)
        _rectangle(0.0, 5.0, 1.0, 4.0),  # 4 double workbench (north-east)
    )
    node_waypoints: tuple[XY, ...] = ((2.2, -3.35), (0.5, -0.5), (-3.5, -1.6), (-2.2, 2.3), (2.0, 2.4))
    human_spots: tuple[XY, ...] = ((3.1, -2.6), (1.7, 0.1), (-4.2, -0.7), (-3.4, 2.6), (3.2, 2.1))
    ball_spots: tuple[XY, ...] = ((3.6, -3.3), (2.4, -1.0), (-4.3, -2.2), (-3.8, 1.6), (3.9, 1.6))
    passages: tuple[Passage, ...] = (
        Passage((0, 1), (1.0, -2.0), (0.0, 1.0), 1.2),
        Passage((1, 2), (-2.5, -0.5), (-1.0, 0.0), 1.2),
        Passage((1, 3), (-1.0, 1.0), (0.0, 1.0), 1.2),
        Passage((3, 4), (0.0, 2.5), (1.0, 0.0), 1.2),
    )
    passage_offset: float = 0.6
    human_clearance: float = 0.75
    room_extent: tuple[float, float, float, float] = (-5.0, 5.0, -4.0, 4.0)
    _adjacency: dict[int, tuple[int, ...]] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        n = len(self.nodes)
        for name, values in (
            ("node_names", self.node_names),
            ("area_polygons", self.area_polygons),
            ("node_waypoints", self.node_waypoints),
            ("human_spots", self.human_spots),
            ("ball_spots", self.ball_spots),
        ):
            if len(values) != n:
                raise SceneError(f"LabLayout.{name} has {len(values)} entries, expected one per node ({n})")
        if tuple(self.nodes) != tuple(range(n)):
            raise SceneError(f"LabLayout.nodes must be 0..{n - 1} in order, got {self.nodes}")
        if {tuple(sorted(p.nodes)) for p in self.passages} != {tuple(sorted(e)) for e in self.edges}:
            raise SceneError(
                "LabLayout.passages must contain exactly one passage per edge of LabLayout.edges"
            )
        adjacency: dict[int, list[int]] = {node: [] for node in self.nodes}
        for a, b in self.edges:
            adjacency[a].append(b)
            adjacency[b].append(a)
        object.__setattr__(self, "_adjacency", {k: tuple(sorted(v)) for k, v in adjacency.items()})
        for node, spots in enumerate(
            zip(self.node_waypoints, self.human_spots, self.ball_spots, strict=True)
        ):
            for spot in spots:
                if self.node_at(spot) != node:
                    raise SceneError(f"LabLayout: spot {spot} of node {node} lies outside that node's area")

    # ----------------------------------------------------------------------------------------- graph
    def neighbours(self, node: int) -> tuple[int, ...]:
        """Adjacent nodes in ascending index (the order the abstract model's move actions use)."""
        self.check_node(node)
        return self._adjacency[node]

    def node_path(self, from_node: int, to_node: int) -> list[int]:
        """Shortest node sequence from ``from_node`` to ``to_node`` inclusive (breadth-first search)."""
        self.check_node(from_node)
        self.check_node(to_node)
        parent = {from_node: from_node}
        queue = deque([from_node])
        while queue:
            node = queue.popleft()
            for nxt in self._adjacency[node]:
                if nxt not in parent:
                    parent[nxt] = node
                    queue.append(nxt)
        if to_node not in parent:
            raise SceneError(f"LabLayout: node {to_node} is unreachable from node {from_node}")
        path = [to_node]
        while path[-1] != from_node:
            path.append(parent[path[-1]])
        return path[::-1]

    def passage(self, a: int, b: int) -> Passage:
        """The passage joining adjacent nodes ``a`` and ``b``."""
        for passage in self.passages:
            if set(passage.nodes) == {a, b}:
                return passage
        raise SceneError(f"LabLayout: nodes {a} and {b} are not adjacent (edges: {self.edges})")

    @property
    def passage_midpoints(self) -> dict[tuple[int, int], XY]:
        """Passage midpoints keyed by the (sorted) edge."""
        return {tuple(sorted(p.nodes)): p.midpoint for p in self.passages}

    def crossing(self, a: int, b: int) -> tuple[XY, XY]:
        """The two points a route uses to cross straight through the passage from area ``a`` into ``b``:
        ``passage_offset`` metres before and after the wall, on the passage's centre line."""
        passage = self.passage(a, b)
        sign = 1.0 if passage.nodes == (a, b) else -1.0
        mid = np.asarray(passage.midpoint)
        normal = sign * np.asarray(passage.normal)
        before = mid - self.passage_offset * normal
        after = mid + self.passage_offset * normal
        return (float(before[0]), float(before[1])), (float(after[0]), float(after[1]))

    def route(self, from_node: int, to_node: int, spots: str = "robot") -> list[XY]:
        """Waypoints (xy) from the spot of ``from_node`` (excluded) to the spot of ``to_node`` (included).

        The route follows the node path and crosses each passage straight through its two crossing points.
        ``spots`` selects the end points: "robot" (node waypoints) or "human" (human spots).
        An empty list when ``from_node == to_node``.
        """
        targets = self._spots(spots)
        path = self.node_path(from_node, to_node)
        waypoints: list[XY] = []
        previous = targets[from_node]
        for a, b in zip(path[:-1], path[1:], strict=True):
            before, after = self.crossing(a, b)
            if spots == "human":  # walk around a robot parked in the area being left / entered
                waypoints.extend(self._detour(previous, before, a))
            waypoints.extend((before, after))
            if spots == "human":
                waypoints.extend(self._detour(after, targets[b], b))
            waypoints.append(targets[b])
            previous = targets[b]
        return waypoints

    def _detour(self, start: XY, end: XY, node: int) -> list[XY]:
        """A point to insert on the leg start -> end (inside ``node``'s area) so that a walking person keeps
        ``human_clearance`` from a robot parked at the node's waypoint; [] if the straight leg already does."""
        robot = np.asarray(self.node_waypoints[node])
        a, b = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
        leg = b - a
        t = float(np.clip((robot - a) @ leg / (leg @ leg), 0.0, 1.0))
        offset = a + t * leg - robot
        if np.linalg.norm(offset) >= self.human_clearance:
            return []
        normal = np.array([-leg[1], leg[0]]) / np.linalg.norm(leg)
        if offset @ normal < 0:
            normal = -normal
        point = robot + self.human_clearance * normal
        return [(float(point[0]), float(point[1]))]

    def route_from(self, xy: Sequence[float], to_node: int, spots: str = "robot") -> list[XY]:
        """Waypoints from an arbitrary position to ``to_node``'s spot: the route from the node containing ``xy``
        (or the nearest node waypoint when ``xy`` lies in no area). Waypoints already passed are not skipped:
        the first leg goes from ``xy`` to the first crossing point (or to the target spot, same node)."""
        start = self.node_at(xy)
        if start is None:
            start = self.nearest_node(xy)
        if start == to_node:
            return [self._spots(spots)[to_node]]
        return self.route(start, to_node, spots)

    # ----------------------------------------------------------------------------------------- geometry
    def node_at(self, xy: Sequence[float]) -> int | None:
        """The node whose area polygon contains ``xy`` (borders count for the lower index); None if none."""
        x, y = float(xy[0]), float(xy[1])
        for node, polygon in enumerate(self.area_polygons):
            if _point_in_polygon(x, y, polygon):
                return node
        return None

    def nearest_node(self, xy: Sequence[float]) -> int:
        """The node whose waypoint is closest to ``xy`` (the original HOTSPOT robot's mapping)."""
        points = np.asarray(self.node_waypoints)
        return int(np.argmin(np.hypot(points[:, 0] - xy[0], points[:, 1] - xy[1])))

    def _spots(self, spots: str) -> tuple[XY, ...]:
        if spots == "robot":
            return self.node_waypoints
        if spots == "human":
            return self.human_spots
        raise SceneError(f"LabLayout.route: spots must be 'robot' or 'human', got {spots!r}")

    def check_node(self, node: int) -> None:
        """Raise a SceneError unless ``node`` is a valid node id."""
        if not isinstance(node, int | np.integer) or not 0 <= int(node) < len(self.nodes):
            raise SceneError(f"LabLayout: node must be an int in 0..{len(self.nodes) - 1}, got {node!r}")


def _point_in_polygon(x: float, y: float, polygon: Sequence[XY]) -> bool:
    """Inclusive point-in-polygon test (points on an edge count as inside), by ray casting."""
    inside = False
    count = len(polygon)
    for i in range(count):
        (x0, y0), (x1, y1) = polygon[i], polygon[(i + 1) % count]
        # on the edge?
        cross = (x1 - x0) * (y - y0) - (y1 - y0) * (x - x0)
        if (
            abs(cross) < 1e-12
            and min(x0, x1) - 1e-12 <= x <= max(x0, x1) + 1e-12
            and (min(y0, y1) - 1e-12 <= y <= max(y0, y1) + 1e-12)
        ):
            return True
        if (y0 > y) != (y1 > y):
            x_cross = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
            if x < x_cross:
                inside = not inside
    return inside


LAB_LAYOUT = LabLayout()
"""The default lab (the one ``scenes/lab.xml`` is built for)."""
