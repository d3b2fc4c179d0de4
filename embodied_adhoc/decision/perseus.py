"""Perseus: randomized point-based value iteration (Spaan & Vlassis 2005, JAIR 24, Algorithm 1).

Infinite horizon. Start from a lower bound ``V_0`` (the blind-policy vectors, each the value of an executable
policy), then repeat: take the beliefs ``B~`` of the set not yet improved, back up a random one against ``V_n``
(:mod:`embodied_adhoc.decision.backup`), keep the new vector if it improves that belief (else its old best
vector), and drop from ``B~`` every belief whose value did not decrease, until ``B~`` is empty. Every vector is
the value of a conditional plan, so ``max_k alpha_k . b`` is a lower bound of the optimal value at every ``b``.

Vectorisation: beliefs are backed up in random batches of ``batch_size`` against the same ``V_n`` (exactly what
the sequential algorithm computes, since each backup only reads ``V_n``); the Perseus acceptance rule then runs
over the batch in random order. Batches are skipped once their beliefs are all improved.

Finite horizon (``horizon=H``, mandatory when the discount is 1.0): ``H`` exact point-based stages
``V_t = backup(V_{t-1})`` over every belief, from ``V_0 = 0``; the policy keeps each stage's vectors.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.decision.backup import BackupOperator, blind_policy_vectors
from embodied_adhoc.decision.beliefs import collect_beliefs
from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.policy import AlphaVectorPolicy, SolverStats
from embodied_adhoc.decision.value_iteration import value_iteration
from embodied_adhoc.errors import SolverError

STOP_RULES = ("bound", "gain")


@dataclass(frozen=True)
class PerseusConfig:
    """Perseus options. ``time_limit`` in seconds (None: none); ``horizon`` for a finite-horizon solve."""

    n_beliefs: int = 1000
    # improvement = the largest gain of any belief of B in one iteration (confirmed by a full backup of B).
    # stop="bound": stop when the geometric bound on the remaining gain, improvement * gamma / (1 - gamma), is
    # <= tolerance; stop="gain": the classic Perseus rule, stop when improvement itself is <= tolerance.
    tolerance: float = 1e-3
    stop: str = "bound"
    max_iterations: int = 10_000
    time_limit: float | None = None
    seed: int = 0
    horizon: int | None = None
    epsilon: float = 0.5  # exploration: probability of a random action (else greedy on the MDP's Q*)
    batch_size: int = 256  # beliefs backed up together in one vectorised call
    blas_threads: int | None = 1  # BLAS threads during the solve (None: library default); see _blas_threads

    def __post_init__(self) -> None:
        if self.n_beliefs < 1:
            raise SolverError(f"n_beliefs must be >= 1, got {self.n_beliefs}")
        if self.tolerance < 0:
            raise SolverError(f"tolerance must be >= 0, got {self.tolerance}")
        if self.stop not in STOP_RULES:
            raise SolverError(f"stop must be one of {', '.join(STOP_RULES)}, got {self.stop!r}")
        if self.horizon is not None and self.horizon < 1:
            raise SolverError(f"horizon must be a positive number of steps, got {self.horizon}")
        if not 0.0 <= self.epsilon <= 1.0:
            raise SolverError(f"epsilon must lie in [0, 1], got {self.epsilon}")
        if self.batch_size < 1:
            raise SolverError(f"batch_size must be >= 1, got {self.batch_size}")
        if self.time_limit is not None and self.time_limit <= 0:
            raise SolverError(f"time_limit must be positive seconds, got {self.time_limit}")


@dataclass(frozen=True)
class SolverProgress:
    """One progress report, sent after every iteration (stage, for finite horizon)."""

    iteration: int
    seconds: float
    value_b0: float
    n_vectors: int
    improvement: float


ProgressCallback = Callable[[SolverProgress], None]


def perseus(
    pomdp: POMDP, config: PerseusConfig | None = None, progress: ProgressCallback | None = None
) -> AlphaVectorPolicy:
    """Solve ``pomdp`` with Perseus; the policy's ``stats`` hold iterations, seconds and the value trace."""
    config = config or PerseusConfig()
    if config.horizon is None and pomdp.discount >= 1.0:
        raise SolverError(
            "discount is 1.0: an infinite-horizon solve does not converge; give a finite horizon (--horizon N)"
        )
    with _blas_threads(config.blas_threads):
        return _solve(pomdp, config, progress)


def _solve(pomdp: POMDP, config: PerseusConfig, progress: ProgressCallback | None) -> AlphaVectorPolicy:
    start = time.perf_counter()
    rng = np.random.default_rng(config.seed)
    greedy_q = value_iteration(pomdp.as_mdp(), tolerance=1e-6, horizon=config.horizon).q_values
    # A finite-horizon solve only needs beliefs reachable within the horizon.
    beliefs = collect_beliefs(
        pomdp, config.n_beliefs, rng, greedy_q=greedy_q, epsilon=config.epsilon, max_depth=config.horizon
    )
    operator = BackupOperator(pomdp)
    if config.horizon is not None:
        return _finite_horizon(pomdp, config, operator, beliefs, start, progress)
    return _infinite_horizon(pomdp, config, operator, beliefs, rng, start, progress)


