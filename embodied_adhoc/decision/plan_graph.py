"""Alpha vectors kept with their conditional plans, so that the greedy policy achieves the value it claims.

A backed-up vector ``alpha = R_a + gamma T_a sum_z O_z alpha_{c(z)}`` is the value of the plan "do ``a``, then
after ``z`` follow the plan of ``alpha_{c(z)}``" (thesis Eq. 2.4). Perseus replaces ``V_n`` by ``V_{n+1}``, which
is only guaranteed to be at least ``V_n`` on the belief set: the continuation vectors ``alpha_{c(z)}`` of
``V_{n+1}`` may be gone, and at the beliefs the policy then reaches ``V_{n+1}`` can be far below them. Acting
greedily on ``V_{n+1}`` alone then earns less than ``V_{n+1}(b0)`` (Tag at 1,000 beliefs: -11.0 simulated for a
claimed -6.89).

The graph keeps every vector reachable from the current set through continuations (its closure). For a set
closed that way, ``V(b) = alpha_k . b <= R(b, a_k) + gamma sum_z P(z | b, a_k) V(b_z)`` at every belief, with
``k`` the greedy vector: the greedy policy's value is at least ``V`` everywhere (by monotonicity of its Bellman
operator), so the saved policy achieves its reported lower bound in expectation.
"""

from __future__ import annotations

import numpy as np

_KEY_STATES = (
    8  # per row, the states its dominance test reads first (where it is closest to the roots' envelope)
)
_DOMINATOR_TRIES = 8  # candidate dominators tested per row, in root order
_PRUNE_BLOCK = 512  # rows whose (rows x roots) candidate table is built at once


class PlanGraph:
    """Vectors (M, S), their first actions (M,) and continuation rows (M, Z) into the same arrays.

    Stored in buffers that grow by doubling, and compacted only when a quarter of the rows became unreachable
    (copying the whole graph at every Perseus stage took 9 % of a Tag solve).
    """

    def __init__(self, vectors: np.ndarray, actions: np.ndarray, children: np.ndarray) -> None:
        self._vectors = np.ascontiguousarray(vectors, dtype=np.float64)
        self._actions = np.asarray(actions, dtype=np.int64)
        self._children = np.asarray(children, dtype=np.int64)
        self._size = self._vectors.shape[0]

    @classmethod
    def of_blind_policies(cls, vectors: np.ndarray, n_observations: int) -> PlanGraph:
        """The blind-policy vectors "always do a": each continues with itself after every observation."""
        count = vectors.shape[0]
        return cls(vectors, np.arange(count), np.repeat(np.arange(count)[:, None], n_observations, axis=1))

    @property
    def vectors(self) -> np.ndarray:
        return self._vectors[: self._size]

    @property
    def actions(self) -> np.ndarray:
        return self._actions[: self._size]

    @property
    def children(self) -> np.ndarray:
        return self._children[: self._size]

    def __len__(self) -> int:
        return self._size

    def add(self, vectors: np.ndarray, actions: np.ndarray, children: np.ndarray) -> np.ndarray:
        """Append plans whose ``children`` are rows of this graph; returns their rows."""
        first, count = self._size, len(vectors)
        if first + count > self._vectors.shape[0]:
            capacity = max(2 * self._vectors.shape[0], first + count)
            self._vectors = _grown(self._vectors, capacity)
            self._actions = _grown(self._actions, capacity)
            self._children = _grown(self._children, capacity)
        self._vectors[first : first + count] = vectors
        self._actions[first : first + count] = actions
        self._children[first : first + count] = children
        self._size += count
        return np.arange(first, self._size)

    def redirect(self, replacement: np.ndarray) -> None:
        """Continue with ``replacement[row]`` wherever a plan continued with ``row`` (a dominating vector)."""
        self._children[: self._size] = replacement[self.children]

    def prune_dominated(self, roots: np.ndarray) -> np.ndarray:
        """Drop the rows outside ``roots`` that a root dominates at every state, continuing with that root wherever
        a plan continued with them, then the rows no longer reachable; returns the rows of ``roots`` afterwards.

        ``max_k alpha_k . b`` over the kept rows is unchanged at every belief (a dropped row is below a kept one
        everywhere), and every kept plan still earns at least its vector: its continuations only got larger
        pointwise, and the Bellman operator of a plan is monotone (cycles through a root included). Comparisons
        are exact, so the result is the same on any host.
        """
        roots = np.asarray(roots, dtype=np.int64)
        others = np.setdiff1d(np.arange(len(self)), roots)
        if others.size == 0 or roots.size == 0:
            return roots
        found, dominator = _dominated(self.vectors[others], self.vectors[roots])
        if not found.any():
            return roots
        replacement = np.arange(len(self))
        replacement[others[found]] = roots[dominator[found]]
        self.redirect(replacement)
        return self.keep_closure(roots, force=True)

    def closure(self, roots: np.ndarray) -> np.ndarray:
        """Sorted rows reachable from ``roots`` through continuations (the roots included)."""
        reached = np.zeros(len(self), dtype=bool)
        frontier = np.unique(roots)
        children = self.children
        while frontier.size:
            reached[frontier] = True
            # The next level by marks, not np.unique (its sort of every continuation of the level cost 12x more
            # on a plan graph of 110 stages).
            fresh = np.zeros(len(self), dtype=bool)
            fresh[children[frontier]] = True
            fresh &= ~reached
            frontier = np.flatnonzero(fresh)
        return np.flatnonzero(reached)

    def keep_closure(self, roots: np.ndarray, force: bool = False) -> np.ndarray:
        """Drop the plans not reachable from ``roots`` (once they are a quarter of the graph, or when ``force``d:
        until then they stay, unused but still exact); returns the rows of ``roots`` afterwards."""
        keep = self.closure(roots)
        if keep.size == len(self) or (not force and keep.size > 0.75 * len(self)):
            return np.asarray(roots)
        renumber = np.full(len(self), -1, dtype=np.int64)
        renumber[keep] = np.arange(keep.size)
        self._vectors = self.vectors[keep]
        self._actions = self.actions[keep]
        self._children = renumber[self.children[keep]]
        self._size = keep.size
        return renumber[roots]


