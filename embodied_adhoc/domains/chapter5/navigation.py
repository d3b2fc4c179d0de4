"""Two-agent navigation libraries: the gridworld domain and the map domains (section 5.2.5, Figs. 5.5 and 5.7).

State ``x = (agent cell, teammate cell)`` plus one absorbing state (index ``n_states - 1``). Actions up, down,
left, right, stay; a move into a wall or the border leaves the agent in place. A task is a pair of goal cells; a
state with the two agents on the two cells (either way round) is a goal state: reward +100 in the step taken from
it, then the absorbing state (reward 0); -1 in every other step (``library.step_rewards``).

Observation (both kinds of domain): four directional sensors (up, down, left, right), each reading nothing /
wall / teammate; a wall or the teammate next to the agent is read correctly w.p. ``1 - eps`` and as each of the two
other readings w.p. ``eps / 2``; an empty direction always reads nothing. The agent never observes its own cell.
``z = 27 u + 9 d + 3 l + r`` (81 observations); the absorbing state reads nothing everywhere.

*gridworld* (open 5x5, 626 = 25^2 + 1 states: the agents may share a cell): each move succeeds w.p. ``1 - eps``,
else the agent stays (the ad hoc agent and the teammate alike); the teammate walks to its closest goal cell
(Manhattan, ties to the first) along columns first, then rows. Tasks: pairs of cells drawn once with a seeded
generator (``task_seed``). Initial belief: uniform over non-goal states.

*maps* (n open cells, n(n-1)+1 states: no shared cell): moves are deterministic; the teammate moves first and
stays if its target is the agent's cell; the agent then stays if its target is the teammate's new cell. The
teammate knows the task and acts optimally (``library.optimal_teammate_policy`` on the MMDP). Initial belief:
uniform over both agents on distinct start cells 'S'.

The original's goal-layout bug (``bug_compatible=True``): it kept as goal every 'G' cell sharing a row or a column
with a task cell (``and`` where ``or`` was meant), and a state was a goal when both agents stood on any two kept
goal cells. On ntu every task then kept all four goals (the four tasks were identical) and on mit two tasks were
identical. The fix: the goal states are exactly the task's two cells.
"""

from __future__ import annotations

import itertools

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.domains.chapter5.grid_maps import ACTION_NAMES, STAY, GridMap, load_map, open_grid
from embodied_adhoc.domains.chapter5.library import (
    ModelLibrary,
    deterministic_matrix,
    joint_mdp,
    optimal_teammate_policy,
    reduce_joint,
    step_rewards,
    task_pomdp,
)
from embodied_adhoc.errors import ConfigError

__all__ = [
    "MAP_SETTINGS",
    "MAX_MODELS",
    "MAX_OPEN_CELLS",
    "build_gridworld",
    "build_map_library",
    "four_sensor_observations",
]

NOTHING, WALL, TEAMMATE = range(3)
N_OBSERVATIONS = 81

MAP_SETTINGS = {  # Table 5.2: (eps, horizon h, Perseus beliefs, library size |M|)
    "ntu": (0.20, 75, 5000, 4),
    "isr": (0.20, 75, 5000, 3),
    "mit": (0.20, 75, 5000, 3),
    "pentagon": (0.20, 75, 5000, 3),
    "cit": (0.10, 85, 8000, 3),
}
DEFAULT_MAP_SETTINGS = (0.20, 75, 5000, None)  # a user's map: every goal pair is a task
MAX_OPEN_CELLS = 150
"""A map domain has n(n-1)+1 states for n open cells, each task a POMDP over them: 150 cells give 22,351 states
(cit, the largest built-in map, has 70 cells and 4,831 states)."""
MAX_MODELS = 45
"""At most this many tasks (goal pairs) per library: 10 goal cells' pairs."""


def _observation_names() -> tuple[str, ...]:
    letters = "nwt"
    readings = itertools.product(letters, repeat=4)  # up, down, left, right
    return tuple(f"u{up}d{down}l{left}r{right}" for up, down, left, right in readings)


