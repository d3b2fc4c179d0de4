"""Map files of the chapter-5 navigation domains (ntu, isr, mit, pentagon, cit; Melo & Veloso 2009, Fig. 5.7).

Format: one text line per grid row, one character per cell: ``#`` blocked, ``.`` open, ``S`` open start cell,
``G`` open goal cell. Lines must all have the same length. The five maps of the thesis ship in ``assets/maps/``
(resolved through :mod:`embodied_adhoc.paths`); :func:`load_map` accepts any file in that format and refuses a bad
one with :class:`~embodied_adhoc.errors.ConfigError` naming ``file:line:column`` (bad character), the goal that
no start reaches, or what is missing for two agents. A file is read up to :data:`MAX_MAP_CHARS` and a grid holds at
most :data:`MAX_MAP_CELLS` cells (rows x columns); domains whose state count grows faster than the cell count set
their own, lower limit on open cells.

Cells are numbered column-major (column, then row), as the original implementation enumerated them, so that
task indices (pairs of goal cells in ``itertools.combinations`` order) match the thesis's.
"""

from __future__ import annotations

import itertools
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from embodied_adhoc import checks
from embodied_adhoc.errors import ConfigError

__all__ = ["BUILTIN_MAPS", "MAX_MAP_CHARS", "MAX_MAP_CELLS", "GridMap", "load_map", "parse_map"]

BUILTIN_MAPS = ("ntu", "isr", "mit", "pentagon", "cit")
MAX_MAP_CHARS = 1 << 20
MAX_MAP_CELLS = 10_000
BLOCKED, OPEN, START, GOAL = "#", ".", "S", "G"
UP, DOWN, LEFT, RIGHT, STAY = range(5)
ACTION_NAMES = ("up", "down", "left", "right", "stay")
_DELTAS = ((-1, 0), (1, 0), (0, -1), (0, 1), (0, 0))  # (row, column) per action


@dataclass(frozen=True, eq=False)
class GridMap:
    """An open-cell graph: ``cells`` (n, 2) as (row, column), column-major; ``moves`` (n, 5) next cell per action
    (the same cell when the move hits a wall or the border); ``starts`` and ``goals`` are cell indices."""

    name: str
    shape: tuple[int, int]
    cells: np.ndarray
    moves: np.ndarray
    starts: tuple[int, ...]
    goals: tuple[int, ...]

    @property
    def n_cells(self) -> int:
        return len(self.cells)

    def goal_pairs(self) -> tuple[tuple[int, int], ...]:
        """Every pair of goal cells, in the original's order: the candidate tasks."""
        return tuple(itertools.combinations(self.goals, 2))

    def cell_name(self, cell: int) -> str:
        row, column = self.cells[cell]
        return f"r{row}c{column}"

    @classmethod
    def from_grid(cls, name: str, is_open: np.ndarray, starts: set, goals: set) -> GridMap:
        """Build the cell graph of a boolean ``is_open`` grid; ``starts``/``goals`` are sets of (row, column)."""
        rows, columns = is_open.shape
        order = [(r, c) for c in range(columns) for r in range(rows) if is_open[r, c]]
        index = {cell: k for k, cell in enumerate(order)}
        moves = np.empty((len(order), len(_DELTAS)), dtype=np.int64)
        for k, (r, c) in enumerate(order):
            for a, (dr, dc) in enumerate(_DELTAS):
                moves[k, a] = index.get((r + dr, c + dc), k)
        return cls(
            name,
            (rows, columns),
            np.array(order, dtype=np.int64).reshape(-1, 2),
            moves,
            tuple(index[cell] for cell in order if cell in starts),
            tuple(index[cell] for cell in order if cell in goals),
        )


def parse_map(text: str, source: str = "<map>") -> GridMap:
    """Parse map text; ConfigError naming ``source:line:column`` or the missing element; see the module docstring."""
    lines = [line.rstrip("\r") for line in text.split("\n")]
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        raise ConfigError(f"{source}: the map is empty; write one row per line with '#', '.', 'S', 'G'")
    width = max(len(line) for line in lines)
    if len(lines) * width > MAX_MAP_CELLS:
        raise ConfigError(
            f"{source}: {len(lines)} rows x {width} columns = {len(lines) * width:,} cells, more than the limit of "
            f"{MAX_MAP_CELLS:,}; draw a smaller map"
        )
    is_open = np.zeros((len(lines), width), dtype=bool)
    starts, goals = set(), set()
    for row, line in enumerate(lines):
        for column, char in enumerate(line):
            if char not in (BLOCKED, OPEN, START, GOAL):
                raise ConfigError(
                    f"{source}:{row + 1}:{column + 1}: bad character {char!r}; use '#' blocked, '.' open, "
                    "'S' start, 'G' goal"
                )
            is_open[row, column] = char != BLOCKED
            if char == START:
                starts.add((row, column))
            elif char == GOAL:
                goals.add((row, column))
        if len(line) != len(lines[0]):
            raise ConfigError(
                f"{source}:{row + 1}: the row has {len(line)} cells, the first row {len(lines[0])}; every row must "
                "be equally long (pad with '#')"
            )
    if int(is_open.sum()) < 2 or len(starts) < 2 or len(goals) < 2:
        raise ConfigError(
            f"{source}: too small for two agents: {int(is_open.sum())} open cell(s), {len(starts)} start cell(s) "
            f"'S', {len(goals)} goal cell(s) 'G'; two agents need at least 2 of each"
        )
    _check_reachable(is_open, starts, goals, source)
    return GridMap.from_grid(Path(source).stem, is_open, starts, goals)


def _check_reachable(is_open: np.ndarray, starts: set, goals: set, source: str) -> None:
    rows, columns = is_open.shape
    reached = set(starts)
    queue = deque(starts)
    while queue:
        r, c = queue.popleft()
        for dr, dc in _DELTAS[:4]:
            cell = (r + dr, c + dc)
            if 0 <= cell[0] < rows and 0 <= cell[1] < columns and is_open[cell] and cell not in reached:
                reached.add(cell)
                queue.append(cell)
    for r, c in sorted(goals):
        if (r, c) not in reached:
            raise ConfigError(
                f"{source}:{r + 1}:{c + 1}: goal 'G' is unreachable from every start cell 'S'; open a path to it "
                "or remove it"
            )


def load_map(name_or_path: str | Path) -> GridMap:
    """A built-in map by name (``ntu``, ``isr``, ``mit``, ``pentagon``, ``cit``) or any map file by path."""
    from embodied_adhoc.paths import asset

    text_name = str(name_or_path)
    if text_name in BUILTIN_MAPS:
        path = asset(f"maps/{text_name}.txt")
    else:
        path = Path(name_or_path)
        if not path.is_file():
            what = "not a regular file" if path.exists() else "no such file"
            raise ConfigError(f"--map {text_name}: {what} (built-in maps: {', '.join(BUILTIN_MAPS)})")
    grid = parse_map(checks.read_text(path, MAX_MAP_CHARS, "map file"), str(path))
    return grid if text_name not in BUILTIN_MAPS else _renamed(grid, text_name)


def _renamed(grid: GridMap, name: str) -> GridMap:
    return GridMap(name, grid.shape, grid.cells, grid.moves, grid.starts, grid.goals)


def open_grid(rows: int, columns: int) -> GridMap:
    """An obstacle-free grid (the gridworld domain); every cell is a start and a goal candidate."""
    is_open = np.ones((rows, columns), dtype=bool)
    every = {(r, c) for r in range(rows) for c in range(columns)}
    return GridMap.from_grid(f"open{rows}x{columns}", is_open, every, every)
