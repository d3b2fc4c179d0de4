"""Vectorised point-based Bellman backup (thesis Eq. 2.4 restricted to a set of beliefs).

For beliefs ``B`` (n x S) and an alpha set ``Gamma`` (K x S) the backup at ``b`` is

    alpha_a^b = R(., a) + gamma * sum_z T_a (O_{a,z} * Gamma[k*_{a,z}(b)]),
    k*_{a,z}(b) = argmax_k  sum_{s'} (b T_a)(s') O(z | s', a) Gamma[k](s'),

and ``backup(b) = alpha_{a*}^b`` for the action maximising ``b . alpha_a^b``. All beliefs of a batch are handled
at once: one sparse product ``B T_a`` per action, then the scores of every vector on every branch, and one
sparse product per action to map the chosen continuation vectors back through ``T_a``. The scores are computed
on the support of the predicted beliefs when they are sparse: one sparse (possible branches x S) matrix
``W[(i, z), s'] = (b_i T_a)(s') O(z | s', a)`` times the dense ``Gamma^T``, so the cost is ``K`` times the
nonzeros of ``W`` (about ``n * |supp(b T_a)| * nnz(O_a) / S``); dense predicted beliefs use one product with the
projection of all vectors on all observations (``n * K * nnz(O_a)`` per action, not ``n * K * S * |Z|``).

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


_SUPPORT_DENSITY = 0.3  # predicted-belief density below which scores are computed on the belief supports


@dataclass(frozen=True)
class PreparedAlphas:
    """A value function with its per-action projections (built on first use, reused for many batches)."""

    alphas: np.ndarray
    alphas_t: np.ndarray  # (S, K) float32, contiguous: right operand of the support-restricted scores
    projections: dict[int, sp.csr_matrix | np.ndarray]
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
        self.observation_rows = tuple(sp.csr_matrix(matrix) for matrix in pomdp.observations)  # (S x Z) each
        for matrix in self.observation_rows:
            matrix.sort_indices()
        self.sparse_observations = tuple(
            matrix.nnz < _DENSE_DENSITY * pomdp.n_states * pomdp.n_observations for matrix in self.observation_rows
        )

    def prepare(self, alphas: np.ndarray) -> PreparedAlphas:
        """A value function ready for many :meth:`backup` calls against it (projections built lazily)."""
        alphas = np.ascontiguousarray(alphas, dtype=np.float64)
        # For branches impossible at a belief: the vector best for a uniform spread over the states emitting z.
        fallbacks = tuple(np.argmax(entry[4] @ alphas.T, axis=1) for entry in self.entries)
        return PreparedAlphas(alphas, np.ascontiguousarray(alphas.T, dtype=np.float32), {}, fallbacks)

    def _projection(self, prepared: PreparedAlphas, action: int) -> sp.csr_matrix | np.ndarray:
        """Projection of every vector on every observation of ``action`` (used for dense predicted beliefs)."""
        if action in prepared.projections:
            return prepared.projections[action]
        alphas = prepared.alphas
        end_states, observations, probabilities, _, observation_t = self.entries[action]
        n_vectors, n_obs, n_states = alphas.shape[0], self.n_observations, self.pomdp.n_states
        # projected (K*Z x S'): row k*Z+z holds O(z|s',a) alpha_k(s'); scores[k, z, i] = row . (b_i T_a)
        shape = (n_vectors * n_obs, n_states)
        density = len(end_states) / (n_states * n_obs)
        if density >= _DENSE_DENSITY and shape[0] * shape[1] <= _DENSE_MAX_ELEMENTS:
            # Dense observation models: a dense BLAS product beats the sparse one despite the extra zeros.
            # Laid out (Z, K, S) so that the scores come out (n, Z, K), K last for a contiguous argmax.
            dense_t = observation_t.toarray()  # (Z, S)
            projection = (dense_t[:, None, :] * alphas[None, :, :]).reshape(n_obs * n_vectors, n_states)
        else:
            weights = alphas[:, end_states] * probabilities  # (K, nnz)
            rows = (np.arange(n_vectors)[:, None] * n_obs + observations[None, :]).ravel()
            columns = np.tile(end_states, n_vectors)
            projection = sp.csr_matrix((weights.ravel(), (rows, columns)), shape=shape)
        prepared.projections[action] = projection
        return projection

    def _support_choices(
        self, prepared: PreparedAlphas, action: int, predicted: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Best vector of each possible branch, scored on the support of the predicted beliefs only.

        Returns ``(observations, beliefs, best)`` for every branch ``(z, i)`` with ``P(z | b_i, a) > 0``. The
        scores are float32 (half the memory traffic of this, the solver's hottest product): they only choose
        the continuation, the vectors are then built in float64, so a near-tie picked differently still gives
        the exact value of a conditional plan (the lower bound holds).
        """
        observation = self.observation_rows[action]  # CSR (S x Z)
        n_obs = self.n_observations
        ends, columns = np.nonzero(predicted)  # predicted is (S, n)
        mass = predicted[ends, columns]
        counts = np.diff(observation.indptr)[ends]
        total = int(counts.sum())
        owner = np.repeat(np.arange(len(ends)), counts)
        first = np.repeat(np.cumsum(counts) - counts, counts)
        position = observation.indptr[ends][owner] + np.arange(total) - first
        keys = columns[owner] * n_obs + observation.indices[position]  # branch (i, z) of every product entry
        branch_keys, rows = np.unique(keys, return_inverse=True)
        weights = sp.csr_matrix(
            ((mass[owner] * observation.data[position]).astype(np.float32), (rows.ravel(), ends[owner])),
            shape=(len(branch_keys), self.pomdp.n_states),
        )
        best = np.argmax(weights @ prepared.alphas_t, axis=1)  # (branches,)
        return branch_keys % n_obs, branch_keys // n_obs, best

    def backup(
        self,
        beliefs: np.ndarray,
        alphas: np.ndarray | PreparedAlphas,
        with_children: bool = False,
        project: bool = True,
    ) -> tuple[np.ndarray, ...]:
        """Backed-up vectors for each row of ``beliefs``: ``(vectors (n, S), actions (n,), values (n,))``.

        ``values[i] = beliefs[i] . vectors[i]``. ``alphas`` is the current value function (K x S), or its
        :meth:`prepare`-d form when several batches are backed up against the same one. ``with_children``
        appends ``children`` (n, Z): the row of ``alphas`` each new vector continues with after each
        observation, i.e. its conditional plan (``vectors[i] = R_a + gamma T_a sum_z O_z alphas[children[i, z]]``).
        Internally everything is laid out (S, n) so that every sparse product is a row-oriented CSR product.
        ``project=False`` always scores on the predicted beliefs' support, never building the projection of all
        vectors (for one or a few beliefs, e.g. the solver's trials, building it costs more than the scores).
        """
        prepared = alphas if isinstance(alphas, PreparedAlphas) else self.prepare(alphas)
        alphas = prepared.alphas
        n, n_states = beliefs.shape
        n_vectors, n_obs = alphas.shape[0], self.n_observations
        beliefs_t = np.ascontiguousarray(beliefs.T)  # (S, n)
        best_vectors = np.empty((n, n_states))
        best_values = np.full(n, -np.inf)
        best_actions = np.zeros(n, dtype=np.int64)
        best_children = np.zeros((n, n_obs), dtype=np.int64) if with_children else None
        for action in range(self.pomdp.n_actions):
            end_states, observations, probabilities, from_entries, observation_t = self.entries[action]
            # predicted[s', i] = sum_s b_i(s) T(s, a, s')  (one sparse product for the whole batch)
            predicted = self.transitions_t[action] @ beliefs_t
            if not project or (
                self.sparse_observations[action] and np.count_nonzero(predicted) < _SUPPORT_DENSITY * predicted.size
            ):
                # (Z, n): best continuation per branch and belief; impossible branches keep the fallback.
                chosen = np.repeat(prepared.fallbacks[action][:, None], n, axis=1)
                branch_observations, branch_beliefs, best = self._support_choices(prepared, action, predicted)
                chosen[branch_observations, branch_beliefs] = best
            else:
                projected = self._projection(prepared, action)
                if isinstance(projected, np.ndarray):  # dense (Z*K, S): scores (n, Z, K)
                    scores = (predicted.T @ projected.T).reshape(n, n_obs, n_vectors)
                    chosen = np.ascontiguousarray(np.argmax(scores, axis=2).T)  # (Z, n)
                else:  # sparse (K*Z, S): scores (K, Z, n)
                    scores = (projected @ predicted).reshape(n_vectors, n_obs, n)
                    chosen = _argmax_first_axis(scores)  # (Z, n): best continuation per branch and belief
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
            if with_children:
                best_children[better] = chosen[:, better].T
        if with_children:
            return best_vectors, best_actions, best_values, best_children
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
