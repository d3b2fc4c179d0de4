"""Seeded random POMDPs with sparse structure: the "random model" class of solver benchmarks.

``random_pomdp(states, actions, observations, seed)`` draws, from one Generator in a fixed order:

* transitions: each (state, action) reaches ``successors`` distinct states drawn uniformly, with probabilities
  from a flat Dirichlet (each row's support and weights independent);
* observations: each (next state, action) emits one of ``emissions`` distinct observations drawn uniformly, with
  Dirichlet weights, so a belief sharpens only through several noisy looks;
* rewards ``R(s, a)`` uniform in [0, 1), discount 0.9 (values in [0, 10)); the initial belief uniform.

No structure favours a solver: no goal, no grid, no deterministic moves; every state is reachable from the
start. The model depends on its arguments alone.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.errors import ConfigError

DISCOUNT = 0.9
MAX_STATES = 100_000
MAX_SUPPORT = 64  # successors or emissions per row, and actions: the model holds states x actions x support


def _rows(rng: np.random.Generator, n_rows: int, n_columns: int, support: int) -> sp.csr_matrix:
    """``n_rows`` stochastic rows, each on ``support`` distinct columns drawn uniformly, Dirichlet(1) weights.
    Rows with a repeated column are drawn again (few: ``support`` is at most ``MAX_SUPPORT``), so memory stays
    ``n_rows x support``."""
    if support > n_columns // 2:  # dense rows: a permutation's prefix per row (n_columns < 2 MAX_SUPPORT)
        columns = np.sort(np.argsort(rng.random((n_rows, n_columns)), axis=1)[:, :support], axis=1)
    else:
        columns = np.sort(rng.integers(0, n_columns, (n_rows, support)), axis=1)
    while (repeated := np.flatnonzero((np.diff(columns, axis=1) == 0).any(axis=1))).size:
        columns[repeated] = np.sort(rng.integers(0, n_columns, (repeated.size, support)), axis=1)
    weights = rng.dirichlet(np.ones(support), size=n_rows)
    indptr = np.arange(0, n_rows * support + 1, support)
    return sp.csr_matrix((weights.ravel(), columns.ravel(), indptr), shape=(n_rows, n_columns))


def check_counts(
    states: int, actions: int, observations: int, seed: int = 0, successors: int = 5, emissions: int = 3
) -> None:
    """Refuse counts :func:`random_pomdp` cannot build (ConfigError naming the count), before it allocates."""
    for name, value, low in (
        ("states", states, 1),
        ("actions", actions, 1),
        ("observations", observations, 1),
        ("seed", seed, 0),
        ("successors", successors, 1),
        ("emissions", emissions, 1),
    ):
        if not isinstance(value, (int, np.integer)) or value < low:
            raise ConfigError(f"random model: {name} must be an integer >= {low}, got {value!r}")
    if states > MAX_STATES:
        raise ConfigError(f"random model: {states:,} states exceed {MAX_STATES:,}; give fewer")
    for name, value in (("actions", actions), ("successors", successors), ("emissions", emissions)):
        if value > MAX_SUPPORT:
            raise ConfigError(f"random model: {name} = {value} exceeds {MAX_SUPPORT}; give fewer")
    if successors > states or emissions > observations:
        raise ConfigError(
            f"random model: {successors} successors of {states} states and {emissions} emissions of "
            f"{observations} observations: each must be at most its count"
        )


def random_pomdp(
    states: int,
    actions: int,
    observations: int,
    seed: int = 0,
    successors: int = 5,
    emissions: int = 3,
) -> POMDP:
    """The seeded random POMDP of the module docstring."""
    check_counts(states, actions, observations, seed, successors, emissions)
    rng = np.random.default_rng(seed)
    transitions = [_rows(rng, states, states, successors) for _ in range(actions)]
    emitted = [_rows(rng, states, observations, emissions) for _ in range(actions)]
    rewards = rng.random((states, actions))
    return POMDP(
        transitions,
        rewards,
        DISCOUNT,
        observations=emitted,
        initial_belief=np.full(states, 1.0 / states),
    )
