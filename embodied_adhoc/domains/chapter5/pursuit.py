"""Two-predator pursuit under partial observability (section 5.2.5, Fig. 5.6): pursuit-task, -teammate, -both.

Toroidal ``size`` x ``size`` grid. State: the teammate's and the prey's offsets from the ad hoc agent, each
``(row, column)`` in ``[-size//2, size//2]`` (626 = 25 x 25 + 1 states for 5x5, the +1 the absorbing state). No
collisions. Each step the agent, the teammate and the prey (uniformly random over the 5 actions) move at once.

Every offset sum (moves, the capture test, the teammates' targets and paths) is brought back onto the torus by
:func:`wrap_offsets`: ``wrap="modular"`` (the default, correct) or ``"original"``, the original experiment's
generator's ``toroidal_check`` (HOTSPOT platform, ``backend/environments/pursuit.py``), which maps an offset d with
``size // 2 < |d| < size`` to ``-d - size // 2`` (d < 0) or ``size // 2 - d`` (d > 0): on the 5 x 5 torus +3
becomes -1 and +4 becomes -2 instead of -2 and -1, so a teammate or prey crossing the edge lands one cell closer
than it is and the capture test accepts teammates two cells away (Fig. 7.12's ablation,
:mod:`embodied_adhoc.experiments.domains.pursuit_pairs_ablation`).

Tasks: the capture pairs of :func:`~embodied_adhoc.domains.grid_rules.pair_tasks` (N+S, W+E, SW+NE, NW+SE,
positions interchangeable). A state whose two predators sit on the task's two cells around the prey is a goal
state: +100 in the step taken from it, then the absorbing state (``library.step_rewards``).

Teammates (each a deterministic function of the state; the arenas' and chapter 4's teammates of the same
names are other policies, for other rules: :mod:`embodied_adhoc.teammates.pursuit_teams` says how they differ):

* ``greedy``: picks its closest capture cell (Manhattan on the torus, ties to the task's first cell) and steps
  along columns first, then rows, ignoring the agent;
* ``aware``: the same capture cell, reached along a shortest toroidal path that avoids the agent's cell (a
  breadth-first search, i.e. A* with a zero heuristic; first-step ties broken in the order up, down, left, right);
  uniformly random when no path exists (the agent sits on the cell), stays when there.

Observation ``z = 9 t + p``: the teammate's (t) and the prey's (p) cell in the agent's 3x3 neighbourhood
(``3 (dr + 1) + (dc + 1)``), each seen w.p. ``1 - eps``; a miss, or an agent outside the neighbourhood, reads as the
agent's own cell (4). 81 observations.
"""

from __future__ import annotations

import itertools
from collections import deque

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.domains.chapter5.library import (
    ModelLibrary,
    joint_mdp,
    reduce_joint,
    step_rewards,
    task_pomdp,
)
from embodied_adhoc.domains.grid_rules import pair_tasks
from embodied_adhoc.errors import ConfigError

__all__ = [
    "PURSUIT_VARIANTS",
    "TEAMMATES",
    "WRAPS",
    "build_pursuit",
    "observation_distribution",
    "wrap_offsets",
]

ACTION_NAMES = ("up", "down", "left", "right", "stay")
DELTAS = np.array([(-1, 0), (1, 0), (0, -1), (0, 1), (0, 0)])  # (row, column) per action
TEAMMATES = ("greedy", "aware")
WRAPS = ("modular", "original")
PURSUIT_VARIANTS = {  # Table 5.2: (models as (teammate, task index)), eps, horizon h, Perseus beliefs
    "pursuit-task": ([("greedy", k) for k in range(4)], 0.20, 75, 5000),
    "pursuit-teammate": ([("greedy", 0), ("aware", 0)], 0.15, 85, 5000),
    "pursuit-both": ([(t, k) for t in TEAMMATES for k in range(4)], 0.15, 85, 5000),
}


