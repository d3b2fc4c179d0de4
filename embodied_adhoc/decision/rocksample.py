"""RockSample[n, k] (Smith & Simmons 2004): a large POMDP with two observations and a long information horizon.

A robot on an ``n x n`` grid (cell ``(x, y)``, ``x`` the column, east is ``x + 1``) starts at ``(0, n // 2)``;
``k`` rocks lie at distinct cells drawn from ``seed``, each good or bad with probability 1/2, independently.

* States: ``cell x 2^k`` rock qualities (index ``(y n + x) 2^k + bits``, bit ``i`` set = rock ``i`` good), then
  one absorbing exit state: ``n^2 2^k + 1`` states.
* Actions (``5 + k``): north, south, east, west, sample, check_0 .. check_(k-1). Moves are deterministic; a move
  into the north, south or west wall leaves the robot in place; east from the last column enters the exit
  (+10). ``sample`` at a good rock gives +10 and turns it bad; at a bad rock, or on a cell without a rock, -10.
  Every action in the exit state stays there with reward 0.
* Observations (2): ``good``, ``bad``. ``check_i`` reports rock ``i``'s quality correctly with probability
  ``eta = (1 + 2^(-d / d0)) / 2`` (``d`` the Euclidean distance from the robot to the rock, ``d0 = 20``); every
  other action observes ``bad`` with probability 1, which carries no information.
* Discount 0.95.

The model depends on ``(n, k, seed)`` alone; :func:`rocksample` builds it with vectorised index arithmetic, so
RockSample[7, 8] (12,545 states) takes well under a second.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.errors import ConfigError

HALF_DISTANCE = 20.0
"""``d0`` of the sensor's efficiency ``(1 + 2^(-d / d0)) / 2``, as in Smith & Simmons (2004)."""
DISCOUNT = 0.95
EXIT_REWARD, SAMPLE_GOOD, SAMPLE_BAD = 10.0, 10.0, -10.0
MOVES = ((0, 1), (0, -1), (1, 0), (-1, 0))  # north, south, east, west as (dx, dy)
MAX_STATES = 2_000_000


def rock_positions(n: int, k: int, seed: int) -> np.ndarray:
    """``(k, 2)`` distinct cells ``(x, y)`` for the rocks, drawn from ``seed``."""
    cells = np.random.default_rng(seed).choice(n * n, size=k, replace=False)
    return np.stack([cells % n, cells // n], axis=1)


def rocksample(n: int, k: int, seed: int = 0) -> POMDP:
    """RockSample[n, k] with rocks at :func:`rock_positions` (module docstring)."""
    for name, value, low in (("n", n, 1), ("k", k, 1), ("seed", seed, 0)):
        if not isinstance(value, (int, np.integer)) or value < low:
            raise ConfigError(f"rocksample: {name} must be an integer >= {low}, got {value!r}")
    if k > n * n:
        raise ConfigError(f"rocksample: k = {k} rocks do not fit on {n * n} cells; give k <= n^2")
    n_configs = 2**k
    exit_state = n * n * n_configs
    n_states = exit_state + 1
    if n_states > MAX_STATES:
        raise ConfigError(f"rocksample: {n_states:,} states exceed {MAX_STATES:,}; give a smaller n or k")
    rocks = rock_positions(n, k, seed)
    grid = np.arange(exit_state)
    cell, bits = grid // n_configs, grid % n_configs
    x, y = cell % n, cell // n
    rock_at = np.full(n * n, -1)
    rock_at[rocks[:, 1] * n + rocks[:, 0]] = np.arange(k)
    n_actions = 5 + k
    rewards = np.zeros((n_states, n_actions))
    next_states = []
    for action, (dx, dy) in enumerate(MOVES):
        nx, ny = np.clip(x + dx, 0, n - 1), np.clip(y + dy, 0, n - 1)
        target = (ny * n + nx) * n_configs + bits
        if dx == 1:
            leaves = x == n - 1
            target = np.where(leaves, exit_state, target)
            rewards[:exit_state, action] = np.where(leaves, EXIT_REWARD, 0.0)
        next_states.append(target)
    here = rock_at[cell]
    good = (here >= 0) & ((bits >> np.maximum(here, 0)) & 1).astype(bool)
    rewards[:exit_state, 4] = np.where(good, SAMPLE_GOOD, SAMPLE_BAD)
    next_states.append(np.where(good, grid - (1 << np.maximum(here, 0)), grid))
    next_states.extend([grid] * k)  # checks change nothing
    rows = np.arange(n_states)
    transitions = [
        sp.csr_matrix((np.ones(n_states), (rows, np.append(target, exit_state))), shape=(n_states, n_states))
        for target in next_states
    ]
    uninformative = sp.csr_matrix((np.ones(n_states), (rows, np.ones(n_states, int))), shape=(n_states, 2))
    observations = [uninformative] * 5
    for rock in range(k):
        distance = np.hypot(x - rocks[rock, 0], y - rocks[rock, 1])
        efficiency = (1.0 + np.power(2.0, -distance / HALF_DISTANCE)) / 2.0
        is_good = ((bits >> rock) & 1).astype(bool)
        p_good = np.append(np.where(is_good, efficiency, 1.0 - efficiency), 0.0)
        dense = np.stack([p_good, 1.0 - p_good], axis=1)
        observations.append(sp.csr_matrix(dense))
    initial = np.zeros(n_states)
    start_cell = (n // 2) * n
    initial[start_cell * n_configs : (start_cell + 1) * n_configs] = 1.0 / n_configs
    action_names = ("north", "south", "east", "west", "sample") + tuple(f"check_{i}" for i in range(k))
    return POMDP(
        transitions,
        rewards,
        DISCOUNT,
        action_names=action_names,
        observations=observations,
        initial_belief=initial,
        observation_names=("good", "bad"),
    )
