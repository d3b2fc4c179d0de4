"""Navigation on the rules' grid, shared by every scripted team and batched over B envs: shortest paths around
obstacles, task-slot assignment and the encircling ring. Randomness (tie-breaks) comes in as uniforms drawn by
the caller from its seeded Generator, a fixed number per member and step, so that one env (B=1) and the vector
env consume their Generators identically.

Cell sets are bitsets (bit ``row * cols + col``), one integer per (env, member): a breadth-first search then
costs a few whole-array shifts per layer. Grids of up to 64 cells use ``uint64``; larger grids use Python
integers in object arrays (the same code, slower).

Batches of at least ``TABLE_MIN_BATCH`` envs on small grids (the training vector env) look the searches' answers
up instead: :class:`MoveTable` holds the best first moves from every start to every goal around every blocked set
that can occur (up to ``n_agents - 1 + n_targets`` cells), computed once per grid by the same layer-by-layer
search. A search is a few array operations per layer and about ten layers, a lookup two operations.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from embodied_adhoc.domains.grid_rules import INTERACT, GridRules


class CellBits:
    """Bitset algebra of one grid: single-cell bits, one-step expansion (walls or wrap), membership."""

    def __init__(self, rules: GridRules) -> None:
        cfg = rules.config
        self.rules, self.cols, self.cells = rules, cfg.cols, cfg.rows * cfg.cols
        self.dtype = np.uint64 if self.cells <= 64 else object
        self.bit = np.array(
            [self.as_int(1 << i) for i in range(self.cells)] + [self.as_int(0)], dtype=self.dtype
        )
        index = np.arange(self.cells)
        row, col = np.divmod(index, cfg.cols)
        self.full = self.mask(np.ones(self.cells, dtype=bool))
        self.first_row, self.last_row = self.mask(row == 0), self.mask(row == cfg.rows - 1)
        self.first_col, self.last_col = self.mask(col == 0), self.mask(col == cfg.cols - 1)
        self.not_first_col, self.not_last_col = self.full ^ self.first_col, self.full ^ self.last_col
        self.toroidal = cfg.toroidal
        self.wrap_rows, self.wrap_cols = self.as_int(cfg.cols * (cfg.rows - 1)), self.as_int(cfg.cols - 1)
        self.one, self.width, self.zero = self.as_int(1), self.as_int(cfg.cols), self.as_int(0)
        self.neighbours = rules.neighbours  # (cells, 4) flat neighbour per move, -1 at a wall
        self.neighbour_bits = self.of(self.neighbours)  # (cells, 4) their bits, empty at a wall
        xy = np.stack([row, col], axis=-1)
        self.distance = rules.distance(xy[:, None], xy[None, :])  # (cells, cells) Manhattan (wrapping)
        gap = np.abs(rules.delta(xy[:, None], xy[None, :]))
        # the greedy walker's axis from cell to goal: 0 rows (larger row gap), 1 columns, 2 a tie
        self.axis_preference = np.where(
            gap[..., 0] > gap[..., 1], 0, np.where(gap[..., 0] < gap[..., 1], 1, 2)
        )

    def as_int(self, value: int):
        return np.uint64(value) if self.dtype is np.uint64 else value

    def mask(self, cells: np.ndarray):
        return self.as_int(sum(1 << int(i) for i in np.flatnonzero(cells)))

    def of(self, flat: np.ndarray) -> np.ndarray:
        """Bits of flat cells (-1, a wall, gives the empty set)."""
        return self.bit[flat]  # -1 indexes the last entry, the empty set

    def expand(self, bits: np.ndarray) -> np.ndarray:
        """Cells one move away from any cell of ``bits`` (through the wrap on a torus); may carry bits beyond
        the grid's last cell, which callers mask off with a subset of :attr:`full`."""
        out = (bits >> self.width) | (bits << self.width) | ((bits >> self.one) & self.not_last_col)
        out |= (bits << self.one) & self.not_first_col
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


MOVE_WEIGHTS = np.array([1, 2, 4, 8], dtype=np.int64)  # a set of the 4 moves as a 4-bit code


