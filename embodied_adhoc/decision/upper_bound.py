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

_COVER_BLOCK_ENTRIES = 1 << 18  # (points x beliefs) support counts formed at once by SawtoothBound.values


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
        n_states, n_obs = pomdp.n_states, pomdp.n_observations
        # The successors of a belief for all actions and observations from two fixed-pattern products: the
        # predicted beliefs of every action stacked, (A S, S) @ b, then the joint P(z, s' | b, a) as the data of
        # one (A Z, S') matrix whose entries are O(z | s', a) times a gathered predicted mass. Row (a, z) sums
        # its entries in increasing s', as a per-action product would, so the bits do not depend on the batching.
        self._predict = sp.vstack([m.T.tocsr() for m in pomdp.transitions], format="csr")
        joint = sp.vstack([m.T.tocsr() for m in pomdp.observations], format="csr")  # (A Z, S')
        joint.sort_indices()
        self._joint = joint
        self._joint_rows = np.repeat(np.arange(joint.shape[0]), np.diff(joint.indptr))
        self._filled = (
            np.diff(joint.indptr) > 0
        )  # rows (a, z) with an entry: their starts delimit the row sums
        self._gather = (self._joint_rows // n_obs) * n_states + joint.indices  # predicted mass of each entry
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
        points, rows = self._covering_pairs(beliefs)
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

    def _covering_pairs(self, beliefs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The (point, belief) pairs where the belief covers the point's whole support, in row-major order (as
        ``np.nonzero`` of the whole (P, n) table gives them), from that table formed a block of points at a time:
        whole, it is the largest array of a solve's last upper-bound rounds, when the points are many."""
        covers = (beliefs > 0.0).T.astype(np.float64)  # (S, n)
        step = max(1, _COVER_BLOCK_ENTRIES // max(beliefs.shape[0], 1))
        points, rows = [], []
        for first in range(0, self.n_points, step):
            covered = np.asarray(self._indicator[first : first + step] @ covers)  # (block, n) support counts
            block_points, block_rows = np.nonzero(covered >= self._sizes[first : first + step, None])
            points.append(block_points + first)
            rows.append(block_rows)
        return np.concatenate(points), np.concatenate(rows)

    def successors(self, belief: np.ndarray) -> Successors:
        """Per action: the observations of nonzero probability, their probabilities and posteriors (Eq. 2.3)."""
        predicted = self._predict @ belief  # (A S,)
        entries = self._joint.data * predicted[self._gather]
        # Row sums as scipy's CSR sum(axis=1) takes them of a per-action product (np.add.reduceat over each row's
        # entries, zeros included): the same bits as summing each action's joint alone.
        totals = np.zeros(self._joint.shape[0])
        totals[self._filled] = np.add.reduceat(entries, self._joint.indptr[:-1][self._filled])
        nonzero = entries != 0.0
        possible = np.flatnonzero(totals > 0.0)
        rank = np.full(totals.shape[0], -1)
        rank[possible] = np.arange(possible.size)
        kept = (rank[self._joint_rows] >= 0) & nonzero
        posteriors = np.zeros((possible.size, self.pomdp.n_states))
        rows = self._joint_rows[kept]
        posteriors[rank[rows], self._joint.indices[kept]] = entries[kept] / totals[rows]
        return Successors(
            possible, totals[possible], posteriors, self.pomdp.n_observations, self.pomdp.n_actions
        )

    def q_values(self, belief: np.ndarray, successors: Successors | None = None) -> np.ndarray:
        """``R(b, a) + gamma sum_z P(z | b, a) U(b_az)`` for every action (A,)."""
        return self.q_values_and_successor_values(belief, successors)[0]

    def q_values_and_successor_values(
        self, belief: np.ndarray, successors: Successors | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`q_values` and ``U`` of every posterior (rows of ``successors.posteriors``), from one
        :meth:`values` call."""
        successors = successors if successors is not None else self.successors(belief)
        values = self.values(successors.posteriors)
        # Each action's sum over its observations in increasing z (the rows of one CSR product).
        expected = np.asarray(successors.by_action @ values).ravel()
        return dot(belief, self.pomdp.rewards) + self.pomdp.discount * expected, values

    def update(self, belief: np.ndarray, successors: Successors | None = None) -> float:
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


class Successors:
    """The possible branches ``(a, z)`` of one belief, in increasing ``a`` then ``z``: ``pairs`` (m,) is
    ``a Z + z``, ``probabilities`` (m,) ``P(z | b, a)``, ``posteriors`` (m, S) ``b_az``. ``successors[a]`` is
    action ``a``'s ``(observations, probabilities, posteriors)``."""

    def __init__(
        self, pairs: np.ndarray, probabilities: np.ndarray, posteriors: np.ndarray, n_obs: int, n_actions: int
    ) -> None:
        self.pairs, self.probabilities, self.posteriors = pairs, probabilities, posteriors
        self.actions = pairs // n_obs
        self.observations = pairs % n_obs
        self.bounds = np.searchsorted(self.actions, np.arange(n_actions + 1))
        # (A, m): P(z | b, a) in row a, the weights of each action's expectation over its branches
        self.by_action = sp.csr_matrix(
            (probabilities, np.arange(pairs.size), self.bounds), shape=(n_actions, pairs.size)
        )

    def __len__(self) -> int:
        return len(self.bounds) - 1

    def __getitem__(self, action: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        part = slice(self.bounds[action], self.bounds[action + 1])
        return self.observations[part], self.probabilities[part], self.posteriors[part]