def _infinite_horizon(
    pomdp: POMDP,
    config: PerseusConfig,
    operator: BackupOperator,
    beliefs: np.ndarray,
    rng: np.random.Generator,
    start: float,
    progress: ProgressCallback | None,
) -> AlphaVectorPolicy:
    alphas = blind_policy_vectors(pomdp)
    actions = np.arange(pomdp.n_actions, dtype=np.int64)
    b0 = pomdp.initial_belief
    rows = _belief_rows(beliefs)
    values = (rows @ alphas.T).max(axis=1)  # V_n on the belief set
    trace = [(time.perf_counter() - start, float((alphas @ b0).max()))]
    improvement, converged, iteration = np.inf, False, 0
    gamma = pomdp.discount
    bound = config.stop == "bound" and gamma > 0
    threshold = config.tolerance * (1.0 - gamma) / gamma if bound else config.tolerance
    deadline = None if config.time_limit is None else start + config.time_limit
    for iteration in range(1, config.max_iterations + 1):
        new_alphas, new_actions, new_values, timed_out = _perseus_iteration(
            operator, beliefs, rows, alphas, actions, values, rng, config.batch_size, deadline
        )
        if timed_out and not new_alphas.shape[0]:
            iteration -= 1
            break
        if timed_out:
            # A partial iteration: keep the old vectors too, so no belief loses value.
            new_alphas = np.vstack([new_alphas, alphas])
            new_actions = np.concatenate([new_actions, actions])
            new_values = (rows @ new_alphas.T).max(axis=1)
        improvement = float(np.max(new_values - values))
        alphas, actions, values = new_alphas, new_actions, new_values
        seconds = time.perf_counter() - start
        value_b0 = float((alphas @ b0).max())
        trace.append((seconds, value_b0))
        if progress is not None:
            progress(SolverProgress(iteration, seconds, value_b0, alphas.shape[0], improvement))
        if timed_out:
            break
        if improvement <= threshold:
            # Perseus may stall on ties (a belief "improved" by an equal vector); stop only if a full backup
            # of every belief confirms the Bellman residual on B is within tolerance, else add the fixes.
            residual, fixes, fix_actions = _full_backup_check(
                operator, beliefs, rows, alphas, values, threshold, config
            )
            if residual <= threshold:
                improvement, converged = residual, True
                break
            alphas = np.vstack([alphas, fixes])
            actions = np.concatenate([actions, fix_actions])
            values = (rows @ alphas.T).max(axis=1)
    stats = SolverStats(
        "perseus",
        iteration,
        time.perf_counter() - start,
        converged,
        improvement,
        beliefs.shape[0],
        tuple(trace),
    )
    return AlphaVectorPolicy(alphas, actions, stats=stats)