def wrap_offsets(values: np.ndarray, size: int, wrap: str = "modular") -> np.ndarray:
    """Offsets on a ``size`` torus brought back to the centred range: ``"modular"`` (correct) to
    ``[-(size // 2), size - size // 2 - 1]``; ``"original"``, the original generator's ``toroidal_check`` (see the
    module docstring), to ``[-(size // 2), size // 2]``, for ``|d| <= size``."""
    d = np.asarray(values, dtype=np.int64)
    half = size // 2
    if wrap == "modular":
        return (d + half) % size - half
    if wrap != "original":
        raise ConfigError(f"wrap={wrap!r}: choose from {', '.join(WRAPS)}")
    far = np.abs(d) > half
    wrapped = np.where(far, np.where(d < 0, -d - half, half - d), d)
    if size % 2 == 0:
        wrapped = np.where((d < 0) & (np.abs(d) == half), half, wrapped)
    return np.where(np.abs(d) == size, 0, wrapped)


def _greedy_step(target: np.ndarray) -> np.ndarray:
    """Columns first, then rows; stay when there. ``target`` (N, 2) offsets from the mover."""
    d_row, d_col = target[:, 0], target[:, 1]
    return np.select([d_col > 0, d_col < 0, d_row > 0, d_row < 0], [3, 2, 1, 0], default=4)


def _closest_capture(teammate: np.ndarray, prey: np.ndarray, task, size: int, wrap: str) -> np.ndarray:
    """The capture cell closest to the teammate, as an offset from the teammate (N, 2)."""
    first, second = (np.array(offset) for offset in task.offsets)
    prey_from_mate = wrap_offsets(prey - teammate, size, wrap)
    cell_a = wrap_offsets(prey_from_mate + first, size, wrap)
    cell_b = wrap_offsets(prey_from_mate + second, size, wrap)
    closer_b = np.abs(cell_b).sum(axis=1) < np.abs(cell_a).sum(axis=1)
    return np.where(closer_b[:, None], cell_b, cell_a)


def _aware_policy(teammate: np.ndarray, target: np.ndarray, size: int, wrap: str) -> np.ndarray:
    """(N, 5) policy of the teammate-aware predator; see the module docstring."""
    policy = np.zeros((len(teammate), 5))
    cache: dict[tuple, int | None] = {}
    for k, (obstacle, goal) in enumerate(zip(map(tuple, -teammate), map(tuple, target), strict=True)):
        key = (obstacle, goal)
        if key not in cache:
            cache[key] = _first_step(obstacle, goal, size, wrap)
        step = cache[key]
        if step is None:
            policy[k] = 1.0 / 5
        else:
            policy[k, step] = 1.0
    return policy


def _first_step(obstacle: tuple, goal: tuple, size: int, wrap: str = "modular") -> int | None:
    """First action of a shortest toroidal path from (0, 0) to ``goal`` avoiding ``obstacle``; 4 when there."""
    if goal == (0, 0):
        return 4
    if goal == obstacle:
        return None
    start = (0, 0)
    first: dict[tuple, int] = {start: -1}
    queue = deque([start])
    while queue:
        cell = queue.popleft()
        for action, (dr, dc) in enumerate(DELTAS[:4]):
            nxt = tuple(int(v) for v in wrap_offsets(np.array([cell[0] + dr, cell[1] + dc]), size, wrap))
            if nxt == obstacle or nxt in first:
                continue
            first[nxt] = action if cell == start else first[cell]
            if nxt == goal:
                return first[nxt]
            queue.append(nxt)
    return None


