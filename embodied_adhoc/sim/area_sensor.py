"""The robot's area sensor: the area its localiser (or, without one, its wheel odometry) puts it in, as the robot
observes it.

The reading is reported with probability ``accuracy`` and is unknown otherwise. That dropout is the sensor's own
parameter; the lab model's robot-node factor (``domains.lab.LabConfig.robot_node_accuracy``) describes the same
sensor with the same number, so the physics lab builds its sensor from that one setting
(``envs.toxic_waste_world.make_world``) and the model's observation matrices are built from it too. With a
measured localisation model (``localisation_model``) the model describes the localiser's own errors instead and
the sensor drops nothing (``accuracy=1``).
"""

from __future__ import annotations

import numpy as np

from embodied_adhoc import checks

__all__ = ["AreaSensor"]


class AreaSensor:
    """``observe(area)``: ``area`` with probability ``accuracy``, else None (unknown), one draw per reading from
    the stream given to :meth:`reset`."""

    def __init__(self, accuracy: float = 1.0) -> None:
        self.accuracy = checks.number("area sensor accuracy", accuracy, 0.0, 1.0)
        self.rng = np.random.default_rng(0)

    def reset(self, rng: np.random.Generator) -> None:
        self.rng = rng

    def observe(self, area: int | None) -> int | None:
        if self.rng.random() >= self.accuracy:
            return None  # the reading is lost
        return area
