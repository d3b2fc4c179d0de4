"""Navigation on the rules' grid, shared by every scripted team and batched over B envs: shortest paths around
obstacles, task-slot assignment and the encircling ring. Randomness (tie-breaks) comes in as uniforms drawn by
the caller from its seeded Generator, a fixed number per member and step, so that one env (B=1) and the vector
env consume their Generators identically.

Cell sets are bitsets (bit ``row * cols + col``), one integer per (env, member): a breadth-first search then
costs a few whole-array shifts per layer. Grids of up to 64 cells use ``uint64``; larger grids use Python
integers in object arrays (the same code, slower).
"""

from __future__ import annotations

import itertools

import numpy as np

from embodied_adhoc.domains.grid_rules import INTERACT, GridRules


class CellBits:
    """Bitset algebra of one grid: single-cell bits, one-step expansion (walls or wrap), membership."""

    def __init__(self, rules: GridRules) -> None:
        cfg = rules.config
        self.rules, self.cols, self.cells = rules, cfg.cols, cfg.rows * cfg.cols
        self.dtype = np.uint64 if self.cells <= 64 else object
        self.bit = np.array([self.as_int(1 << i) for i in range(self.cells)] + [self.as_int(0)], dtype=self.dtype)
        index = np.arange(self.cells)
        row, col = np.divmod(index, cfg.cols)
        self.full = self.mask(np.ones(self.cells, dtype=bool))
        self.first_row, self.last_row = self.mask(row == 0), self.mask(row == cfg.rows - 1)
        self.first_col, self.last_col = self.mask(col == 0), self.mask(col == cfg.cols - 1)
        self.toroidal = cfg.toroidal
        self.wrap_rows, self.wrap_cols = self.as_int(cfg.cols * (cfg.rows - 1)), self.as_int(cfg.cols - 1)
        self.one, self.width, self.zero = self.as_int(1), self.as_int(cfg.cols), self.as_int(0)
        self.neighbours = rules.neighbours  # (cells, 4) flat neighbour per move, -1 at a wall

    def as_int(self, value: int):
        return np.uint64(value) if self.dtype is np.uint64 else value

    def mask(self, cells: np.ndarray):
        return self.as_int(sum(1 << int(i) for i in np.flatnonzero(cells)))

    def of(self, flat: np.ndarray) -> np.ndarray:
        """Bits of flat cells (-1, a wall, gives the empty set)."""
        return self.bit[np.where(flat < 0, self.cells, flat)]

    def expand(self, bits: np.ndarray) -> np.ndarray:
        """Cells one move away from any cell of ``bits`` (through the wrap on a torus)."""
        out = ((bits & (self.full ^ self.first_row)) >> self.width) | ((bits & (self.full ^ self.last_row)) << self.width)
        out |= ((bits & (self.full ^ self.first_col)) >> self.one) | ((bits & (self.full ^ self.last_col)) << self.one)
        if self.toroidal:
            out |= ((bits & self.first_row) << self.wrap_rows) | ((bits & self.last_row) >> self.wrap_rows)
            out |= ((bits & self.first_col) << self.wrap_cols) | ((bits & self.last_col) >> self.wrap_cols)
        return out

    def union(self, bits: np.ndarray, axis: int) -> np.ndarray:
        return np.bitwise_or.reduce(bits, axis=axis) if self.dtype is np.uint64 else _or_reduce(bits, axis)

    def has(self, bits: np.ndarray, members: np.ndarray) -> np.ndarray:
        return (bits & members) != self.zero


def _or_reduce(bits: np.ndarray, axis: int) -> np.ndarray:
    out = np.zeros(np.delete(bits.shape, axis), dtype=object)
    for part in np.moveaxis(bits, axis, 0):
        out = out | part
    return out


def best_moves(cellbits: CellBits, start: np.ndarray, goal: np.ndarray, blocked: np.ndarray) -> np.ndarray:
    """(..., 4) bool: the moves from flat ``start`` to a neighbour at least step count from flat ``goal``
    through cells not ``blocked`` (bitsets), by breadth-first search from the goal (which counts as reachable
    even if blocked); all False where no neighbour reaches the goal."""
    neighbour_bits = cellbits.of(cellbits.neighbours[start])  # (..., 4)
    reach = cellbits.of(goal)
    open_cells = cellbits.full ^ blocked
    moves = np.zeros(neighbour_bits.shape, dtype=bool)
    done = np.zeros(reach.shape, dtype=bool)
    for _ in range(cellbits.cells):
        hit = cellbits.has(reach[..., None], neighbour_bits)
        newly = hit.any(axis=-1) & ~done
        moves |= hit & newly[..., None]
        done |= newly
        grown = reach | (cellbits.expand(reach) & open_cells)
        done |= grown == reach  # nothing new: the goal is walled off from the remaining searches
        if done.all():
            break
        reach = grown
    return moves


