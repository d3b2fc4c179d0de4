"""Scene compiles, steps under random controls without warnings; object counts pinned; layout matches walls."""

from __future__ import annotations

import itertools

import mujoco
import numpy as np
import pytest

from embodied_adhoc import paths
from embodied_adhoc.domains.lab_graph import DEFAULT_GRAPH
from embodied_adhoc.errors import SceneError
from embodied_adhoc.sim.lab_layout import LAB_LAYOUT, LabLayout
from embodied_adhoc.sim.lab_model import LabIds, load_lab_model

ROBOT_CLEARANCE = 0.34  # circumscribed radius of the robot footprint (chassis + wheels) plus margin


def _walls(model: mujoco.MjModel) -> list[tuple[np.ndarray, np.ndarray]]:
    ids = LabIds.resolve(model)
    return [(model.geom_pos[g][:2].copy(), model.geom_size[g][:2].copy()) for g in ids.wall_geoms]


def _distance_to_box(points: np.ndarray, centre: np.ndarray, half: np.ndarray) -> np.ndarray:
    outside = np.maximum(np.abs(points - centre) - half, 0.0)
    return np.hypot(outside[:, 0], outside[:, 1])


def test_lab_scene_counts_are_pinned():
    model = load_lab_model()
    counts = (model.nbody, model.ngeom, model.njnt, model.nu, model.nsensor, model.nsite, model.ncam)
    assert counts == (
        12,
        84,
        6,
        2,
        77,
        76,
        3,
    )  # the robot's lidar: 72 rangefinders on 72 sites, 1 visual geom
    assert model.nmocap == 2 and model.neq == 3


@pytest.mark.parametrize("scene", sorted(p.name for p in paths.scenes_dir().glob("*.xml")))
def test_every_scene_steps_two_seconds_of_random_controls_without_warnings(scene):
    model = load_lab_model(scene)
    data = mujoco.MjData(model)
    rng = np.random.default_rng(7)
    low, high = model.actuator_ctrlrange.T
    for _ in range(int(2.0 / model.opt.timestep)):
        data.ctrl[:] = rng.uniform(low, high)
        mujoco.mj_step(model, data)
    assert [w.number for w in data.warning] == [0] * len(data.warning)
    assert np.all(np.isfinite(data.qpos))


def test_robot_file_compiles_alone_and_follows_conventions():
    model = mujoco.MjModel.from_xml_path(str(paths.asset("robots/container_robot/container_robot.xml")))
    assert model.nu == 2 and model.nsensor == 5 + 72  # wheel encoders and speeds, gyro; the lidar's 72 beams
    unnamed = [g for g in range(model.ngeom) if not mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)]
    assert unnamed == []
    assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "rfid") >= 0


def test_layout_graph_is_the_abstract_lab_graph():
    assert sorted(LAB_LAYOUT.edges) == sorted(DEFAULT_GRAPH.edges)
    assert LAB_LAYOUT.node_names == DEFAULT_GRAPH.names
    for node in LAB_LAYOUT.nodes:
        assert LAB_LAYOUT.neighbours(node) == DEFAULT_GRAPH.neighbours[node]


def test_node_at_maps_spots_and_rejects_outside_points():
    for node in LAB_LAYOUT.nodes:
        assert LAB_LAYOUT.node_at(LAB_LAYOUT.node_waypoints[node]) == node
    assert LAB_LAYOUT.node_at((6.0, 0.0)) is None
    assert LAB_LAYOUT.node_at((0.0, 4.5)) is None


def test_every_route_keeps_clear_of_every_wall():
    walls = _walls(load_lab_model())
    for start, goal in itertools.permutations(LAB_LAYOUT.nodes, 2):
        for spots in ("robot", "human"):
            origin = (LAB_LAYOUT.node_waypoints if spots == "robot" else LAB_LAYOUT.human_spots)[start]
            points = np.array([origin, *LAB_LAYOUT.route(start, goal, spots)])
            samples = np.concatenate([np.linspace(a, b, 60) for a, b in itertools.pairwise(points)], axis=0)
            clearance = min(_distance_to_box(samples, c, h).min() for c, h in walls)
            assert clearance >= ROBOT_CLEARANCE, (start, goal, spots, clearance)


