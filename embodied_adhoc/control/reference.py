"""Time-optimal, jerk-limited reference along a polyline of waypoints, built from chained ruckig segments.

Community ruckig has no intermediate waypoints, so a route is planned as a chain of single-target problems:
each drive segment is a 2-DoF (x, y) ruckig trajectory from one waypoint to the next whose target velocity is
the *pass-through velocity* at that waypoint (nonzero at gentle corners, zero at the last waypoint and at sharp
corners). Where the robot must stop and face a new direction (the start, sharp corners) a 1-DoF ruckig turn
segment rotates the reference heading in place. Phase synchronisation keeps straight segments straight.
No mujoco here: plain numpy and ruckig.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from ruckig import InputParameter, Result, Ruckig, Synchronization, Trajectory

from embodied_adhoc.errors import ConfigError


@dataclass(frozen=True)
class DriveLimits:
    """Limits of the reference the robot tracks (the tracker adds small corrections on top).

    Attributes:
        max_speed: linear speed limit, m/s (wheel limit 8 rad/s x 0.075 m = 0.6 m/s leaves tracking headroom).
        max_acceleration: linear acceleration limit, m/s^2.
        max_jerk: linear jerk limit, m/s^3.
        max_yaw_rate: turn-in-place rate limit, rad/s.
        max_yaw_acceleration: rad/s^2.
        max_yaw_jerk: rad/s^3.
        max_corner_angle: corners sharper than this (rad) are taken by stopping and turning in place;
            gentler corners are passed through without stopping.
        turn_threshold: a heading change below this (rad) at a stop is left to the tracker, not turned in place.
    """

    max_speed: float = 0.5
    max_acceleration: float = 0.6
    max_jerk: float = 2.0
    max_yaw_rate: float = 1.5
    max_yaw_acceleration: float = 3.0
    max_yaw_jerk: float = 12.0
    max_corner_angle: float = math.radians(60.0)
    turn_threshold: float = math.radians(10.0)

    def __post_init__(self) -> None:
        for name in (
            "max_speed",
            "max_acceleration",
            "max_jerk",
            "max_yaw_rate",
            "max_yaw_acceleration",
            "max_yaw_jerk",
        ):
            value = getattr(self, name)
            if not value > 0:
                raise ConfigError(f"DriveLimits.{name} must be > 0, got {value}")
        if not 0 <= self.max_corner_angle < math.pi / 2:
            raise ConfigError(
                f"DriveLimits.max_corner_angle must be in [0, pi/2), got {self.max_corner_angle}"
            )


class ReferenceState(NamedTuple):
    """Reference pose and its derivatives at one instant: xy (m), heading (rad), speed v (m/s), yaw rate (rad/s).

    A named tuple: one is made at every control tick, and a frozen dataclass costs several times more to build."""

    x: float
    y: float
    heading: float
    speed: float
    yaw_rate: float


def wrap_angle(angle: float) -> float:
    """Angle wrapped to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


class _Segment:
    """One ruckig piece of the reference: ``start`` time offset, ``duration`` and the trajectory."""

    __slots__ = ("start", "duration", "trajectory", "kind", "xy", "heading")

    def __init__(self, start: float, trajectory: Trajectory, kind: str, xy: np.ndarray, heading: float):
        self.start = start
        self.duration = float(trajectory.duration)
        self.trajectory = trajectory
        self.kind = kind  # "turn": heading trajectory at fixed xy; "drive": xy trajectory
        self.xy = xy
        self.heading = heading  # turn: unused; drive: direction of the chord (used while the speed is ~0)


def _solve(inp: InputParameter, dofs: int) -> Trajectory:
    trajectory = Trajectory(dofs)
    result = Ruckig(dofs).calculate(inp, trajectory)
    if result not in (Result.Working, Result.Finished):
        raise ConfigError(f"ruckig could not plan a reference segment ({result}); check DriveLimits")
    return trajectory


AXIS_FLOOR = 0.15
"""Smallest per-axis share of the drive limits (keeps every ruckig problem feasible on near-axis legs)."""


def _axis_scale(chord: np.ndarray) -> np.ndarray:
    """Per-axis shares of the drive limits for a leg along ``chord``: ``max(|unit chord|, AXIS_FLOOR)``.

    Limits proportional to the chord direction keep the Euclidean limits on straight legs; with the floor the
    Euclidean speed can exceed ``max_speed`` by at most ``sqrt(1 + AXIS_FLOOR**2) - 1`` (1.1 %).
    """
    return np.maximum(np.abs(chord) / np.linalg.norm(chord), AXIS_FLOOR)