def pick_nth(mask: np.ndarray, uniforms: np.ndarray) -> np.ndarray:
    """Index of the ``floor(u * count)``-th True entry of each row of ``mask`` (-1 for an empty row)."""
    count = mask.sum(axis=-1)
    nth = np.minimum((uniforms * count).astype(np.int64), np.maximum(count - 1, 0))
    chosen = mask & (np.cumsum(mask, axis=-1) == (nth + 1)[..., None])
    return np.where(count > 0, np.argmax(chosen, axis=-1), -1)


def navigate(rules: GridRules, cellbits: CellBits, agents: np.ndarray, goals: np.ndarray, static: np.ndarray,
             obstacles: np.ndarray, free: np.ndarray, greedy_axis: np.ndarray, uniforms: np.ndarray,
             unstick: float = 0.25) -> np.ndarray:
    """(B, N) first move of a shortest path from each member's cell ``agents`` to its ``goals`` (INTERACT once
    there) around the live targets (bitsets ``static``, (B,)) and the teammates in ``obstacles`` (bitsets,
    (B, N)). If those wall the goal off, the path around targets only. A member waits while its next cell is
    taken (``free``: (B,) bitsets of empty cells), except that with probability ``unstick`` it steps to a
    random free cell instead. Ties between equally short moves go uniformly at random, or, where
    ``greedy_axis`` (B,), 4 times in 5 to the axis with the larger gap to the goal, rows first: the greedy
    walker's habit (always doing so lets two greedy members mirror each other forever). ``uniforms`` (B, N, 3)
    in [0, 1): axis habit, choice among moves, unstick."""
    start, goal = rules.flat(agents), rules.flat(goals)
    goal_bits = cellbits.of(goal)
    static = np.broadcast_to(static[:, None], start.shape)
    # a teammate standing on the goal may still leave it; a live target on it may not
    blocked = (static | obstacles) & (cellbits.full ^ goal_bits) | (static & goal_bits)
    fields = best_moves(cellbits, np.stack([start, start]), np.stack([goal, goal]), np.stack([blocked, static]))
    moves = np.where(fields[0].any(axis=-1)[..., None], fields[0], fields[1])
    neighbour_bits = cellbits.of(cellbits.neighbours[start])
    open_step = cellbits.has(free[:, None, None], neighbour_bits) & (cellbits.neighbours[start] >= 0)
    moves &= open_step
    count = moves.sum(axis=-1)
    gap = np.abs(rules.delta(agents, goals))  # (B, N, 2)
    axis_score = np.where(moves, gap[..., [0, 0, 1, 1]] * 8 - np.arange(4), -100)
    by_axis = np.argmax(axis_score, axis=-1)
    random_move = pick_nth(moves, uniforms[..., 1])
    escape = pick_nth(open_step, uniforms[..., 1])
    action = np.where(uniforms[..., 2] < unstick, np.where(escape >= 0, escape, INTERACT), INTERACT)
    action = np.where(count > 0, random_move, action)
    action = np.where((count > 1) & greedy_axis[:, None] & (uniforms[..., 0] < 0.8), by_axis, action)
    return np.where(start == goal, INTERACT, action)


def permutations_table(n: int) -> np.ndarray:
    """All orderings of ``range(n)`` in lexicographic order, (n!, n)."""
    return np.array(list(itertools.permutations(range(n))), dtype=np.int64)


def assign_slots(rules: GridRules, agents: np.ndarray, slots: np.ndarray, orders: np.ndarray) -> np.ndarray:
    """Slot index per agent minimising the team's summed distance, ties to the lexicographically first
    assignment: ``agents`` (B, N, 2), ``slots`` (B, N, K, 2) (each member's own target's slots), result (B, N)."""
    cost = rules.distance(agents[:, None, :, None, :], slots[:, :, None, :, :])  # (B, member, agent, slot)
    n = agents.shape[1]
    totals = cost[:, :, np.arange(n)[None, :], orders].sum(axis=-1)  # (B, member, n!)
    best = np.argmin(totals, axis=-1)
    return orders[best, np.arange(n)[None, :]]


def ring_goal(rules: GridRules, agents: np.ndarray, targets: np.ndarray, offsets: np.ndarray,
              radius: int = 2) -> np.ndarray:
    """Encircling plan (team tau2), (B, N, 2): off its own ray ``target + k * offset``, a member heads for the
    ray's cell at ``radius`` (the circle around the target, pulled inside the walls); on the ray at ``k``, it
    closes in to ``k - 1`` (at least 1, its task slot), so the circle tightens one step at a time."""
    rel = rules.delta(targets, agents)
    scale = np.maximum(np.abs(offsets).max(axis=-1), 1)
    k = np.abs(rel).max(axis=-1) // scale
    on_ray = (k >= 1) & np.all(rel == k[..., None] * offsets, axis=-1)
    start = np.where(on_ray, np.maximum(1, k - 1), radius)
    goal, _ = rules.normalise(targets + offsets)
    for r in range(2, int(start.max()) + 1):
        cell, inside = rules.normalise(targets + r * offsets)
        goal = np.where((inside & (r <= start))[..., None], cell, goal)
    return goal
