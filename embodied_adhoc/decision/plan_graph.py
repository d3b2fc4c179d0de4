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

    def growth_bytes(self, count: int) -> int:
        """Bytes that adding ``count`` rows allocates: the grown buffers when they no longer fit, else none."""
        if self._size + count <= self._vectors.shape[0]:
            return 0
        row = self._vectors.itemsize * self._vectors.shape[1] + 8 * (1 + self._children.shape[1])
        return self._capacity_for(count) * row

    def _capacity_for(self, count: int) -> int:
        # By half: growing copies the buffer (old and new held at once), and doubling left up to half of a graph
        # that is most of a solve's memory unused.
        return max(self._vectors.shape[0] + self._vectors.shape[0] // 2, self._size + count)

    def reserve(self, count: int) -> None:
        """Make room for ``count`` more rows now (the buffers grow as :meth:`add` would grow them): growing copies
        the graph, and a solver calls this where little else is held (before a stage, whose own arrays are then
        not yet allocated). Rows beyond the graph's size are not written, so they take address space only."""
        if self._size + count > self._vectors.shape[0]:
            capacity = self._capacity_for(count)
            self._vectors = _grown(self._vectors, capacity)
            self._actions = _grown(self._actions, capacity)
            self._children = _grown(self._children, capacity)

    def add(self, vectors: np.ndarray, actions: np.ndarray, children: np.ndarray) -> np.ndarray:
        """Append plans whose ``children`` are rows of this graph; returns their rows."""
        first, count = self._size, len(vectors)
        self.reserve(count)
        self._vectors[first : first + count] = vectors
        self._actions[first : first + count] = actions
        self._children[first : first + count] = children
        self._size += count
        return np.arange(first, self._size)

    def redirect(self, replacement: np.ndarray) -> None:
        """Continue with ``replacement[row]`` wherever a plan continued with ``row`` (a dominating vector)."""
        self._children[: self._size] = replacement[self.children]

    def prune_dominated(self, roots: np.ndarray, supports: Supports | None = None) -> np.ndarray:
        """Drop the rows outside ``roots`` that a root dominates, continuing with that root wherever a plan
        continued with them, then the rows no longer reachable; returns the rows of ``roots`` afterwards.

        Without ``supports`` a root must dominate at every state; ``max_k alpha_k . b`` over the kept rows is then
        unchanged at every belief (a dropped row is below a kept one everywhere). With ``supports``
        (:func:`observation_supports`) each continuation ``(row, z)`` is tested on its own: a root that dominates
        the continuation at the end states that can emit ``z`` after the row's action replaces it there, since
        ``O(z | s', a) = 0`` elsewhere and the plan's value reads the continuation only through ``O_{a,z}``. The
        kept set's value is then unchanged at the roots' beliefs (``max`` over the roots), and may be lower only at
        beliefs where a dropped non-root row was best. Either way every kept plan still earns at least its vector:
        its continuations only got larger where they count, and the Bellman operator of a plan is monotone (cycles
        through a root included). Comparisons are exact, so the result is the same on any host.
        """
        roots = np.asarray(roots, dtype=np.int64)
        if supports is not None:
            if roots.size and self._redirect_by_support(roots, supports):
                return self.keep_closure(roots, force=True)
            return roots
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

    def _redirect_by_support(self, roots: np.ndarray, supports: Supports) -> bool:
        """Per support of :func:`observation_supports`: the continuations into non-root rows that it governs,
        each replaced by a root that dominates it on those states (``_dominated``); True if any was."""
        is_root = np.zeros(len(self), dtype=bool)
        is_root[roots] = True
        children, actions = self._children[: self._size], self.actions
        root_vectors = self.vectors[roots]
        changed = False
        for states, pairs in supports:
            edge = pairs[actions] & ~is_root[children]  # (rows, Z): continuations this support governs
            parents, observations = np.nonzero(edge)
            if parents.size == 0:
                continue
            candidates, inverse = np.unique(children[parents, observations], return_inverse=True)
            if states.size == 0:  # an impossible observation: its continuation is never read
                found, dominator = np.ones(candidates.size, dtype=bool), np.zeros(candidates.size, np.int64)
            else:
                found = np.zeros(candidates.size, dtype=bool)
                dominator = np.zeros(candidates.size, dtype=np.int64)
                dominators = np.ascontiguousarray(root_vectors[:, states])
                for first in range(0, candidates.size, _PRUNE_BLOCK):
                    part = candidates[first : first + _PRUNE_BLOCK]
                    found[first : first + part.size], dominator[first : first + part.size] = _dominated(
                        self._vectors[np.ix_(part, states)], dominators
                    )
            hit = found[inverse.ravel()]
            if hit.any():
                children[parents[hit], observations[hit]] = roots[dominator[inverse.ravel()[hit]]]
                changed = True
        return changed

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
        # In place, by blocks (a copy of the kept rows beside the buffer would double the graph's memory for the
        # moment): keep is sorted, so keep[i] >= i and a block reads only rows that no earlier block overwrote.
        for first in range(0, keep.size, _PRUNE_BLOCK):
            part = keep[first : first + _PRUNE_BLOCK]
            last = first + part.size
            self._vectors[first:last] = self._vectors[part]
            self._actions[first:last] = self._actions[part]
            self._children[first:last] = renumber[self._children[part]]
        self._size = keep.size
        return renumber[roots]


Supports = tuple[tuple[np.ndarray, np.ndarray], ...]


def observation_supports(observations: tuple) -> Supports:
    """The distinct sets of end states that can emit an observation after an action, each with the (A, Z)
    boolean table of the pairs ``(a, z)`` whose states they are, from the (S, Z) observation matrices
    ``O(z | s', a)`` per action: what :meth:`PlanGraph.prune_dominated` tests continuations on."""
    n_actions, n_obs = len(observations), observations[0].shape[1]
    groups: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
    for action, matrix in enumerate(observations):
        by_observation = matrix.T.tocsr()  # (Z, S)
        by_observation.sort_indices()
        for z in range(n_obs):
            states = by_observation.indices[by_observation.indptr[z] : by_observation.indptr[z + 1]]
            states = states.astype(np.int64)
            pairs = groups.setdefault(states.tobytes(), (states, np.zeros((n_actions, n_obs), dtype=bool)))[1]
            pairs[action, z] = True
    return tuple(groups.values())


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