def four_sensor_observations(
    grid: GridMap, agent: np.ndarray, teammate: np.ndarray, noise: float
) -> sp.csr_matrix:
    """``O(z | y)`` (S x 81) for states ``(agent[y], teammate[y])``; rows with ``agent < 0`` are the absorbing state."""
    live = agent >= 0
    cell = np.where(live, agent, 0)
    per_direction = np.zeros((len(agent), 4, 3))
    per_direction[:, :, NOTHING] = 1.0
    for direction in range(4):  # up, down, left, right: the action index of the same move
        neighbour = grid.moves[cell, direction]
        wall = live & (neighbour == cell)
        mate = live & ~wall & (neighbour == teammate)
        per_direction[wall, direction] = (noise / 2, 1.0 - noise, noise / 2)
        per_direction[mate, direction] = (noise / 2, noise / 2, 1.0 - noise)
    joint = np.einsum("su,sd,sl,sr->sudlr", *(per_direction[:, d] for d in range(4)))
    return sp.csr_matrix(joint.reshape(len(agent), N_OBSERVATIONS))


def pair_states(n_cells: int, shared_cells: bool) -> tuple[np.ndarray, np.ndarray]:
    agent, teammate = np.divmod(np.arange(n_cells * n_cells), n_cells)
    if not shared_cells:
        keep = agent != teammate
        agent, teammate = agent[keep], teammate[keep]
    return agent, teammate


def state_table(n_cells: int, agent: np.ndarray, teammate: np.ndarray) -> np.ndarray:
    table = np.full((n_cells, n_cells), -1, dtype=np.int64)
    table[agent, teammate] = np.arange(len(agent))
    return table


def goal_mask(
    agent: np.ndarray, teammate: np.ndarray, goal_cells: tuple[int, ...], pair: tuple[int, int] | None
) -> np.ndarray:
    """Goal states: both agents on the task's two cells (``pair``), or (bug) on any two distinct ``goal_cells``."""
    if pair is not None:
        a, b = pair
        return ((agent == a) & (teammate == b)) | ((agent == b) & (teammate == a))
    on_goal = np.isin(agent, goal_cells) & np.isin(teammate, goal_cells)
    return on_goal & (agent != teammate)


def _buggy_goal_cells(grid: GridMap, pair: tuple[int, int]) -> tuple[int, ...]:
    """The original's ``layout_for_goal``: a 'G' cell stayed a goal unless its row and column both differed from
    both task cells' (``x != ga_x and y != ga_y and x != gb_x and y != gb_y``)."""
    (ra, ca), (rb, cb) = grid.cells[pair[0]], grid.cells[pair[1]]
    kept = []
    for g in grid.goals:
        r, c = grid.cells[g]
        cleared = c != ca and r != ra and c != cb and r != rb
        if not cleared:
            kept.append(g)
    return tuple(kept)


def _library(
    domain: str,
    grid: GridMap,
    pairs: list[tuple[int, int]],
    noise: float,
    horizon: int,
    n_beliefs: int,
    shared_cells: bool,
    bug_compatible: bool,
    description: str,
    settings: dict,
) -> ModelLibrary:
    n = grid.n_cells
    agent, teammate = pair_states(n, shared_cells)
    n_live = len(agent)
    absorbing = n_live
    table = state_table(n, agent, teammate)
    agent_all = np.append(agent, -1)
    teammate_all = np.append(teammate, -1)
    observations = four_sensor_observations(grid, agent_all, teammate_all, noise)
    state_names = tuple(
        f"a{grid.cell_name(i)}-t{grid.cell_name(j)}" for i, j in zip(agent, teammate, strict=True)
    )
    state_names += ("absorbing",)
    z_names = _observation_names()
    pomdps, mmdps, names = [], [], []
    for pair in pairs:
        goal_cells = _buggy_goal_cells(grid, pair) if bug_compatible else grid.goals
        goal = np.append(goal_mask(agent, teammate, goal_cells, None if bug_compatible else pair), False)
        rewards = step_rewards(goal, absorbing, len(ACTION_NAMES))
        if shared_cells:
            joint = independent_moves_joint(grid, agent, teammate, table, goal, noise)
        else:
            joint = _colliding_joint(grid, agent, teammate, table, goal)
        mmdp = joint_mdp(joint, rewards, ACTION_NAMES)
        if shared_cells:  # gridworld: the teammate walks greedily to its closest goal cell
            policy = _greedy_policy(grid, teammate_all, pair)
        else:
            policy = optimal_teammate_policy(mmdp, len(ACTION_NAMES))
        transitions = reduce_joint(joint, policy)
        start = ~goal.copy()
        start[absorbing] = False
        if not shared_cells:
            start[:n_live] &= np.isin(agent, grid.starts) & np.isin(teammate, grid.starts)
        pomdps.append(
            task_pomdp(transitions, rewards, observations, start, state_names, ACTION_NAMES, z_names)
        )
        mmdps.append(mmdp)
        names.append(f"{grid.cell_name(pair[0])}+{grid.cell_name(pair[1])}")
    teammates = {}
    if shared_cells:  # --teammate greedy on gridworld (its own); maps' teammate is the MMDP's optimal one
        teammates["greedy"] = lambda m: _greedy_policy(grid, teammate_all, pairs[m])
    return ModelLibrary(
        domain,
        tuple(names),
        tuple(pomdps),
        tuple(mmdps),
        horizon,
        noise,
        n_beliefs,
        absorbing,
        description,
        settings,
        teammates=teammates,
    )


