"""The lidar and Monte Carlo localisation of the container robot (sim/lidar.py, sim/localisation.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from embodied_adhoc.errors import ConfigError, SceneError
from embodied_adhoc.sim.lab_world import HumanCommand, LabWorld, LabWorldConfig
from embodied_adhoc.sim.lidar import Lidar, LidarConfig
from embodied_adhoc.sim.localisation import LocalisationConfig, compose, relative
from embodied_adhoc.sim.odometry import OdometryConfig


@pytest.fixture(scope="module")
def world():
    lab = LabWorld()
    yield lab
    lab.close()


def _error(world: LabWorld) -> float:
    x, y, _ = world.true_robot_pose()
    estimate = world.pose_estimate()
    return math.hypot(estimate[0] - x, estimate[1] - y)


def test_lidar_ring_reads_the_walls_and_never_the_robot(world):
    world.reset(seed=0, robot_node=1, human_node=4, ball_nodes=(0, 1, 2))
    world.drive((0.0, 0.0), 0.2)
    lidar = world.lidar
    assert 36 <= lidar.n_beams <= 72
    raw = lidar.raw(world.data)
    # the robot stands at (0.5, -0.5) facing east (yaw 0), nothing closer than 1 m: no beam hits its own body
    assert raw.min() > 1.0, raw.min()
    # beam 0 points east along the scan plane; beams 18 (90 deg) north: partition 1-3 at y = 0.95
    origin_x = 0.5 + lidar.origin[0]
    angles = np.degrees(lidar.angles)
    north = int(np.argmin(np.abs(angles - 90.0)))
    assert raw[north] == pytest.approx(0.95 + 0.5, abs=0.02)
    east = int(np.argmin(np.abs(angles)))
    assert raw[east] > 4.0 - origin_x  # the open space reaches the east wall (furniture-free at y = -0.5)
    scan = lidar.scan(world.data, np.random.default_rng(0))
    assert np.nanmax(np.abs(scan.ranges - raw)) < 0.1  # noise of a few centimetres


def test_lidar_noise_dropout_and_range_window_are_seeded():
    model_world = LabWorld(LabWorldConfig(lidar=LidarConfig(noise=0.02, dropout=0.5, max_range=3.0)))
    model_world.reset(seed=1, robot_node=1, human_node=4, ball_nodes=(0, 1, 2))
    lidar = model_world.lidar
    first = lidar.scan(model_world.data, np.random.default_rng(5)).ranges
    again = lidar.scan(model_world.data, np.random.default_rng(5)).ranges
    np.testing.assert_array_equal(first, again)
    assert 0.2 < np.isnan(first).mean() < 0.95  # half the beams dropped, plus those beyond 3 m
    assert np.nanmax(first) <= 3.0
    with pytest.raises(ConfigError, match="dropout"):
        LidarConfig(dropout=1.5)
    with pytest.raises(ConfigError, match="cutoff"):
        Lidar(model_world.model, LidarConfig(max_range=12.0))
    model_world.close()


def test_se2_compose_and_relative_are_inverse():
    a, b = (1.0, -2.0, 0.7), (-0.5, 3.0, -2.9)
    back = compose(a, relative(a, b))
    assert back == pytest.approx(b)


def test_converges_from_a_uniform_start_after_a_short_drive(world):
    world.reset(seed=2, robot_node=1, human_node=4, ball_nodes=(0, 1, 2))
    world.localiser.reset(np.random.default_rng(3), world.odometry.pose, pose=None, time=world.data.time)
    assert world.localiser.covariance[0, 0] > 1.0  # spread over the whole lab
    world.drive((4.0, 4.0), 1.5)  # ~0.4 m straight ahead
    world.drive((-3.0, 3.0), 1.0)  # turn left on the spot
    world.drive((4.0, 4.0), 1.0)
    assert _error(world) < 0.2, (world.true_robot_pose(), world.pose_estimate())
    assert np.sqrt(world.localiser.covariance[0, 0] + world.localiser.covariance[1, 1]) < 0.2
    assert world.robot_node_reading() == world.ground_truth().robot_node == 1


def test_without_lidar_it_degrades_to_odometry_and_says_so():
    lab = LabWorld(LabWorldConfig(lidar=LidarConfig(enabled=False)))
    lab.reset(seed=4, robot_node=1, human_node=4, ball_nodes=(0, 1, 2))
    spread_before = lab.localiser.covariance[0, 0]
    result = lab.step_macro(3, HumanCommand.stay())
    assert result.localisation_mode == "odometry" and lab.localiser.mode == "odometry"
    assert lab.localiser.status().mode == "odometry"
    # the estimate is dead reckoning (the particles move with odometry), and honest about it: the spread grows
    odometry = lab.odometry_pose()
    assert math.hypot(lab.pose_estimate()[0] - odometry[0], lab.pose_estimate()[1] - odometry[1]) < 0.15
    assert lab.localiser.covariance[0, 0] > 4 * spread_before
    lab.close()


def test_kidnapping_is_detected_and_recovered(world):
    world.reset(seed=5, robot_node=1, human_node=4, ball_nodes=(0, 1, 2))
    world.drive((3.0, 3.0), 1.0)
    assert _error(world) < 0.1
    # teleport the robot from the open space into the double-workbench area, turned around
    q = world.ids.root_qpos
    world.data.qpos[q : q + 7] = [2.0, 2.4, 0.075, math.cos(1.2), 0, 0, math.sin(1.2)]
    world.data.qvel[world.ids.root_dof : world.ids.root_dof + 6] = 0.0
    assert _error(world) > 2.0
    kidnaps = world.localiser.kidnaps
    world.drive((2.0, -2.0), 1.5)  # turn on the spot: the filter must notice it is lost
    world.drive((3.0, 3.0), 1.5)
    assert world.localiser.kidnaps > kidnaps
    assert _error(world) < 0.2, (world.true_robot_pose(), world.pose_estimate())
    assert world.robot_node_reading() == 4


def test_same_seed_same_particles():
    clouds = []
    for _ in range(2):
        lab = LabWorld(LabWorldConfig(odometry=OdometryConfig(wheel_slip=0.01)))
        lab.reset(seed=7, robot_node=1, human_node=4, ball_nodes=(0, 1, 2))
        lab.drive((4.0, 3.0), 1.0)
        clouds.append(lab.localiser.particles.copy())
        lab.close()
    np.testing.assert_array_equal(clouds[0], clouds[1])


def test_skipping_scans_the_filter_will_not_use_changes_nothing():
    """The world computes a lidar scan only when the filter is due (its noise is drawn either way): computing every
    scan gives the same particles."""
    clouds = []
    for compute_all in (False, True):
        with LabWorld() as lab:
            lab.reset(seed=4, robot_node=1, human_node=4, ball_nodes=(0, 1, 2))
            if compute_all:
                lab.localiser.due = lambda pose, time: (
                    True
                )  # every scan computed; the filter still gates itself
            lab.step_macro(3, HumanCommand.stay())
            clouds.append(lab.localiser.particles.copy())
    np.testing.assert_array_equal(clouds[0], clouds[1])


def test_wheel_slip_is_corrected_and_a_blocked_step_says_so():
    lab = LabWorld(
        LabWorldConfig(odometry=OdometryConfig(wheel_slip=0.02, encoder_noise=0.05), stall_seconds=3.0)
    )
    lab.reset(seed=3, robot_node=1, human_node=4, ball_nodes=(0, 1, 2))
    for target in (3, 4):
        result = lab.step_macro(target, HumanCommand.stay())
        assert result.robot_node_reading == result.true_robot_node == target
        assert result.pose_error < 0.15 and not result.blocked
    # wedge the robot: a wall of welded mass in front is not available, so hold the base with a huge damping
    lab.model.dof_damping[lab.ids.root_dof : lab.ids.root_dof + 6] = 1e6
    result = lab.step_macro(3, HumanCommand.stay())
    assert result.blocked and not result.robot_arrived
    assert result.sim_seconds < 10.0  # ended by the stall detector, not by the 60 s timeout
    lab.close()


def test_localisation_config_refuses_bad_values():
    with pytest.raises(ConfigError, match="particles"):
        LocalisationConfig(particles=3)
    with pytest.raises(ConfigError, match="z_hit"):
        LocalisationConfig(z_hit=0.5, z_rand=0.1)


def test_overhead_render_can_draw_the_belief(world):
    world.reset(seed=6, robot_node=1, human_node=4, ball_nodes=(0, 1, 2))
    plain = world.render("overhead", 320, 256)
    marked = world.render("overhead", 320, 256, markers=True)
    assert (plain != marked).any(axis=2).sum() > 30  # particles, estimate and odometry drawn above the robot
    robot_view = world.render("robot", 64, 48)
    np.testing.assert_array_equal(robot_view, world.render("robot", 64, 48, markers=True))  # overhead only


def test_map_builder_refuses_geoms_it_cannot_rasterise():
    import mujoco

    from embodied_adhoc.sim.localisation import LikelihoodField

    xml = """<mujoco><worldbody>
      <geom name="wall" type="box" size="0.05 2 1" pos="1 0 1"/>
      <geom name="blob" type="ellipsoid" size="0.3 0.2 1" pos="-1 0 1"/>
    </worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with pytest.raises(SceneError, match="blob"):
        LikelihoodField.from_scene(model, data, 0.4, LocalisationConfig(), 8.0, (-2, 2, -2, 2))
    with pytest.raises(SceneError, match="no static geom cuts"):
        LikelihoodField.from_scene(model, data, 2.5, LocalisationConfig(), 8.0, (-2, 2, -2, 2))
