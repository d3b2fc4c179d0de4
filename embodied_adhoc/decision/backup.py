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

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg

from embodied_adhoc.decision.models import POMDP


class BackupOperator:
    """Precomputed per-(action, observation) supports of a POMDP; ``backup(beliefs, alphas)`` is the operator."""

    def __init__(self, pomdp: POMDP) -> None:
        self.pomdp = pomdp
        self.discount = pomdp.discount
        self.rewards_by_action = np.ascontiguousarray(pomdp.rewards.T)  # (A, S)
        self.transitions = pomdp.transitions  # CSR (S x S) per action
        self.transitions_t = tuple(m.T.tocsr() for m in pomdp.transitions)
        # For each action, the observations with any support, each with (end states, probabilities).
        self.branches: list[list[tuple[int, np.ndarray, np.ndarray]]] = []
        for matrix in pomdp.observations:
            csc = sp.csc_matrix(matrix)
            branches = []
            for z in range(csc.shape[1]):
                start, end = csc.indptr[z], csc.indptr[z + 1]
                if end > start:
                    branches.append((z, csc.indices[start:end].copy(), csc.data[start:end].copy()))
            self.branches.append(branches)

    def backup(self, beliefs: np.ndarray, alphas: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Backed-up vectors for each row of ``beliefs``: ``(vectors (n, S), actions (n,), values (n,))``.

        ``values[i] = beliefs[i] . vectors[i]``. ``alphas`` is the current value function (K x S).
        """
        n, n_states = beliefs.shape
        best_vectors = np.empty((n, n_states))
        best_values = np.full(n, -np.inf)
        best_actions = np.zeros(n, dtype=np.int64)
        rows = np.arange(n)
        for action in range(self.pomdp.n_actions):
            predicted = np.asarray(self.transitions_t[action] @ beliefs.T).T  # (n, S'): sum_s b(s) T(s,a,s')
            continuation = np.zeros((n, n_states))
            for _, states, probabilities in self.branches[action]:
                weighted = alphas[:, states] * probabilities  # (K, m): O(z|s',a) alpha_k(s')
                scores = predicted[:, states] @ weighted.T  # (n, K)
                chosen = np.argmax(scores, axis=1)
                impossible = ~np.any(predicted[:, states] > 0.0, axis=1)
                if impossible.any():
                    chosen[impossible] = int(np.argmax(weighted.sum(axis=1)))
                continuation[:, states] += weighted[chosen]
            vectors = (
                self.rewards_by_action[action]
                + self.discount * np.asarray(self.transitions[action] @ continuation.T).T
            )
            values = np.einsum("ij,ij->i", beliefs, vectors)
            better = values > best_values
            best_values[better] = values[better]
            best_actions[better] = action
            best_vectors[rows[better]] = vectors[better]
        return best_vectors, best_actions, best_values


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
