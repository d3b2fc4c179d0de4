"""The scripted human cleaner of the toxic-waste lab (thesis section 7.1, "The Human Teammate").

One policy, used by the abstract model (to build the task MMDPs and the averaged transitions of Eq. 7.1), by the
abstract simulator and by the embodied MuJoCo env. It lives in ``domains/`` because the lab's models are built from
it (it is one of the lab's rules); ``teammates/`` sits above ``domains/`` and holds the grid domains' labelled team
types (``tests/test_layers.py`` checks the direction). The human knows the task (where the balls lie) and sees the
state. Rules:

* holding a ball: wait where it was picked up (humans "were unable to move if they had picked up any balls");
  the ball goes into the container when the robot is at the same node and stays or asks (see ``lab_model``);
* a ball on the ground at the human's node: pick it up (the lowest-index such ball);
* otherwise, balls still on the ground: move one node along a shortest path towards the nearest one; ties
  (several nearest balls or several shortest paths) give several optimal actions, chosen uniformly;
* nothing left: stay.

With probability ``epsilon`` a move or a pick fails and the human stays ("distractions such as looking at the
phone"). Human actions: ``0..D-1`` move to the (k+1)-th lowest-index neighbour, ``D`` stay, ``D + 1`` pick.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from embodied_adhoc.domains.lab_graph import GROUND, HELD, LabGraph
from embodied_adhoc.errors import ConfigError

__all__ = ["HumanOutcome", "LabHuman"]


@dataclass(frozen=True)
class HumanOutcome:
    """One possible result of the human's step: probability, the human's next node, the ball picked (-1: none),
    and whether a human holding a ball drops it on the floor (it lies on the ground again, outside the container).
    """

    probability: float
    next_node: int
    picked_ball: int = -1
    dropped: bool = False


@dataclass(frozen=True, eq=False)
class LabHuman:
    """The human teammate for one task: ``balls[i]`` is the node where ball ``i`` starts."""

    graph: LabGraph
    balls: tuple[int, ...]
    epsilon: float = 0.05
    _cache: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        if not 0.0 <= float(self.epsilon) <= 1.0:
            raise ConfigError(f"human epsilon must lie in [0, 1], got {self.epsilon}")
        object.__setattr__(self, "balls", tuple(int(b) for b in self.balls))
        object.__setattr__(self, "epsilon", float(self.epsilon))

    # ------------------------------------------------------------------------------------------ actions
    @property
    def stay_action(self) -> int:
        return self.graph.max_degree

    @property
    def pick_action(self) -> int:
        return self.graph.max_degree + 1

    @property
    def n_actions(self) -> int:
        return self.graph.max_degree + 2

    @property
    def action_names(self) -> tuple[str, ...]:
        moves = tuple(f"move to neighbour {k + 1}" for k in range(self.graph.max_degree))
        return (*moves, "stay", "pick")

    def optimal_actions(self, human_node: int, ball_status: Sequence[int]) -> tuple[int, ...]:
        """The set A*(x) of the human's optimal actions in this state (thesis Eq. 7.1's averaging set)."""
        status = tuple(ball_status)
        if HELD in status:
            return (self.stay_action,)
        remaining = [self.balls[i] for i, s in enumerate(status) if s == GROUND]
        if not remaining:
            return (self.stay_action,)
        distances = self.graph.distances
        nearest = min(int(distances[human_node, node]) for node in remaining)
        if nearest == 0:
            return (self.pick_action,)
        targets = [node for node in remaining if distances[human_node, node] == nearest]
        neighbours = self.graph.neighbours[human_node]
        return tuple(
            k for k, nxt in enumerate(neighbours) if any(distances[nxt, t] == nearest - 1 for t in targets)
        )

    def outcomes(self, human_node: int, ball_status: Sequence[int], action: int) -> tuple[HumanOutcome, ...]:
        """Distribution of one human action's effect (the human part of the MMDP's P_m), epsilon included."""
        status = tuple(ball_status)
        stay = HumanOutcome(1.0, human_node)
        if not 0 <= action < self.n_actions:
            raise ConfigError(f"human action {action} outside 0..{self.n_actions - 1}")
        if action == self.stay_action or HELD in status:
            return (stay,)
        if action == self.pick_action:
            here = [i for i, s in enumerate(status) if s == GROUND and self.balls[i] == human_node]
            if not here:
                return (stay,)
            success = HumanOutcome(1.0 - self.epsilon, human_node, here[0])
        else:
            success = HumanOutcome(1.0 - self.epsilon, self.graph.move_target(human_node, action))
        if self.epsilon == 0.0:
            return (HumanOutcome(1.0, success.next_node, success.picked_ball),)
        return (success, HumanOutcome(self.epsilon, human_node))

    def policy_outcomes(self, human_node: int, ball_status: Sequence[int]) -> tuple[HumanOutcome, ...]:
        """The human policy's next-step distribution: uniform over A*(x), each through :meth:`outcomes`.

        Outcomes with the same effect are merged. Cached per (node, status): the simulator calls this every step.
        """
        key = (int(human_node), tuple(int(s) for s in ball_status))
        cached = self._cache.get(key)
        if cached is not None:
            return cached
        actions = self.optimal_actions(*key)
        merged: dict[tuple[int, int], float] = {}
        for action in actions:
            for outcome in self.outcomes(*key, action):
                effect = (outcome.next_node, outcome.picked_ball)
                merged[effect] = merged.get(effect, 0.0) + outcome.probability / len(actions)
        result = tuple(HumanOutcome(p, node, ball) for (node, ball), p in merged.items() if p > 0.0)
        self._cache[key] = result
        return result

    def step(self, rng: np.random.Generator, human_node: int, ball_status: Sequence[int]) -> HumanOutcome:
        """Sample the human's step (one uniform draw from ``rng``)."""
        outcomes = self.policy_outcomes(human_node, ball_status)
        u = rng.random()
        for outcome in outcomes[:-1]:
            u -= outcome.probability
            if u < 0.0:
                return outcome
        return outcomes[-1]
