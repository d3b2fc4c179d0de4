"""Wheel odometry integration and its error model (no physics)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.sim.odometry import OdometryConfig, WheelOdometry

EXACT = OdometryConfig(ticks_per_revolution=10**9, encoder_noise=0.0, wheel_slip=0.0)


def _drive(odometry: WheelOdometry, left_rate: float, right_rate: float, seconds: float, dt: float = 0.02):
    angles = np.zeros(2)
    odometry.reset((0.0, 0.0, 0.0), angles)
    for _ in range(int(round(seconds / dt))):
        angles = angles + dt * np.array([left_rate, right_rate])
        odometry.update(angles)
    return odometry.pose


def test_straight_line_and_circle_are_integrated_exactly():
    config = EXACT
    pose = _drive(WheelOdometry(config, np.random.default_rng(0)), 4.0, 4.0, 2.0)
    assert pose == pytest.approx([8.0 * config.wheel_radius, 0.0, 0.0], abs=1e-6)
    # turning on the spot half a turn: wheel arc = pi * track / 2
    rate = math.pi * config.track_width / 2 / config.wheel_radius / 2.0
    pose = _drive(WheelOdometry(config, np.random.default_rng(0)), -rate, rate, 2.0)
    assert abs(abs(pose[2]) - math.pi) < 1e-6 and np.hypot(*pose[:2]) < 1e-9


def test_noise_grows_with_distance_not_with_control_rate():
    config = OdometryConfig(encoder_noise=0.01, wheel_slip=0.0)

    def spread(dt: float) -> float:
        ends = [
            _drive(WheelOdometry(config, np.random.default_rng(s)), 5.0, 5.0, 4.0, dt)[2] for s in range(60)
        ]
        return float(np.std(ends))

    coarse, fine = spread(0.04), spread(0.005)
    assert 0.6 < coarse / fine < 1.6
    assert coarse > 0


def test_same_seed_same_estimate_and_config_is_checked():
    config = OdometryConfig()
    a = _drive(WheelOdometry(config, np.random.default_rng(4)), 3.0, 3.5, 3.0).copy()
    b = _drive(WheelOdometry(config, np.random.default_rng(4)), 3.0, 3.5, 3.0).copy()
    assert np.array_equal(a, b)
    with pytest.raises(ConfigError, match="ticks_per_revolution"):
        OdometryConfig(ticks_per_revolution=0)


def test_block_drawn_encoder_noise_is_the_same_stream_as_per_tick_draws():
    per_tick = WheelOdometry(OdometryConfig(), np.random.default_rng(7))
    per_tick.NOISE_BLOCK = 2  # two normals per update, drawn at each update
    blocked = WheelOdometry(OdometryConfig(), np.random.default_rng(7))
    assert np.array_equal(_drive(per_tick, 3.0, 3.4, 5.0), _drive(blocked, 3.0, 3.4, 5.0))
