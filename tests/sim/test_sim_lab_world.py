"""LabWorld behaviour: driving the whole graph on odometry, RFID events, human commands, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.sim.lab_layout import LAB_LAYOUT
from embodied_adhoc.sim.lab_world import HumanCommand, LabWorld, LabWorldConfig

# from the door, every edge in both directions: 0-1, 1-2, 2-1, 1-3, 3-4, 4-3, 3-1, 1-0
TOUR = (1, 2, 1, 3, 4, 3, 1, 0)


@pytest.fixture(scope="module")
def world():
    lab = LabWorld()
    yield lab
    lab.close()


DIRECTED_EDGES = tuple((a, b) for edge in LAB_LAYOUT.edges for a, b in (edge, edge[::-1]))


def test_robot_drives_every_edge_both_ways_on_odometry_alone(world):
    for index, (start, goal) in enumerate(DIRECTED_EDGES):
        yaw = float(np.random.default_rng(index).uniform(-math.pi, math.pi))
        world.reset(seed=index, robot_node=start, human_node=start, ball_nodes=(0, 1, 2), robot_yaw=yaw)
        result = world.step_macro(goal, HumanCommand.stay())
        truth = world.ground_truth()
        assert result.robot_arrived and not result.timed_out, (start, goal, result)
        assert math.dist(truth.robot_pose[:2], LAB_LAYOUT.node_waypoints[goal]) <= 0.15, (start, goal, truth)
        assert not result.wall_contact, (start, goal)
        assert result.mujoco_warnings == 0
        assert result.true_robot_node == result.odometry_node == goal


def test_node_estimate_over_a_full_tour_is_right_thesis_metric_7(world):
    """Dead reckoning over a whole tour (drift accumulates, no re-localisation): the node estimate from the
    area polygons matches the true node at every arrival."""
    world.reset(seed=11, robot_node=0, human_node=4, ball_nodes=(0, 1, 2))
    for target in TOUR:
        result = world.step_macro(target, HumanCommand.stay())
        assert result.robot_arrived and not result.wall_contact, (target, result)
        assert result.true_robot_node == target and result.odometry_node == target, (target, result)
    assert world.odometry_error() < 0.6


def test_every_dropped_ball_gives_exactly_one_rfid_event(world):
    world.reset(seed=3, robot_node=1, human_node=1, ball_nodes=(1, 1, 1))
    seen: list[int] = []
    for ball in (2, 0, 1):
        picked = world.step_macro(None, HumanCommand.pick(ball))
        assert picked.human_succeeded, picked.human_status
        assert world.ground_truth().ball_states[ball] == "held"
        seen.extend(picked.rfid_events)
        dropped = world.step_macro(None, HumanCommand.drop_into_container(ball))
        assert dropped.human_succeeded, dropped.human_status
        assert dropped.rfid_events == (ball,)
        seen.extend(dropped.rfid_events)
    settle = world.step_macro(None, HumanCommand.stay())
    seen.extend(settle.rfid_events)
    assert seen == [2, 0, 1]
    assert world.ground_truth().ball_states == ("container",) * 3


def test_rfid_reader_that_always_misses_reports_nothing():
    with LabWorld(LabWorldConfig(rfid_miss_probability=1.0)) as lab:
        lab.reset(seed=0, robot_node=2, human_node=2, ball_nodes=(2, 0, 1))
        lab.step_macro(None, HumanCommand.pick(0))
        result = lab.step_macro(None, HumanCommand.drop_into_container(0))
        assert result.human_succeeded and result.rfid_events == ()
        assert lab.ground_truth().ball_states[0] == "container"


def test_human_walks_and_refuses_impossible_commands(world):
    world.reset(seed=0, robot_node=0, human_node=3, ball_nodes=(0, 1, 2))
    far = world.step_macro(None, HumanCommand.pick(0))  # ball 0 lies at the door, the human is at node 3
    assert not far.human_succeeded and "not in the human's area" in far.human_status
    walk = world.step_macro(None, HumanCommand.move_to(0))
    assert walk.human_succeeded and walk.human_node == 0
    assert math.dist(world.ground_truth().human_pose[:2], LAB_LAYOUT.human_spots[0]) < 1e-6
    points = np.array([LAB_LAYOUT.human_spots[3], *LAB_LAYOUT.route(3, 0, spots="human")])
    length = np.hypot(*np.diff(points, axis=0).T).sum()
    assert walk.sim_seconds == pytest.approx(length / world.config.human_speed, abs=0.1)
    assert world.step_macro(None, HumanCommand.pick(0)).human_succeeded
    world.step_macro(1, HumanCommand.stay())
    away = world.step_macro(None, HumanCommand.drop_into_container(0))
    assert not away.human_succeeded and "not co-located" in away.human_status
    assert world.ground_truth().ball_states[0] == "held"


def test_same_seed_gives_a_bit_identical_trajectory():
    def run(seed: int) -> tuple[np.ndarray, tuple[float, ...]]:
        with LabWorld() as lab:
            lab.reset(seed=seed, robot_node=1, human_node=1, ball_nodes=(1, 2, 3))
            lab.step_macro(3, HumanCommand.pick(0))
            return lab.data.qpos.copy(), lab.odometry_pose()

    qpos_a, odo_a = run(5)
    qpos_b, odo_b = run(5)
    qpos_c, odo_c = run(6)
    assert np.array_equal(qpos_a, qpos_b) and odo_a == odo_b
    assert odo_a != odo_c  # encoder noise and slip come from the seed


def test_public_control_tick_drives_stands_and_collects_sensing(world):
    """start_action/tick/sensed/action_result: what step_macro loops over and the real-time env calls."""
    world.reset(seed=2, robot_node=1, human_node=4, ball_nodes=(0, 1, 2))
    start, pose = world.data.time, world.true_robot_pose()
    world.start_action(3)
    for _ in range(50):  # one simulated second standing still while the agent "decides"
        world.tick(drive=False)
    assert math.dist(world.true_robot_pose()[:2], pose[:2]) < 0.01
    assert not world.controller.finished and world.current_route
    while not world.controller.finished and world.data.time - start < 30.0:
        world.tick()
    result = world.action_result(start, 0, 0, with_human=False)
    assert result.robot_arrived and not result.blocked and result.true_robot_node == 3
    assert result.sim_seconds == pytest.approx(world.data.time - start)
    assert world.sensed() == ((), False)  # action_result collected (and cleared) the sensing
    with pytest.raises(ConfigError, match="before reset"):
        LabWorld().start_action(1)


def test_fast_renders_leave_the_models_render_settings_alone():
    with LabWorld() as lab:
        quality = lab.model.vis.quality
        before = (quality.numslices, quality.numstacks, quality.numquads, quality.offsamples)
        lab.reset(seed=0, robot_node=1, human_node=1, ball_nodes=(0, 1, 2))
        assert lab.render("overhead", 64, 48).std() > 5
        assert (quality.numslices, quality.numstacks, quality.numquads, quality.offsamples) == before
        assert lab.model.vis.global_.offwidth == 1920


def test_frame_callback_runs_at_the_video_rate_and_renders(world):
    world.reset(seed=0, robot_node=1, human_node=1, ball_nodes=(0, 1, 2))
    frames = []
    result = world.step_macro(None, HumanCommand.stay(), frame_callback=lambda w: frames.append(w.data.time))
    assert len(frames) == pytest.approx(result.sim_seconds * world.config.video_fps, abs=1)
    for camera in ("overhead", "robot", "perspective"):
        image = world.render(camera, width=80, height=64)
        assert image.shape == (64, 80, 3) and image.dtype == np.uint8 and image.std() > 5
    with pytest.raises(ConfigError, match="no camera"):
        world.render("ceiling")
    with pytest.raises(ConfigError, match="offscreen"):
        world.render("overhead", width=4000, height=100)


def test_bad_arguments_are_clear_errors(world):
    with pytest.raises(ConfigError, match="render_quality"):
        LabWorldConfig(render_quality="ultra")
    with pytest.raises(ConfigError, match="whole multiple"):
        LabWorldConfig(control_period=0.021)
    with pytest.raises(ConfigError, match="ball_nodes"):
        world.reset(seed=0, robot_node=0, human_node=0, ball_nodes=(0, 1))
    with pytest.raises(ConfigError, match="kind must be one of"):
        HumanCommand("dance")
