"""Robot sensing besides odometry: the container's RFID reader and the wall-contact check."""

from __future__ import annotations

import mujoco
import numpy as np

from embodied_adhoc.errors import SceneError
from embodied_adhoc.sim.lab_model import LabIds


class RfidReader:
    """Reads a ball's tag when the ball's centre enters the ``rfid`` site box (the container interior).

    One read attempt per ball and episode: when a ball first enters, the read succeeds with probability
    ``1 - miss_probability`` and yields one event; a missed ball is never reported later (the tag stays in the
    field without a new entry). So every dropped ball gives exactly one event at miss probability 0.
    """

    def __init__(self, model: mujoco.MjModel, ids: LabIds, miss_probability: float, rng: np.random.Generator):
        self.ids = ids
        self.miss_probability = miss_probability
        self.rng = rng
        self.half_size = model.site_size[ids.rfid_site].copy()
        self.entered = np.zeros(len(ids.ball_bodies), dtype=bool)
        self._unread = len(self.entered)  # balls that have not entered yet
        self.misses = 0  # read attempts (balls entered) that missed, since the reset
        self._bodies = [int(body) for body in ids.ball_bodies]
        self._reach2 = float(self.half_size @ self.half_size)  # squared radius of the sphere around the box

    def reset(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.entered[:] = False
        self._unread = len(self.entered)
        self.misses = 0

    def inside_mask(self, data: mujoco.MjData) -> np.ndarray:
        """Per ball: is its centre inside the reader's box?"""
        site = self.ids.rfid_site
        local = (data.xpos[self.ids.ball_bodies] - data.site_xpos[site]) @ data.site_xmat[site].reshape(3, 3)
        # a ufunc reduce: ndarray.all adds a Python layer
        return np.logical_and.reduce(np.abs(local) <= self.half_size, axis=1)

    def inside(self, data: mujoco.MjData, ball: int) -> bool:
        return bool(self.inside_mask(data)[ball])

    def _any_near(self, data: mujoco.MjData) -> bool:
        """Is any ball centre within the sphere around the box? (Scalar Python: cheaper than the box test for
        three balls, and the box test is needed only when it says yes.)"""
        cx, cy, cz = data.site_xpos[self.ids.rfid_site].tolist()
        xpos = data.xpos
        for body in self._bodies:
            x, y, z = xpos[body].tolist()
            if (x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2 <= self._reach2:
                return True
        return False

    def poll(self, data: mujoco.MjData) -> list[int]:
        """Balls read at this tick (first entries that were not missed)."""
        if self._unread == 0 or not self._any_near(data):
            return []
        events = []
        for ball in (self.inside_mask(data) & ~self.entered).nonzero()[0].tolist():
            self.entered[ball] = True
            self._unread -= 1
            if self.rng.random() >= self.miss_probability:
                events.append(ball)
            else:
                self.misses += 1
        return events

    @property
    def attempts(self) -> int:
        """Read attempts since the reset: one per ball that entered the container."""
        return len(self.entered) - self._unread


class WallContact:
    """Does any robot geom touch a wall or partition right now? ``WallContact(ids)(data)``.

    Each geom has a class code (robot 1, wall 2, anything else 0), so a contact pair is robot-wall exactly when
    the product of its two codes is 2: one table look-up per pair."""

    def __init__(self, ids: LabIds):
        if (ids.robot_geom_mask & ids.wall_geom_mask).any():
            raise SceneError(
                "a geom is both part of the robot and a wall; the wall-contact check needs them apart"
            )
        self.codes = (ids.robot_geom_mask.astype(int) + 2 * ids.wall_geom_mask.astype(int)).tolist()

    def __call__(self, data: mujoco.MjData) -> bool:
        if data.ncon == 0:
            return False
        codes = self.codes
        # a handful of contacts: a Python loop over the pairs costs less than numpy's fancy indexing
        return any(codes[a] * codes[b] == 2 for a, b in data.contact.geom.tolist())
