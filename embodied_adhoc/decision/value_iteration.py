"""Value iteration on a sparse MDP (thesis Eq. 2.2, the Bellman optimality backup).

Each sweep costs one sparse mat-vec per action. Used directly by the oracle baseline and ``--solver vi``,
by QMDP, by HOTSPOT's per-task MDPs (Q*_m and Q*_m,info) and to initialise Perseus' upper structure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from embodied_adhoc.decision.models import MDP
from embodied_adhoc.errors import SolverError


@dataclass(frozen=True)
class ValueIterationResult:
    values: np.ndarray  # V*(s), shape (S,)
    q_values: np.ndarray  # Q*(s, a), shape (S, A)
    iterations: int
    residual: float  # sup-norm of the last Bellman update
    converged: bool

    def greedy_actions(self) -> np.ndarray:
        return np.argmax(self.q_values, axis=1)


def value_iteration(
    mdp: MDP,
    rewards: np.ndarray | None = None,
    tolerance: float = 1e-8,
    max_iterations: int = 100_000,
    horizon: int | None = None,
) -> ValueIterationResult:
    """Solve ``mdp`` (optionally with an alternative ``rewards`` array of shape |S| x |A|).

    Infinite horizon (default): iterate until the Bellman residual is below
    ``tolerance * (1 - gamma) / (2 gamma)``, which bounds the value error of the greedy policy by ``tolerance``.
    Finite ``horizon``: exactly ``horizon`` backups from V = 0 (required when the discount is 1.0).
    """
    rewards = mdp.rewards if rewards is None else np.asarray(rewards, dtype=np.float64)
    if rewards.shape != (mdp.n_states, mdp.n_actions):
        raise SolverError(f"rewards has shape {rewards.shape}, expected {(mdp.n_states, mdp.n_actions)}")
    gamma = mdp.discount
    if horizon is None and gamma >= 1.0:
        raise SolverError(
            "discount is 1.0: an infinite-horizon solve does not converge; give a finite horizon (--horizon N)"
        )
    if horizon is not None and horizon < 1:
        raise SolverError(f"horizon must be a positive number of steps, got {horizon}")

    values = np.zeros(mdp.n_states)
    q_values = rewards.copy()
    if horizon is not None:
        for _ in range(horizon):
            q_values = rewards + gamma * mdp.expected_next_values(values)
            values = q_values.max(axis=1)
        return ValueIterationResult(values, q_values, horizon, math.nan, True)

    threshold = tolerance * (1.0 - gamma) / (2.0 * gamma) if gamma > 0 else 0.0
    residual = math.inf
    for iteration in range(1, max_iterations + 1):
        q_values = rewards + gamma * mdp.expected_next_values(values)
        new_values = q_values.max(axis=1)
        residual = float(np.max(np.abs(new_values - values))) if values.size else 0.0
        values = new_values
        if residual <= threshold:
            return ValueIterationResult(values, q_values, iteration, residual, True)
    return ValueIterationResult(values, q_values, max_iterations, residual, False)
