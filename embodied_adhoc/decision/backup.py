"""Vectorised point-based Bellman backup (thesis Eq. 2.4 restricted to a set of beliefs).

For beliefs ``B`` (n x S) and an alpha set ``Gamma`` (K x S) the backup at ``b`` is

    alpha_a^b = R(., a) + gamma * sum_z T_a (O_{a,z} * Gamma[k*_{a,z}(b)]),
    k*_{a,z}(b) = argmax_k  sum_{s'} (b T_a)(s') O(z | s', a) Gamma[k](s'),

and ``backup(b) = alpha_{a*}^b`` for the action maximising ``b . alpha_a^b``. All beliefs of a batch are handled
at once: one sparse product ``B T_a`` per action, then the scores of every vector on every branch. With sparse
observations the scores are computed on the support of the predicted beliefs: one sparse (possible branches x S)
matrix ``W[(i, z), s'] = (b_i T_a)(s') O(z | s', a)`` times the dense ``Gamma^T`` (float32), so the cost is ``K``
times the nonzeros of ``W``, never more than a product with the projection of all vectors on all observations
(``n * K * nnz(O_a)``) and less by the predicted beliefs' density; dense observation models use dense products
with that projection, a block of vectors at a time. Each action's value follows from the best scores (float64, on
the same entries); the vector, mapped back through ``T_a`` by two sparse products, is built only for each belief's
best action.

Every product that decides a choice gives the same bits on any host (products.py): sparse products are scipy's,
in one summation order; the dense projection's BLAS scores are rescored in a fixed order wherever a runner-up lies
within the summation-order error bound of the best (:func:`_dense_choices`).

Branches ``(a, z)`` impossible at a belief still get a continuation vector (the one best for a uniform spread
over the states emitting ``z``): dropping them would give a vector that is not the value of any plan, and the
solver's value would no longer be a lower bound.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.products import dot
from embodied_adhoc.errors import SolverError

_DENSE_DENSITY = 0.1  # observation-matrix density from which scores use a dense projection of the vectors
_DENSE_MAX_ELEMENTS = 20_000_000
_EPS = float(np.finfo(np.float64).eps)
_SPLIT_MIN_WORK = 1 << 22  # multiply-adds (nnz x columns) from which a product is split over the threads
_BLOCK_ENTRIES = 1 << 18  # entries of a reduced product formed at once (RowProducts: 2 MiB of float64)
DENSE_BLOCK_BYTES = 8 * _BLOCK_ENTRIES  # a block of the dense projection, or of its scores (_dense_choices)


class RowProducts:
    """Products ``csr @ dense`` split by rows over a persistent pool of ``threads`` threads.

    Row ``i`` of a CSR product is the sum over that row's entries in stored order whichever rows are computed with
    it, so the split results are bit-identical to one product; scipy's kernel releases the GIL, so the parts run on
    separate cores. ``threads=1`` (the library default: parallel sweeps already use worker processes) never starts
    a thread. Parts are balanced by stored entries; products under ``_SPLIT_MIN_WORK`` multiply-adds run whole (a
    thread hand-off costs more).
    """

    def __init__(self, threads: int = 1) -> None:
        if threads < 1:
            raise SolverError(f"threads must be an integer >= 1, got {threads!r}")
        self.threads = threads
        # threads - 1 workers: the calling thread computes the first part itself.
        self._pool = (
            ThreadPoolExecutor(threads - 1, thread_name_prefix="row-products") if threads > 1 else None
        )

    def __call__(
        self,
        matrix: sp.csr_matrix | np.ndarray,
        dense: np.ndarray,
        reduce: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> np.ndarray:
        """``reduce(matrix @ dense)`` for a ``reduce`` that works row by row (e.g. an argmax over axis 1).

        With a ``reduce``, the product is formed ``_BLOCK_ENTRIES`` entries at a time (blocks of rows, each reduced
        before the next): the solver's value products over the whole belief set (|B| x vectors) and the branch
        scores of a batch would otherwise be its largest arrays, and a row's entries are the same in any block."""
        if not sp.issparse(
            matrix
        ):  # dense rows (beliefs) in CSR form: scipy's fixed summation order, never BLAS
            matrix = sp.csr_matrix(matrix)
        dense = np.ascontiguousarray(dense)  # scipy copies a non-contiguous operand per product: once, here
        columns = dense.shape[1] if dense.ndim == 2 else 1
        n_rows = matrix.shape[0]
        if reduce is None or n_rows * columns <= _BLOCK_ENTRIES:
            return self._split(matrix, dense, reduce or _identity)
        matrix = matrix.tocsr()
        step = max(1, _BLOCK_ENTRIES // columns)
        return np.concatenate(
            [
                self._split(_row_range(matrix, first, min(first + step, n_rows)), dense, reduce)
                for first in range(0, n_rows, step)
            ],
            axis=0,
        )

    def _split(
        self, matrix: sp.csr_matrix, dense: np.ndarray, reduce: Callable[[np.ndarray], np.ndarray]
    ) -> np.ndarray:
        """``reduce(matrix @ dense)``, split by rows over the threads when it is large enough."""
        if self._pool is None or matrix.nnz * dense.shape[-1] < _SPLIT_MIN_WORK:
            return reduce(dot(matrix, dense))
        matrix = matrix.tocsr()
        indptr = matrix.indptr
        bounds = np.searchsorted(indptr, np.linspace(0, matrix.nnz, self.threads + 1)[1:-1], side="left")
        bounds = np.unique(np.concatenate([[0], bounds, [matrix.shape[0]]]))
        parts = [_row_range(matrix, a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
        others = [self._pool.submit(lambda part: reduce(part @ dense), part) for part in parts[1:]]
        results = [reduce(parts[0] @ dense)] + [future.result() for future in others]
        return results[0] if len(results) == 1 else np.concatenate(results, axis=0)

    def close(self) -> None:
        """Stop the threads (idempotent)."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None


def _identity(array: np.ndarray) -> np.ndarray:
    return array


def _row_range(matrix: sp.csr_matrix, first: int, last: int) -> sp.csr_matrix:
    """Rows ``[first, last)`` of a CSR matrix, on views of its entries (no copy)."""
    start, end = matrix.indptr[first], matrix.indptr[last]
    return sp.csr_matrix(
        (matrix.data[start:end], matrix.indices[start:end], matrix.indptr[first : last + 1] - start),
        shape=(last - first, matrix.shape[1]),
    )


@dataclass(frozen=True)
class PreparedAlphas:
    """A value function with its per-action projections (built on first use, reused for many batches)."""

    alphas: np.ndarray
    alphas_t: np.ndarray  # (S, K) float32, contiguous: right operand of the support-restricted scores
    projections: dict[int, np.ndarray | None]
    fallbacks: tuple[np.ndarray, ...]
    state_best: dict[str, np.ndarray]  # per end state, for single-state observations (see _state_best)


class BackupOperator:
    """Precomputed sparse observation structure of a POMDP; ``backup(beliefs, alphas)`` is the operator."""

    def __init__(self, pomdp: POMDP, threads: int = 1) -> None:
        self.pomdp = pomdp
        # The branch scores (and the solver's value products) split by rows over this many threads; close() ends them.
        self.products = RowProducts(threads)
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
            matrix.nnz < _DENSE_DENSITY * pomdp.n_states * pomdp.n_observations
            for matrix in self.observation_rows
        )
        # backup_one's layout: every action's T_a^T and O_a stacked, row a * S + s', so one product predicts a
        # belief under every action and one CSR row lookup finds the observations of each predicted state.
        self._stacked_transitions_t = sp.vstack(self.transitions_t, format="csr")
        self._stacked_observations = sp.vstack(self.observation_rows, format="csr")
        self._stacked_observations.sort_indices()

    def close(self) -> None:
        """Stop the product threads (``threads > 1``); the operator still works afterwards, on one thread."""
        self.products.close()

    def prepare(self, alphas: np.ndarray) -> PreparedAlphas:
        """A value function ready for many :meth:`backup` calls against it (projections built lazily)."""
        alphas = np.ascontiguousarray(alphas, dtype=np.float64)
        # For branches impossible at a belief: the vector best for a uniform spread over the states emitting z.
        fallbacks = tuple(np.argmax(scores, axis=1) for scores in self.fallback_scores(alphas))
        return PreparedAlphas(alphas, np.ascontiguousarray(alphas.T, dtype=np.float32), {}, fallbacks, {})

    def fallback_scores(self, alphas: np.ndarray) -> tuple[np.ndarray, ...]:
        """Per action, the (Z, K) values of each vector for a uniform spread over the states emitting each
        observation (the fallback continuation of impossible branches is each row's first maximum)."""
        alphas_t = np.ascontiguousarray(np.atleast_2d(alphas).T)
        return tuple(np.asarray(entry[4] @ alphas_t) for entry in self.entries)

    def prepare_parts(
        self, alphas: np.ndarray, alphas_t: np.ndarray, fallback_scores: tuple[np.ndarray, ...]
    ) -> PreparedAlphas:
        """:meth:`prepare` from parts a caller keeps up to date as its vectors change (the solver's Gauss-Seidel
        stages): ``alphas`` (K, S) float64, ``alphas_t`` its (S, K) float32 transpose, and
        :meth:`fallback_scores` of it. The same object as ``prepare(alphas)``."""
        fallbacks = tuple(np.argmax(scores, axis=1) for scores in fallback_scores)
        return PreparedAlphas(alphas, alphas_t, {}, fallbacks, {})

    def _state_best(self, prepared: PreparedAlphas) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per end state ``s``: the largest float32 value ``m_s`` of any vector, the first vector reaching it, and
        whether it is *clean*: no other vector lies within ``2^-20 |m_s|`` below ``m_s``.

        A branch with a single entry ``w > 0`` at ``s`` (an observation only ``s`` emits, or only one reachable state
        emitting it) has the float32 scores ``w * alpha_k(s)``, whose first maximum is that first vector when ``s``
        is clean and ``w m_s`` is a normal float32 (rounding is monotone, and values farther below ``m_s`` stay
        several units in the last place below it after the product), i.e. exactly what the product and argmax would
        pick. Built once per value function, on first use."""
        if not prepared.state_best:
            values = prepared.alphas_t  # (S, K) float32
            top = values.max(axis=1)
            first = np.argmax(values, axis=1)
            near = np.count_nonzero(values >= (top - np.abs(top) * 2.0**-20)[:, None], axis=1)
            clean = near == np.count_nonzero(values == top[:, None], axis=1)
            prepared.state_best.update(top=top, first=first, clean=clean)
        best = prepared.state_best
        return best["top"], best["first"], best["clean"]

    def _dense_observations(self, prepared: PreparedAlphas, action: int) -> np.ndarray | None:
        """The dense (S, Z) observation matrix of ``action`` when its branch scores use the dense projection of every
        vector on every observation (dense observation models: a dense BLAS product then beats the
        support-restricted one despite the zeros); None when the observations are sparse or the whole projection
        would exceed ``_DENSE_MAX_ELEMENTS``. The projection itself is built by blocks of vectors
        (:func:`_dense_choices`)."""
        if action in prepared.projections:
            return None
        n_vectors, n_obs, n_states = prepared.alphas.shape[0], self.n_observations, self.pomdp.n_states
        if not self.sparse_observations[action] and n_vectors * n_obs * n_states <= _DENSE_MAX_ELEMENTS:
            return self.observation_rows[action].toarray()
        # Only "none" is remembered: the dense matrix is small, and a projection kept per action held |A| times the
        # largest array of the backup between batches.
        prepared.projections[action] = None
        return None

    def _support_choices(
        self, prepared: PreparedAlphas, action: int, predicted: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Best vector of each possible branch, scored on the support of the predicted beliefs only.

        Returns ``(observations, beliefs, best, values)`` for every branch ``(z, i)`` with ``P(z | b_i, a) > 0``,
        and per belief ``sum_z sum_s' (b_i T_a)(s') O(z | s', a) alpha_best(s')`` in float64 (the continuation
        part of the backed-up value, from the same entries). The scores are float32 (half the memory traffic of
        this, the solver's hottest product): they only choose the continuation, the vectors are then built in
        float64, so a near-tie picked differently still gives the exact value of a conditional plan.
        """
        observation = self.observation_rows[action]  # CSR (S x Z)
        n_obs = self.n_observations
        ends, columns = np.nonzero(predicted)  # predicted is (S, n)
        mass = predicted[ends, columns]
        owner, position = _row_entries(observation, ends)
        total = len(position)
        keys = columns[owner] * n_obs + observation.indices[position]  # branch (i, z) of every product entry
        if predicted.shape[1] * n_obs <= max(4 * total, 1 << 16):
            # The branches present, numbered in key order without sorting (np.unique's argsort would be a
            # large share of a backup): a mark per possible key, then its running count.
            present = np.zeros(predicted.shape[1] * n_obs, dtype=bool)
            present[keys] = True
            branch_keys, rows = np.flatnonzero(present), (np.cumsum(present) - 1)[keys]
        else:
            branch_keys, rows = np.unique(keys, return_inverse=True)
            rows = rows.ravel()
        states = ends[owner]
        entries = mass[owner] * observation.data[position]
        weights32 = entries.astype(np.float32)
        best = np.empty(len(branch_keys), dtype=np.int64)
        scored = np.ones(len(branch_keys), dtype=bool)  # branches left to the product
        single = np.bincount(rows, minlength=len(branch_keys)) == 1  # branches with one entry (one state)
        if (
            np.count_nonzero(single) * 8 >= self.pomdp.n_states
        ):  # else the per-state maxima cost more than they save
            # Their best vector is the first one best at that state where that provably equals the product's argmax
            # (_state_best; in models that observe their state, most of a batch's branches); the others stay in
            # the product.
            top, leader, clean = self._state_best(prepared)
            lone = single[rows]
            lone_rows, lone_states = rows[lone], states[lone]
            exact = clean[lone_states] & (
                np.abs(weights32[lone].astype(np.float64) * top[lone_states]) >= 1e-30
            )
            best[lone_rows[exact]] = leader[lone_states[exact]]
            scored[lone_rows[exact]] = False
        if scored.all():
            weights = sp.csr_matrix(
                (weights32, (rows, states)), shape=(len(branch_keys), self.pomdp.n_states)
            )
            best = self.products(weights, prepared.alphas_t, row_argmax)  # (branches,)
        elif scored.any():
            product_rows = np.flatnonzero(scored)
            renumber = np.cumsum(scored) - 1
            kept = scored[rows]
            weights = sp.csr_matrix(
                (weights32[kept], (renumber[rows[kept]], states[kept])),
                shape=(len(product_rows), self.pomdp.n_states),
            )
            best[product_rows] = self.products(weights, prepared.alphas_t, row_argmax)
        branch_beliefs = branch_keys // n_obs
        values = np.bincount(
            branch_beliefs[rows], entries * prepared.alphas[best[rows], states], minlength=predicted.shape[1]
        )
        return branch_keys % n_obs, branch_beliefs, best, values

    def backup_one(
        self,
        belief: np.ndarray,
        alphas: np.ndarray,
        alphas_t: np.ndarray | None,
        fallback_scores: tuple[np.ndarray, ...],
    ) -> tuple[np.ndarray, int, float, np.ndarray]:
        """The backup at one belief (S,): ``(vector (S,), action, value, children (Z,))``, the same bits as
        ``backup(belief[None, :], alphas, with_children=True, project=False)`` (row 0 of each).

        ``alphas`` (K, S) float64, ``alphas_t`` its (S, K) float32 transpose (a view into a wider buffer is read
        without a copy of the whole; None: the reached states' columns of ``alphas`` are cast to float32 here, the
        same values, so a caller need not hold a float32 copy of its whole set) and ``fallback_scores`` its
        :meth:`fallback_scores`, as a caller growing its set keeps them (the solver's trials back up one belief at a
        time). Every action and observation is handled at once: one product predicts the belief under all
        actions, one sparse (branches x S) matrix holds the weights of every possible branch ``(a, z)`` and one
        product with ``alphas_t`` scores them all; the fallback of impossible branches is found for the best
        action alone. Each branch's scores, each action's continuation and the vector are computed from the same
        entries, summed in the same order, as the batched backup's, hence the same bits.
        """
        n_states, n_obs = self.pomdp.n_states, self.n_observations
        immediate = dot(belief, self.pomdp.rewards)  # (A,): R(b, a), as a row of the batched product
        # predicted[a * S + s'] = sum_s b(s) T(s, a, s'), each row summed as the batched (S, 1) product sums it
        predicted = self._stacked_transitions_t @ belief
        flat = np.flatnonzero(
            predicted
        )  # (a, s') increasing: the batched backup's np.nonzero order per action
        mass = predicted[flat]
        observation = self._stacked_observations
        owner, position = _row_entries(observation, flat)
        keys = (flat // n_states)[owner] * n_obs + observation.indices[
            position
        ]  # branch (a, z) of each entry
        present = np.zeros(self.pomdp.n_actions * n_obs, dtype=bool)
        present[keys] = True
        branch_keys, rows = np.flatnonzero(present), (np.cumsum(present) - 1)[keys]
        states = flat[owner] % n_states
        entries = mass[owner] * observation.data[position]
        # Within a branch the entries come in increasing s', the order the batched matrix's rows are sorted in.
        # The product reads only the rows of alphas_t at the reached states (numbered in increasing order, so each
        # row's terms and their order are unchanged): a copy of those rows instead of all S.
        reached = np.flatnonzero(np.bincount(states, minlength=n_states))
        number = np.zeros(n_states, dtype=np.int64)
        number[reached] = np.arange(reached.size)
        weights = sp.csr_matrix(
            (entries.astype(np.float32), (rows, number[states])), shape=(len(branch_keys), reached.size)
        )
        scores_t = alphas_t[reached] if alphas_t is not None else alphas[:, reached].T.astype(np.float32)
        best = self.products(weights, scores_t, row_argmax)  # (branches,)
        continuation = np.bincount(
            branch_keys[rows] // n_obs, entries * alphas[best[rows], states], minlength=self.pomdp.n_actions
        )
        action = int(np.argmax(immediate + self.discount * continuation))
        chosen = np.argmax(fallback_scores[action], axis=1)  # (Z,): impossible branches' continuation
        mine = branch_keys // n_obs == action
        chosen[branch_keys[mine] % n_obs] = best[mine]
        vector = self._vectors(alphas, action, chosen[:, None])  # (S, 1)
        value = np.add.reduce(belief[:, None] * vector, axis=0)  # as the batched backup sums it
        return vector[:, 0], action, float(value[0]), chosen

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
        vectors (dense observation models use it by default; for one or a few beliefs, e.g. the solver's trials,
        building it costs more than the scores).

        Each action's value ``b . R_a + gamma sum_z max_k (b T_a O_z) . alpha_k`` is computed from the branch
        scores alone; the vector (two sparse products over all states) is built only for the best action of
        each belief (vectors of actions not chosen would be a large share of a solve).
        """
        prepared = alphas if isinstance(alphas, PreparedAlphas) else self.prepare(alphas)
        alphas = prepared.alphas
        n, n_states = beliefs.shape
        n_actions, n_obs = self.pomdp.n_actions, self.n_observations
        beliefs_t = np.ascontiguousarray(beliefs.T)  # (S, n)
        immediate = dot(beliefs, self.pomdp.rewards).T  # (A, n): R(b_i, a)
        action_values = np.empty((n_actions, n))
        chosen_by_action = np.empty((n_actions, n_obs, n), dtype=np.int64)
        for action in range(n_actions):
            # predicted[s', i] = sum_s b_i(s) T(s, a, s')  (one sparse product for the whole batch)
            predicted = self.transitions_t[action] @ beliefs_t
            chosen = chosen_by_action[action]  # (Z, n): best continuation per branch and belief
            dense = self._dense_observations(prepared, action) if project else None
            if dense is None:
                # Scored on the predicted beliefs' support: the same products as the projection's, restricted to
                # the states a belief can reach, in float32. Impossible branches keep the fallback.
                chosen[:] = prepared.fallbacks[action][:, None]
                branch_observations, branch_beliefs, best, continuation = self._support_choices(
                    prepared, action, predicted
                )
                chosen[branch_observations, branch_beliefs] = best
            else:
                branch_mass = self.entries[action][4] @ predicted  # (Z, n): P(z | b_i, a)
                chosen[:], continuation = _dense_choices(predicted, dense, branch_mass, prepared.alphas)
                impossible = branch_mass <= 0.0
                if impossible.any():
                    chosen[:] = np.where(impossible, prepared.fallbacks[action][:, None], chosen)
            action_values[action] = immediate[action] + self.discount * continuation
        best_actions = np.argmax(
            action_values, axis=0
        )  # the first of equal values, as a running maximum would
        best_vectors = np.empty((n, n_states))
        best_values = np.empty(n)
        best_children = np.empty((n, n_obs), dtype=np.int64)
        for action in np.unique(best_actions):
            which = np.flatnonzero(best_actions == action)
            chosen = chosen_by_action[action][:, which]
            vectors = self._vectors(alphas, int(action), chosen)  # (S, len(which))
            best_vectors[which] = vectors.T
            # summed over s in increasing order (a reduction over the first axis), as dot() sums
            best_values[which] = np.add.reduce(beliefs_t[:, which] * vectors, axis=0)
            best_children[which] = chosen.T
        if with_children:
            return best_vectors, best_actions, best_values, best_children
        return best_vectors, best_actions, best_values

    def _vectors(self, alphas: np.ndarray, action: int, chosen: np.ndarray) -> np.ndarray:
        """``R_a + gamma T_a sum_z O_z alphas[chosen[z, i]]`` for each column ``i`` of ``chosen`` (S, n)."""
        end_states, observations, probabilities, from_entries, _ = self.entries[action]
        # continuation[s', i] = sum_z O(z|s',a) alpha_{chosen[z,i]}(s'), gathered per observation entry.
        per_entry = alphas[chosen[observations], end_states[:, None]] * probabilities[:, None]  # (nnz, n)
        continuation = from_entries @ per_entry  # (S', n)
        return self.rewards_by_action[action][:, None] + self.discount * (
            self.transitions[action] @ continuation
        )


def _dense_choices(
    predicted: np.ndarray, dense: np.ndarray, branch_mass: np.ndarray, alphas: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Best vector of every branch ``(z, i)`` from the dense projection of the vectors on the observations
    (``dense[s', z] * alphas[k, s']``), and each belief's continuation value ``sum_z score(i, z, best)``, both the
    same on any host.

    The scores come from BLAS products (fast), whose last bits depend on the kernel. Any summation order is
    within ``gamma_S sum_s |terms| <= S u max|alpha| P(z | b_i)`` (``branch_mass``, Z x n) of the exact sum, so a
    vector more than ``margin`` (twice the distance between two orders, with slack) below a branch's best BLAS score
    is below its best fixed-order score too: the first maximum of the fixed-order scores lies among the candidates
    within ``margin``, and only those (exact ties, mostly) are rescored in a fixed order (a reduction over ``s``).
    The projection and its scores are formed for a block of vectors at a time (:func:`_vector_blocks`): each block
    adds to the running first maximum and runner-up of every branch, and keeps its entries within ``margin`` of
    the running maximum (a superset of the final candidates, since that maximum only grows); every block is formed
    in the same two buffers (blocks mapped afresh would each fault in and unmap pages of their own: time spent in
    the kernel). Which vector wins is
    the first maximum of the fixed-order scores whatever the blocks, so the result is the one of a single product.
    Impossible branches (all scores 0) are left to the caller's fallback. The continuation is summed from
    fixed-order scores of the chosen vectors alone."""
    n_states, n = predicted.shape
    n_obs = branch_mass.shape[0]
    predicted_t = np.ascontiguousarray(predicted.T)  # (n, S): left operand of every block's product
    unit = 4.0 * n_states * _EPS * float(np.abs(alphas).max())
    margin = unit * branch_mass.T + 1e-290  # (n, Z)
    possible = branch_mass.T > 0.0
    first = np.zeros((n, n_obs), dtype=np.int64)
    top = np.full((n, n_obs), -np.inf)
    second = np.full((n, n_obs), -np.inf)
    near: list[tuple[np.ndarray, ...]] = []  # per block: branch (i, z), vector k and BLAS score of candidates
    blocks = _vector_blocks(alphas.shape[0], n_states * n_obs, n * n_obs)
    widest = max((high - low for low, high in blocks), default=1)
    projection_buffer, scores_buffer = np.empty(n_states * n_obs * widest), np.empty(n * n_obs * widest)
    for low, high in blocks:
        width = high - low
        projected = projection_buffer[: n_states * n_obs * width].reshape(n_states, n_obs * width)
        np.multiply(
            dense[:, :, None], alphas[low:high].T[:, None, :], out=projected.reshape(n_states, n_obs, width)
        )
        scores = scores_buffer[: n * n_obs * width].reshape(n, n_obs * width)
        np.matmul(predicted_t, projected, out=scores)
        scores = scores.reshape(n, n_obs, width)  # (n, Z, block)
        block_first = np.argmax(scores, axis=2)
        block_top = np.take_along_axis(scores, block_first[:, :, None], axis=2)[:, :, 0]
        # the block's runner-up: its best score masked for one max pass (cheaper than counting a comparison)
        np.put_along_axis(scores, block_first[:, :, None], -np.inf, axis=2)
        block_second = scores.max(axis=2) if width > 1 else np.full_like(block_top, -np.inf)
        np.put_along_axis(scores, block_first[:, :, None], block_top[:, :, None], axis=2)
        better = block_top > top  # strictly: the first of equal maxima stays, as one argmax keeps it
        second = np.where(better, np.maximum(top, block_second), np.maximum(second, block_top))
        first = np.where(better, block_first + low, first)
        top = np.where(better, block_top, top)
        threshold = top - margin
        # Entries within margin of the running maximum: a branch's block runner-up decides whether more than its
        # block maximum can be (the candidates of those branches only: the full boolean array's nonzero costs as
        # much as the product).
        several_i, several_z = np.nonzero(possible & (block_second >= threshold))
        rows, near_k = np.nonzero(scores[several_i, several_z] >= threshold[several_i, several_z, None])
        near.append(
            (several_i[rows], several_z[rows], near_k + low, scores[several_i[rows], several_z[rows], near_k])
        )
        lone_i, lone_z = np.nonzero(possible & (block_second < threshold) & (block_top >= threshold))
        near.append((lone_i, lone_z, block_first[lone_i, lone_z] + low, block_top[lone_i, lone_z]))
    tied = possible & (second >= top - margin)
    if tied.any():
        near_i, near_z, near_k, near_scores = (np.concatenate(parts) for parts in zip(*near, strict=True))
        keep = tied[near_i, near_z] & (near_scores >= (top - margin)[near_i, near_z])
        near_i, near_z, near_k = near_i[keep], near_z[keep], near_k[keep]
        exact = _fixed_order_scores(predicted, dense, alphas, near_i, near_z, near_k)
        # per tied branch, the first (lowest k) of the largest fixed-order scores: sort by branch, -score, k
        order = np.lexsort((near_k, -exact, near_i * n_obs + near_z))
        branch = (near_i * n_obs + near_z)[order]
        leads = np.flatnonzero(np.r_[True, branch[1:] != branch[:-1]])
        first[near_i[order][leads], near_z[order][leads]] = near_k[order][leads]
    chosen = first.T  # (Z, n)
    beliefs = np.tile(np.arange(n), n_obs)
    observations = np.repeat(np.arange(n_obs), n)
    continuation = np.add.reduce(
        _fixed_order_scores(predicted, dense, alphas, beliefs, observations, chosen.ravel()).reshape(
            n_obs, n
        ),
        axis=0,
    )
    return chosen, continuation


def _vector_blocks(n_vectors: int, projection_row: int, scores_row: int) -> list[tuple[int, int]]:
    """Ranges of vectors whose projection (``projection_row`` entries a vector) and scores (``scores_row``) stay
    within ``_BLOCK_ENTRIES`` entries each (at least one vector a block)."""
    step = max(1, _BLOCK_ENTRIES // max(projection_row, scores_row, 1))
    return [(low, min(low + step, n_vectors)) for low in range(0, n_vectors, step)]


def _fixed_order_scores(
    predicted: np.ndarray,
    dense: np.ndarray,
    alphas: np.ndarray,
    beliefs: np.ndarray,
    observations: np.ndarray,
    vectors: np.ndarray,
) -> np.ndarray:
    """``sum_s predicted[s, beliefs[j]] * (dense[s, observations[j]] * alphas[vectors[j], s])`` for each ``j``, summed
    over ``s`` in increasing order (the projection's entries, formed as the block products form them), by blocks of
    ``j`` of at most ``_BLOCK_ENTRIES`` entries (each sum is over its own column, so the same in any block)."""
    n_states = predicted.shape[0]
    step = max(1, _BLOCK_ENTRIES // max(n_states, 1))
    parts = []
    for low in range(0, len(beliefs), step):
        high = low + step
        projected = dense[:, observations[low:high]] * alphas[vectors[low:high]].T
        parts.append(np.add.reduce(predicted[:, beliefs[low:high]] * projected, axis=0))
    return np.concatenate(parts) if parts else np.zeros(0)


def _row_entries(matrix: sp.csr_matrix, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The stored entries of ``matrix``'s ``rows`` (each row's in stored order, rows in the given order): for each,
    the index in ``rows`` it belongs to and its position in ``matrix.data`` / ``matrix.indices``."""
    counts = np.diff(matrix.indptr)[rows]
    owner = np.repeat(np.arange(len(rows)), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    return owner, matrix.indptr[rows][owner] + np.arange(int(counts.sum())) - first


def row_argmax(scores: np.ndarray) -> np.ndarray:
    """The first best column of each row: a ``reduce`` of :class:`RowProducts`."""
    return np.argmax(scores, axis=1)


def row_max(scores: np.ndarray) -> np.ndarray:
    """The largest entry of each row: a ``reduce`` of :class:`RowProducts`."""
    return scores.max(axis=1)


def blind_policy_vectors(pomdp: POMDP, tolerance: float = 1e-13) -> np.ndarray:
    """Values of the blind policies "always do a" (A x S): ``alpha_a = R(., a) + gamma T_a alpha_a``, to within
    ``tolerance`` times the return scale, from below.

    Each is (a lower bound of) the value of an executable policy, so ``max_a alpha_a . b`` is a lower bound of V*(b):
    the initial value function of Perseus. Computed by iterating the policy's Bellman operator with sparse products
    (the same bits on any host; a sparse LU solve goes through BLAS, whose kernel decides the last bits and with them
    Perseus' later ties) from the constant ``min_s R(s, a) / (1 - gamma)``, which the operator maps above itself: the
    iterates rise towards the exact value and stop below it, and each vector is then at most its own backup, as the
    plan graph's closure needs. Requires ``gamma < 1``.
    """
    gamma = pomdp.discount
    rewards = np.ascontiguousarray(pomdp.rewards.T)  # (A, S)
    flat_rewards = rewards.ravel()
    # All actions in one product: the block-diagonal matrix of the T_a applied to the stacked vectors.
    blocks = sp.block_diag(pomdp.transitions, format="csr")
    scale = max(float(np.abs(rewards).max()) / (1.0 - gamma), 1.0)
    # A change of c leaves at most c gamma / (1 - gamma) to go; the floor of 64 units in the last place keeps the
    # threshold above the rounding noise of the iterates when gamma is close to 1.
    threshold = max(tolerance * (1.0 - gamma), 64 * _EPS) * scale
    values = np.repeat(rewards.min(axis=1) / (1.0 - gamma), pomdp.n_states)
    while True:
        new = flat_rewards + gamma * (blocks @ values)
        change = float(np.max(np.abs(new - values)))
        values = new
        if change <= threshold:
            break
    return np.atleast_2d(values.reshape(pomdp.n_actions, pomdp.n_states))