def build_pursuit(
    variant: str = "pursuit-task",
    size: int = 5,
    noise: float | None = None,
    horizon: int | None = None,
    n_beliefs: int | None = None,
    wrap: str = "modular",
) -> ModelLibrary:
    """The library of one pursuit variant (``pursuit-task``, ``pursuit-teammate``, ``pursuit-both``); ``wrap``:
    :func:`wrap_offsets`'s ``"modular"`` torus or the original generator's (``"original"``, odd sizes only: its
    range ``[-(size // 2), size // 2]`` is the state layout's only then)."""
    if variant not in PURSUIT_VARIANTS:
        raise ConfigError(f"unknown pursuit variant {variant!r}; choose from {', '.join(PURSUIT_VARIANTS)}")
    if size < 3:
        raise ConfigError(f"pursuit size must be >= 3 (a 3x3 neighbourhood), got {size}")
    if wrap not in WRAPS:
        raise ConfigError(f"pursuit wrap={wrap!r}: choose from {', '.join(WRAPS)}")
    if wrap == "original" and size % 2 == 0:
        raise ConfigError(f"pursuit wrap='original' needs an odd size (got {size}); use wrap='modular'")
    models, default_noise, default_horizon, default_beliefs = PURSUIT_VARIANTS[variant]
    noise = default_noise if noise is None else float(noise)
    horizon = default_horizon if horizon is None else int(horizon)
    n_beliefs = default_beliefs if n_beliefs is None else int(n_beliefs)
    offsets = np.array(list(itertools.product(range(size), repeat=2))) - size // 2
    offsets = wrap_offsets(offsets, size, wrap)
    n_offsets = len(offsets)
    mate_index, prey_index = np.divmod(np.arange(n_offsets * n_offsets), n_offsets)
    teammate, prey = offsets[mate_index], offsets[prey_index]
    n_live = len(teammate)
    absorbing, n_states = n_live, n_live + 1

    def index_of(cells: np.ndarray) -> np.ndarray:
        shifted = cells + size // 2
        return shifted[:, 0] * size + shifted[:, 1]

    observations = _observations(teammate, prey, noise)
    names = tuple(f"t{r}_{c}-p{pr}_{pc}" for (r, c), (pr, pc) in zip(teammate, prey, strict=True)) + (
        "absorbing",
    )
    z_names = tuple(f"t{t}p{p}" for t in range(9) for p in range(9))
    tasks = pair_tasks()
    pomdps, mmdps, task_names = [], [], []
    for teammate_name, task_index in models:
        task = tasks[task_index]
        goal = np.append(_captured(teammate, prey, task, size, wrap), False)
        rewards = step_rewards(goal, absorbing, 5)
        joint = _joint(teammate, prey, goal, absorbing, n_states, size, wrap, index_of)
        transitions = reduce_joint(joint, _teammate_policy(teammate_name, teammate, prey, task, size, wrap))
        start = ~goal
        start[absorbing] = False
        pomdps.append(task_pomdp(transitions, rewards, observations, start, names, ACTION_NAMES, z_names))
        mmdps.append(joint_mdp(joint, rewards, ACTION_NAMES))
        task_names.append(f"{teammate_name}:{task.name.split(':')[1]}")
    settings = {"variant": variant, "size": size, "noise": noise, "wrap": wrap}

    def named(name: str):  # --teammate NAME: that predator in model m's capture configuration
        return lambda m: _teammate_policy(name, teammate, prey, tasks[models[m][1]], size, wrap)

    description = (
        f"{variant}: toroidal {size}x{size} pursuit, 2 predators, capture pairs, greedy/aware teammates"
        + ("" if wrap == "modular" else ", the original generator's torus wrap")
    )
    return ModelLibrary(
        variant,
        tuple(task_names),
        tuple(pomdps),
        tuple(mmdps),
        horizon,
        noise,
        n_beliefs,
        absorbing,
        description,
        settings,
        teammates={name: named(name) for name in TEAMMATES},
    )


