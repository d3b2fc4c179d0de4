"""Waypoint controller: ruckig reference limits and pass-through, tracking on a kinematic unicycle."""

from __future__ import annotations

import itertools
import math
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from embodied_adhoc.control.reference import DriveLimits, RouteReference
from embodied_adhoc.control.tracking import DiffDriveGeometry
from embodied_adhoc.control.waypoint_controller import ControllerConfig, WaypointController
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.sim.lab_layout import LAB_LAYOUT


def _sample(reference: RouteReference, dt: float = 0.01):
    times = np.arange(0.0, reference.duration + dt, dt)
    return [reference.at(t) for t in times]


def test_reference_respects_speed_and_ends_at_goal_at_rest():
    limits = DriveLimits()
    route = LAB_LAYOUT.route(0, 4)
    reference = RouteReference((*LAB_LAYOUT.node_waypoints[0], 0.0), route, limits)
    states = _sample(reference)
    speeds = np.array([s.speed for s in states])
    assert speeds.max() <= limits.max_speed * 1.02
    assert max(abs(s.yaw_rate) for s in states if s.speed == 0.0) <= limits.max_yaw_rate + 1e-6
    end = reference.at(reference.duration + 1.0)
    assert (end.x, end.y) == pytest.approx(route[-1]) and end.speed == 0.0
    # the reference passes every waypoint of the route (within a few cm; corners are rounded)
    xy = np.array([(s.x, s.y) for s in states])
    for waypoint in route:
        assert np.min(np.hypot(*(xy - waypoint).T)) < 0.06


def test_gentle_corners_are_passed_without_stopping_and_sharp_ones_with_a_turn():
    limits = DriveLimits()
    gentle = RouteReference((0.0, 0.0, 0.0), [(1.0, 0.0), (2.0, 0.3)], limits)
    assert [s.kind for s in gentle.segments] == ["drive", "drive"]
    corner_time = gentle.segments[1].start
    assert gentle.at(corner_time).speed > 0.3
    sharp = RouteReference((0.0, 0.0, 0.0), [(1.0, 0.0), (1.0, 1.0)], limits)
    assert [s.kind for s in sharp.segments] == ["drive", "turn", "drive"]
    assert sharp.at(sharp.segments[1].start).speed == 0.0


def test_straight_segments_stay_straight():
    reference = RouteReference((0.0, 0.0, math.atan2(2, 3)), [(3.0, 2.0)], DriveLimits())
    xy = np.array([(s.x, s.y) for s in _sample(reference)])
    cross = xy[:, 0] * 2.0 - xy[:, 1] * 3.0
    assert np.abs(cross).max() < 1e-6


def _simulate(controller: WaypointController, pose: np.ndarray, dt: float, horizon: float) -> np.ndarray:
    """Ideal unicycle driven by the controller's wheel speeds."""
    geometry = controller.config.geometry
    t = 0.0
    while not controller.finished and t < horizon:
        left, right = controller.update(t, pose)
        v = 0.5 * geometry.wheel_radius * (left + right)
        omega = geometry.wheel_radius * (right - left) / geometry.track_width
        pose = pose + dt * np.array([v * math.cos(pose[2]), v * math.sin(pose[2]), omega])
        t += dt
    return pose


@pytest.mark.parametrize("start,goal", [(0, 4), (4, 2), (2, 0), (3, 1)])
def test_controller_drives_a_unicycle_through_a_lab_route(start, goal):
    controller = WaypointController()
    pose = np.array([*LAB_LAYOUT.node_waypoints[start], 2.0])
    route = LAB_LAYOUT.route(start, goal)
    controller.start(pose, route)
    final = _simulate(controller, pose, 0.01, 120.0)
    assert controller.arrived
    assert math.dist(final[:2], route[-1]) <= controller.config.arrival_tolerance


def test_wheel_speeds_are_saturated_keeping_curvature():
    controller = WaypointController(ControllerConfig(geometry=DiffDriveGeometry(max_wheel_speed=2.0)))
    controller.start((0.0, 0.0, 0.0), [(5.0, 0.0)])
    left, right = controller.update(3.0, (0.0, 0.2, 0.0))  # far behind and to the side: big command
    assert max(abs(left), abs(right)) <= 2.0 + 1e-9


def test_bad_limits_are_rejected():
    with pytest.raises(ConfigError, match="max_speed"):
        DriveLimits(max_speed=0.0)
    with pytest.raises(ConfigError, match="no waypoints"):
        WaypointController().start((0.0, 0.0, 0.0), [])


def test_control_layer_does_not_import_mujoco():
    code = "import sys, embodied_adhoc.control.waypoint_controller; print('mujoco' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


_points = st.lists(st.tuples(st.floats(-4.0, 4.0), st.floats(-4.0, 4.0)), min_size=1, max_size=5).filter(
    lambda pts: all(math.dist(a, b) > 0.05 for a, b in itertools.pairwise(pts))
)


@settings(max_examples=30, deadline=None)
@given(waypoints=_points, yaw=st.floats(-math.pi, math.pi))
def test_any_route_reference_is_within_limits_and_ends_at_rest_on_the_goal(waypoints, yaw):
    limits = DriveLimits()
    reference = RouteReference((0.0, 0.0, yaw), waypoints, limits)
    states = _sample(reference, dt=0.05)
    assert max(s.speed for s in states) <= limits.max_speed * 1.02
    end = reference.at(reference.duration)
    assert (end.x, end.y) == pytest.approx(reference.goal, abs=1e-6) and end.speed == 0.0
