"""One scripted team policy for both grid domains, parameterised by a :class:`TeamSpec` (section 6.2.2).

A team member picks a target, a cell to reach (its task slot, or a point on the closing ring) and a way to get
there (greedy ignoring obstacles, or a shortest path around them). Every member computes the same target and
slot assignment from the full state, which is how the thesis's teams "assume teammates do the same".
Randomness only breaks ties and stalemates (seeded Generator).
The same policy drives the ad hoc robot as the thesis's *original teammate* baseline.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from embodied_adhoc.domains.grid_rules import INTERACT, MOVES, GridRules, GridState, Task
from embodied_adhoc.domains.grid_rules_plan import assign_slots, navigate, ring_goal, slot_cells
from embodied_adhoc.errors import ConfigError


@dataclass(frozen=True)
class TeamSpec:
    """How one team type behaves. ``target``: closest (to the member), highest_level (LBF, ties to the lowest
    index) or team_closest (least summed distance to the team). ``slot`` (interchangeable tasks only): closest
    free-for-me slot or the team's distance-minimising assignment. ``goal``: the slot itself or the encircling
    ring that closes in. ``navigation``: greedy (ignores obstacles) or path (shortest path around them)."""

    name: str
    description: str
    target: str = "closest"
    slot: str = "assigned"
    goal: str = "slot"
    navigation: str = "path"

    def __post_init__(self) -> None:
        for field_name, value, allowed in (("target", self.target, ("closest", "highest_level", "team_closest")),
                                           ("slot", self.slot, ("closest", "assigned")),
                                           ("goal", self.goal, ("slot", "ring")),
                                           ("navigation", self.navigation, ("greedy", "path"))):
            if value not in allowed:
                raise ConfigError(f"TeamSpec {self.name}: {field_name}={value!r}, use one of {allowed}")


def choose_target(rules: GridRules, state: GridState, agent: int, spec: TeamSpec) -> int:
    """Index of the live target this member works on."""
    alive = np.flatnonzero(state.alive)
    if spec.target == "highest_level":
        return int(alive[np.argmax(state.target_levels[alive])])
    if spec.target == "team_closest":
        cost = rules.distance(state.agents[None, :, :], state.targets[alive][:, None, :]).sum(axis=1)
    else:
        cost = rules.distance(state.agents[agent], state.targets[alive])
    return int(alive[np.argmin(cost)])


def member_goal(rules: GridRules, state: GridState, task: Task, agent: int, spec: TeamSpec) -> np.ndarray:
    """The cell member ``agent`` heads for now: its task slot around its target, or its point on the ring."""
    target = choose_target(rules, state, agent, spec)
    slots = slot_cells(rules, state, target, task)
    if not task.interchangeable:
        slot = agent
    elif spec.slot == "closest":
        # greedy: the closest slot, skipping slots another agent already stands on
        taken = np.array([any(np.array_equal(s, a) for j, a in enumerate(state.agents) if j != agent)
                          for s in slots])
        slot = int(np.argmin(rules.distance(state.agents[agent], slots) + 1000 * taken))
    else:
        slot = assign_slots(rules, state.agents, slots)[agent]
    if spec.goal == "ring":
        return ring_goal(rules, state.agents[agent], state.targets[target], np.array(task.offsets[slot]))
    return slots[slot]


def team_actions(rules: GridRules, state: GridState, task: Task, spec: TeamSpec, rng: np.random.Generator,
                 members: range | list[int] | None = None) -> np.ndarray:
    """Actions of the listed members (default: everyone) of a team of type ``spec`` doing ``task``.

    Every member computes the whole team's plan (assuming all follow the team policy) and members resolve
    stalemates by index, as the thesis's teams do: every member plans around teammates already on their goal;
    path-planning members also plan around lower-index members (prioritised planning); and when several intend to enter
    the same cell all but the lowest index wait. ``rng`` breaks ties between equally short moves and lets a
    blocked member sidestep at random (see :func:`navigate`); the team is deterministic given its Generator.
    """
    n = rules.config.n_agents
    if not state.alive.any():
        intended = np.full(n, INTERACT, dtype=np.int64)
    else:
        goals = np.array([member_goal(rules, state, task, i, spec) for i in range(n)])
        settled = np.all(goals == state.agents, axis=1)
        intended = np.empty(n, dtype=np.int64)
        for i in range(n):
            # greedy members ignore teammates on the move; path planners also avoid lower-index members
            obstacles = settled | (np.arange(n) < i) if spec.navigation == "path" else settled
            intended[i] = navigate(rules, state, i, goals[i], obstacles, rng,
                                   greedy_axis=spec.navigation == "greedy")
    wanted, _ = rules.normalise(state.agents + MOVES[intended])
    flat = wanted[:, 0] * rules.config.cols + wanted[:, 1]
    moving = intended != INTERACT
    for i in range(n):
        if moving[i] and np.any(moving[:i] & (flat[:i] == flat[i])):
            intended[i] = INTERACT
    return intended[list(range(n)) if members is None else list(members)]


def team_action(rules: GridRules, state: GridState, task: Task, agent: int, spec: TeamSpec,
                rng: np.random.Generator) -> int:
    """The action of member ``agent`` (see :func:`team_actions`)."""
    return int(team_actions(rules, state, task, spec, rng, [agent])[0])
