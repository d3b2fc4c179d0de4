"""One scripted team policy for both grid domains, parameterised by a :class:`TeamSpec` (section 6.2.2).

A team member picks a target, a cell to reach (its task slot, or a point on the closing ring) and a way to get
there (greedy ignoring obstacles, or a shortest path around them). Every member computes the same target and
slot assignment from the full state, which is how the thesis's teams "assume teammates do the same".
Randomness only breaks ties and stalemates (uniforms from a seeded Generator). The policy is batched over B
envs (:class:`TeamPlanner`); the single envs call it with B=1 and the vector env (``learning/vector_grid.py``)
with many, so both run one implementation.
The same policy drives the ad hoc robot as the thesis's *original teammate* baseline.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from embodied_adhoc.domains.grid_rules import INTERACT, GridBatch, GridRules, GridState, Task
from embodied_adhoc.domains.grid_rules_plan import (
    CellBits,
    assign_slots,
    navigate,
    permutations_table,
    ring_goal,
)
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
        for field_name, value, allowed in (
            ("target", self.target, ("closest", "highest_level", "team_closest")),
            ("slot", self.slot, ("closest", "assigned")),
            ("goal", self.goal, ("slot", "ring")),
            ("navigation", self.navigation, ("greedy", "path")),
        ):
            if value not in allowed:
                raise ConfigError(f"TeamSpec {self.name}: {field_name}={value!r}, use one of {allowed}")


TEAM_DRAWS = 3  # uniforms per member and step (see navigate): drawn always, so Generators stay aligned
TARGET_RULES = ("closest", "highest_level", "team_closest")


@dataclass(frozen=True)
class TeamTable:
    """The :class:`TeamSpec` of each of B envs as arrays, so that one batched pass serves mixed teams."""

    target: np.ndarray  # (B,) index into TARGET_RULES
    slot_closest: np.ndarray  # (B,) bool
    ring: np.ndarray  # (B,) bool
    greedy: np.ndarray  # (B,) bool: greedy navigation (ignores members on the move, axis habit)

    @classmethod
    def of(cls, specs) -> TeamTable:
        return cls(
            np.array([TARGET_RULES.index(s.target) for s in specs], dtype=np.int64),
            np.array([s.slot == "closest" for s in specs]),
            np.array([s.goal == "ring" for s in specs]),
            np.array([s.navigation == "greedy" for s in specs]),
        )

    def take(self, index: np.ndarray) -> TeamTable:
        return TeamTable(self.target[index], self.slot_closest[index], self.ring[index], self.greedy[index])


class TeamPlanner:
    """The scripted team policy of one grid, batched over B envs (a single env is B=1)."""

    def __init__(self, rules: GridRules) -> None:
        self.rules, self.cellbits = rules, CellBits(rules)
        n = rules.config.n_agents
        self.orders = permutations_table(n)
        self.lower = np.tril(np.ones((n, n), dtype=bool), -1)  # lower[i, j]: j < i
        self.others = ~np.eye(n, dtype=bool)
        # step_to[cell, action]: the cell an action aims at (its own cell for INTERACT and into walls)
        cells = np.arange(len(rules.neighbours))
        self.step_to = np.concatenate(
            [np.where(rules.neighbours >= 0, rules.neighbours, cells[:, None]), cells[:, None]], axis=1
        )
        self.cells = np.stack(np.divmod(cells, rules.config.cols), axis=-1)
        # task offsets seen so far, as columns of the goal tables (filled on first use of an offset)
        rows, cols = rules.config.rows, rules.config.cols
        self.offset_index = np.full((2 * rows + 1) * (2 * cols + 1), -1, dtype=np.int64)
        self.slot_cell = np.zeros((len(cells), 0), dtype=np.int64)  # [target cell, offset]: the task slot
        self.ring_cell = np.zeros((len(cells), len(cells), 0), dtype=np.int64)  # [target, member, offset]

    def _offset_columns(self, offsets: np.ndarray) -> np.ndarray:
        """Column of each task offset (..., 2) in the goal tables, adding the columns of new offsets: the slot
        ``target + offset`` and the :func:`ring_goal` of every member cell, as flat cells."""
        cfg = self.rules.config
        code = (offsets[..., 0] + cfg.rows) * (2 * cfg.cols + 1) + offsets[..., 1] + cfg.cols
        columns = self.offset_index[code]
        if (columns >= 0).all():
            return columns
        for value in np.unique(code[columns < 0]).tolist():
            offset = np.array(divmod(value, 2 * cfg.cols + 1)) - [cfg.rows, cfg.cols]
            targets = np.broadcast_to(self.cells[:, None, :], (len(self.cells), len(self.cells), 2))
            members = np.broadcast_to(self.cells[None, :, :], targets.shape)
            ring = self.rules.flat(
                ring_goal(self.rules, members, targets, np.broadcast_to(offset, targets.shape))
            )
            slot = self.rules.flat(self.rules.normalise(self.cells + offset)[0])
            self.offset_index[value] = self.slot_cell.shape[1]
            self.slot_cell = np.concatenate([self.slot_cell, slot[:, None]], axis=1)
            self.ring_cell = np.concatenate([self.ring_cell, ring[..., None]], axis=2)
        return self.offset_index[code]

    def goals(
        self, batch: GridBatch, offsets: np.ndarray, interchangeable: bool, teams: TeamTable
    ) -> np.ndarray:
        """(B, N) flat cell each member heads for now: its task slot around its target, or its point on the
        ring (:func:`ring_goal`, tabulated). Every member computes the same target rule and slot assignment
        from the full state."""
        rules, agents = self.rules, batch.agents
        env = np.arange(len(agents))[:, None]
        start, targets_flat = rules.flat(agents), rules.flat(batch.targets)
        if targets_flat.shape[1] == 1:  # one apple/prey: every rule picks it
            target_flat = np.broadcast_to(targets_flat, start.shape)
        else:
            distance = self.cellbits.distance[
                start[:, :, None], targets_flat[:, None, :]
            ]  # (B, member, target)
            cost = np.where(teams.target[:, None, None] == 0, distance, -batch.target_levels[:, None, :])
            cost = np.where(teams.target[:, None, None] == 2, distance.sum(axis=1, keepdims=True), cost)
            target = np.argmin(
                np.where(batch.alive[:, None, :], cost, np.iinfo(np.int64).max), axis=-1
            )  # (B, N)
            target_flat = targets_flat[env, target]  # (B, N)
        columns = self._offset_columns(offsets)  # (B, slot)
        if interchangeable:
            # greedy: the closest slot, skipping slots another agent already stands on
            slot_flat = self.slot_cell[target_flat[:, :, None], columns[:, None, :]]  # (B, member, slot)
            on_slot = start[:, None, :, None] == slot_flat[:, :, None, :]  # (B, member, agent, slot)
            taken = np.any(on_slot & self.others[None, :, :, None], axis=2)
            closest = np.argmin(self.cellbits.distance[start[:, :, None], slot_flat] + 1000 * taken, axis=-1)
            cost = self.cellbits.distance[start[:, None, :, None], slot_flat[:, :, None, :]]
            slot = np.where(teams.slot_closest[:, None], closest, assign_slots(cost, self.orders))
            column = columns[env, slot]
        else:
            column = columns  # member i fills slot i
        ring = self.ring_cell[target_flat, start, column]
        return np.where(teams.ring[:, None], ring, self.slot_cell[target_flat, column])

    def actions(
        self,
        batch: GridBatch,
        offsets: np.ndarray,
        interchangeable: bool,
        teams: TeamTable,
        uniforms: np.ndarray,
    ) -> np.ndarray:
        """(B, N) actions of every member of each env's team (``uniforms``: (B, N, TEAM_DRAWS) in [0, 1)).

        Every member computes the whole team's plan (assuming all follow the team policy) and members resolve
        stalemates by index, as the thesis's teams do: every member plans around teammates already on their
        goal; path-planning members also plan around lower-index members (prioritised planning); and when
        several intend to enter the same cell all but the lowest index wait. The uniforms break ties between
        equally short moves and let a blocked member sidestep at random (see :func:`navigate`).
        """
        rules, bits = self.rules, self.cellbits
        lower = self.lower
        start = rules.flat(batch.agents)
        goal = self.goals(batch, offsets, interchangeable, teams)
        settled = goal == start  # (B, N)
        obstacle = (settled[:, None, :] | (lower[None] & ~teams.greedy[:, None, None])) & self.others
        agent_bits = bits.of(start)  # (B, N)
        obstacles = bits.union(np.where(obstacle, agent_bits[:, None, :], bits.zero), axis=2)
        static = bits.union(np.where(batch.alive, bits.of(rules.flat(batch.targets)), bits.zero), axis=1)
        free = bits.full ^ (static | bits.union(agent_bits, axis=1))
        intended = navigate(bits, start, goal, static, obstacles, free, teams.greedy, uniforms)
        intended = np.where(batch.alive.any(axis=1)[:, None], intended, INTERACT)
        wanted = self.step_to[start, intended]
        moving = intended != INTERACT
        clash = (lower[None] & moving[:, None, :] & (wanted[:, None, :] == wanted[:, :, None])).any(axis=-1)
        return np.where(moving & clash, INTERACT, intended)


_PLANNERS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def planner_for(rules: GridRules) -> TeamPlanner:
    """The (cached) batched planner of ``rules``."""
    if rules not in _PLANNERS:
        _PLANNERS[rules] = TeamPlanner(rules)
    return _PLANNERS[rules]


def team_actions(
    rules: GridRules,
    state: GridState,
    task: Task,
    spec: TeamSpec,
    rng: np.random.Generator,
    members: range | list[int] | None = None,
) -> np.ndarray:
    """Actions of the listed members (default: everyone) of a team of type ``spec`` doing ``task`` in one env:
    :meth:`TeamPlanner.actions` with B=1 on ``rng.random((N, TEAM_DRAWS))`` (drawn every call)."""
    n = rules.config.n_agents
    uniforms = rng.random((1, n, TEAM_DRAWS))
    offsets = np.array(task.offsets, dtype=np.int64)[None]
    intended = planner_for(rules).actions(
        GridBatch.stack([state]), offsets, task.interchangeable, TeamTable.of([spec]), uniforms
    )[0]
    return intended[list(range(n)) if members is None else list(members)]


def team_action(
    rules: GridRules, state: GridState, task: Task, agent: int, spec: TeamSpec, rng: np.random.Generator
) -> int:
    """The action of member ``agent`` (see :func:`team_actions`)."""
    return int(team_actions(rules, state, task, spec, rng, [agent])[0])