def test_robot_routes_keep_clear_of_balls_and_human_spots():
    """The robot never drives over a ball lying at its spot, nor through the human's standing spot."""
    obstacles = np.array([*LAB_LAYOUT.ball_spots, *LAB_LAYOUT.human_spots])
    for start, goal in itertools.permutations(LAB_LAYOUT.nodes, 2):
        points = np.array([LAB_LAYOUT.node_waypoints[start], *LAB_LAYOUT.route(start, goal)])
        samples = np.concatenate([np.linspace(a, b, 60) for a, b in itertools.pairwise(points)], axis=0)
        gaps = np.hypot(*(samples[:, None, :] - obstacles[None]).transpose(2, 0, 1))
        assert gaps.min() >= 0.6, (start, goal, gaps.min())


def test_passages_are_gaps_and_area_borders_are_walled():
    """A straight line between adjacent areas' crossing points passes the wall; every other border is closed."""
    walls = _walls(load_lab_model())
    for passage in LAB_LAYOUT.passages:
        mid = np.asarray(passage.midpoint)
        assert min(_distance_to_box(mid[None], c, h)[0] for c, h in walls) >= passage.width / 2 - 1e-9
    # sample points just inside each area: a point of area a at distance 0.1 from a point of a non-adjacent area b
    # must have a wall between them (checked on a grid across the room)
    xs, ys = np.meshgrid(np.arange(-4.95, 5.0, 0.05), np.arange(-3.95, 4.0, 0.05))
    grid = np.stack([xs.ravel(), ys.ravel()], axis=1)
    nodes = np.array([LAB_LAYOUT.node_at(p) for p in grid])
    adjacent = {tuple(sorted(e)) for e in LAB_LAYOUT.edges}
    in_wall = np.zeros(len(grid), dtype=bool)
    for c, h in walls:
        in_wall |= _distance_to_box(grid, c, h) < 0.03
    step = {(1, 0), (0, 1)}
    shape = xs.shape
    node_grid, wall_grid = nodes.reshape(shape), in_wall.reshape(shape)
    for di, dj in step:
        a, b = node_grid[: shape[0] - di, : shape[1] - dj], node_grid[di:, dj:]
        walled = wall_grid[: shape[0] - di, : shape[1] - dj] | wall_grid[di:, dj:]
        crossing = (a != b) & ~walled
        pairs = {tuple(sorted((int(x), int(y)))) for x, y in zip(a[crossing], b[crossing], strict=True)}
        assert pairs <= adjacent, pairs - adjacent


def test_layout_rejects_inconsistent_metadata():
    with pytest.raises(SceneError, match="outside that node's area"):
        LabLayout(node_waypoints=((0.0, 0.0),) * 5)
    with pytest.raises(SceneError, match="not adjacent"):
        LAB_LAYOUT.passage(0, 4)


def test_scene_compiles_from_the_wheel_layout(tmp_path):
    """An installed wheel carries scenes/ and assets/ side by side under embodied_adhoc/_data/ (setup.py); the
    scene's relative includes must resolve there too."""
    import shutil

    for name in ("scenes", "assets"):
        shutil.copytree(
            paths.scenes_dir() if name == "scenes" else paths.assets_dir(), tmp_path / "_data" / name
        )
    model = mujoco.MjModel.from_xml_path(str(tmp_path / "_data" / "scenes" / "lab.xml"))
    assert model.nbody == load_lab_model().nbody


def test_areas_partition_the_room():
    """Every point of the room lies in exactly one area (borders go to the lower index), none outside."""
    rng = np.random.default_rng(0)
    x0, x1, y0, y1 = LAB_LAYOUT.room_extent
    points = rng.uniform((x0, y0), (x1, y1), size=(2000, 2))
    nodes = [LAB_LAYOUT.node_at(p) for p in points]
    assert None not in nodes and set(nodes) == set(LAB_LAYOUT.nodes)
    assert LAB_LAYOUT.node_at((-2.5, -3.0)) == 0  # on the 0 | 2 border: the lower index


def test_human_routes_walk_around_parked_robots():
    robots = np.array(LAB_LAYOUT.node_waypoints)
    for start, goal in itertools.permutations(LAB_LAYOUT.nodes, 2):
        points = np.array([LAB_LAYOUT.human_spots[start], *LAB_LAYOUT.route(start, goal, spots="human")])
        samples = np.concatenate([np.linspace(a, b, 60) for a, b in itertools.pairwise(points)], axis=0)
        gaps = np.hypot(*(samples[:, None, :] - robots[None]).transpose(2, 0, 1))
        assert gaps.min() >= 0.6, (start, goal, gaps.min())