def _perseus_iteration(
    operator: BackupOperator,
    beliefs: np.ndarray,
    rows: np.ndarray | sp.csr_matrix,
    alphas: np.ndarray,
    actions: np.ndarray,
    values: np.ndarray,
    rng: np.random.Generator,
    batch_size: int,
    deadline: float | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """One Perseus stage ``V_n -> V_{n+1}``; returns the new vectors, their actions, V_{n+1} on B, timed_out.

    ``rows`` is ``beliefs`` in the form used for value products (sparse when the beliefs are).
    """
    n = beliefs.shape[0]
    new_values = np.full(n, -np.inf)
    kept_vectors: list[np.ndarray] = []
    kept_actions: list[int] = []
    kept_old: set[int] = set()
    order = rng.permutation(n)
    prepared = operator.prepare(alphas)
    size = min(batch_size, 16)
    while True:
        if deadline is not None and time.perf_counter() > deadline:
            return _stack(kept_vectors, kept_actions, beliefs.shape[1]) + (new_values, True)
        pending = order[new_values[order] < values[order]]  # B~: not improved yet, in random order
        if pending.size == 0:
            break
        # Growing batches: early in a stage a few vectors cover most beliefs, so small batches avoid
        # computing backups that the Perseus rule would discard; later batches amortise the fixed costs.
        batch = pending[:size]
        size = min(batch_size, 2 * size)
        vectors, vector_actions, _ = operator.backup(beliefs[batch], prepared)
        pending_beliefs = rows[pending]
        candidate_values = (
            pending_beliefs @ vectors.T
        )  # (P, m): pending beliefs' values under the new vectors
        pending_new = new_values[pending]
        pending_old = values[pending]
        for j, index in enumerate(batch):  # batch == pending[:m], so belief `index` sits at row j
            if pending_new[j] >= pending_old[j]:
                continue  # improved by a vector accepted earlier in this batch
            # candidate_values (not the backup's own value) so the test and the stored value agree to the bit.
            if candidate_values[j, j] >= pending_old[j]:
                kept_vectors.append(vectors[j])
                kept_actions.append(int(vector_actions[j]))
                np.maximum(pending_new, candidate_values[:, j], out=pending_new)
            else:
                old = int(np.argmax(alphas @ beliefs[index]))
                if old not in kept_old:
                    kept_old.add(old)
                    kept_vectors.append(alphas[old])
                    kept_actions.append(int(actions[old]))
                    np.maximum(pending_new, (pending_beliefs @ alphas[old][:, None]).ravel(), out=pending_new)
                # V_n(b) is kept exactly (guards against a last-bit difference between matvec and matmul).
                pending_new[j] = max(pending_new[j], pending_old[j])
        new_values[pending] = pending_new
    new_alphas, new_actions = _stack(kept_vectors, kept_actions, beliefs.shape[1])
    # Exact V_{n+1} on B (beliefs that left B~ early were not re-evaluated against later vectors), and pruning
    # of the vectors maximal at no belief of B: V_{n+1} on B is unchanged and later backups get cheaper.
    scores = rows @ new_alphas.T
    best = np.argmax(scores, axis=1)
    keep = np.unique(best)
    return new_alphas[keep], new_actions[keep], scores[np.arange(len(best)), best], False


def _blas_threads(count: int | None) -> contextlib.AbstractContextManager:
    """Limit BLAS threads: the backups' dense products are small, and threads then cost more than they give
    (measured 1.5x faster single-threaded on a busy 2-core machine). Needs ``threadpoolctl`` (optional)."""
    if count is None:
        return contextlib.nullcontext()
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return contextlib.nullcontext()
    return threadpool_limits(limits=count, user_api="blas")


def _full_backup_check(
    operator: BackupOperator,
    beliefs: np.ndarray,
    rows: np.ndarray | sp.csr_matrix,
    alphas: np.ndarray,
    values: np.ndarray,
    threshold: float,
    config: PerseusConfig,
) -> tuple[float, np.ndarray, np.ndarray]:
    """Max over B of ``backup(b) - V(b)``, and a greedy cover of the beliefs that gain more than the tolerance."""
    parts = [
        operator.backup(beliefs[i : i + config.batch_size], alphas)
        for i in range(0, len(beliefs), config.batch_size)
    ]
    vectors = np.vstack([part[0] for part in parts])
    actions = np.concatenate([part[1] for part in parts])
    gains = np.concatenate([part[2] for part in parts]) - values
    residual = float(gains.max())
    chosen = []
    current = values.copy()
    for index in np.argsort(-gains):
        if gains[index] <= threshold:
            break
        if current[index] + threshold < values[index] + gains[index]:
            chosen.append(index)
            np.maximum(current, (rows @ vectors[index][:, None]).ravel(), out=current)
    return residual, vectors[chosen], actions[chosen]


def _belief_rows(beliefs: np.ndarray) -> np.ndarray | sp.csr_matrix:
    """The belief set for value products ``B @ Gamma^T``: CSR when sparse (large models' beliefs mostly are)."""
    if np.count_nonzero(beliefs) < 0.3 * beliefs.size:
        return sp.csr_matrix(beliefs)
    return beliefs


def _stack(vectors: list[np.ndarray], actions: list[int], n_states: int) -> tuple[np.ndarray, np.ndarray]:
    if not vectors:
        return np.empty((0, n_states)), np.empty(0, dtype=np.int64)
    return np.asarray(vectors), np.asarray(actions, dtype=np.int64)


def _finite_horizon(
    pomdp: POMDP,
    config: PerseusConfig,
    operator: BackupOperator,
    beliefs: np.ndarray,
    start: float,
    progress: ProgressCallback | None,
) -> AlphaVectorPolicy:
    horizon = int(config.horizon)
    previous = np.zeros((1, pomdp.n_states))
    stage_alphas, stage_actions, stage_numbers = [], [], []
    trace = []
    b0 = pomdp.initial_belief
    for stage in range(1, horizon + 1):
        vectors = []
        actions = []
        for first in range(0, beliefs.shape[0], config.batch_size):
            batch_vectors, batch_actions, _ = operator.backup(
                beliefs[first : first + config.batch_size], previous
            )
            vectors.append(batch_vectors)
            actions.append(batch_actions)
        vectors = np.vstack(vectors)
        _, keep = np.unique(np.round(vectors, 12), axis=0, return_index=True)
        vectors, actions = vectors[keep], np.concatenate(actions)[keep]
        stage_alphas.append(vectors)
        stage_actions.append(actions)
        stage_numbers.append(np.full(len(actions), stage, dtype=np.int64))
        previous = vectors
        seconds = time.perf_counter() - start
        trace.append((seconds, float((vectors @ b0).max())))
        if progress is not None:
            progress(SolverProgress(stage, seconds, trace[-1][1], vectors.shape[0], float("nan")))
        if config.time_limit is not None and seconds > config.time_limit and stage < horizon:
            raise SolverError(
                f"finite-horizon Perseus reached only stage {stage} of {horizon} within the time limit "
                f"({config.time_limit} s); a partial finite-horizon policy is not usable: raise --time-limit "
                "or lower --beliefs"
            )
    stats = SolverStats(
        "perseus", horizon, time.perf_counter() - start, True, float("nan"), beliefs.shape[0], tuple(trace)
    )
    return AlphaVectorPolicy(
        np.vstack(stage_alphas), np.concatenate(stage_actions), np.concatenate(stage_numbers), stats=stats
    )
