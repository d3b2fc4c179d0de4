"""Waypoint controller: drives a differential-drive base through a list of waypoints on its *estimated* pose.

A route (list of xy waypoints, e.g. ``LabLayout.route``) becomes a chained ruckig reference
(:class:`~embodied_adhoc.control.reference.RouteReference`); each control tick the tracking law turns the error
between that reference and the pose estimate (wheel odometry, never ground truth) into wheel speeds.
The route is finished when the reference has ended and the estimate is within ``arrival_tolerance`` of the goal
(arrived), or ``settle_time`` seconds after the reference ended (not arrived). numpy + ruckig only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from embodied_adhoc.control.reference import DriveLimits, RouteReference
from embodied_adhoc.control.tracking import DiffDriveGeometry, TrackingGains, tracking_command, wheel_speeds
from embodied_adhoc.errors import ConfigError


@dataclass(frozen=True)
class ControllerConfig:
    """Waypoint controller settings.

    Attributes:
        limits: reference limits (speed, acceleration, jerk, yaw rate, corner handling).
        gains: tracking-law gains.
        geometry: nominal wheel radius / track width / wheel speed limit used to map (v, omega) to wheels.
        arrival_tolerance: the route is done when the pose estimate is this close (m) to the goal.
        settle_time: extra seconds after the reference ends to reach the tolerance before giving up.
    """

    limits: DriveLimits = field(default_factory=DriveLimits)
    gains: TrackingGains = field(default_factory=TrackingGains)
    geometry: DiffDriveGeometry = field(default_factory=DiffDriveGeometry)
    arrival_tolerance: float = 0.03
    settle_time: float = 3.0

    def __post_init__(self) -> None:
        if not self.arrival_tolerance > 0:
            raise ConfigError(
                f"ControllerConfig.arrival_tolerance must be > 0 m, got {self.arrival_tolerance}"
            )
        if not self.settle_time >= 0:
            raise ConfigError(f"ControllerConfig.settle_time must be >= 0 s, got {self.settle_time}")


class WaypointController:
    """Tracks one route at a time. ``start(pose, waypoints)`` then ``update(t, pose)`` every control tick."""

    def __init__(self, config: ControllerConfig | None = None):
        self.config = config or ControllerConfig()
        self.reference: RouteReference | None = None
        self.finished = True
        self.arrived = False

    def start(self, pose: Sequence[float], waypoints: Sequence[Sequence[float]]) -> float:
        """Plan a route from ``pose`` (x, y, yaw) through ``waypoints``; returns the planned duration (s)."""
        if len(waypoints) == 0:
            raise ConfigError("WaypointController.start: the route has no waypoints")
        self.reference = RouteReference(pose, waypoints, self.config.limits)
        self.finished = False
        self.arrived = False
        return self.reference.duration

    def update(self, t: float, pose: Sequence[float]) -> tuple[float, float]:
        """Wheel speeds (left, right) in rad/s for time ``t`` (s since ``start``) and the pose estimate."""
        if self.reference is None or self.finished:
            return 0.0, 0.0
        reference = self.reference.at(t)
        if t >= self.reference.duration:
            distance = math.hypot(self.reference.goal[0] - pose[0], self.reference.goal[1] - pose[1])
            if distance <= self.config.arrival_tolerance:
                self.finished, self.arrived = True, True
                return 0.0, 0.0
            if t >= self.reference.duration + self.config.settle_time:
                self.finished = True
                return 0.0, 0.0
        v, omega = tracking_command(pose, reference, self.config.gains)
        return wheel_speeds(v, omega, self.config.geometry)