def _move_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lookups over 4-bit move sets: size, the k-th move (INTERACT past the end) and the greedy walker's
    preferred move for each axis preference (0 rows first, 1 columns first, 2 none: the lowest move)."""
    size = np.array([bin(code).count("1") for code in range(16)], dtype=np.int64)
    nth = np.full((16, 4), INTERACT, dtype=np.int64)
    by_axis = np.full((16, 3), INTERACT, dtype=np.int64)
    for code in range(16):
        moves = [a for a in range(4) if code >> a & 1]
        nth[code, : len(moves)] = moves
        for preference, order in enumerate(((0, 1, 2, 3), (2, 3, 0, 1), (0, 1, 2, 3))):
            by_axis[code, preference] = next((a for a in order if a in moves), INTERACT)
    return size, nth, by_axis


MOVE_COUNT, NTH_MOVE, AXIS_MOVE = _move_tables()


def best_moves(
    cellbits: CellBits, neighbour_bits: np.ndarray, goal_bits: np.ndarray, blocked: np.ndarray
) -> np.ndarray:
    """4-bit codes of the moves from a start (its neighbours' bits, (..., 4)) to a neighbour at least step
    count from the goal (bits) through cells not ``blocked`` (bitsets), by breadth-first search from the goal
    (which counts as reachable even if blocked); 0 where no neighbour reaches the goal. The searches grow layer
    by layer until each touches its start's neighbourhood or stops growing; the first layer that touches a
    neighbour gives the best moves."""
    open_cells = cellbits.full ^ blocked
    around = neighbour_bits[..., 0] | neighbour_bits[..., 1] | neighbour_bits[..., 2] | neighbour_bits[..., 3]
    reach = np.broadcast_to(goal_bits, open_cells.shape)
    touching = np.zeros(reach.shape, dtype=bool)
    first_touch = reach  # the first layer that touches the start's neighbourhood (the goal's where none does)
    for _ in range(cellbits.cells):
        touched = (reach & around) != cellbits.zero
        first_touch = np.where(touched & ~touching, reach, first_touch)
        touching |= touched
        grown = reach | (cellbits.expand(reach) & open_cells)
        if (touching | (grown == reach)).all():
            break  # every search touches its start's neighbourhood or cannot grow any more
        reach = grown
    return cellbits.has(first_touch[..., None], neighbour_bits).astype(np.int64) @ MOVE_WEIGHTS


TABLE_MIN_BATCH = 8  # smaller batches (the single envs) search; larger ones build and use a MoveTable
TABLE_MAX_ENTRIES = 12_000_000  # (blocked sets x goals x starts) bytes a MoveTable may take


class MoveTable:
    """``codes[set, goal, start]``: the 4-bit code of :func:`best_moves` from ``start`` to ``goal`` around every
    blocked set of at most ``max_blocked`` cells (sets sorted by bitset, found by binary search)."""

    def __init__(self, cellbits: CellBits, max_blocked: int) -> None:
        cells = cellbits.cells
        sets = [c for k in range(max_blocked + 1) for c in itertools.combinations(range(cells), k)]
        self.keys = np.sort(np.array([sum(1 << i for i in c) for c in sets], dtype=np.uint64))
        goal_bits = cellbits.bit[:cells]
        open_cells = (cellbits.full ^ self.keys)[:, None]  # (sets, 1)
        reach = np.broadcast_to(goal_bits, (len(self.keys), cells)).copy()  # (sets, goals)
        # distance[set, goal, cell]: search layers from the goal to the cell (cells: never reached)
        distance = np.full((len(self.keys), cells, cells + 1), cells, dtype=np.uint8)
        for layer in range(cells):
            inside = (reach[..., None] & goal_bits) != cellbits.zero  # (sets, goals, cells)
            distance[..., :cells] = np.where(
                inside & (distance[..., :cells] == cells), layer, distance[..., :cells]
            )
            grown = reach | (cellbits.expand(reach) & open_cells)
            if (grown == reach).all():
                break
            reach = grown
        around = distance[
            :, :, cellbits.neighbours
        ]  # (sets, goals, starts, 4); a wall reads column -1: never
        nearest = around.min(axis=-1, keepdims=True)
        best = (around == nearest) & (nearest < cells)
        self.codes = best.astype(np.uint8) @ MOVE_WEIGHTS.astype(np.uint8)  # 4-bit codes as bytes

    @staticmethod
    def fits(cellbits: CellBits, max_blocked: int) -> bool:
        if cellbits.dtype is not np.uint64:
            return False
        sets = sum(math.comb(cellbits.cells, k) for k in range(max_blocked + 1))
        return sets * cellbits.cells**2 <= TABLE_MAX_ENTRIES

    def lookup(self, start: np.ndarray, goal: np.ndarray, blocked: np.ndarray) -> np.ndarray | None:
        """Codes of the moves from ``start`` to ``goal`` (flat cells) around ``blocked`` (bitsets); None if
        some blocked set is not in the table."""
        index = np.minimum(np.searchsorted(self.keys, blocked), len(self.keys) - 1)
        if not (self.keys[index] == blocked).all():
            return None
        return self.codes[index, goal, start].astype(np.int64)


_MOVE_TABLES: dict = {}


def move_table(cellbits: CellBits, max_blocked: int) -> MoveTable | None:
    """The (cached, per grid shape and wrap) :class:`MoveTable`, or None where it would be too large."""
    cfg = cellbits.rules.config
    key = (cfg.rows, cfg.cols, cfg.toroidal, max_blocked)
    if key not in _MOVE_TABLES:
        _MOVE_TABLES[key] = (
            MoveTable(cellbits, max_blocked) if MoveTable.fits(cellbits, max_blocked) else None
        )
    return _MOVE_TABLES[key]


def first_moves(cellbits: CellBits, start: np.ndarray, goal: np.ndarray, blocked: np.ndarray) -> np.ndarray:
    """:func:`best_moves` from flat cells ``start`` to ``goal`` (B, N) around each of ``blocked`` (K, B, N)
    bitsets, (K, B, N): looked up in the grid's :class:`MoveTable` for batches of at least
    ``TABLE_MIN_BATCH`` envs where it fits, else searched."""
    if len(start) >= TABLE_MIN_BATCH:
        cfg = cellbits.rules.config
        table = move_table(cellbits, cfg.n_agents - 1 + cfg.n_targets)
        codes = None if table is None else table.lookup(start, goal, blocked)
        if codes is not None:
            return codes
    return best_moves(cellbits, cellbits.neighbour_bits[start], cellbits.of(goal), blocked)


def navigate(
    cellbits: CellBits,
    start: np.ndarray,
    goal: np.ndarray,
    static: np.ndarray,
    obstacles: np.ndarray,
    free: np.ndarray,
    greedy_axis: np.ndarray,
    uniforms: np.ndarray,
    unstick: float = 0.25,
) -> np.ndarray:
    """(B, N) first move of a shortest path from each member's flat cell ``start`` to its flat ``goal``
    (INTERACT once there) around the live targets (bitsets ``static``, (B,)) and the teammates in ``obstacles``
    (bitsets, (B, N)). If those wall the goal off, the path around targets only. A member waits while its next
    cell is taken (``free``: (B,) bitsets of empty cells), except that with probability ``unstick`` it steps to
    a random free cell instead. Ties between equally short moves go uniformly at random, or, where
    ``greedy_axis`` (B,), 4 times in 5 to the axis with the larger gap to the goal, rows first: the greedy
    walker's habit (always doing so lets two greedy members mirror each other forever). ``uniforms`` (B, N, 3)
    in [0, 1): axis habit, choice among moves, unstick."""
    goal_bits = cellbits.of(goal)
    neighbour_bits = cellbits.neighbour_bits[start]  # (B, N, 4), empty at walls
    static = static[:, None]
    # a teammate standing on the goal may still leave it; a live target on it may not
    blocked = (static | obstacles) & (cellbits.full ^ goal_bits) | (static & goal_bits)
    fields = first_moves(cellbits, start, goal, np.stack([blocked, np.broadcast_to(static, blocked.shape)]))
    open_step = cellbits.has(free[:, None, None], neighbour_bits).astype(np.int64) @ MOVE_WEIGHTS
    moves = np.where(fields[0] > 0, fields[0], fields[1]) & open_step
    count = MOVE_COUNT[moves]
    pick = uniforms[..., 1]
    action = NTH_MOVE[open_step, np.minimum((pick * MOVE_COUNT[open_step]).astype(np.int64), 3)]
    action = np.where(uniforms[..., 2] < unstick, action, INTERACT)
    action = np.where(count > 0, NTH_MOVE[moves, np.minimum((pick * count).astype(np.int64), 3)], action)
    habit = (count > 1) & greedy_axis[:, None] & (uniforms[..., 0] < 0.8)
    action = np.where(habit, AXIS_MOVE[moves, cellbits.axis_preference[start, goal]], action)
    return np.where(start == goal, INTERACT, action)


def permutations_table(n: int) -> np.ndarray:
    """All orderings of ``range(n)`` in lexicographic order, (n!, n)."""
    return np.array(list(itertools.permutations(range(n))), dtype=np.int64)


def assign_slots(cost: np.ndarray, orders: np.ndarray) -> np.ndarray:
    """Slot index per agent minimising the team's summed distance, ties to the lexicographically first
    assignment: ``cost`` (B, member, agent, slot) the distances from each agent to the slots of each member's
    own target, ``orders`` the permutations (:func:`permutations_table`); result (B, N)."""
    n = cost.shape[2]
    totals = cost[:, :, np.arange(n)[None, :], orders].sum(axis=-1)  # (B, member, n!)
    best = np.argmin(totals, axis=-1)
    return orders[best, np.arange(n)[None, :]]


def ring_goal(
    rules: GridRules, agents: np.ndarray, targets: np.ndarray, offsets: np.ndarray, radius: int = 2
) -> np.ndarray:
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