def _finish(next_states: np.ndarray, goal: np.ndarray, absorbing: int) -> np.ndarray:
    """Goal states and the absorbing state lead to the absorbing state whatever the actions."""
    result = np.append(next_states, absorbing)
    result[goal] = absorbing
    return result


def _colliding_joint(grid: GridMap, agent, teammate, table, goal) -> list[list[sp.csr_matrix]]:
    n_states, absorbing = len(agent) + 1, len(agent)
    joint = []
    for a in range(len(ACTION_NAMES)):
        row = []
        agent_target = grid.moves[agent, a]
        for b in range(len(ACTION_NAMES)):
            mate_next = grid.moves[teammate, b]
            mate_next = np.where(mate_next == agent, teammate, mate_next)  # the teammate moves first
            agent_next = np.where(agent_target == mate_next, agent, agent_target)
            row.append(deterministic_matrix(_finish(table[agent_next, mate_next], goal, absorbing), n_states))
        joint.append(row)
    return joint


def independent_moves_joint(
    grid: GridMap, agent, teammate, table, goal, noise: float
) -> list[list[sp.csr_matrix]]:
    """Independent moves, each succeeding w.p. 1 - eps (no collisions: the agents may share a cell)."""
    n_states, absorbing = len(agent) + 1, len(agent)
    live = ~goal[:-1]
    terminal = np.append(np.flatnonzero(~live), absorbing)
    joint = []
    for a in range(len(ACTION_NAMES)):
        row = []
        for b in range(len(ACTION_NAMES)):
            rows, cols, probs = [terminal], [np.full(len(terminal), absorbing)], [np.ones(len(terminal))]
            for agent_cell, p_agent in _move_outcomes(grid, agent, a, noise):
                for mate_cell, p_mate in _move_outcomes(grid, teammate, b, noise):
                    p = p_agent * p_mate
                    keep = live & (p > 0.0)
                    rows.append(np.flatnonzero(keep))
                    cols.append(table[agent_cell[keep], mate_cell[keep]])
                    probs.append(p[keep])
            row.append(  # duplicate (row, column) entries are summed
                sp.csr_matrix(
                    (np.concatenate(probs), (np.concatenate(rows), np.concatenate(cols))),
                    shape=(n_states, n_states),
                )
            )
        joint.append(row)
    return joint


def _move_outcomes(
    grid: GridMap, cells: np.ndarray, action: int, noise: float
) -> list[tuple[np.ndarray, np.ndarray]]:
    """[(next cell per state, probability per state)]: the move w.p. 1 - eps, staying w.p. eps (1 if blocked)."""
    target = grid.moves[cells, action]
    moved = target != cells
    return [(target, np.where(moved, 1.0 - noise, 1.0)), (cells, np.where(moved, noise, 0.0))]


def _greedy_policy(grid: GridMap, teammate: np.ndarray, pair: tuple[int, int]) -> np.ndarray:
    """The gridworld teammate: to its closest goal cell (Manhattan, ties to the first), columns first, then rows."""
    policy = np.zeros((len(teammate), len(ACTION_NAMES)))
    live = teammate >= 0
    here = grid.cells[np.where(live, teammate, 0)]
    goals = grid.cells[list(pair)]
    distance = np.abs(here[:, None, :] - goals[None, :, :]).sum(axis=2)
    target = goals[np.argmin(distance, axis=1)]  # argmin takes the first on ties
    d_row, d_col = (target - here).T
    action = np.select(
        [d_col > 0, d_col < 0, d_row > 0, d_row < 0], [3, 2, 1, 0], default=STAY
    )  # right, left, down, up
    policy[np.arange(len(teammate)), np.where(live, action, STAY)] = 1.0
    return policy


