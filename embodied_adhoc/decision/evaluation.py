"""Monte-Carlo policy evaluation: mean discounted return with a 95 % confidence interval (Student t).

Each episode samples ``s0 ~ b0`` and runs ``horizon`` steps of the generative model (``s' ~ T``, ``z ~ O``,
reward ``R(s, a)``), the policy acting on the exact Bayesian belief (Eq. 2.3). Seeded: the same seed gives the
same returns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy import stats

from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.policy import AlphaVectorPolicy
from embodied_adhoc.errors import SolverError


@dataclass(frozen=True)
class EvaluationResult:
    mean: float  # mean discounted return
    ci95: float  # half-width of the 95 % confidence interval of the mean
    std: float
    episodes: int
    horizon: int
    returns: np.ndarray

    def as_dict(self) -> dict:
        return {
            "mean": self.mean,
            "ci95": self.ci95,
            "std": self.std,
            "episodes": self.episodes,
            "horizon": self.horizon,
        }


def evaluate_policy(
    pomdp: POMDP, policy: AlphaVectorPolicy, episodes: int, horizon: int, seed: int = 0
) -> EvaluationResult:
    """Simulate ``episodes`` episodes of ``horizon`` steps; a finite-horizon policy is used stage by stage.

    The episodes run in lockstep: one product ``beliefs @ alphas^T`` picks every episode's action (policies of
    thousands of vectors stay cheap to evaluate), then states, observations and beliefs advance per action group.
    """
    if episodes < 1 or horizon < 1:
        raise SolverError(f"episodes and horizon must be >= 1, got {episodes} and {horizon}")
    if policy.n_states != pomdp.n_states:
        raise SolverError(f"policy has {policy.n_states} states, the model {pomdp.n_states}")
    if policy.horizon is not None and horizon > policy.horizon:
        raise SolverError(
            f"policy was solved for {policy.horizon} steps; evaluate with --horizon <= {policy.horizon}"
        )
    rng = np.random.default_rng(seed)
    transitions_t = tuple(matrix.T.tocsr() for matrix in pomdp.transitions)
    observations_t = tuple(matrix.T.tocsr() for matrix in pomdp.observations)  # (Z, S') per action
    cumulative = np.cumsum(pomdp.initial_belief)
    states = np.minimum(
        np.searchsorted(cumulative, rng.random(episodes) * cumulative[-1], side="right"), pomdp.n_states - 1
    )
    beliefs = np.repeat(pomdp.initial_belief[None, :], episodes, axis=0)
    returns, weight = np.zeros(episodes), 1.0
    for step in range(horizon):
        steps_to_go = horizon - step if policy.horizon is not None else None
        actions = policy.actions_of(beliefs, steps_to_go)
        returns += weight * pomdp.rewards[states, actions]
        weight *= pomdp.discount
        uniforms = rng.random((2, episodes))
        for action in np.unique(actions):
            group = np.flatnonzero(actions == action)
            states[group] = _sample_rows(pomdp.transitions[action], states[group], uniforms[0, group])
            observations = _sample_rows(pomdp.observations[action], states[group], uniforms[1, group])
            # Eq. 2.3 for the whole group: b'(s') ~ O(z | s', a) sum_s T(s, a, s') b(s)
            predicted = (transitions_t[action] @ beliefs[group].T).T  # (g, S')
            likelihood = observations_t[action][observations].toarray()  # (g, S')
            posterior = predicted * likelihood
            totals = posterior.sum(axis=1)
            if np.any(totals <= 0.0):  # a sampled observation of probability 0: the model is inconsistent
                episode = int(group[np.argmax(totals <= 0.0)])
                raise SolverError(f"episode {episode}, step {step}: sampled observation has probability 0")
            beliefs[group] = posterior / totals[:, None]
    std = float(returns.std(ddof=1)) if episodes > 1 else 0.0
    half = float(stats.t.ppf(0.975, episodes - 1) * std / np.sqrt(episodes)) if episodes > 1 else float("inf")
    return EvaluationResult(float(returns.mean()), half, std, episodes, horizon, returns)


def _sample_rows(matrix: sp.csr_matrix, rows: np.ndarray, uniforms: np.ndarray) -> np.ndarray:
    """One column index per row of ``matrix[rows]``, drawn from the row's weights by inverse CDF on ``uniforms``."""
    sub = matrix[rows]
    cumulative = np.cumsum(sub.data)
    before = np.concatenate([[0.0], cumulative])[sub.indptr[:-1]]  # cumulative mass before each row
    totals = cumulative[sub.indptr[1:] - 1] - before
    positions = np.searchsorted(cumulative, before + uniforms * totals, side="right")
    positions = np.clip(positions, sub.indptr[:-1], sub.indptr[1:] - 1)
    return sub.indices[positions]
