"""The physics lab's human decides for itself, from what it perceives in the MuJoCo world.

Each macro step :class:`HumanMind` looks at the room (``LabWorld.ground_truth``: its own area, where each ball
physically is: on the floor, in its hand or in the robot's container; the robot's area) and at what the robot
does (driving away, or staying / asking where it is), asks its policy for a step and turns the answer into the
walker's motion command (:class:`~embodied_adhoc.sim.human.HumanCommand`). No transition rule of the abstract
model is consulted: what happens then (a pick that fails in physics, a drop that misses the container) is up to
the physics.

The policy has the lab's human interface (``domains.lab_human.LabHuman``, or a plug-in of ``envs.lab_humans``):
``step(rng, human_node, ball_status) -> HumanOutcome``, called only when the human holds no ball; a human holding
a ball waits where it is and hands the ball over when the robot is in its area and stays or asks (thesis section
7.1), so it makes no draw then. When the robot asks where it is, the human says so (:meth:`HumanMind.reply`: the
policy's ``answer`` where it has one) and the speech channel carries what it said. A policy's ``dropped`` outcome
(letting a held ball fall) is not acted out: the walker has no such motion.
"""

from __future__ import annotations

import numpy as np

from embodied_adhoc.domains.lab_graph import DISPOSED, GROUND, HELD
from embodied_adhoc.sim.human import HumanCommand
from embodied_adhoc.sim.lab_layout import LabLayout

__all__ = ["BALL_STATUS", "HumanMind"]

BALL_STATUS = {"ground": GROUND, "held": HELD, "container": DISPOSED}
"""A ball's physical state (``GroundTruth.ball_states``) as the lab's ball status."""


class HumanMind:
    """The world's human for one episode: ``policy`` (the lab human interface) and its random stream."""

    def __init__(self, policy, rng: np.random.Generator, layout: LabLayout) -> None:
        self.policy, self.rng, self.layout = policy, rng, layout

    def decide(self, truth, robot_stays: bool) -> HumanCommand:
        """The command for this macro step, from the world as it is at its start (``truth``) and whether the
        robot stays in its area or asks (``robot_stays``) rather than drives to a neighbour."""
        status = tuple(BALL_STATUS[state] for state in truth.ball_states)
        here = truth.human_node
        if HELD in status:
            robot_area = truth.robot_node
            if robot_area is None:  # on a border between areas: the area of the nearest waypoint
                robot_area = self.layout.nearest_node(truth.robot_pose[:2])
            if robot_stays and robot_area == here:
                return HumanCommand.drop_into_container(status.index(HELD))
            return HumanCommand.stay()
        outcome = self.policy.step(self.rng, here, status)
        if outcome.picked_ball >= 0:
            return HumanCommand.pick(outcome.picked_ball)
        if outcome.next_node != here:
            return HumanCommand.move_to(outcome.next_node)
        return HumanCommand.stay()

    def reply(self, human_node: int) -> int | None:
        """Where the human says it is when the robot asks "where are you?" (``human_node``: its true area): its
        policy's ``answer(rng, human_node)`` if it has one (None: no reply), else its area."""
        answer = getattr(self.policy, "answer", None)
        return human_node if answer is None else answer(self.rng, human_node)
