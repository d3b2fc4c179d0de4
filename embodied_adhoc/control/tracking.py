"""Unicycle tracking law (Kanayama et al. 1990) and the differential-drive wheel mapping. numpy only."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from embodied_adhoc.control.reference import ReferenceState, wrap_angle
from embodied_adhoc.errors import ConfigError


@dataclass(frozen=True)
class TrackingGains:
    """Gains of the tracking law.

    v     = v_r cos(e_theta) + k_x e_x
    omega = omega_r + v_r k_y e_y + k_theta sin(e_theta)

    (e_x, e_y) is the reference position in the robot frame and e_theta the heading error. Unlike Kanayama's
    original law the heading term is not multiplied by v_r, so heading errors are also corrected while the
    reference turns in place. Units: k_x in 1/s, k_y in rad/m^2 (times v_r in m/s and e_y in m gives rad/s),
    k_theta in 1/s.
    """

    k_x: float = 2.0
    k_y: float = 12.0
    k_theta: float = 4.0

    def __post_init__(self) -> None:
        for name in ("k_x", "k_y", "k_theta"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"TrackingGains.{name} must be >= 0, got {getattr(self, name)}")


@dataclass(frozen=True)
class DiffDriveGeometry:
    """Nominal geometry of a differential-drive base: wheel radius (m), track width between wheel contact
    centres (m), and the wheel speed limit (rad/s) commands are saturated to."""

    wheel_radius: float = 0.075
    track_width: float = 0.38
    max_wheel_speed: float = 8.0

    def __post_init__(self) -> None:
        for name in ("wheel_radius", "track_width", "max_wheel_speed"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"DiffDriveGeometry.{name} must be > 0, got {getattr(self, name)}")


def tracking_command(
    pose: Sequence[float], reference: ReferenceState, gains: TrackingGains
) -> tuple[float, float]:
    """Linear and angular velocity (v, omega) that steer a unicycle at ``pose`` (x, y, yaw) onto ``reference``."""
    x, y, yaw = pose
    dx, dy = reference.x - x, reference.y - y
    cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
    e_x = cos_yaw * dx + sin_yaw * dy
    e_y = -sin_yaw * dx + cos_yaw * dy
    e_theta = wrap_angle(reference.heading - yaw)
    v = reference.speed * math.cos(e_theta) + gains.k_x * e_x
    omega = reference.yaw_rate + reference.speed * gains.k_y * e_y + gains.k_theta * math.sin(e_theta)
    return v, omega


def wheel_speeds(v: float, omega: float, geometry: DiffDriveGeometry) -> tuple[float, float]:
    """Left and right wheel speeds (rad/s) for body velocities (v, omega); if either exceeds the limit both are
    scaled down by the same factor, which keeps the path curvature."""
    half_track = 0.5 * geometry.track_width
    left = (v - omega * half_track) / geometry.wheel_radius
    right = (v + omega * half_track) / geometry.wheel_radius
    peak = max(abs(left), abs(right))
    if peak > geometry.max_wheel_speed:
        scale = geometry.max_wheel_speed / peak
        left, right = left * scale, right * scale
    return left, right
