"""Robot sensing besides odometry: the container's RFID reader and the wall-contact check."""

from __future__ import annotations

import mujoco
import numpy as np

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

    def reset(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.entered[:] = False

    def inside_mask(self, data: mujoco.MjData) -> np.ndarray:
        """Per ball: is its centre inside the reader's box?"""
        rotation = data.site_xmat[self.ids.rfid_site].reshape(3, 3)
        local = (data.xpos[self.ids.ball_bodies] - data.site_xpos[self.ids.rfid_site]) @ rotation
        return np.all(np.abs(local) <= self.half_size, axis=1)

    def inside(self, data: mujoco.MjData, ball: int) -> bool:
        return bool(self.inside_mask(data)[ball])

    def poll(self, data: mujoco.MjData) -> list[int]:
        """Balls read at this tick (first entries that were not missed)."""
        if self.entered.all():
            return []
        new = np.flatnonzero(self.inside_mask(data) & ~self.entered)
        events = []
        for ball in new:
            self.entered[ball] = True
            if self.rng.random() >= self.miss_probability:
                events.append(int(ball))
        return events


def robot_wall_contact(data: mujoco.MjData, ids: LabIds) -> bool:
    """Does any robot geom touch a wall or partition right now?"""
    if data.ncon == 0:
        return False
    pairs = data.contact.geom[: data.ncon]
    robot, wall = ids.robot_geom_mask, ids.wall_geom_mask
    return bool(np.any((robot[pairs[:, 0]] & wall[pairs[:, 1]]) | (robot[pairs[:, 1]] & wall[pairs[:, 0]])))
