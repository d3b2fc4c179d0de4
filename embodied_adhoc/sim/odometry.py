"""Wheel odometry (dead reckoning) from encoder readings only, with an encoder and wheel-slip error model.

The robot knows only its nominal wheel radius and track width and the two encoder counts; it integrates the
differential-drive kinematics with the midpoint (second-order Runge-Kutta) rule. Error sources, all seeded:

* quantisation: an encoder reports whole ticks (``ticks_per_revolution``);
* ``encoder_noise``: non-systematic error (uneven floor, micro-slip): each increment dtheta gets zero-mean
  Gaussian noise of variance ``encoder_noise**2 * |dtheta|`` (a random walk in distance travelled, so the error
  does not depend on the control rate; Borenstein & Feng 1996), unit rad^0.5;
* ``wheel_slip``: systematic error: each wheel's effective radius differs from the nominal one by a relative
  factor drawn once per episode from N(0, wheel_slip^2) (tyre compression, slip under load);
* the physics itself: MuJoCo's soft wheel contacts roll on a slightly smaller radius and slip under torque.

``WheelOdometry.slip_distance`` and ``noise_distance`` say, since the reset, how many metres of wheel travel the
two modelled errors added to or removed from the measurement (the mean of the two wheels' absolute errors): the
size of each fault in an episode, reported by the sweeps beside the pose errors they cause.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from embodied_adhoc.control.reference import wrap_angle
from embodied_adhoc.errors import ConfigError


@dataclass(frozen=True)
class OdometryConfig:
    """Dead-reckoning model: nominal geometry the robot believes in and the encoder/slip error model."""

    wheel_radius: float = 0.075
    track_width: float = 0.38
    ticks_per_revolution: int = 4096
    encoder_noise: float = 0.002
    wheel_slip: float = 0.0005

    def __post_init__(self) -> None:
        if not self.wheel_radius > 0 or not self.track_width > 0:
            raise ConfigError("OdometryConfig.wheel_radius and track_width must be > 0 m")
        if not isinstance(self.ticks_per_revolution, int) or self.ticks_per_revolution < 1:
            raise ConfigError(
                f"OdometryConfig.ticks_per_revolution must be a positive int, got {self.ticks_per_revolution!r}"
            )
        if not self.encoder_noise >= 0 or not self.wheel_slip >= 0:
            raise ConfigError("OdometryConfig.encoder_noise and wheel_slip must be >= 0")


class WheelOdometry:
    """Integrates encoder readings into a dead-reckoning pose (x, y, yaw).

    ``update`` runs at every control tick, so it is scalar Python on floats (numpy scalars and small arrays cost
    more than the arithmetic); the encoder noise is drawn from ``rng`` in blocks of ``NOISE_BLOCK`` values, the
    same stream as two draws per tick (a ``numpy.random.Generator`` fills an array value by value)."""

    NOISE_BLOCK = 512

    def __init__(self, config: OdometryConfig, rng: np.random.Generator):
        self.config = config
        self._tick = 2.0 * math.pi / config.ticks_per_revolution
        self.pose_tuple: tuple[float, float, float] = (0.0, 0.0, 0.0)
        """The dead-reckoning pose (x, y, yaw) as Python floats (what the control tick reads)."""
        self._last_counts = (0, 0)
        self._scale = (1.0, 1.0)
        self.rng = rng
        self.distance = 0.0  # metres travelled by the wheel-centre midpoint, as measured
        # metres of wheel travel the radius error / the encoder noise added or removed (mean of the two wheels)
        self.slip_distance = self.noise_distance = 0.0

    @property
    def pose(self) -> np.ndarray:
        """The dead-reckoning pose (x, y, yaw) as a new array."""
        return np.array(self.pose_tuple)

    @property
    def rng(self) -> np.random.Generator:
        return self._rng

    @rng.setter
    def rng(self, rng: np.random.Generator) -> None:
        self._rng = rng
        self._noise: list[float] = []  # the block drawn from the previous generator is dropped
        self._noise_index = 0

    def reset(self, pose: tuple[float, float, float], wheel_angles: np.ndarray) -> None:
        """Start from a known ``pose`` with the current true wheel angles (rad, left/right)."""
        self.pose_tuple = (float(pose[0]), float(pose[1]), float(pose[2]))
        counts = self.counts(wheel_angles)
        self._last_counts = (int(counts[0]), int(counts[1]))
        self._noise, self._noise_index = [], 0  # the slip factors come first in the stream, then the noise
        scale = 1.0 + self.config.wheel_slip * self._rng.standard_normal(2)
        self._scale = (float(scale[0]), float(scale[1]))
        self.distance = self.slip_distance = self.noise_distance = 0.0

    def counts(self, wheel_angles: np.ndarray) -> np.ndarray:
        """Encoder readings (whole ticks) for true wheel angles (rad)."""
        return np.floor(np.asarray(wheel_angles, dtype=float) / self._tick).astype(np.int64)

    def update(self, wheel_angles: np.ndarray) -> tuple[float, float, float]:
        """Read the encoders at the true ``wheel_angles`` (rad, left/right), integrate, return the pose (x, y,
        yaw)."""
        config, tick = self.config, self._tick
        left_angle, right_angle = float(wheel_angles[0]), float(wheel_angles[1])
        left, right = math.floor(left_angle / tick), math.floor(right_angle / tick)
        step_left = (left - self._last_counts[0]) * tick  # radians turned, as counted
        step_right = (right - self._last_counts[1]) * tick
        self._last_counts = (left, right)
        if config.encoder_noise > 0:
            if self._noise_index + 2 > len(self._noise):
                self._noise = self._rng.standard_normal(self.NOISE_BLOCK).tolist()
                self._noise_index = 0
            i = self._noise_index
            self._noise_index = i + 2
            noise_left = config.encoder_noise * math.sqrt(abs(step_left)) * self._noise[i]
            noise_right = config.encoder_noise * math.sqrt(abs(step_right)) * self._noise[i + 1]
            step_left += noise_left
            step_right += noise_right
            self.noise_distance += 0.5 * (abs(noise_left) + abs(noise_right)) * config.wheel_radius
        # metres rolled by each wheel, as measured
        travel_left = step_left * self._scale[0] * config.wheel_radius
        travel_right = step_right * self._scale[1] * config.wheel_radius
        # the measured travel is counted + noise + (counted + noise) * (scale - 1): the last term is the slip's
        self.slip_distance += 0.5 * (
            abs(travel_left - step_left * config.wheel_radius)
            + abs(travel_right - step_right * config.wheel_radius)
        )
        ds = 0.5 * (travel_left + travel_right)
        dyaw = (travel_right - travel_left) / config.track_width
        x, y, yaw = self.pose_tuple
        mid_yaw = yaw + 0.5 * dyaw
        self.pose_tuple = (x + ds * math.cos(mid_yaw), y + ds * math.sin(mid_yaw), wrap_angle(yaw + dyaw))
        self.distance += abs(ds)
        return self.pose_tuple