class RouteReference:
    """The reference for one route, from a start pose through ``waypoints`` (the last one is the goal).

    ``duration`` is the total planned time; ``at(t)`` samples the reference (clamped to the end).
    """

    def __init__(
        self, start_pose: Sequence[float], waypoints: Sequence[Sequence[float]], limits: DriveLimits
    ):
        self.limits = limits
        points = [np.asarray(start_pose[:2], dtype=float)]
        for waypoint in waypoints:
            point = np.asarray(waypoint, dtype=float)
            if np.linalg.norm(point - points[-1]) > 1e-6:  # drop zero-length legs
                points.append(point)
        self.goal = points[-1]
        self.segments: list[_Segment] = []
        self._time = 0.0
        heading = float(start_pose[2])
        velocity = np.zeros(2)
        for i in range(1, len(points)):
            chord = points[i] - points[i - 1]
            direction = math.atan2(chord[1], chord[0])
            if not np.any(velocity) and abs(wrap_angle(direction - heading)) > limits.turn_threshold:
                self._add_turn(points[i - 1], heading, direction)
            target_velocity = self._pass_through_velocity(points, i)
            self._add_drive(points[i - 1], velocity, points[i], target_velocity, direction)
            heading, velocity = direction, target_velocity
        self.duration = self._time
        self._final_heading = heading
        self._segment_ends = [segment.start + segment.duration for segment in self.segments]

    # ------------------------------------------------------------------------------------------ planning
    def _pass_through_velocity(self, points: list[np.ndarray], i: int) -> np.ndarray:
        """Velocity at waypoint ``i``: zero at the goal and at sharp corners; else along the corner bisector,
        slowed by the corner angle and by what the shorter adjacent leg allows (v^2 <= a * length)."""
        if i == len(points) - 1:
            return np.zeros(2)
        leg_in, leg_out = points[i] - points[i - 1], points[i + 1] - points[i]
        len_in, len_out = np.linalg.norm(leg_in), np.linalg.norm(leg_out)
        u_in, u_out = leg_in / len_in, leg_out / len_out
        corner = math.acos(float(np.clip(u_in @ u_out, -1.0, 1.0)))
        if corner > self.limits.max_corner_angle:
            return np.zeros(2)
        bisector = (u_in + u_out) / np.linalg.norm(u_in + u_out)
        speed = self.limits.max_speed * math.cos(corner)
        speed = min(speed, math.sqrt(self.limits.max_acceleration * min(len_in, len_out)))
        velocity = speed * bisector
        # Both legs plan with per-axis velocity limits (_axis_scale); a boundary velocity beyond them would force
        # the limits up and let the Euclidean speed exceed max_speed, so slow the pass-through to fit both legs.
        caps = self.limits.max_speed * np.minimum(_axis_scale(leg_in), _axis_scale(leg_out))
        magnitudes = np.abs(velocity)
        moving = magnitudes > 0.0
        if moving.any():
            velocity *= min(1.0, float(np.min(caps[moving] / magnitudes[moving])))
        return velocity

    def _add_turn(self, xy: np.ndarray, heading: float, direction: float) -> None:
        inp = InputParameter(1)
        inp.current_position = [heading]
        inp.current_velocity = [0.0]
        inp.current_acceleration = [0.0]
        inp.target_position = [heading + wrap_angle(direction - heading)]
        inp.target_velocity = [0.0]
        inp.target_acceleration = [0.0]
        inp.max_velocity = [self.limits.max_yaw_rate]
        inp.max_acceleration = [self.limits.max_yaw_acceleration]
        inp.max_jerk = [self.limits.max_yaw_jerk]
        trajectory = _solve(inp, 1)
        self.segments.append(_Segment(self._time, trajectory, "turn", xy.copy(), direction))
        self._time += float(trajectory.duration)

    def _add_drive(
        self, start: np.ndarray, v0: np.ndarray, end: np.ndarray, v1: np.ndarray, direction: float
    ) -> None:
        limits = self.limits
        scale = _axis_scale(end - start)
        max_velocity = np.maximum(limits.max_speed * scale, np.maximum(np.abs(v0), np.abs(v1)) + 1e-6)
        inp = InputParameter(2)
        inp.current_position = start.tolist()
        inp.current_velocity = v0.tolist()
        inp.current_acceleration = [0.0, 0.0]
        inp.target_position = end.tolist()
        inp.target_velocity = v1.tolist()
        inp.target_acceleration = [0.0, 0.0]
        inp.max_velocity = max_velocity.tolist()
        inp.max_acceleration = (limits.max_acceleration * scale).tolist()
        inp.max_jerk = (limits.max_jerk * scale).tolist()
        inp.synchronization = Synchronization.Phase
        trajectory = _solve(inp, 2)
        self.segments.append(_Segment(self._time, trajectory, "drive", start.copy(), direction))
        self._time += float(trajectory.duration)

    # ------------------------------------------------------------------------------------------ sampling
    def at(self, t: float) -> ReferenceState:
        """The reference at time ``t`` (s since the route started); after ``duration``, the goal at rest."""
        if not self.segments or t >= self.duration:
            return ReferenceState(float(self.goal[0]), float(self.goal[1]), self._final_heading, 0.0, 0.0)
        # the first segment still running at t (the last one if none is)
        segment = self.segments[min(bisect.bisect_right(self._segment_ends, t), len(self.segments) - 1)]
        local = min(max(t - segment.start, 0.0), segment.duration)
        position, velocity, acceleration = segment.trajectory.at_time(local)
        if segment.kind == "turn":
            return ReferenceState(
                float(segment.xy[0]), float(segment.xy[1]), float(position[0]), 0.0, float(velocity[0])
            )
        vx, vy = velocity
        ax, ay = acceleration
        speed_sq = vx * vx + vy * vy
        if speed_sq > 1e-8:
            heading = math.atan2(vy, vx)
            yaw_rate = (vx * ay - vy * ax) / speed_sq if speed_sq > 1e-4 else 0.0
        else:
            heading, yaw_rate = segment.heading, 0.0
        return ReferenceState(float(position[0]), float(position[1]), heading, math.sqrt(speed_sq), yaw_rate)
