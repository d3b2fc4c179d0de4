"""QMDP (Littman, Cassandra & Kaelbling 1995): act as if the state became fully observable after one step.

``Q_MDP(b, a) = sum_s b(s) Q*(s, a)``, i.e. one alpha vector per action, ``alpha_a = Q*(., a)`` from value
iteration on the underlying MDP (thesis Eq. 2.2). Its value is an *upper* bound of the POMDP's optimum, not a
lower bound. With a finite horizon the policy is time dependent (one vector per action per stage).
"""

from __future__ import annotations

import time

import numpy as np

from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.policy import AlphaVectorPolicy, SolverStats
from embodied_adhoc.decision.value_iteration import value_iteration
from embodied_adhoc.errors import SolverError


def qmdp(pomdp: POMDP, horizon: int | None = None, tolerance: float = 1e-8) -> AlphaVectorPolicy:
    """The QMDP policy of ``pomdp``; ``horizon`` is required when the discount is 1.0."""
    start = time.perf_counter()
    actions = np.arange(pomdp.n_actions, dtype=np.int64)
    if horizon is None:
        result = value_iteration(pomdp.as_mdp(), tolerance=tolerance)
        stats = SolverStats(
            "qmdp", result.iterations, time.perf_counter() - start, result.converged, result.residual
        )
        return AlphaVectorPolicy(result.q_values.T.copy(), actions, stats=stats)
    if horizon < 1:
        raise SolverError(f"horizon must be a positive number of steps, got {horizon}")
    mdp = pomdp.as_mdp()
    values = np.zeros(pomdp.n_states)
    stages = []
    for _ in range(horizon):  # finite-horizon Bellman backups, keeping Q_t for t = 1..H steps to go
        q_values = pomdp.rewards + pomdp.discount * mdp.expected_next_values(values)
        values = q_values.max(axis=1)
        stages.append(q_values.T)
    stats = SolverStats("qmdp", horizon, time.perf_counter() - start, True, float("nan"))
    return AlphaVectorPolicy(
        np.vstack(stages),
        np.tile(actions, horizon),
        np.repeat(np.arange(1, horizon + 1, dtype=np.int64), pomdp.n_actions),
        stats=stats,
    )
