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
             rng: np.random.Generator, unstick: float = 0.25) -> int:
    """First move of a shortest path to ``goal`` (A*-equivalent on a unit grid; INTERACT once there) around the
    live targets and the teammates flagged in ``obstacles`` (bool per agent). If those wall the goal off, the
    path around targets only. The member waits while its next cell is taken, except that with probability
    ``unstick`` it steps to a random free cell instead; ties between equally short moves are broken with
    ``rng``. Both break the stalemates a deterministic team could repeat forever.
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


def ring_goal(rules: GridRules, agent_cell: np.ndarray, target_cell: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Encircling plan: a cell on the agent's own ray ``target + k * offset`` with ``k`` one less than the agent's
    current Chebyshev distance (at least 1), pulled inside the walls, so the ring closes in step by step."""
    k = max(1, int(np.abs(rules.delta(target_cell, agent_cell)).max()) - 1)
    for radius in range(k, 0, -1):
        cell, inside = rules.normalise(target_cell + radius * np.asarray(offset))
        if inside:
            return cell
    return rules.normalise(target_cell + np.asarray(offset))[0]
