"""Vectorised point-based Bellman backup (thesis Eq. 2.4 restricted to a set of beliefs).

For beliefs ``B`` (n x S) and an alpha set ``Gamma`` (K x S) the backup at ``b`` is

    alpha_a^b = R(., a) + gamma * sum_z T_a (O_{a,z} * Gamma[k*_{a,z}(b)]),
    k*_{a,z}(b) = argmax_k  sum_{s'} (b T_a)(s') O(z | s', a) Gamma[k](s'),

and ``backup(b) = alpha_{a*}^b`` for the action maximising ``b . alpha_a^b``. All beliefs of a batch are handled
at once: one sparse product ``B T_a`` per action, then per observation a dense product restricted to the end
states where ``O(z | s', a) > 0`` (so the cost is ``n * K * nnz(O_a)`` per action, not ``n * K * S * |Z|``), and
one sparse product per action to map the chosen continuation vectors back through ``T_a``.

Branches ``(a, z)`` impossible at a belief still get a continuation vector (the one best for a uniform spread
over the states emitting ``z``): dropping them would give a vector that is not the value of any plan, and the
solver's value would no longer be a lower bound.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg

from embodied_adhoc.decision.models import POMDP

_DENSE_DENSITY = 0.1  # observation-matrix density above which projections are stored densely
_DENSE_MAX_ELEMENTS = 20_000_000


@dataclass(frozen=True)
class PreparedAlphas:
    """A value function with its per-action projections (built once, used for many batches)."""

    alphas: np.ndarray
    projections: tuple[sp.csr_matrix | np.ndarray, ...]
    fallbacks: tuple[np.ndarray, ...]


class BackupOperator:
    """Precomputed sparse observation structure of a POMDP; ``backup(beliefs, alphas)`` is the operator."""

    def __init__(self, pomdp: POMDP) -> None:
        self.pomdp = pomdp
        self.discount = pomdp.discount
        self.n_observations = pomdp.n_observations
        self.rewards_by_action = np.ascontiguousarray(pomdp.rewards.T)  # (A, S)
        self.transitions = pomdp.transitions  # CSR (S x S) per action
        self.transitions_t = tuple(m.T.tocsr() for m in pomdp.transitions)
        # Per action, the nonzero entries (s', z, O(z|s',a)) of the observation matrix, and the (nnz x S)
        # matrix that sums per-entry terms back into their end state.
        self.entries = []
        for matrix in pomdp.observations:
            coo = matrix.tocoo()
            end_states, observations, probabilities = (
                coo.row.astype(np.int64),
                coo.col.astype(np.int64),
                coo.data,
            )
            from_entries = sp.csr_matrix(
                (np.ones(coo.nnz), (end_states, np.arange(coo.nnz))), shape=(pomdp.n_states, coo.nnz)
            )
            self.entries.append((end_states, observations, probabilities, from_entries, matrix.T.tocsr()))

    def prepare(self, alphas: np.ndarray) -> PreparedAlphas:
        """Per-action projections of a value function, reused by every :meth:`backup` against it."""
        n_vectors, n_obs, n_states = alphas.shape[0], self.n_observations, self.pomdp.n_states
        projections, fallbacks = [], []
        for end_states, observations, probabilities, _, observation_t in self.entries:
            # projected (K*Z x S'): row k*Z+z holds O(z|s',a) alpha_k(s'); scores[k, z, i] = row . (b_i T_a)
            weights = alphas[:, end_states] * probabilities  # (K, nnz)
            rows = (np.arange(n_vectors)[:, None] * n_obs + observations[None, :]).ravel()
            columns = np.tile(end_states, n_vectors)
            shape = (n_vectors * n_obs, n_states)
            density = len(end_states) / (n_states * n_obs)
            if density >= _DENSE_DENSITY and shape[0] * shape[1] <= _DENSE_MAX_ELEMENTS:
                # Dense observation models: a dense BLAS product beats the sparse one despite the extra zeros.
                # Laid out (Z, K, S) so that the scores come out (n, Z, K), K last for a contiguous argmax.
                dense_t = observation_t.toarray()  # (Z, S)
                projections.append(
                    (dense_t[:, None, :] * alphas[None, :, :]).reshape(n_obs * n_vectors, n_states)
                )
            else:
                projections.append(sp.csr_matrix((weights.ravel(), (rows, columns)), shape=shape))
            # For branches impossible at a belief: the vector best for a uniform spread over the states emitting z.
            fallbacks.append(np.argmax(observation_t @ alphas.T, axis=1))
        return PreparedAlphas(np.ascontiguousarray(alphas), tuple(projections), tuple(fallbacks))

    def backup(
        self, beliefs: np.ndarray, alphas: np.ndarray | PreparedAlphas
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Backed-up vectors for each row of ``beliefs``: ``(vectors (n, S), actions (n,), values (n,))``.

        ``values[i] = beliefs[i] . vectors[i]``. ``alphas`` is the current value function (K x S), or its
        :meth:`prepare`-d form when several batches are backed up against the same one.
        Internally everything is laid out (S, n) so that every sparse product is a row-oriented CSR product.
        """
        prepared = alphas if isinstance(alphas, PreparedAlphas) else self.prepare(alphas)
        alphas = prepared.alphas
        n, n_states = beliefs.shape
        n_vectors, n_obs = alphas.shape[0], self.n_observations
        beliefs_t = np.ascontiguousarray(beliefs.T)  # (S, n)
        best_vectors = np.empty((n, n_states))
        best_values = np.full(n, -np.inf)
        best_actions = np.zeros(n, dtype=np.int64)
        for action in range(self.pomdp.n_actions):
            end_states, observations, probabilities, from_entries, observation_t = self.entries[action]
            # predicted[s', i] = sum_s b_i(s) T(s, a, s')  (one sparse product for the whole batch)
            predicted = self.transitions_t[action] @ beliefs_t
            projected = prepared.projections[action]
            if isinstance(projected, np.ndarray):  # dense (Z*K, S): scores (n, Z, K)
                scores = (predicted.T @ projected.T).reshape(n, n_obs, n_vectors)
                chosen = np.ascontiguousarray(np.argmax(scores, axis=2).T)  # (Z, n)
            else:  # sparse (K*Z, S): scores (K, Z, n)
                scores = (projected @ predicted).reshape(n_vectors, n_obs, n)
                chosen = _argmax_first_axis(scores)  # (Z, n): best continuation vector per branch and belief
            impossible = (observation_t @ predicted) <= 0.0  # (Z, n)
            if impossible.any():
                chosen = np.where(impossible, prepared.fallbacks[action][:, None], chosen)
            # continuation[s', i] = sum_z O(z|s',a) alpha_{chosen[z,i]}(s'), gathered per observation entry.
            per_entry = alphas[chosen[observations], end_states[:, None]] * probabilities[:, None]  # (nnz, n)
            continuation = from_entries @ per_entry  # (S', n)
            vectors = self.rewards_by_action[action][:, None] + self.discount * (
                self.transitions[action] @ continuation
            )
            values = np.einsum("si,si->i", beliefs_t, vectors)
            better = values > best_values
            best_values[better] = values[better]
            best_actions[better] = action
            best_vectors[better] = vectors[:, better].T
        return best_vectors, best_actions, best_values


def _argmax_first_axis(scores: np.ndarray) -> np.ndarray:
    """``argmax(scores, axis=0)`` by a running maximum over contiguous slabs (about 2x numpy's strided argmax)."""
    best = scores[0].copy()
    chosen = np.zeros(best.shape, dtype=np.int64)
    for k in range(1, scores.shape[0]):
        better = scores[k] > best
        np.copyto(best, scores[k], where=better)
        chosen[better] = k
    return chosen


def blind_policy_vectors(pomdp: POMDP) -> np.ndarray:
    """Values of the blind policies "always do a" (A x S): ``alpha_a = (I - gamma T_a)^-1 R(., a)``.

    Each is the exact value of an executable policy, so ``max_a alpha_a . b`` is a lower bound of V*(b):
    the initial value function of Perseus. Requires ``gamma < 1``.
    """
    identity = sp.identity(pomdp.n_states, format="csc")
    vectors = []
    for action, matrix in enumerate(pomdp.transitions):
        system = (identity - pomdp.discount * matrix).tocsc()
        vectors.append(scipy.sparse.linalg.spsolve(system, pomdp.rewards[:, action]))
    return np.atleast_2d(np.asarray(vectors, dtype=np.float64))
