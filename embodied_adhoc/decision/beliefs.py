"""Belief-set collection for point-based solvers (Perseus, Spaan & Vlassis 2005, section 3).

Beliefs are gathered along simulated trajectories from ``b0``: each step samples a state from the true
hidden-state process, picks an action (uniformly at random, or greedily w.r.t. the MDP's Q* with probability
``1 - epsilon``), samples ``s'`` and ``z`` and applies the Bayesian update (thesis Eq. 2.3). Duplicates (to 1e-9)
are dropped, so the set may be smaller than asked when the reachable belief space is small.
"""

from __future__ import annotations

import hashlib
from array import array

import numpy as np
import scipy.sparse as sp

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


def collect_beliefs(pomdp: POMDP, count: int, rng: np.random.Generator, **options) -> np.ndarray:
    """Up to ``count`` distinct reachable beliefs (rows), the first being ``b0``: :func:`collect_belief_rows`'
    rows, dense (``options``: its ``greedy_q``, ``epsilon`` and ``max_depth``)."""
    rows, _ = collect_belief_rows(pomdp, count, rng, **options)
    return rows.toarray()


def collect_belief_rows(
    pomdp: POMDP,
    count: int,
    rng: np.random.Generator,
    greedy_q: np.ndarray | None = None,
    epsilon: float = 0.5,
    max_depth: int | None = None,
) -> tuple[sp.csr_matrix, list[bytes]]:
    """Up to ``count`` distinct reachable beliefs as CSR rows (the first being ``b0``) and their :func:`digest`s.

    ``greedy_q`` (|S| x |A|, e.g. the MDP's Q*) makes exploration epsilon-greedy on ``b . Q``; without it actions
    are uniform. Trajectories restart from ``b0`` after ``max_depth`` steps (default: the effective horizon
    ``1 / (1 - gamma)`` clipped to [20, 200]).

    The rows are built as the beliefs come, and only one belief is dense at a time: a large expansion of a
    model with many states (Tag) would otherwise hold the new beliefs dense, their keys and the returned array.
    The rows equal ``sp.csr_matrix`` of the dense beliefs bit for bit (the same values and column order).
    """
    if max_depth is None:
        gamma = pomdp.discount
        max_depth = int(np.clip(1.0 / (1.0 - gamma) if gamma < 1.0 else 200, 20, 200))
    stepper = BeliefStepper(pomdp)
    rows = _RowBuilder(pomdp.n_states)
    rows.append(pomdp.initial_belief)
    digests = [digest(pomdp.initial_belief)]
    seen = set(digests)
    attempts_without_new = 0
    belief, state, depth = pomdp.initial_belief, pomdp.sample_initial_state(rng), 0
    # Stop early when the reachable set seems exhausted (many consecutive steps without a new belief).
    while len(digests) < count and attempts_without_new < _EXHAUSTED_AFTER:
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
        key = digest(belief)
        if key in seen:
            attempts_without_new += 1
            continue
        attempts_without_new = 0
        seen.add(key)
        digests.append(key)
        rows.append(belief)
    return rows.matrix(), digests


class _RowBuilder:
    """CSR rows appended one dense row at a time, their nonzeros kept in growing flat buffers."""

    def __init__(self, n_columns: int) -> None:
        self.n_columns = n_columns
        self.data, self.indices, self.indptr = array("d"), array("q"), array("q", [0])

    def append(self, row: np.ndarray) -> None:
        columns = np.flatnonzero(row)
        self.data.frombytes(np.ascontiguousarray(row[columns], dtype=np.float64).tobytes())
        self.indices.frombytes(columns.astype(np.int64).tobytes())
        self.indptr.append(len(self.data))

    def matrix(self) -> sp.csr_matrix:
        shape = (len(self.indptr) - 1, self.n_columns)
        data = np.frombuffer(self.data, dtype=np.float64).copy()
        indices = np.frombuffer(self.indices, dtype=np.int64)
        indptr = np.frombuffer(self.indptr, dtype=np.int64)
        # The index dtype sp.csr_matrix picks for a dense array of this shape (int32 while it fits).
        index_dtype = sp.csr_matrix((0, 0)).indices.dtype
        if max(shape[1], len(data)) > np.iinfo(index_dtype).max:
            index_dtype = np.int64
        return sp.csr_matrix((data, indices.astype(index_dtype), indptr.astype(index_dtype)), shape=shape)


def _key(belief: np.ndarray) -> bytes:
    return np.round(belief, 9).tobytes()


def digest(belief: np.ndarray) -> bytes:
    """A 16-byte digest of ``belief``'s values rounded to 1e-9: beliefs that agree to 1e-9 share it, at 16 bytes a
    belief instead of 8 per state (the keys of a large set outweigh the set itself)."""
    return hashlib.blake2b(_key(belief), digest_size=16).digest()