def build_gridworld(
    n_models: int = 4,
    size: int = 5,
    noise: float = 0.20,
    horizon: int = 50,
    n_beliefs: int = 5000,
    task_seed: int = 0,
) -> ModelLibrary:
    """Table 5.2's gridworld: ``size`` x ``size``, ``n_models`` tasks (2 to 32 in Fig. 5.9, 4 in Table 5.5)."""
    if size < 2:
        raise ConfigError(f"gridworld size must be >= 2, got {size}")
    grid = open_grid(size, size)
    all_pairs = grid.goal_pairs()
    if not 1 <= n_models <= len(all_pairs):
        raise ConfigError(
            f"gridworld: {n_models} models asked; a {size}x{size} grid has 1..{len(all_pairs)} goal pairs"
        )
    # A seeded order of every goal pair, of which the library takes the first n_models: the libraries of Fig. 5.9
    # are nested (each size contains the smaller ones), so their solved policies are shared through the cache.
    order = np.random.default_rng(task_seed).permutation(len(all_pairs))
    pairs = [all_pairs[int(k)] for k in order[:n_models]]
    settings = {"n_models": n_models, "size": size, "noise": noise, "task_seed": task_seed}
    return _library(
        "gridworld",
        grid,
        pairs,
        noise,
        horizon,
        n_beliefs,
        True,
        False,
        f"gridworld {size}x{size}, 2 agents, 2 goal cells per task",
        settings,
    )


def build_map_library(
    map_name_or_path: str = "ntu",
    noise: float | None = None,
    horizon: int | None = None,
    n_beliefs: int | None = None,
    n_models: int | None = None,
    bug_compatible: bool = False,
) -> ModelLibrary:
    """A map domain (``ntu``, ``isr``, ``mit``, ``pentagon``, ``cit`` or any map file); Table 5.2's settings by
    default (a user's map: eps 0.2, h 75, 5000 beliefs, every goal pair a task)."""
    grid = load_map(map_name_or_path)
    if grid.n_cells > MAX_OPEN_CELLS:
        raise ConfigError(
            f"map {map_name_or_path}: {grid.n_cells:,} open cells give {grid.n_cells * (grid.n_cells - 1) + 1:,} "
            f"states; the map domains accept at most {MAX_OPEN_CELLS} open cells "
            f"({MAX_OPEN_CELLS * (MAX_OPEN_CELLS - 1) + 1:,} states): block cells with '#' or draw a smaller map"
        )
    default = MAP_SETTINGS.get(str(map_name_or_path), DEFAULT_MAP_SETTINGS)
    noise = default[0] if noise is None else float(noise)
    horizon = default[1] if horizon is None else int(horizon)
    n_beliefs = default[2] if n_beliefs is None else int(n_beliefs)
    pairs = list(grid.goal_pairs())
    n_models = (default[3] or len(pairs)) if n_models is None else int(n_models)
    if not 1 <= n_models <= len(pairs):
        raise ConfigError(
            f"map {grid.name}: {n_models} models asked; its {len(grid.goals)} goals give 1..{len(pairs)} pairs"
        )
    if n_models > MAX_MODELS:
        raise ConfigError(
            f"map {grid.name}: {n_models} models (goal pairs of its {len(grid.goals)} goals); at most {MAX_MODELS} "
            "are accepted: give --models K or fewer goal cells 'G'"
        )
    if not 0.0 <= noise <= 1.0:
        raise ConfigError(f"noise must lie in [0, 1], got {noise}")
    settings = {
        "map": str(map_name_or_path),
        "noise": noise,
        "n_models": n_models,
        "bug_compatible": bool(bug_compatible),
    }
    return _library(
        grid.name,
        grid,
        pairs[:n_models],
        noise,
        horizon,
        n_beliefs,
        False,
        bug_compatible,
        f"map {grid.name}: 2 agents navigate to a pair of goal cells",
        settings,
    )