def _dominated(rows: np.ndarray, dominators: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per row of ``rows``: whether a row of ``dominators`` is >= it at every state, and the first one found.

    A row above the dominators' pointwise envelope at some state has none; for the others, a dominator must be
    >= the row at the states where it comes closest to that envelope (``_KEY_STATES`` of them), and the first
    ``_DOMINATOR_TRIES`` dominators passing that filter are compared at every state."""
    found = np.zeros(len(rows), dtype=bool)
    dominator = np.zeros(len(rows), dtype=np.int64)
    envelope = dominators.max(axis=0)
    keys = min(_KEY_STATES, rows.shape[1])
    for first in range(0, len(rows), _PRUNE_BLOCK):
        part = rows[first : first + _PRUNE_BLOCK]
        margin = part - envelope
        open_rows = np.flatnonzero(margin.max(axis=1) <= 0.0)
        if open_rows.size == 0:
            continue
        margin = margin[open_rows]
        states = np.argpartition(-margin, keys - 1, axis=1)[:, :keys]  # (open, keys)
        passes = np.ones((open_rows.size, len(dominators)), dtype=bool)
        for k in range(keys):
            column = states[:, k]
            passes &= dominators[:, column].T >= part[open_rows, column][:, None]
        for _ in range(_DOMINATOR_TRIES):
            if not passes.any():
                break
            has = passes.any(axis=1)
            candidate = np.argmax(passes, axis=1)
            which = np.flatnonzero(has)
            ok = np.all(dominators[candidate[which]] >= part[open_rows[which]], axis=1)
            hit = which[ok]
            found[first + open_rows[hit]] = True
            dominator[first + open_rows[hit]] = candidate[hit]
            passes[hit] = False
            passes[which[~ok], candidate[which[~ok]]] = False
    return found, dominator


def _grown(array: np.ndarray, capacity: int) -> np.ndarray:
    grown = np.empty((capacity,) + array.shape[1:], dtype=array.dtype)
    grown[: len(array)] = array
    return grown
