"""Upper bounds on the optimal value: the fast informed bound, improved by sawtooth interpolation.

* Fast informed bound (Hauskrecht 2000): one vector per action,
  ``Q(s, a) = R(s, a) + gamma sum_z max_a' sum_s' T(s, a, s') O(z | s', a) Q(s', a')``, iterated from the MDP's
  ``Q*`` (the QMDP bound, which the operator maps below itself), so every iterate is an upper bound of ``V*``
  and the bound is valid from the first instant; ``V_FIB(b) = max_a b . Q(., a)``.
* Sawtooth (Hauskrecht 2000; as in HSVI and SARSOP): corner values ``c(s) = max_a Q(s, a)`` and points
  ``(b_i, v_i)``; ``U(b) = min(V_FIB(b), min_i c.b + phi_i(b) (v_i - c.b_i))`` with
  ``phi_i(b) = min_{s in supp b_i} b(s) / b_i(s)``. A point's value is a Bellman backup (thesis Eq. 2.4) of
  the current bound, ``max_a [R(b, a) + gamma sum_z P(z | b, a) U(b_az)]``, capped by ``U(b)``, so the bound
  stays above ``V*`` and never rises.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.products import dot
from embodied_adhoc.decision.value_iteration import value_iteration


def fast_informed_bound(pomdp: POMDP, tolerance: float = 1e-6, max_iterations: int = 100_000) -> np.ndarray:
    """``Q_FIB`` (S, A), an upper bound of ``Q*`` of the POMDP at every stage of its iteration (the iteration
    stops at ``tolerance`` or ``max_iterations``, never at a time: what it computes depends on the model alone)."""
    q_values = value_iteration(pomdp.as_mdp(), tolerance=tolerance).q_values.copy()
    n_states = pomdp.n_states
    # Per action, only the possible (s, z) pairs: the sparse (pairs x S') matrix of T(s, a, s') O(z | s', a)
    # and the start state of each pair. Pairs with P(z | s, a) = 0 add max_a' 0 = 0 to the sum over z, so they
    # are left out (a dense (Z, S, A) array per action grows with Z x S x A, prohibitive for models with many
    # observations such as identity observations).
    joined = [
        _joint_rows(transition, observation)
        for transition, observation in zip(pomdp.transitions, pomdp.observations, strict=True)
    ]
    gamma = pomdp.discount
    for _ in range(max_iterations):
        new = np.empty_like(q_values)
        for action, (matrix, starts) in enumerate(joined):
            best = (matrix @ q_values).max(axis=1) if matrix.shape[0] else np.empty(0)  # max_a' per (s, z)
            new[:, action] = pomdp.rewards[:, action] + gamma * np.bincount(starts, best, minlength=n_states)
        new = np.minimum(new, q_values)  # both are upper bounds; keep the tighter one (monotone anyway)
        change = float(np.max(q_values - new))
        q_values = new
        if change <= tolerance:
            break
    return q_values


def _joint_rows(transition: sp.csr_matrix, observation: sp.csr_matrix) -> tuple[sp.csr_matrix, np.ndarray]:
    """``M[(s, z), s'] = T(s, s') O(z | s')`` on the pairs ``(s, z)`` with a nonzero row, sorted by ``(s, z)``,
    and ``s`` of each row. Built from the nonzeros: each entry of T joined with the entries of O's row ``s'``."""
    transition, observation = sp.csr_matrix(transition), sp.csr_matrix(observation)
    transition.sort_indices()
    transition.eliminate_zeros()
    observation.eliminate_zeros()
    n_states, n_obs = transition.shape[0], observation.shape[1]
    starts = np.repeat(np.arange(n_states), np.diff(transition.indptr))
    ends = transition.indices
    counts = np.diff(observation.indptr)[ends]
    owner = np.repeat(np.arange(len(ends)), counts)  # the T entry of each joined entry
    offset = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
    position = observation.indptr[ends][owner] + offset
    keys = starts[owner] * n_obs + observation.indices[position]
    values = transition.data[owner] * observation.data[position]
    pairs, rows = np.unique(keys, return_inverse=True)
    matrix = sp.csr_matrix((values, (rows.ravel(), ends[owner])), shape=(len(pairs), n_states))
    return matrix, pairs // n_obs


class SawtoothBound:
    """The fast informed bound with sawtooth points; :meth:`values` and :meth:`update` take dense beliefs."""

    def __init__(self, pomdp: POMDP, fib: np.ndarray) -> None:
        self.pomdp = pomdp
        self.fib = fib  # (S, A)
        self.corners = fib.max(axis=1)  # (S,)
        self.transitions_t = tuple(m.T.tocsr() for m in pomdp.transitions)
        self.observations_t = tuple(m.T.tocsr() for m in pomdp.observations)  # (Z, S') per action
        # Sawtooth points, flattened: the supports of all b_i one after the other, their masses, each point's
        # first position, and v_i; excess v_i - c.b_i is cached until a point or a corner changes.
        self._support = np.empty(0, dtype=np.int64)
        self._masses = np.empty(0)
        self._starts = np.empty(0, dtype=np.int64)
        self._values = np.empty(0)
        self._excess: np.ndarray | None = None
        self._indicator: sp.csr_matrix | None = (
            None  # (P, S): 1 on each point's support; rebuilt when one is added
        )
        self._sizes = np.empty(0, dtype=np.int64)

    @property
    def n_points(self) -> int:
        return len(self._values)

    def values(self, beliefs: np.ndarray) -> np.ndarray:
        """``U(b)`` for each row of ``beliefs`` (n, S)."""
        beliefs = np.atleast_2d(beliefs)
        bound = dot(beliefs, self.fib).max(axis=1)
        if not self.n_points:
            return bound
        if self._excess is None:
            self._excess = self._values - np.add.reduceat(
                self._masses * self.corners[self._support], self._starts
            )
        if self._indicator is None:
            sizes = np.diff(np.append(self._starts, len(self._support)))
            indptr = np.append(self._starts, len(self._support))
            self._indicator = sp.csr_matrix(
                (np.ones(len(self._support)), self._support, indptr),
                shape=(self.n_points, self.pomdp.n_states),
            )
            self._sizes = sizes
        # phi_i(b) > 0 only where b covers the whole support of b_i: find those (point, belief) pairs with one
        # sparse product, then take the ratios on them alone (phi is 0 elsewhere, and so is its term).
        covered = np.asarray(self._indicator @ (beliefs > 0.0).T.astype(np.float64))  # (P, n)
        points, rows = np.nonzero(covered >= self._sizes[:, None])
        terms = np.zeros(beliefs.shape[0])
        if points.size:
            lengths = self._sizes[points]
            positions = np.repeat(self._starts[points] - np.cumsum(lengths) + lengths, lengths) + np.arange(
                lengths.sum()
            )
            # A mass near the smallest doubles can make its ratio overflow to inf: harmless, since a point's masses
            # sum to 1, so one of them is >= 1 / its support size and phi (their minimum) stays finite.
            with np.errstate(over="ignore"):
                ratios = beliefs[np.repeat(rows, lengths), self._support[positions]] / self._masses[positions]
            phi = np.minimum.reduceat(ratios, np.cumsum(lengths) - lengths)
            np.minimum.at(terms, rows, phi * self._excess[points])
        sawtooth = dot(beliefs, self.corners) + terms
        return np.minimum(bound, sawtooth)

    def successors(self, belief: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Per action: the observations of nonzero probability, their probabilities and posteriors (Eq. 2.3)."""
        result = []
        for action in range(self.pomdp.n_actions):
            predicted = self.transitions_t[action] @ belief
            joint = self.observations_t[action].multiply(predicted[None, :]).tocsr()  # (Z, S')
            probabilities = np.asarray(joint.sum(axis=1)).ravel()
            possible = np.flatnonzero(probabilities > 0.0)
            posteriors = joint[possible].toarray() / probabilities[possible][:, None]
            result.append((possible, probabilities[possible], posteriors))
        return result

    def q_values(self, belief: np.ndarray, successors=None) -> np.ndarray:
        """``R(b, a) + gamma sum_z P(z | b, a) U(b_az)`` for every action (A,)."""
        successors = successors if successors is not None else self.successors(belief)
        # One values() call for the posteriors of every action (its cost is mostly per call, not per row).
        values = self.values(np.vstack([posteriors for _, _, posteriors in successors]))
        ends = np.cumsum([len(probabilities) for _, probabilities, _ in successors])
        expected = [
            float(dot(probabilities, part))
            for (_, probabilities, _), part in zip(successors, np.split(values, ends[:-1]), strict=True)
        ]
        return dot(belief, self.pomdp.rewards) + self.pomdp.discount * np.asarray(expected)

    def update(self, belief: np.ndarray, successors=None) -> float:
        """Back up ``U`` at ``belief`` and keep the point when it tightens the bound; returns the new ``U(b)``."""
        current = float(self.values(belief)[0])
        backed_up = float(self.q_values(belief, successors).max())
        if backed_up >= current - 1e-12:
            return current
        support = np.flatnonzero(belief > 0.0)
        if support.size == 1:  # a corner: tighten the corner value itself
            self.corners[support[0]] = backed_up
        else:
            self._starts = np.append(self._starts, len(self._support))
            self._support = np.concatenate([self._support, support])
            self._masses = np.concatenate([self._masses, belief[support]])
            self._values = np.append(self._values, backed_up)
            self._indicator = None
        self._excess = None
        return backed_up