def _teammate_policy(
    name: str, teammate: np.ndarray, prey: np.ndarray, task, size: int, wrap: str
) -> np.ndarray:
    """``pi(b | x)`` (S x 5) of the ``greedy`` or (teammate-)``aware`` predator heading for ``task``'s capture
    cell closest to it (the absorbing state's row: stay)."""
    target = _closest_capture(teammate, prey, task, size, wrap)
    if name == "greedy":
        policy = np.zeros((len(teammate), 5))
        policy[np.arange(len(teammate)), _greedy_step(target)] = 1.0
    else:
        policy = _aware_policy(teammate, target, size, wrap)
    return np.vstack([policy, np.eye(5)[4]])


def _captured(teammate: np.ndarray, prey: np.ndarray, task, size: int, wrap: str) -> np.ndarray:
    """Goal states: {agent, teammate} offsets from the prey equal the task's two cells, either way round."""
    first, second = (np.array(offset) for offset in task.offsets)
    agent_from_prey = wrap_offsets(-prey, size, wrap)
    mate_from_prey = wrap_offsets(teammate - prey, size, wrap)
    straight = (agent_from_prey == first).all(axis=1) & (mate_from_prey == second).all(axis=1)
    crossed = (agent_from_prey == second).all(axis=1) & (mate_from_prey == first).all(axis=1)
    return straight | crossed


def _joint(teammate, prey, goal, absorbing, n_states, size, wrap, index_of) -> list[list[sp.csr_matrix]]:
    """``P(. | ., a, b)`` with the prey's uniformly random move averaged in."""
    live = ~goal[:-1]
    terminal = np.append(np.flatnonzero(~live), absorbing)
    live_rows = np.flatnonzero(live)
    joint = []
    for a in range(5):
        row = []
        for b in range(5):
            mate_next = index_of(wrap_offsets(teammate + DELTAS[b] - DELTAS[a], size, wrap))
            rows, cols, probs = [terminal], [np.full(len(terminal), absorbing)], [np.ones(len(terminal))]
            for move in range(5):
                prey_next = index_of(wrap_offsets(prey + DELTAS[move] - DELTAS[a], size, wrap))
                rows.append(live_rows)
                cols.append((mate_next * size * size + prey_next)[live])
                probs.append(np.full(len(live_rows), 1.0 / 5))
            row.append(
                sp.csr_matrix(
                    (np.concatenate(probs), (np.concatenate(rows), np.concatenate(cols))),
                    shape=(n_states, n_states),
                )
            )
        joint.append(row)
    return joint


def observation_distribution(teammate: np.ndarray, prey: np.ndarray, noise: float) -> np.ndarray:
    """``P(z | offsets)``, (N, 81), of the observation of section 5.2.5 (the module docstring): the teammate's and
    the prey's (row, column) offsets from the agent, each seen in its cell of the agent's 3x3 neighbourhood with
    probability ``1 - noise``; a miss, or an offset outside the neighbourhood, reads 4. The library's ``O`` and the
    arenas' ``info["observation_index"]`` both come from here."""

    def cell_distribution(offsets: np.ndarray) -> np.ndarray:
        offsets = np.asarray(offsets).reshape(-1, 2)
        distribution = np.zeros((len(offsets), 9))
        visible = (np.abs(offsets) <= 1).all(axis=1) & (np.abs(offsets).sum(axis=1) > 0)
        cell = 3 * (offsets[:, 0] + 1) + offsets[:, 1] + 1
        rows = np.flatnonzero(visible)
        distribution[rows, cell[visible]] = 1.0 - noise
        distribution[rows, 4] += noise
        distribution[np.flatnonzero(~visible), 4] = 1.0
        return distribution

    mate, seen_prey = cell_distribution(teammate), cell_distribution(prey)
    return np.einsum("st,sp->stp", mate, seen_prey).reshape(len(mate), 81)


def _observations(teammate: np.ndarray, prey: np.ndarray, noise: float) -> sp.csr_matrix:
    absorbing = np.zeros((1, 81))
    absorbing[0, 9 * 4 + 4] = 1.0  # nothing seen
    return sp.csr_matrix(np.vstack([observation_distribution(teammate, prey, noise), absorbing]))
