"""Perseus stages: one ``V_n -> V_{n+1}`` over the belief set, classic or Gauss-Seidel, and the plan graph's update.

A classic stage (Spaan & Vlassis 2005, Algorithm 1) backs up beliefs of ``B~`` (those not yet improved) in random
order against ``V_n`` (thesis Eq. 2.4 at a point), keeps a new vector where it improves its belief (else the
belief's old best vector), and drops from ``B~`` every belief whose value did not decrease, until ``B~`` is empty.
A Gauss-Seidel stage (:class:`Seidel`) backs each batch up against the vectors of ``V_n`` still best at a belief
not improved yet and every new vector the stage already kept, with the same acceptance rule. :func:`record_stage`
adds a stage's vectors to the plan graph; :func:`full_backup_check` confirms convergence on ``B``.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.decision.backup import BackupOperator, PreparedAlphas, RowProducts, row_argmax
from embodied_adhoc.decision.plan_graph import PlanGraph
from embodied_adhoc.decision.products import dot, transposed

_DOMINANCE_CANDIDATES = 4  # new vectors tested for dominating each vector a stage drops
# A stage keeps its vectors' values on all of B (for the next Gauss-Seidel stage and record_stage) while they
# stay within this many floats (8 MiB); beyond, it keeps only the first best vector and value per belief, and
# those rows are products again where they are needed (the same CSR row products: the same bits).
_STAGE_ROWS_MAX_ENTRIES = 1 << 20
# Values of new vectors on all of B computed at once (a batch's columns by chunks of this many floats: the
# product, its parts when split over threads and its transpose are held together).
_EVERYWHERE_BLOCK_ENTRIES = 1 << 18


@dataclass
class Stage:
    """New vectors of a stage: ``origin[k] >= 0`` is a vector of V_n kept as it is, else a backup whose
    continuations are ``children[k]`` (rows of V_n); ``values`` is the new value of every belief of B."""

    vectors: np.ndarray
    actions: np.ndarray
    origin: np.ndarray
    children: np.ndarray
    values: np.ndarray
    witness: np.ndarray | None = None  # a belief of B where each vector is the best one (None: not known)
    score_rows: list[np.ndarray] | None = None  # per vector, its value at every belief of B (None: not kept)
    owner: np.ndarray | None = None  # per belief of B, the first vector best there (None: not known)
    n_backups: int = 0  # beliefs backed up to build it

    def with_old(self, alphas: np.ndarray, actions: np.ndarray) -> Stage:
        """This stage together with every vector of V_n."""
        count = alphas.shape[0]
        return Stage(
            np.vstack([self.vectors, alphas]),
            np.concatenate([self.actions, actions]),
            np.concatenate([self.origin, np.arange(count)]),
            np.vstack([self.children, np.zeros((count, self.children.shape[1]), dtype=np.int64)]),
            self.values,
        )


def record_stage(
    graph: PlanGraph,
    current: np.ndarray,
    stage: Stage,
    rows: np.ndarray | sp.csr_matrix,
    witness: np.ndarray | None = None,
) -> np.ndarray:
    """Add a stage's backups to the graph; returns the graph rows of V_{n+1} (plans unreachable from it dropped).

    A vector of V_n that V_{n+1} drops but one of its vectors dominates at every state is replaced by that one as
    a continuation (the plans then earn at least their vectors' values, so the lower bound still holds), so the
    graph does not keep it. Candidates: the best new vectors at the belief of B where the dropped one was best.
    """
    kept = stage.origin >= 0
    new_rows = np.empty(len(stage.origin), dtype=np.int64)
    new_rows[kept] = current[stage.origin[kept]]
    new_rows[~kept] = graph.add(stage.vectors[~kept], stage.actions[~kept], current[stage.children[~kept]])
    dropped_mask = ~np.isin(current, new_rows)
    dropped = current[dropped_mask]
    if dropped.size:
        old = graph.vectors[dropped]
        # A belief of B per dropped vector: where it was best (kept from its stage, since finding them by a
        # product with all of B would be most of this function's cost), else its argmax.
        witnesses = np.full(dropped.size, -1) if witness is None else witness[dropped_mask]
        unknown = witnesses < 0
        if unknown.any():
            witnesses[unknown] = _column_argmax(rows, old[unknown])
        if stage.score_rows is not None:  # the same products, kept from the stage
            scores = np.stack([row[witnesses] for row in stage.score_rows], axis=1)  # (dropped, new)
            candidates = _best_candidates(scores)
        else:  # by blocks of dropped vectors (RowProducts), the (dropped, new) scores being large
            candidates = RowProducts()(rows[witnesses], transposed(stage.vectors), _best_candidates)
        dominates = _dominates(stage.vectors, candidates, old)  # (dropped, candidates)
        found = dominates.any(axis=1)
        if found.any():
            first = np.argmax(dominates[found], axis=1)
            replacement = np.arange(len(graph))
            replacement[dropped[found]] = new_rows[candidates[found, first]]
            graph.redirect(replacement)
    return graph.keep_closure(new_rows)


def _dominates(vectors: np.ndarray, candidates: np.ndarray, old: np.ndarray) -> np.ndarray:
    """``vectors[candidates[i, c]] >= old[i]`` at every state, per dropped vector ``i`` and candidate ``c``, by
    blocks of dropped vectors (their candidates' rows, gathered at once, would be four times the dropped set)."""
    step = max(1, _EVERYWHERE_BLOCK_ENTRIES // max(candidates.shape[1] * old.shape[1], 1))
    return np.concatenate(
        [
            np.all(vectors[candidates[first : first + step]] >= old[first : first + step, None, :], axis=2)
            for first in range(0, len(old), step)
        ]
    )


def _best_candidates(scores: np.ndarray) -> np.ndarray:
    """Per row of (dropped, new) scores, the new vectors that score highest: dominance candidates."""
    return np.argsort(-scores, axis=1)[:, :_DOMINANCE_CANDIDATES]


def _column_argmax(rows: sp.csr_matrix, vectors: np.ndarray) -> np.ndarray:
    """``np.argmax(rows @ vectors.T, axis=0)``: per vector the first belief where it is largest, by blocks of
    vectors (the whole product is |B| x vectors floats)."""
    step = max(1, _EVERYWHERE_BLOCK_ENTRIES // max(rows.shape[0], 1))
    return np.concatenate(
        [
            np.asarray(np.argmax(dot(rows, transposed(vectors[first : first + step])), axis=0)).ravel()
            for first in range(0, len(vectors), step)
        ]
    )


@dataclass
class Seidel:
    """What a Gauss-Seidel stage (:func:`perseus_stage` with ``seidel``) reads and adds beyond a classic one.

    ``current``: the graph rows of V_n; ``owner``: per belief of B, the first vector of V_n best there (None: one
    product); ``old_rows``: per vector of V_n, its values on B (None: products when needed). The stage adds its new
    vectors to ``graph`` as it accepts them and sets ``extended`` (``current`` and then their rows: the stage's
    ``origin`` indexes it) and ``new_witness`` (per new row, the belief it was backed up at)."""

    graph: PlanGraph
    current: np.ndarray
    owner: np.ndarray | None
    old_rows: list[np.ndarray] | None
    extended: np.ndarray | None = None
    new_witness: np.ndarray | None = None


class _ScoredSet:
    """The vectors a Gauss-Seidel batch is backed up against: the vectors of V_n marked alive, then every new vector
    of the stage, in that order (``codes``: V_n's index, or ``count`` + the new vector's). Prepared from parts kept
    up to date (V_n's float32 columns and fallback scores once per stage, new vectors appended as they come), not
    anew per batch: the same :class:`PreparedAlphas` as ``operator.prepare`` of those vectors."""

    def __init__(self, operator: BackupOperator, alphas: np.ndarray) -> None:
        self.operator, self.alphas, self.count = operator, alphas, alphas.shape[0]
        self.old_t = np.ascontiguousarray(alphas.T, dtype=np.float32)
        self.old_fallback = operator.fallback_scores(alphas)
        self.new = np.zeros((0, alphas.shape[1]))
        self.new_t = np.zeros((alphas.shape[1], 0), dtype=np.float32)
        self.new_fallback = tuple(np.zeros((scores.shape[0], 0)) for scores in self.old_fallback)
        self.codes: np.ndarray | None = None
        self.prepared: PreparedAlphas | None = None

    def prepared_for(self, alive: np.ndarray) -> PreparedAlphas:
        old = np.flatnonzero(alive)
        codes = np.concatenate([old, self.count + np.arange(self.new.shape[0])])
        if self.codes is None or not np.array_equal(codes, self.codes):
            self.codes = codes
            self.prepared = self.operator.prepare_parts(
                np.concatenate([self.alphas[old], self.new]),
                np.concatenate([self.old_t[:, old], self.new_t], axis=1),
                tuple(
                    np.concatenate([o[:, old], m], axis=1)
                    for o, m in zip(self.old_fallback, self.new_fallback, strict=True)
                ),
            )
        return self.prepared

    def add(self, vectors: np.ndarray) -> None:
        self.new = np.concatenate([self.new, vectors])
        self.new_t = np.concatenate([self.new_t, vectors.T.astype(np.float32)], axis=1)
        scores = self.operator.fallback_scores(vectors)
        self.new_fallback = tuple(
            np.concatenate([m, f], axis=1) for m, f in zip(self.new_fallback, scores, strict=True)
        )


def perseus_stage(
    operator: BackupOperator,
    beliefs: np.ndarray,
    rows: np.ndarray | sp.csr_matrix,
    alphas: np.ndarray,
    actions: np.ndarray,
    values: np.ndarray,
    rng: np.random.Generator,
    batch_size: int,
    seidel: Seidel | None = None,
) -> Stage:
    """One Perseus stage ``V_n -> V_{n+1}`` (its vectors, their plans, V_{n+1} on B, the beliefs backed up).

    ``rows`` is ``beliefs`` in the form used for value products (sparse when the beliefs are). With ``seidel`` a
    Gauss-Seidel stage: each batch is backed up against the vectors of V_n still best at a belief not improved yet
    (or kept as they are) and every new vector the stage accepted so far (same acceptance rule); the new vectors
    go into ``seidel.graph`` as they are accepted, and ``origin`` indexes ``seidel.extended`` (see :class:`Seidel`).
    """
    run = _StageRun(operator, beliefs, rows, alphas, actions, values, seidel)
    order = rng.permutation(beliefs.shape[0])
    size = min(batch_size, 16)
    while True:
        pending = order[run.new_values[order] < values[order]]  # B~: not improved yet, in random order
        if pending.size == 0:
            break
        # Growing batches: early in a stage a few vectors cover most beliefs, so small batches avoid
        # computing backups that the Perseus rule would discard; later batches amortise the fixed costs.
        run.back_up(pending, pending[:size])
        size = min(batch_size, 2 * size)
    return run.finish()


class _StageRun:
    """What one stage accumulates as its batches are backed up: the vectors it keeps with their plans (``origin``:
    an index in V_n for a vector kept as it is, -1 or, Gauss-Seidel, an index in ``extended`` for a backup), the
    new value of every belief of B, and with a CSR belief set each kept vector's values on all of B.

    With a sparse (CSR) belief set, each batch's vectors are valued at every belief of B, not only the pending
    ones: the row of each kept vector is then its value everywhere, and V_{n+1} on B, the stage's pruning and
    record_stage's dominance candidates need no further product (each entry is the same CSR row product, so the
    values are bit-identical to a product over the whole stage). A dense belief set keeps the pending products."""

    def __init__(self, operator, beliefs, rows, alphas, actions, values, seidel: Seidel | None) -> None:
        self.operator, self.beliefs, self.rows, self.seidel = operator, beliefs, rows, seidel
        self.alphas, self.actions, self.values = alphas, actions, values
        self.new_values = np.full(beliefs.shape[0], -np.inf)
        self.kept_vectors: list[np.ndarray] = []
        self.kept_actions: list[int] = []
        self.kept_origin: list[int] = []
        self.kept_children: list[np.ndarray] = []
        self.no_children = np.zeros(operator.n_observations, dtype=np.int64)
        self.kept_old = np.zeros(alphas.shape[0], dtype=bool)
        self.everywhere = sp.issparse(rows)
        # With `everywhere`: per belief of B, the first kept vector best there and its value so far; and per kept
        # vector its values on B while they fit in _STAGE_ROWS_MAX_ENTRIES (None: not kept).
        self.best = np.zeros(beliefs.shape[0], dtype=np.int64)
        self.best_values = np.full(beliefs.shape[0], -np.inf)
        self.n_scored = 0
        # A stage keeps about as many vectors as V_n holds: where their rows would pass the limit they are not
        # kept from the start (rows kept until they overflow would add to the stage's peak for nothing).
        fits = alphas.shape[0] * beliefs.shape[0] <= _STAGE_ROWS_MAX_ENTRIES
        self.score_rows: list[np.ndarray] | None = [] if self.everywhere and fits else None
        self.n_backups = 0
        if seidel is None:
            self.prepared = operator.prepare(alphas)
            return
        self.scored = _ScoredSet(operator, alphas)
        self.owner = seidel.owner
        if self.owner is None:
            self.owner = operator.products(rows, alphas.T, row_argmax)
        self.extended = seidel.current  # V_n's rows, then the stage's new ones as they enter the graph
        self.new_witness: list[np.ndarray] = []

    def back_up(self, pending: np.ndarray, batch: np.ndarray) -> None:
        """Back up ``batch`` (the first beliefs of ``pending``) and apply the Perseus rule to its beliefs."""
        seidel, operator = self.seidel, self.operator
        if seidel is not None:
            alive = self.kept_old.copy()
            alive[self.owner[self.new_values < self.values]] = True
            self.prepared = self.scored.prepared_for(alive)
        vectors, vector_actions, _, children = operator.backup(
            self.beliefs[batch], self.prepared, with_children=True
        )
        self.n_backups += len(batch)
        if seidel is not None:
            children = self.scored.codes[children]
        pending_beliefs = self.rows[pending]
        # (P, m): pending beliefs' values under the new vectors
        candidate_values = operator.products(pending_beliefs, vectors.T)
        kept_here, accepted = self._accept(
            batch, pending, pending_beliefs, vectors, vector_actions, children, candidate_values
        )
        if seidel is not None and accepted:
            added = seidel.graph.add(
                vectors[accepted], vector_actions[accepted], self.extended[children[accepted]]
            )
            self.extended = np.concatenate([self.extended, added])
            self.new_witness.append(batch[accepted])
            self.scored.add(vectors[accepted])
        if self.everywhere and kept_here:
            for row in _values_everywhere(
                self.rows, vectors, kept_here, pending, candidate_values, operator.products
            ):
                self._score(row)

    def _score(self, row: np.ndarray) -> None:
        """Take the next kept vector's values on B into the running first maximum (the first vector of equal
        values stays best, as an argmax over all rows would keep it) and, while they fit, keep them."""
        better = row > self.best_values
        self.best[better] = self.n_scored
        self.best_values[better] = row[better]
        self.n_scored += 1
        if self.score_rows is not None:
            if self.n_scored * row.shape[0] <= _STAGE_ROWS_MAX_ENTRIES:
                self.score_rows.append(row)
            else:
                self.score_rows = None

    def _accept(self, batch, pending, pending_beliefs, vectors, vector_actions, children, candidate_values):
        """The Perseus rule over a batch, in its random order: keep a backup that improves its belief, else the
        belief's best vector of V_n. Returns what the batch kept (with `everywhere`: a new vector's column, or an
        old one's values on B) and the columns of the new vectors it accepted."""
        kept_here: list[int | np.ndarray] = []
        accepted: list[int] = []
        pending_new = self.new_values[pending]
        pending_old = self.values[pending]
        count = self.alphas.shape[0]
        for j, index in enumerate(batch):  # batch == pending[:m], so belief `index` sits at row j
            if pending_new[j] >= pending_old[j]:
                continue  # improved by a vector accepted earlier in this batch
            # candidate_values (not the backup's own value) so the test and the stored value agree to the bit.
            if candidate_values[j, j] >= pending_old[j]:
                origin = -1 if self.seidel is None else count + self.scored.new.shape[0] + len(accepted)
                self._keep(vectors[j], vector_actions[j], origin, children[j])
                accepted.append(j)
                np.maximum(pending_new, candidate_values[:, j], out=pending_new)
                kept_here.append(j)
            else:
                self._keep_old(index, pending, pending_beliefs, pending_new, kept_here)
                # V_n(b) is kept exactly (guards against a last-bit difference between matvec and matmul).
                pending_new[j] = max(pending_new[j], pending_old[j])
        self.new_values[pending] = pending_new
        return kept_here, accepted

    def _keep(self, vector: np.ndarray, action, origin: int, children: np.ndarray) -> None:
        self.kept_vectors.append(vector)
        self.kept_actions.append(int(action))
        self.kept_origin.append(origin)
        self.kept_children.append(children)

    def _keep_old(self, index, pending, pending_beliefs, pending_new, kept_here) -> None:
        """Keep V_n's best vector at belief ``index`` (pending: V_n's value there is still its value), once."""
        alphas = self.alphas
        old = (
            int(np.argmax(dot(self.beliefs[index], alphas.T)))
            if self.seidel is None
            else int(self.owner[index])
        )
        if self.kept_old[old]:
            return
        self.kept_old[old] = True
        self._keep(alphas[old], self.actions[old], old, self.no_children)
        if self.everywhere:
            known = None if self.seidel is None or self.seidel.old_rows is None else self.seidel.old_rows[old]
            kept_here.append(np.asarray(self.rows @ alphas[old][:, None]).ravel() if known is None else known)
            np.maximum(pending_new, kept_here[-1][pending], out=pending_new)
        else:
            np.maximum(pending_new, (pending_beliefs @ alphas[old][:, None]).ravel(), out=pending_new)

    def finish(self) -> Stage:
        """The stage's vectors with the exact V_{n+1} on B (beliefs that left B~ early were not re-evaluated
        against later vectors), pruned of the vectors maximal at no belief of B: V_{n+1} on B is unchanged and
        later backups get cheaper (the plan graph still keeps those that remaining plans continue with)."""
        if self.seidel is not None:
            self.seidel.extended = self.extended
            self.seidel.new_witness = (
                np.concatenate(self.new_witness) if self.new_witness else np.zeros(0, dtype=np.int64)
            )
        n = self.beliefs.shape[0]
        stage = _stack(
            self.kept_vectors,
            self.kept_actions,
            self.kept_origin,
            self.kept_children,
            (self.beliefs.shape[1], self.operator.n_observations),
            self.new_values,
        )
        if self.everywhere:
            best, values = self.best, self.best_values
        else:
            scores = self.rows @ stage.vectors.T
            best = np.argmax(scores, axis=1)
            values = scores[np.arange(n), best]
        keep, witness = np.unique(best, return_index=True)
        return Stage(
            stage.vectors[keep],
            stage.actions[keep],
            stage.origin[keep],
            stage.children[keep],
            values,
            witness=witness,
            score_rows=None if self.score_rows is None else [self.score_rows[k] for k in keep],
            owner=np.searchsorted(keep, best),
            n_backups=self.n_backups,
        )


def _values_everywhere(
    rows: sp.csr_matrix,
    vectors: np.ndarray,
    kept: list[int | np.ndarray],
    pending: np.ndarray,
    candidate_values: np.ndarray,
    products: RowProducts,
) -> Iterator[np.ndarray]:
    """The values on all of B of the vectors a batch kept (``kept``: a column of ``vectors``, or an old vector's
    values already computed), in order. The pending beliefs' values are ``candidate_values``; the others are
    computed on their rows alone (gathered), unless recomputing the pending ones costs less than that gather (a
    row gather costs about three products per entry). New vectors are computed ``_EVERYWHERE_BLOCK_ENTRIES``
    values at a time (a row's product is the same whichever columns go with it)."""
    n = rows.shape[0]
    new = [j for j in kept if isinstance(j, int)]
    whole = len(new) * len(pending) < 3 * (n - len(pending))
    others = others_index = None
    if new and not whole:
        mask = np.ones(n, dtype=bool)
        mask[pending] = False
        others_index = np.flatnonzero(mask)
        others = rows[others_index]
    step = max(1, _EVERYWHERE_BLOCK_ENTRIES // max(n, 1))
    by_column: dict[int, np.ndarray] = {}
    for entry in kept:
        if not isinstance(entry, int):
            yield entry
            continue
        if entry not in by_column:  # the next chunk of new columns, from this one on
            chunk = new[new.index(entry) : new.index(entry) + step]
            by_column.clear()
            if others is None:
                values = np.ascontiguousarray(products(rows, transposed(vectors[chunk])).T)  # (chunk, n)
                by_column.update(zip(chunk, values, strict=True))
            else:
                rest = products(others, transposed(vectors[chunk]))
                for k, j in enumerate(chunk):
                    row = np.empty(n)
                    row[pending] = candidate_values[:, j]
                    row[others_index] = rest[:, k]
                    by_column[j] = row
        yield by_column.pop(entry)


def full_backup_check(
    operator: BackupOperator,
    beliefs: np.ndarray,
    rows: np.ndarray | sp.csr_matrix,
    alphas: np.ndarray,
    values: np.ndarray,
    threshold: float,
    batch_size: int,
) -> tuple[float, Stage]:
    """Max over B of ``backup(b) - V(b)``, and a greedy cover of the beliefs that gain more than the tolerance."""
    prepared = operator.prepare(alphas)
    # Only the backups that gain more than the threshold can join the cover: the others' vectors are not kept
    # (a backup of all of B would be |B| x |S| floats).
    gains = np.empty(len(beliefs))
    candidates: dict[int, tuple[np.ndarray, int, np.ndarray]] = {}
    for first in range(0, len(beliefs), batch_size):
        vectors, actions, backed_up, children = operator.backup(
            beliefs[first : first + batch_size], prepared, with_children=True
        )
        gains[first : first + len(backed_up)] = backed_up - values[first : first + len(backed_up)]
        for k in np.flatnonzero(gains[first : first + len(backed_up)] > threshold):
            candidates[first + int(k)] = (vectors[k].copy(), int(actions[k]), children[k].copy())
    residual = float(gains.max())
    chosen = []
    current = values.copy()
    for index in np.argsort(-gains):
        if gains[index] <= threshold:
            break
        if current[index] + threshold < values[index] + gains[index]:
            chosen.append(int(index))
            np.maximum(current, (rows @ candidates[index][0][:, None]).ravel(), out=current)
    n_states, n_obs = beliefs.shape[1], operator.n_observations
    fixes = Stage(
        np.asarray([candidates[i][0] for i in chosen]).reshape(len(chosen), n_states),
        np.asarray([candidates[i][1] for i in chosen], dtype=np.int64),
        np.full(len(chosen), -1),
        np.asarray([candidates[i][2] for i in chosen], dtype=np.int64).reshape(len(chosen), n_obs),
        current,
    )
    return residual, fixes


class DenseRows:
    """A CSR belief set read as dense rows (``rows[index]`` is the dense belief or beliefs, bit for bit the ones it
    was built from): the set is kept once, sparse, and only the batches being backed up are dense (Tag's beliefs
    hold a few of its 870 states each, so the dense set would be twenty times the CSR one)."""

    def __init__(self, rows: sp.csr_matrix) -> None:
        self.rows = rows
        self.shape = rows.shape

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, index) -> np.ndarray:
        if np.ndim(index) == 0 and not isinstance(index, slice):
            return self.rows[int(index)].toarray()[0]
        return self.rows[index].toarray()


def belief_rows(beliefs: np.ndarray) -> np.ndarray | sp.csr_matrix:
    """The belief set for value products ``B @ Gamma^T``, as CSR even when dense: scipy's products sum each row in
    one fixed order (products.py), so values on B and the ties they decide do not depend on the BLAS kernel."""
    return sp.csr_matrix(beliefs)


def _stack(
    vectors: list[np.ndarray],
    actions: list[int],
    origin: list[int],
    children: list[np.ndarray],
    shape: tuple[int, int],
    values: np.ndarray,
) -> Stage:
    n_states, n_obs = shape  # (S, Z)
    return Stage(
        np.asarray(vectors).reshape(len(vectors), n_states),
        np.asarray(actions, dtype=np.int64),
        np.asarray(origin, dtype=np.int64),
        np.asarray(children, dtype=np.int64).reshape(len(children), n_obs),
        values,
    )
