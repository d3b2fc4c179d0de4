"""The container robot's 2D lidar: a ring of MuJoCo ``rangefinder`` sensors read by name, with a real lidar's
range limits, range noise and dropout.

The MJCF (``assets/robots/container_robot/container_robot.xml``) defines the beams: sites ``lidar_00`` ..
``lidar_NN`` on the robot's base body, each looking along its +z axis in the scan plane, and one rangefinder per
site with the same name. MuJoCo computes a rangefinder by casting a ray that skips the geoms of the site's body
(the chassis, bin and mast) and invisible geoms; each beam has ``nsample="1" interval="0.1"``, so MuJoCo casts
the ring once per 0.1 s of simulated time (a 10 Hz scan) instead of at every physics step. MuJoCo does not apply
a sensor's ``noise`` attribute, so this module does, from a seeded ``numpy.random.Generator``:

* a reading below ``min_range`` or beyond ``max_range`` (or no hit, -1) is "no return" (NaN), as a real lidar
  reports nothing outside its window;
* each return gets zero-mean Gaussian range noise of standard deviation ``noise`` (m);
* each beam is lost independently with probability ``dropout`` (dark or glossy surfaces, sunlight): NaN.

Defaults are those of a small indoor lidar (RPLidar A1/A2 class): 0.12-8 m, 1.5 cm noise, 1 % dropout.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from embodied_adhoc import checks
from embodied_adhoc.errors import ConfigError, SceneError

__all__ = ["LIDAR_PREFIX", "Lidar", "LidarConfig", "LidarScan"]

LIDAR_PREFIX = "lidar_"
"""Beam k is the site and the rangefinder ``lidar_{k:02d}``."""


@dataclass(frozen=True)
class LidarConfig:
    """Range window, noise and dropout of the lidar; ``enabled=False`` is a lidar that returns nothing (failed
    or switched off: the localiser then falls back to odometry and says so)."""

    min_range: float = 0.12
    max_range: float = 8.0
    noise: float = 0.015
    dropout: float = 0.01
    enabled: bool = True

    def __post_init__(self) -> None:
        checks.number("LidarConfig.min_range", self.min_range, 0.0)
        checks.number("LidarConfig.max_range", self.max_range, self.min_range, low_open=True)
        checks.number("LidarConfig.noise", self.noise, 0.0)
        checks.number("LidarConfig.dropout", self.dropout, 0.0, 1.0)
        checks.flag("LidarConfig.enabled", self.enabled)


@dataclass(frozen=True)
class LidarScan:
    """One scan in the robot's base frame: beam ``k`` starts at ``origin`` (xy, m) and points at ``angles[k]``
    (rad); ``ranges[k]`` in metres or NaN (no return). ``time`` is the simulated time of the reading."""

    angles: np.ndarray
    ranges: np.ndarray
    origin: tuple[float, float]
    time: float

    @property
    def valid(self) -> np.ndarray:
        return np.isfinite(self.ranges)


class Lidar:
    """Reads the rangefinder ring of a compiled model by name and turns it into :class:`LidarScan` objects."""

    def __init__(self, model: mujoco.MjModel, config: LidarConfig | None = None, prefix: str = LIDAR_PREFIX):
        self.config = config or LidarConfig()
        sensors, sites = [], []
        while True:
            name = f"{prefix}{len(sensors):02d}"
            sensor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, name)
            if sensor < 0:
                break
            if model.sensor_type[sensor] != mujoco.mjtSensor.mjSENS_RANGEFINDER:
                raise SceneError(f"sensor '{name}' must be a rangefinder (the lidar ring, sim/lidar.py)")
            sensors.append(sensor)
            sites.append(int(model.sensor_objid[sensor]))
        if len(sensors) < 8:
            raise SceneError(
                f"the model has {len(sensors)} rangefinders named {prefix}NN; the lidar needs at least 8 "
                "(see assets/robots/container_robot/container_robot.xml)"
            )
        bodies = {int(model.site_bodyid[s]) for s in sites}
        if len(bodies) != 1:
            raise SceneError(f"the lidar's sites must all be on one body, found bodies {sorted(bodies)}")
        self.body = bodies.pop()
        cutoff = float(model.sensor_cutoff[sensors].min())
        if 0 < cutoff < self.config.max_range:
            raise ConfigError(
                f"LidarConfig.max_range={self.config.max_range} m exceeds the rangefinders' cutoff {cutoff} m in "
                "the MJCF; lower max_range or raise the cutoff"
            )
        self.addresses = model.sensor_adr[sensors].copy()
        # beam direction = the site's z axis, in the body frame (sites are fixed in their body)
        rotations = np.zeros((len(sites), 9))
        for row, site in enumerate(sites):
            mujoco.mju_quat2Mat(rotations[row], model.site_quat[site])
        z_axes = rotations.reshape(-1, 3, 3)[:, :, 2]
        if np.any(np.abs(z_axes[:, 2]) > 1e-6):
            raise SceneError(
                "the lidar's beams must lie in the body's horizontal plane (site z axes with z = 0)"
            )
        self.angles = np.arctan2(z_axes[:, 1], z_axes[:, 0])
        origin = model.site_pos[sites[0]]
        self.origin = (float(origin[0]), float(origin[1]))
        self.height = float(origin[2])  # above the body frame
        period = model.sensor_interval[sensors, 0]
        self.period = float(period.max())
        """Seconds between scans (0: every physics step)."""
        self.beams_read = 0
        """Beams of the scans computed since :meth:`reset_counts` (what the localiser read)."""
        self.dropped_beams = 0
        """Of those, the beams lost to dropout or to a disabled lidar (not those outside the range window)."""

    def reset_counts(self) -> None:
        """Start counting read and dropped beams afresh (at an episode's reset)."""
        self.beams_read = self.dropped_beams = 0

    @property
    def n_beams(self) -> int:
        return len(self.addresses)

    def raw(self, data: mujoco.MjData) -> np.ndarray:
        """The rangefinders' values as MuJoCo computed them (m; -1 where nothing was hit)."""
        return data.sensordata[self.addresses].copy()

    def scan(self, data: mujoco.MjData, rng: np.random.Generator) -> LidarScan:
        """A scan with the range window, noise and dropout applied (all NaN when the lidar is disabled)."""
        config = self.config
        self.beams_read += self.n_beams
        if not config.enabled:
            ranges = np.full(self.n_beams, np.nan)
            self.dropped_beams += self.n_beams
        else:
            noise, lost = self._draw(rng)
            raw = data.sensordata[self.addresses]
            ranges = raw + config.noise * noise
            outside = (raw < 0) | (ranges < config.min_range) | (ranges > config.max_range)
            ranges[outside | lost] = np.nan
            self.dropped_beams += int(np.count_nonzero(lost))
        return LidarScan(self.angles, ranges, self.origin, float(data.time))

    def skip(self, rng: np.random.Generator) -> None:
        """A scan nobody reads: draw its noise and dropout from ``rng`` all the same, so that the scans that are
        read get the same random numbers whether or not the ones before them were computed."""
        if self.config.enabled:
            self._draw(rng)

    def _draw(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Range noise (standard normal) and dropout mask of one scan, in this order from ``rng``."""
        noise = rng.standard_normal(self.n_beams)
        return noise, rng.random(self.n_beams) < self.config.dropout
