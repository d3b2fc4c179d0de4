"""Navigation on the rules' grid, shared by every scripted team: greedy steps, shortest paths around obstacles,
task-slot assignment and the encircling ring. Randomness (tie-breaks) only through the caller's Generator."""

from __future__ import annotations

import itertools
from collections import deque

import numpy as np

from embodied_adhoc.domains.grid_rules import INTERACT, GridRules, GridState, Task


def slot_cells(rules: GridRules, state: GridState, target: int, task: Task) -> np.ndarray:
    """Cells around ``target`` named by the task's offsets, (K, 2)."""
    cells, _ = rules.normalise(state.targets[target] + np.array(task.offsets, dtype=np.int64))
    return cells


def distance_field(rules: GridRules, goal: int, blocked: list[bool]) -> list[int]:
    """Breadth-first step counts from every flat cell to flat cell ``goal`` through unblocked cells (-1 if
    unreachable). Pure Python over the rules' neighbour table: grids are small and this runs per decision."""
    neighbours = rules.neighbour_lists
    dist = [-1] * len(neighbours)
    dist[goal] = 0
    queue = deque([goal])
    while queue:
        cell = queue.popleft()
        step = dist[cell] + 1
        for nxt in neighbours[cell]:
            if nxt >= 0 and dist[nxt] < 0 and not blocked[nxt]:
                dist[nxt] = step
                queue.append(nxt)
    return dist


def _best_moves(rules: GridRules, start: int, dist: list[int]) -> list[int]:
    """All moves to a neighbour of least finite ``dist`` (empty if no neighbour reaches the goal)."""
    options = [(dist[nxt], action) for action, nxt in enumerate(rules.neighbour_lists[start])
               if nxt >= 0 and dist[nxt] >= 0]
    if not options:
        return []
    least = min(d for d, _ in options)
    return [action for d, action in options if d == least]


def navigate(rules: GridRules, state: GridState, agent: int, goal: np.ndarray, obstacles: np.ndarray,
             rng: np.random.Generator, unstick: float = 0.25, greedy_axis: bool = False) -> int:
    """First move of a shortest path to ``goal`` (A*-equivalent on a unit grid; INTERACT once there) around the
    live targets and the teammates flagged in ``obstacles`` (bool per agent). If those wall the goal off, the
    path around targets only. The member waits while its next cell is taken, except that with probability
    ``unstick`` it steps to a random free cell instead; ties between equally short moves are broken with
    ``rng`` (with ``greedy_axis``, 4 times in 5 in favour of the axis with the larger gap to the goal, rows
    first: the greedy walker's habit; always doing so lets two greedy members mirror each other forever). Both break the stalemates a deterministic team could repeat forever.
    """
    cols = rules.config.cols
    start = int(state.agents[agent, 0] * cols + state.agents[agent, 1])
    target = int(goal[0] * cols + goal[1])
    if start == target:
        return INTERACT
    occupancy = rules.occupancy(state).ravel().tolist()
    free = [o == 0 for o in occupancy]
    static = [o < 0 for o in occupancy]  # live targets
    blocked = list(static)
    for j in np.flatnonzero(obstacles):
        if j != agent:
            blocked[int(state.agents[j, 0] * cols + state.agents[j, 1])] = True
    blocked[target] = static[target]  # a teammate on the goal may still leave it
    neighbours = rules.neighbour_lists[start]
    moves = _best_moves(rules, start, distance_field(rules, target, blocked))
    moves = moves or _best_moves(rules, start, distance_field(rules, target, static))
    moves = [a for a in moves if free[neighbours[a]]]
    if len(moves) > 1 and greedy_axis and rng.random() < 0.8:
        gap = np.abs(rules.delta(state.agents[agent], goal))
        return min(moves, key=lambda a: (-gap[0 if a < 2 else 1], a))
    if moves:
        return int(moves[rng.integers(len(moves))]) if len(moves) > 1 else moves[0]
    if rng.random() < unstick:
        escapes = [a for a, n in enumerate(neighbours) if n >= 0 and free[n]]
        if escapes:
            return int(escapes[rng.integers(len(escapes))])
    return INTERACT


def assign_slots(rules: GridRules, agents: np.ndarray, slots: np.ndarray) -> tuple[int, ...]:
    """Slot index per agent minimising the team's summed distance (brute force over <= 4! permutations)."""
    n = len(agents)
    cost = rules.distance(agents[:, None, :], slots[None, :, :])
    best = min(itertools.permutations(range(len(slots)), n),
               key=lambda perm: (sum(cost[i, perm[i]] for i in range(n)), perm))
    return tuple(best)


def ring_goal(rules: GridRules, agent_cell: np.ndarray, target_cell: np.ndarray, offset: np.ndarray,
              radius: int = 2) -> np.ndarray:
    """Encircling plan (team tau2): off its own ray ``target + k * offset``, a member heads for the ray's cell at
    ``radius`` (the circle around the target, pulled inside the walls); on the ray at ``k``, it closes in to
    ``k - 1`` (at least 1, its task slot), so the circle tightens one step at a time."""
    offset = np.asarray(offset)
    rel = rules.delta(target_cell, agent_cell)
    scale = int(np.abs(offset).max())
    k = int(np.abs(rel).max()) // scale if scale else 0
    on_ray = k >= 1 and np.array_equal(rel, k * offset)
    start = max(1, k - 1) if on_ray else radius
    for r in range(start, 0, -1):
        cell, inside = rules.normalise(target_cell + r * offset)
        if inside:
            return cell
    return rules.normalise(target_cell + offset)[0]
