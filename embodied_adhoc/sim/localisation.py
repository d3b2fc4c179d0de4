"""Monte Carlo localisation of the container robot against the lab's map (Thrun, Burgard & Fox, *Probabilistic
Robotics*, 2005: MCL Table 8.2, augmented MCL Table 8.3, the likelihood-field range model Table 6.3, low-variance
resampling Table 4.4).

* **Map**: :class:`LikelihoodField` rasterises, once per scene, every static geom that cuts the lidar's scan
  plane (walls, partitions, furniture legs, shelves; not the robot, the human or the balls) on a grid, takes the
  Euclidean distance transform and stores ``log(z_hit N(d; 0, sigma_hit) + z_rand / max_range)`` per cell, so a
  beam end point costs one table look-up.
* **Motion model**: the wheel-odometry increment since the last update, expressed in the robot frame
  ``(dx, dy, dyaw)``, applied to every particle with Gaussian noise whose standard deviation grows with the
  distance and the angle travelled (``alpha``: the odometry model's four coefficients, sec. 5.4).
* **Measurement model**: up to ``max_beams`` evenly spaced returns of a :class:`~embodied_adhoc.sim.lidar.LidarScan`;
  the log weight of a particle is the sum over beams of the field at the beam end points.
* **Augmented MCL**: short- and long-term averages of the per-beam likelihood (``alpha_fast``, ``alpha_slow``);
  when the short-term one drops below ``kidnap_ratio`` times the long-term one for ``kidnap_scans`` scans in a
  row the robot is declared lost (*kidnapped*) and the filter re-seeds globally from the current scan
  (sensor-resetting localisation, Lenser & Veloso 2000): ``global_samples`` poses drawn uniformly over the free
  space, weighted by the scan, resampled to ``particles``. Every detection is counted and timed.
* **No lidar**: when the lidar is disabled (or returns nothing) the filter runs the motion model only: the estimate
  follows odometry and its covariance grows; :attr:`MonteCarloLocaliser.mode` says ``"odometry"``.

Between scans the pose handed to the controller is the last estimate composed with the odometry increment since
(the map-to-odometry correction of ROS's AMCL), so the controller gets a pose at every control tick while the
particles move only at scan times. All randomness comes from the ``numpy.random.Generator`` given at reset.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy import ndimage

from embodied_adhoc import checks
from embodied_adhoc.control.reference import wrap_angle
from embodied_adhoc.errors import ConfigError, SceneError
from embodied_adhoc.sim.lidar import LidarScan

__all__ = [
    "LikelihoodField",
    "LocalisationConfig",
    "LocaliserStatus",
    "MonteCarloLocaliser",
    "compose",
    "relative",
]


@dataclass(frozen=True)
class LocalisationConfig:
    """Particle filter settings (units: m, rad).

    Attributes:
        particles: number of particles.
        alpha: odometry noise (rot from rot, rot from trans, trans from trans, trans from rot): standard
            deviations of the increment's heading (rad) and translation (m) per rad turned / m driven.
        sigma_hit: standard deviation (m) of a beam end point around the nearest obstacle.
        z_hit, z_rand: weights of the hit and uniform-noise parts of the range model (sum to 1).
        max_beams: beams used per scan (evenly spaced among the returns).
        resolution: grid cell (m) of the likelihood field.
        clearance: free space for global sampling keeps this distance (m) from obstacles (the robot's radius).
        update_distance, update_angle, update_period: a scan updates the filter when the robot moved this far
            or turned this much since the last update, or at least every ``update_period`` seconds.
        alpha_slow, alpha_fast: averaging rates of the long/short-term likelihood (augmented MCL).
        kidnap_ratio, kidnap_scans: lost when fast / slow < ratio for this many consecutive updates.
        global_samples: uniform poses drawn when (re-)localising globally (also at the first scan after a
            reset with an unknown pose); they are weighted on a coarser field (``sigma_global``) with the log
            likelihood scaled by ``global_exponent``, so the resampled set keeps every plausible mode (a sample
            lands within 0.3 m of the truth far more often than within the fine field's reach).
        roughening: standard deviations (m, rad) of the jitter added after each resampling, so that a resampled
            set never collapses onto copies of one pose (Probabilistic Robotics sec. 4.3.4).
        area_confidence: the robot reports an area only when at least this share of the particles' weight lies
            in it (else "unknown").
    """

    particles: int = 250
    alpha: tuple[float, float, float, float] = (0.1, 0.15, 0.08, 0.02)
    sigma_hit: float = 0.08
    z_hit: float = 0.9
    z_rand: float = 0.1
    max_beams: int = 30
    resolution: float = 0.04
    clearance: float = 0.2
    update_distance: float = 0.1
    update_angle: float = 0.1
    update_period: float = 1.0
    alpha_slow: float = 0.02
    alpha_fast: float = 0.3
    kidnap_ratio: float = 0.5
    kidnap_scans: int = 3
    global_samples: int = 20000
    sigma_global: float = 0.3
    global_exponent: float = 0.3
    roughening: tuple[float, float] = (0.01, 0.005)
    area_confidence: float = 0.95

    def __post_init__(self) -> None:
        checks.integer("LocalisationConfig.particles", self.particles, 10)
        if len(self.alpha) != 4:
            raise ConfigError(f"LocalisationConfig.alpha needs 4 coefficients, got {self.alpha}")
        for i, value in enumerate(self.alpha):
            checks.number(f"LocalisationConfig.alpha[{i}]", value, 0.0)
        checks.number("LocalisationConfig.sigma_hit", self.sigma_hit, 0.0, low_open=True)
        z_hit = checks.number("LocalisationConfig.z_hit", self.z_hit, 0.0, 1.0)
        z_rand = checks.number("LocalisationConfig.z_rand", self.z_rand, 0.0, 1.0)
        if abs(z_hit + z_rand - 1.0) > 1e-9 or z_rand == 0.0:
            raise ConfigError("LocalisationConfig: z_hit + z_rand must be 1 and z_rand > 0")
        checks.integer("LocalisationConfig.max_beams", self.max_beams, 1)
        checks.number("LocalisationConfig.resolution", self.resolution, 0.0, 0.5, low_open=True)
        for name in ("clearance", "update_distance", "update_angle", "update_period"):
            checks.number(f"LocalisationConfig.{name}", getattr(self, name), 0.0)
        checks.number("LocalisationConfig.alpha_slow", self.alpha_slow, 0.0, 1.0, low_open=True)
        checks.number("LocalisationConfig.alpha_fast", self.alpha_fast, self.alpha_slow, 1.0)
        checks.number("LocalisationConfig.kidnap_ratio", self.kidnap_ratio, 0.0, 1.0)
        checks.integer("LocalisationConfig.kidnap_scans", self.kidnap_scans, 1)
        checks.integer("LocalisationConfig.global_samples", self.global_samples, self.particles)
        checks.number("LocalisationConfig.sigma_global", self.sigma_global, 0.0, low_open=True)
        checks.number("LocalisationConfig.global_exponent", self.global_exponent, 0.0, 1.0, low_open=True)
        if len(self.roughening) != 2:
            raise ConfigError(f"LocalisationConfig.roughening needs (metres, radians), got {self.roughening}")
        for i, value in enumerate(self.roughening):
            checks.number(f"LocalisationConfig.roughening[{i}]", value, 0.0)
        checks.number("LocalisationConfig.area_confidence", self.area_confidence, 0.5, 1.0)


def compose(pose: Sequence[float], delta: Sequence[float]) -> tuple[float, float, float]:
    """``pose`` followed by ``delta`` given in ``pose``'s frame (SE(2) composition)."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    return x + c * delta[0] - s * delta[1], y + s * delta[0] + c * delta[1], wrap_angle(yaw + delta[2])


def relative(start: Sequence[float], end: Sequence[float]) -> tuple[float, float, float]:
    """``end`` in the frame of ``start`` (the inverse of :func:`compose`)."""
    dx, dy = end[0] - start[0], end[1] - start[1]
    c, s = math.cos(start[2]), math.sin(start[2])
    return c * dx + s * dy, -s * dx + c * dy, wrap_angle(end[2] - start[2])


class LikelihoodField:
    """The likelihood-field table of one scene at one scan height (see the module docstring)."""

    def __init__(
        self,
        occupied: np.ndarray,
        origin: tuple[float, float],
        resolution: float,
        config: LocalisationConfig,
        max_range: float,
        region: tuple[float, float, float, float],
    ):
        self.occupied = occupied
        self.origin = origin
        self.resolution = resolution
        self.shape = occupied.shape  # (nx, ny)
        distance = ndimage.distance_transform_edt(~occupied) * resolution
        self.distance = distance
        hit = np.exp(-0.5 * (distance / config.sigma_hit) ** 2) / (math.sqrt(2 * math.pi) * config.sigma_hit)
        self.log_likelihood = np.log(config.z_hit * hit + config.z_rand / max_range).astype(np.float32)
        self.far = float(np.log(config.z_rand / max_range))  # an end point off the map: a random reading
        sigma = config.sigma_global
        coarse = np.exp(-0.5 * (distance / sigma) ** 2) / (math.sqrt(2 * math.pi) * sigma)
        coarse = np.log(config.z_hit * coarse + config.z_rand / max_range).astype(np.float32)
        for table in (self.log_likelihood, coarse):
            table[[0, -1], :] = self.far
            table[:, [0, -1]] = self.far
        # for scoring, each table as small integer codes into its few distinct values (a 16th of the memory the
        # random look-ups touch), the values in float64: a beam sum of float32 values in float64 is exact
        self._fine = _coded(self.log_likelihood)
        self._index_type = np.int32 if occupied.size < 2**31 else np.intp  # int32: half the memory
        self._coarse = _coded(coarse)
        self._inverse = 1.0 / resolution
        x0, x1, y0, y1 = region
        xs = origin[0] + (np.arange(self.shape[0]) + 0.5) * resolution
        ys = origin[1] + (np.arange(self.shape[1]) + 0.5) * resolution
        inside = ((xs >= x0) & (xs <= x1))[:, None] & ((ys >= y0) & (ys <= y1))[None, :]
        self.free_cells = np.argwhere(inside & (distance >= config.clearance))
        if len(self.free_cells) == 0:
            raise SceneError("the localisation map has no free space inside the room")

    @classmethod
    def from_scene(
        cls,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        height: float,
        config: LocalisationConfig,
        max_range: float,
        region: tuple[float, float, float, float],
    ) -> LikelihoodField:
        """Rasterise the static geoms (welded to the world, visible, not planes) that cut the horizontal plane
        ``z = height`` (world frame; ``data`` must hold the scene's kinematics)."""
        resolution = config.resolution
        static = np.flatnonzero(model.body_weldid[model.geom_bodyid] == 0)
        shapes = []
        for geom in static:
            kind = int(model.geom_type[geom])
            if kind == mujoco.mjtGeom.mjGEOM_PLANE:
                continue
            if model.geom_matid[geom] < 0 and model.geom_rgba[geom, 3] == 0:
                continue  # invisible: rangefinders do not see it either
            centre, rotation = data.geom_xpos[geom], data.geom_xmat[geom].reshape(3, 3)
            size = model.geom_size[geom]
            if kind == mujoco.mjtGeom.mjGEOM_BOX:
                half = size
            elif kind in (mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_CAPSULE):
                half = np.array(
                    [size[0], size[0], size[1] + (size[0] if kind == mujoco.mjtGeom.mjGEOM_CAPSULE else 0)]
                )
            elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
                half = np.full(3, size[0])
            elif abs(centre[2] - height) > model.geom_rbound[geom]:
                continue  # clear of the scan plane, whatever its shape
            else:
                raise SceneError(
                    f"localisation map: static geom '{model.geom(geom).name}' has a type ({kind}) the map builder "
                    "does not rasterise (box, cylinder, capsule, sphere); give it one of those or make it dynamic"
                )
            z_extent = float(np.abs(rotation[2]) @ half)
            if not centre[2] - z_extent <= height <= centre[2] + z_extent:
                continue
            if abs(rotation[2, 2]) < 1 - 1e-6 and kind != mujoco.mjtGeom.mjGEOM_SPHERE:
                raise SceneError(
                    f"localisation map: static geom '{model.geom(geom).name}' is tilted; the map builder takes "
                    "geoms upright about z"
                )
            shapes.append((kind, centre[:2].copy(), rotation[:2, :2].copy(), half[:2].copy()))
        if not shapes:
            raise SceneError(f"localisation map: no static geom cuts the scan plane z = {height:.3f} m")
        # the grid covers the region with a margin wide enough for the outer walls
        low = np.array([region[0], region[2]]) - 0.6
        high = np.array([region[1], region[3]]) + 0.6
        nx, ny = (int(math.ceil(v)) for v in (high - low) / resolution)
        xs = low[0] + (np.arange(nx) + 0.5) * resolution
        ys = low[1] + (np.arange(ny) + 0.5) * resolution
        gx, gy = np.meshgrid(xs, ys, indexing="ij")
        occupied = np.zeros((nx, ny), dtype=bool)
        for kind, centre, rotation, half in shapes:
            dx, dy = gx - centre[0], gy - centre[1]
            if kind == mujoco.mjtGeom.mjGEOM_BOX:
                local_x = rotation[0, 0] * dx + rotation[1, 0] * dy
                local_y = rotation[0, 1] * dx + rotation[1, 1] * dy
                # a box thinner than a cell still occupies the cells its centre line crosses
                occupied |= (np.abs(local_x) <= max(half[0], resolution / 2)) & (
                    np.abs(local_y) <= max(half[1], resolution / 2)
                )
            else:
                occupied |= np.hypot(dx, dy) <= max(half[0], resolution / 2)
        return cls(occupied, (float(low[0]), float(low[1])), resolution, config, max_range, region)

    def score(
        self, poses: np.ndarray, local_x: np.ndarray, local_y: np.ndarray, coarse: bool = False
    ) -> np.ndarray:
        """Sum over beams of the fine (or the coarse, global) field at each pose's beam end points, shape (P,):
        the log-likelihood of a scan whose used beams end at (``local_x``, ``local_y``) in the robot frame
        (Probabilistic Robotics Table 6.3, without the max-range term: beams without a return are not used).

        End points off the grid count as random readings (the grid's outermost ring of cells holds that value and
        off-grid cells are clamped onto it). The end points of all poses are one matrix product: rows
        ``[cos, -sin, x0]`` and ``[sin, cos, y0]`` per pose, shifted to the grid's origin and scaled to cells,
        times the columns ``[lx, ly, 1]`` per beam."""
        n, nx, ny = len(poses), self.shape[0], self.shape[1]
        transform = np.empty((2 * n, 3))
        np.cos(poses[:, 2], out=transform[:n, 0])
        np.sin(poses[:, 2], out=transform[n:, 0])
        np.negative(transform[n:, 0], out=transform[:n, 1])
        transform[n:, 1] = transform[:n, 0]
        np.subtract(poses[:, 0], self.origin[0], out=transform[:n, 2])
        np.subtract(poses[:, 1], self.origin[1], out=transform[n:, 2])
        transform *= self._inverse
        beams = np.empty((3, len(local_x)))
        beams[0], beams[1], beams[2] = local_x, local_y, 1.0
        cells = transform @ beams  # (2P, B): x cells of every end point, then y cells
        if not (cells.min() >= 0.0 and cells[:n].max() < nx and cells[n:].max() < ny):
            # clamp onto the grid (fmax also sends a NaN to cell 0, i.e. the ring); rare: off-grid end points
            np.fmax(cells, 0.0, out=cells)
            np.fmin(cells[:n], nx - 1, out=cells[:n])
            np.fmin(cells[n:], ny - 1, out=cells[n:])
        index = cells.astype(self._index_type)
        flat = index[:n] * ny
        flat += index[n:]
        values, codes = self._coarse if coarse else self._fine
        return values.take(codes.take(flat)) @ np.ones(len(local_x))

    def sample_free(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """``count`` poses (x, y, yaw) uniform over the free space (cell jitter and heading uniform)."""
        cells = self.free_cells[rng.integers(len(self.free_cells), size=count)]
        jitter = rng.random((count, 2))
        poses = np.empty((count, 3))
        poses[:, 0] = self.origin[0] + (cells[:, 0] + jitter[:, 0]) * self.resolution
        poses[:, 1] = self.origin[1] + (cells[:, 1] + jitter[:, 1]) * self.resolution
        poses[:, 2] = rng.uniform(-math.pi, math.pi, size=count)
        return poses


@dataclass(frozen=True)
class LocaliserStatus:
    """What the localiser reports (for the controller, the observation and the recording)."""

    pose: tuple[float, float, float]  # estimate handed to the controller (x, y, yaw)
    covariance: np.ndarray  # 3 x 3 over (x, y, yaw) of the particles at the last update
    mode: str  # "lidar" (scans are used) or "odometry" (no usable scan: dead reckoning with growing spread)
    kidnaps: int  # times the filter declared itself lost and re-seeded globally
    updates: int  # filter updates so far


class MonteCarloLocaliser:
    """Augmented MCL on a :class:`LikelihoodField`. ``reset`` then, every control tick, ``tick(odometry_pose,
    scan_or_None)``; ``pose`` is the estimate."""

    def __init__(self, field: LikelihoodField, config: LocalisationConfig | None = None):
        self.field = field
        self.config = config or LocalisationConfig()
        self.rng = np.random.default_rng(0)
        n = self.config.particles
        self.particles = np.zeros((n, 3))
        self.weights = np.full(n, 1.0 / n)
        self.kidnaps = 0
        self.kidnap_times: list[float] = []
        self.updates = 0
        self.mode = "lidar"
        self._estimate = (0.0, 0.0, 0.0)
        self._covariance: np.ndarray | None = np.zeros((3, 3))
        self._summarised: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._odometry_at_update = (0.0, 0.0, 0.0)
        self._odometry_now = (0.0, 0.0, 0.0)
        self._last_update_time = 0.0
        self._w_slow = self._w_fast = 0.0
        self._low_streak = 0
        self._global = False
        self._beam_picks: dict[int, np.ndarray] = {}

    # ------------------------------------------------------------------------------------------ start
    def reset(
        self,
        rng: np.random.Generator,
        odometry_pose: Sequence[float],
        pose: Sequence[float] | None = None,
        spread: tuple[float, float] = (0.05, 0.05),
        time: float = 0.0,
    ) -> None:
        """Start at a known ``pose`` (particles Gaussian with ``spread`` = (m, rad) standard deviations) or,
        with ``pose=None``, uniformly over the free space (global localisation: the first scan weighs
        ``global_samples`` uniform poses)."""
        self.rng = rng
        n = self.config.particles
        self._global = pose is None
        if pose is None:
            self.particles = self.field.sample_free(rng, n)
        else:
            self.particles = np.asarray(pose, dtype=float) + rng.standard_normal((n, 3)) * [
                spread[0],
                spread[0],
                spread[1],
            ]
            self.particles[:, 2] = _wrap(self.particles[:, 2])
        self.weights = np.full(n, 1.0 / n)
        self.kidnaps, self.kidnap_times, self.updates = 0, [], 0
        self._w_slow = self._w_fast = 0.0
        self._low_streak = 0
        self._odometry_at_update = self._odometry_now = tuple(float(v) for v in odometry_pose)
        self._last_update_time = time
        self._summarise()

    # ------------------------------------------------------------------------------------------ filter
    def due(self, odometry_pose: Sequence[float], time: float) -> bool:
        """Would a scan taken now update the filter? (The robot moved ``update_distance`` or turned
        ``update_angle`` since the last update, or ``update_period`` passed.) The world reads the lidar only
        then: a scan the filter would not use is not worth computing."""
        return self._moved_enough(relative(self._odometry_at_update, odometry_pose), time)

    def _moved_enough(self, delta: tuple[float, float, float], time: float) -> bool:
        config = self.config
        return (
            math.hypot(delta[0], delta[1]) >= config.update_distance
            or abs(delta[2]) >= config.update_angle
            or time - self._last_update_time >= config.update_period
        )

    def tick(self, odometry_pose: Sequence[float], scan: LidarScan | None, time: float) -> bool:
        """One control tick: remember the odometry; with a new ``scan``, update the filter if the robot moved
        enough (or ``update_period`` passed: :meth:`due`). Returns True when the particles were updated."""
        self._odometry_now = (float(odometry_pose[0]), float(odometry_pose[1]), float(odometry_pose[2]))
        if scan is None:
            return False
        delta = relative(self._odometry_at_update, self._odometry_now)
        if not self._moved_enough(delta, time):
            return False
        self._move(delta)
        self._odometry_at_update = self._odometry_now
        self._last_update_time = time
        valid = scan.valid.nonzero()[0]
        if len(valid) < 3:
            self.mode = "odometry"
        elif self._global:
            self.mode = "lidar"
            self._global = False
            self._relocalise(*self._beams(scan, valid))
        else:
            self.mode = "lidar"
            self._measure(scan, valid, time)
        self.updates += 1
        self._summarise()
        return True

    def _move(self, delta: tuple[float, float, float]) -> None:
        """Sample the odometry motion model for every particle."""
        a1, a2, a3, a4 = self.config.alpha
        distance, turn = math.hypot(delta[0], delta[1]), abs(delta[2])
        n = len(self.particles)
        noise = self.rng.standard_normal((n, 3))
        sigma_trans = a3 * distance + a4 * turn
        sigma_rot = a1 * turn + a2 * distance
        # delta + sigma * noise, per column, as two whole-array operations: six per-column ones would each pay
        # numpy's per-call overhead
        noise *= (sigma_trans, sigma_trans, sigma_rot)
        noise += delta
        dx, dy, dyaw = noise[:, 0], noise[:, 1], noise[:, 2]
        yaw = self.particles[:, 2]
        c, s = np.cos(yaw), np.sin(yaw)
        self.particles[:, 0] += c * dx - s * dy
        self.particles[:, 1] += s * dx + c * dy
        self.particles[:, 2] = _wrap(yaw + dyaw)

    def _beams(self, scan: LidarScan, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """End points of the used beams in the robot frame (B,), (B,): at most ``max_beams`` returns, evenly
        spaced among the valid ones."""
        count = len(valid)
        if count > self.config.max_beams:
            picks = self._beam_picks.get(count)
            if picks is None:  # the same few counts come back scan after scan
                picks = np.linspace(0, count - 1, self.config.max_beams).round().astype(int)
                self._beam_picks[count] = picks
            valid = valid[picks]
        ranges, angles = scan.ranges[valid], scan.angles[valid]
        return scan.origin[0] + ranges * np.cos(angles), scan.origin[1] + ranges * np.sin(angles)

    def _measure(self, scan: LidarScan, valid: np.ndarray, time: float) -> None:
        config = self.config
        local_x, local_y = self._beams(scan, valid)
        log_l = self.field.score(self.particles, local_x, local_y)
        # per-beam geometric-mean likelihood: comparable between scans with different numbers of returns
        per_beam = float(np.exp(log_l / len(local_x)) @ self.weights)
        if self.updates == 0 or self._w_slow == 0.0:
            self._w_slow = self._w_fast = per_beam
        else:
            self._w_slow += config.alpha_slow * (per_beam - self._w_slow)
            self._w_fast += config.alpha_fast * (per_beam - self._w_fast)
        log_w = np.log(self.weights) + log_l
        log_w -= log_w.max()
        weights = np.exp(log_w)
        self.weights = weights / weights.sum()
        self._low_streak = self._low_streak + 1 if self._w_fast < config.kidnap_ratio * self._w_slow else 0
        if self._low_streak >= config.kidnap_scans:
            self.kidnaps += 1
            self.kidnap_times.append(time)
            self._relocalise(local_x, local_y)
            return
        if 1.0 / float(self.weights @ self.weights) < 0.5 * len(self.weights):
            self._resample()

    def _relocalise(self, local_x: np.ndarray, local_y: np.ndarray) -> None:
        """Sensor-resetting: weight uniform free-space poses by the scan and resample the particle set from them."""
        config = self.config
        candidates = self.field.sample_free(self.rng, config.global_samples)
        log_l = config.global_exponent * self.field.score(candidates, local_x, local_y, coarse=True)
        weights = np.exp(log_l - log_l.max())
        weights /= weights.sum()
        picked = _low_variance(self.rng, weights, config.particles)
        self.particles = candidates[picked]
        # spread each pick over the coarse field's reach, so the fine field can pull the right ones in
        self.particles += self.rng.standard_normal(self.particles.shape) * [
            0.5 * config.sigma_global,
            0.5 * config.sigma_global,
            0.1,
        ]
        self.particles[:, 2] = _wrap(self.particles[:, 2])
        self.weights = np.full(config.particles, 1.0 / config.particles)
        # keep the long-term likelihood of the localised robot: if this re-seeding picked a wrong place, the
        # short-term average stays low and the filter declares itself lost again
        self._w_fast = self._w_slow
        self._low_streak = 0

    def _roughen(self) -> None:
        metres, radians = self.config.roughening
        jitter = self.rng.standard_normal(self.particles.shape)
        jitter *= (metres, metres, radians)
        self.particles += jitter
        self.particles[:, 2] = _wrap(self.particles[:, 2])

    def _resample(self) -> None:
        picked = _low_variance(self.rng, self.weights, len(self.weights))
        self.particles = self.particles[picked]
        self._roughen()
        self.weights = np.full(len(self.weights), 1.0 / len(self.weights))

    def globalise(self, scan: LidarScan) -> None:
        """Global localisation from one scan now (as after a kidnapping), without counting a kidnap."""
        valid = scan.valid.nonzero()[0]
        if len(valid) >= 3:
            self._relocalise(*self._beams(scan, valid))
            self._summarise()

    def _summarise(self) -> None:
        w = self.weights
        p = self.particles
        mean_yaw = math.atan2(float(w @ np.sin(p[:, 2])), float(w @ np.cos(p[:, 2])))
        mean = np.array([float(w @ p[:, 0]), float(w @ p[:, 1]), mean_yaw])
        # the covariance is read once per macro step at most, the mean at every update: computed when read, from
        # a snapshot of this update's particles (the filter moves them in place)
        self._covariance = None
        self._summarised = (p.copy(), w, mean)
        self._estimate = (float(mean[0]), float(mean[1]), float(mean[2]))

    # ------------------------------------------------------------------------------------------ outputs
    @property
    def pose(self) -> tuple[float, float, float]:
        """The estimate at the last update composed with the odometry increment since (for the controller)."""
        return compose(self._estimate, relative(self._odometry_at_update, self._odometry_now))

    @property
    def covariance(self) -> np.ndarray:
        if self._covariance is None:
            p, w, mean = self._summarised
            diff = p - mean
            diff[:, 2] = _wrap(diff[:, 2])
            self._covariance = (diff * w[:, None]).T @ diff
        return self._covariance.copy()

    def status(self) -> LocaliserStatus:
        return LocaliserStatus(self.pose, self.covariance, self.mode, self.kidnaps, self.updates)

    def area_weights(self, node_at: Callable[[Sequence[float]], int | None], n_nodes: int) -> np.ndarray:
        """Share of the particles' weight per area (length ``n_nodes + 1``; last: outside every area), with the
        particles shifted by the odometry increment since the last update like :attr:`pose`."""
        shift = relative(self._odometry_at_update, self._odometry_now)
        c, s = np.cos(self.particles[:, 2]), np.sin(self.particles[:, 2])
        xs = self.particles[:, 0] + c * shift[0] - s * shift[1]
        ys = self.particles[:, 1] + s * shift[0] + c * shift[1]
        masses = np.zeros(n_nodes + 1)
        for x, y, weight in zip(xs.tolist(), ys.tolist(), self.weights.tolist(), strict=True):
            node = node_at((x, y))
            masses[n_nodes if node is None else node] += weight
        return masses

    def area(self, node_at: Callable[[Sequence[float]], int | None], n_nodes: int) -> int | None:
        """The area holding at least ``area_confidence`` of the weight, else None (unknown)."""
        masses = self.area_weights(node_at, n_nodes)
        best = int(np.argmax(masses[:n_nodes]))
        return best if masses[best] >= self.config.area_confidence else None


def _coded(table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``table`` (float32) as its distinct values (float64) and the flat code of every cell (uint8/uint16)."""
    values, codes = np.unique(table.ravel(), return_inverse=True)
    dtype = np.uint8 if len(values) <= 256 else np.uint16 if len(values) <= 65536 else np.uint32
    return values.astype(np.float64), codes.astype(dtype)


def _wrap(angles: np.ndarray) -> np.ndarray:
    return (angles + np.pi) % (2 * np.pi) - np.pi


def _low_variance(rng: np.random.Generator, weights: np.ndarray, count: int) -> np.ndarray:
    """Low-variance (systematic) resampling, Probabilistic Robotics Table 4.4: indices of ``count`` draws."""
    positions = (rng.random() + np.arange(count)) / count
    cumulative = weights.cumsum()  # array methods: the np.* functions add a Python dispatch layer
    cumulative[-1] = 1.0
    picked = cumulative.searchsorted(positions, side="right")
    return np.minimum(picked, len(weights) - 1, out=picked)
