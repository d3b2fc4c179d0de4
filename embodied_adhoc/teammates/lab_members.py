"""The toxic-waste lab's benchmark humans: lab-human plug-ins (``envs.lab_humans``) that differ from the thesis's.

Every member is a :class:`PopulationHuman` built from its :class:`~embodied_adhoc.teammates.populations.TeammateSpec`
parameters. Its policy depends on the state alone (the human's node and the balls' status), so that the joint MDP
with the human folded in is exact and its best response is computed by value iteration
(:mod:`embodied_adhoc.bench.bounds`). The parameters:

* ``rule``: which balls the human walks to: ``nearest`` (the thesis's cleaner: the nearest ball on the ground) or
  ``order`` (the balls in the fixed ``order`` of ball indices, a plan no task of the library holds);
* ``switch_after``: once that many balls are in the container the human switches from ``rule`` to ``then`` (a
  human who changes its plan mid-episode);
* ``slow``: probability that a move or a pick fails and the human stays (the thesis's epsilon is 0.05);
* ``wander``: probability that the human walks to a uniformly drawn neighbour instead (an epsilon-wanderer);
* ``drop``: probability per step that a human holding a ball drops it on the floor (back on the ground);
* ``quiet``: probability that the human does not answer "where are you?"; ``mislead``: probability that it names
  a uniformly drawn other node.

A plug-in spec ``embodied_adhoc.teammates.lab_members:<member name>`` names a member (``--human`` and the lab envs'
``human=``), so the benchmark's runs go through the trial runner as any user's human does.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from embodied_adhoc.domains.lab_graph import DISPOSED, GROUND, HELD, LabGraph
from embodied_adhoc.domains.lab_human import HumanOutcome, LabHuman
from embodied_adhoc.errors import ConfigError

__all__ = ["RULES", "LabMemberFactory", "PopulationHuman"]

RULES = ("nearest", "order")


class PopulationHuman:
    """One benchmark human for one task (``balls[i]``: the node of ball ``i``); see the module docstring."""

    def __init__(self, graph: LabGraph, balls: Sequence[int], params: dict) -> None:
        self.graph = graph
        self.balls = tuple(int(b) for b in balls)
        self.rule = str(params.get("rule", "nearest"))
        self.then = str(params.get("then", self.rule))
        for name in (self.rule, self.then):
            if name not in RULES:
                raise ConfigError(f"lab human rule {name!r}: choose from {', '.join(RULES)}")
        self.order = tuple(int(i) for i in params.get("order", range(len(self.balls))))
        if sorted(self.order) != list(range(len(self.balls))):
            raise ConfigError(
                f"lab human order {list(self.order)}: a permutation of 0..{len(self.balls) - 1}"
            )
        self.switch_after = params.get("switch_after")
        self.slow = float(params.get("slow", 0.05))
        self.wander = float(params.get("wander", 0.0))
        self.drop = float(params.get("drop", 0.0))
        self.quiet = float(params.get("quiet", 0.0))
        self.mislead = float(params.get("mislead", 0.0))
        for name in ("slow", "wander", "drop", "quiet", "mislead"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ConfigError(f"lab human {name}={getattr(self, name)}: a probability in [0, 1]")
        if self.quiet + self.mislead > 1.0:
            raise ConfigError("lab human quiet + mislead must not exceed 1")
        self._cache: dict[tuple, tuple[HumanOutcome, ...]] = {}

    # ----------------------------------------------------------------------------------------------- policy
    def _targets(self, human_node: int, status: tuple[int, ...]) -> list[int]:
        """Indices of the balls the human walks to now (ties: several)."""
        disposed = sum(s == DISPOSED for s in status)
        switched = self.switch_after is not None and disposed >= int(self.switch_after)
        rule = self.then if switched else self.rule
        remaining = [i for i, s in enumerate(status) if s == GROUND]
        if rule == "order":
            return [min(remaining, key=self.order.index)]
        distance = self.graph.distances[human_node]
        reach = [int(distance[self.balls[i]]) for i in remaining]
        return [i for i, d in zip(remaining, reach, strict=True) if d == min(reach)]

    def _intended(self, human_node: int, status: tuple[int, ...]) -> dict[tuple[int, int], float]:
        """The human's intended effect ``(next node, picked ball) -> probability`` before slowness and wandering."""
        targets = self._targets(human_node, status)
        here = [i for i in targets if self.balls[i] == human_node]
        if here:
            return {(human_node, here[0]): 1.0}
        distances = self.graph.distances
        moves = []
        for target in targets:
            goal = self.balls[target]
            gap = int(distances[human_node, goal])
            moves += [n for n in self.graph.neighbours[human_node] if distances[n, goal] == gap - 1]
        moves = sorted(set(moves))
        return {(int(n), -1): 1.0 / len(moves) for n in moves}

    def policy_outcomes(self, human_node: int, ball_status: Sequence[int]) -> tuple[HumanOutcome, ...]:
        """The distribution of the human's step in this state (merged effects; cached per state)."""
        key = (int(human_node), tuple(int(s) for s in ball_status))
        cached = self._cache.get(key)
        if cached is not None:
            return cached
        node, status = key
        if HELD in status:
            effects = {(node, -1, True): self.drop, (node, -1, False): 1.0 - self.drop}
        elif GROUND not in status:
            effects = {(node, -1, False): 1.0}
        else:
            effects: dict[tuple[int, int, bool], float] = {}

            def add(effect, p):
                if p > 0.0:
                    effects[effect] = effects.get(effect, 0.0) + p

            for (next_node, ball), p in self._intended(node, status).items():
                add((next_node, ball, False), (1.0 - self.wander) * (1.0 - self.slow) * p)
                add((node, -1, False), (1.0 - self.wander) * self.slow * p)
            neighbours = self.graph.neighbours[node]
            for n in neighbours:
                add((int(n), -1, False), self.wander / len(neighbours))
        outcomes = tuple(
            HumanOutcome(p, next_node, ball, dropped)
            for (next_node, ball, dropped), p in effects.items()
            if p > 0.0
        )
        self._cache[key] = outcomes
        return outcomes

    # The lab-human interface's step: one uniform draw from the generator picks an outcome of policy_outcomes,
    # exactly as the thesis's cleaner draws its own.
    step = LabHuman.step

    def answer(self, rng: np.random.Generator, human_node: int) -> int | None:
        """What the human says when asked where it is: its node, nothing (``quiet``) or another node
        (``mislead``); no draw for a human that always answers truly, so its episodes match the scripted one's."""
        if self.quiet == 0.0 and self.mislead == 0.0:
            return int(human_node)
        u = rng.random()
        if u < self.quiet:
            return None
        if u < self.quiet + self.mislead:
            others = [n for n in range(self.graph.n_nodes) if n != human_node]
            return int(others[int(rng.integers(len(others)))])
        return int(human_node)


class LabMemberFactory:
    """``factory(library, task)`` of one member (the lab-human plug-in interface)."""

    def __init__(self, name: str, params: dict) -> None:
        self.name = name
        self.params = dict(params)

    def __call__(self, library, task: int) -> PopulationHuman:
        return PopulationHuman(library.graph, library.tasks[task], self.params)

    def __repr__(self) -> str:
        return f"LabMemberFactory({self.name!r})"


def __getattr__(name: str) -> LabMemberFactory:
    """``embodied_adhoc.teammates.lab_members:<member>``: the factory of that toxic-waste member (any split)."""
    from embodied_adhoc.teammates.populations import find_member

    spec = find_member("toxic-waste", name)
    if spec is None:
        raise AttributeError(name)
    return LabMemberFactory(spec.name, spec.params)
