"""Belief-set collection for point-based solvers (Perseus, Spaan & Vlassis 2005, section 3).

Beliefs are gathered along simulated trajectories from ``b0``: each step samples a state from the true
hidden-state process, picks an action (uniformly at random, or greedily w.r.t. the MDP's Q* with probability
``1 - epsilon``), samples ``s'`` and ``z`` and applies the Bayesian update (thesis Eq. 2.3). Duplicates (to 1e-9)
are dropped, so the set may be smaller than asked when the reachable belief space is small.
"""

from __future__ import annotations

import numpy as np

from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.products import dot

_DENSE_OBSERVATION_LIMIT = 20_000_000
_EXHAUSTED_AFTER = 1000  # consecutive steps without a new belief: the reachable set is (nearly) exhausted


class BeliefStepper:
    """Fast repeated belief updates: observation matrices cached densely (|A| x |S| x |Z|) when small enough."""

    def __init__(self, pomdp: POMDP) -> None:
        self.pomdp = pomdp
        self._transposed = tuple(matrix.T.tocsr() for matrix in pomdp.transitions)
        size = pomdp.n_actions * pomdp.n_states * pomdp.n_observations
        self._dense = (
            np.stack([matrix.toarray() for matrix in pomdp.observations])
            if size <= _DENSE_OBSERVATION_LIMIT
            else None
        )
        self._columns = None if self._dense is not None else tuple(m.tocsc() for m in pomdp.observations)

    def update(self, belief: np.ndarray, action: int, observation: int) -> np.ndarray | None:
        """The posterior belief (Eq. 2.3), or None when the observation has probability 0 under ``belief``."""
        predicted = self._transposed[action] @ belief
        if self._dense is not None:
            column = self._dense[action, :, observation]
        else:
            column = self._columns[action][:, observation].toarray().ravel()
        unnormalised = column * predicted
        total = unnormalised.sum()
        return unnormalised / total if total > 0.0 else None


def collect_beliefs(
    pomdp: POMDP,
    count: int,
    rng: np.random.Generator,
    greedy_q: np.ndarray | None = None,
    epsilon: float = 0.5,
    max_depth: int | None = None,
) -> np.ndarray:
    """Up to ``count`` distinct reachable beliefs (rows), the first being ``b0``.

    ``greedy_q`` (|S| x |A|, e.g. the MDP's Q*) makes exploration epsilon-greedy on ``b . Q``; without it actions
    are uniform. Trajectories restart from ``b0`` after ``max_depth`` steps (default: the effective horizon
    ``1 / (1 - gamma)`` clipped to [20, 200]).
    """
    if max_depth is None:
        gamma = pomdp.discount
        max_depth = int(np.clip(1.0 / (1.0 - gamma) if gamma < 1.0 else 200, 20, 200))
    stepper = BeliefStepper(pomdp)
    beliefs = [pomdp.initial_belief.copy()]
    seen = {_key(beliefs[0])}
    attempts_without_new = 0
    belief, state, depth = pomdp.initial_belief, pomdp.sample_initial_state(rng), 0
    # Stop early when the reachable set seems exhausted (many consecutive steps without a new belief).
    while len(beliefs) < count and attempts_without_new < _EXHAUSTED_AFTER:
        if depth >= max_depth:
            belief, state, depth = pomdp.initial_belief, pomdp.sample_initial_state(rng), 0
        if greedy_q is not None and rng.random() >= epsilon:
            action = int(np.argmax(dot(belief, greedy_q)))
        else:
            action = int(rng.integers(pomdp.n_actions))
        state, observation, _ = pomdp.step(state, action, rng)
        posterior = stepper.update(belief, action, observation)
        depth += 1
        if posterior is None:  # cannot happen for a sampled z unless the model is inconsistent; restart
            depth = max_depth
            continue
        belief = posterior
        key = _key(belief)
        if key in seen:
            attempts_without_new += 1
            continue
        attempts_without_new = 0
        seen.add(key)
        beliefs.append(belief)
    return np.asarray(beliefs)


def _key(belief: np.ndarray) -> bytes:
    return np.round(belief, 9).tobytes()
