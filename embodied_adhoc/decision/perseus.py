"""Perseus: randomized point-based value iteration (Spaan & Vlassis 2005, JAIR 24, Algorithm 1).

Infinite horizon. Start from a lower bound ``V_0`` (the blind-policy vectors, each the value of an executable
policy), then repeat: take the beliefs ``B~`` of the set not yet improved, back up a random one against ``V_n``
(:mod:`embodied_adhoc.decision.backup`), keep the new vector if it improves that belief (else its old best
vector), and drop from ``B~`` every belief whose value did not decrease, until ``B~`` is empty. Every vector is
the value of a conditional plan, so ``max_k alpha_k . b`` is a lower bound of the optimal value at every ``b``.

Vectorisation: beliefs are backed up in random batches of ``batch_size`` against the same ``V_n`` (exactly what
the sequential algorithm computes, since each backup only reads ``V_n``); the Perseus acceptance rule then runs
over the batch in random order. Batches are skipped once their beliefs are all improved.

Gauss-Seidel stages (``update="gauss-seidel"``, the default): each batch is backed up against the vectors of V_n
still best at a belief not yet improved and every new vector the stage already kept, so improvements found early
in a stage propagate within it (fewer stages to the same stop rule); the acceptance rule, and with it
``V_{n+1} >= V_n`` on B, is Perseus'. ``update="perseus"`` is the classic stage above.

Finite horizon (``horizon=H``, mandatory when the discount is 1.0): ``H`` exact point-based stages
``V_t = backup(V_{t-1})`` over every belief, from ``V_0 = 0``; the policy keeps each stage's vectors.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.decision.backup import BackupOperator, PreparedAlphas, RowProducts, blind_policy_vectors
from embodied_adhoc.decision.belief_expansion import sample_path
from embodied_adhoc.decision.beliefs import _key as _belief_key
from embodied_adhoc.decision.beliefs import collect_beliefs
from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.plan_graph import PlanGraph
from embodied_adhoc.decision.policy import AlphaVectorPolicy, SolverStats
from embodied_adhoc.decision.products import dot, transposed
from embodied_adhoc.decision.upper_bound import SawtoothBound, fast_informed_bound
from embodied_adhoc.decision.value_iteration import value_iteration
from embodied_adhoc.errors import SolverError

STOP_RULES = ("bound", "gain")
UPDATES = ("gauss-seidel", "perseus")
# Looked up in the time module at each reading, so that a patched time.perf_counter (tests simulating load) reaches
# the solver.
CLOCKS: dict[str, Callable[[], float]] = {
    "wall": lambda: time.perf_counter(),
    "cpu": lambda: time.process_time(),
}
_TRIAL_BACKUPS = 250  # with a time limit, a trial step per this many stage backups at most
_ROUND_MIN_UPDATES = 32  # upper-bound updates of one round at least
_ROUND_SHARE = 1 / 300  # ... and this many per belief backup done so far (the lower bound's work)
_DOMINANCE_CANDIDATES = 4  # new vectors tested for dominating each vector a stage drops


@dataclass(frozen=True)
class PerseusConfig:
    """Perseus options. ``time_limit`` in seconds (None: none); ``horizon`` for a finite-horizon solve."""

    n_beliefs: int = 1000
    # improvement = the largest gain of any belief of B in one iteration (confirmed by a full backup of B).
    # stop="bound": stop when the geometric bound on the remaining gain, improvement * gamma / (1 - gamma), is
    # <= tolerance; stop="gain": the classic Perseus rule, stop when improvement itself is <= tolerance.
    tolerance: float = 1e-3
    stop: str = "bound"
    # update="gauss-seidel": each batch of a stage is backed up against the vectors of V_n still best at a belief
    # not improved yet and every vector the stage kept so far (_perseus_iteration with a _Seidel: fewer stages, the same
    # acceptance rule); "perseus": the classic stage, every backup against V_n (Spaan & Vlassis'
    # Algorithm 1, whose result does not depend on the batch schedule).
    update: str = "gauss-seidel"
    max_iterations: int = 10_000
    time_limit: float | None = None
    seed: int = 0
    horizon: int | None = None
    epsilon: float = 0.5  # exploration: probability of a random action (else greedy on the MDP's Q*)
    batch_size: int = 128  # beliefs backed up together in one vectorised call (at most: batches grow from 16)
    blas_threads: int | None = 1  # BLAS threads during the solve (None: library default); see _blas_threads
    # Threads that split the backups' branch scores and the belief set's value products by rows (backup.RowProducts):
    # bit-identical results for any count; 1 (default) starts none, as chapter-5 runs already use worker processes.
    # With clock="cpu", time_limit and the reported seconds count the CPU time of all of them.
    threads: int = 1
    # Anytime expansion: once the backups converge on B (and periodically), add beliefs sampled as B was and
    # continue, until the time limit, a gap <= precision at b0, max_beliefs (None: 10 x n_beliefs with a time
    # limit, 3 x without), or a round that moves neither bound by more than the tolerance. False: the fixed
    # belief set of Perseus.
    expand: bool = False
    precision: float = 1e-3  # stop when upper - lower at b0 <= precision (the only rule that sets converged)
    max_beliefs: int | None = None
    # What time_limit and the reported seconds count: "wall" (time.perf_counter) or "cpu", this process' CPU time
    # (time.process_time), as SARSOP's pomdpsol does (clock()): results then depend far less on machine load.
    clock: str = "wall"

    def __post_init__(self) -> None:
        if self.n_beliefs < 1:
            raise SolverError(f"n_beliefs must be >= 1, got {self.n_beliefs}")
        if self.tolerance < 0:
            raise SolverError(f"tolerance must be >= 0, got {self.tolerance}")
        if self.stop not in STOP_RULES:
            raise SolverError(f"stop must be one of {', '.join(STOP_RULES)}, got {self.stop!r}")
        if self.update not in UPDATES:
            raise SolverError(f"update must be one of {', '.join(UPDATES)}, got {self.update!r}")
        if self.horizon is not None and self.horizon < 1:
            raise SolverError(f"horizon must be a positive number of steps, got {self.horizon}")
        if not 0.0 <= self.epsilon <= 1.0:
            raise SolverError(f"epsilon must lie in [0, 1], got {self.epsilon}")
        if not isinstance(self.threads, int) or self.threads < 1:
            raise SolverError(f"threads must be an integer >= 1, got {self.threads!r}")
        if self.batch_size < 1:
            raise SolverError(f"batch_size must be >= 1, got {self.batch_size}")
        if self.precision < 0:
            raise SolverError(f"precision must be >= 0, got {self.precision}")
        if self.time_limit is not None and self.time_limit <= 0:
            raise SolverError(f"time_limit must be positive seconds, got {self.time_limit}")
        if self.clock not in CLOCKS:
            raise SolverError(f"clock must be one of {', '.join(CLOCKS)}, got {self.clock!r}")

    @property
    def timer(self) -> Callable[[], float]:
        """The clock that ``time_limit`` and the reported seconds count."""
        return CLOCKS[self.clock]


@dataclass(frozen=True)
class SolverProgress:
    """One progress report, sent after every iteration (stage, for finite horizon)."""

    iteration: int
    seconds: float
    value_b0: float  # the lower bound at b0
    n_vectors: int
    improvement: float
    upper_b0: float = float("nan")  # the upper bound at b0 (nan: not computed, e.g. finite horizon)
    n_beliefs: int = 0

    @property
    def gap(self) -> float:
        return self.upper_b0 - self.value_b0


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
    start = config.timer()
    rng = np.random.default_rng(config.seed)
    greedy_q = value_iteration(pomdp.as_mdp(), tolerance=1e-6, horizon=config.horizon).q_values
    # A finite-horizon solve only needs beliefs reachable within the horizon.
    beliefs = collect_beliefs(
        pomdp, config.n_beliefs, rng, greedy_q=greedy_q, epsilon=config.epsilon, max_depth=config.horizon
    )
    operator = BackupOperator(pomdp, threads=config.threads)
    try:
        if config.horizon is not None:
            return _finite_horizon(pomdp, config, operator, beliefs, start, progress)
        return _infinite_horizon(pomdp, config, operator, beliefs, rng, greedy_q, start, progress)
    finally:
        operator.close()


def _infinite_horizon(
    pomdp: POMDP,
    config: PerseusConfig,
    operator: BackupOperator,
    beliefs: np.ndarray,
    rng: np.random.Generator,
    greedy_q: np.ndarray,
    start: float,
    progress: ProgressCallback | None,
) -> AlphaVectorPolicy:
    clock = config.timer
    graph = PlanGraph.of_blind_policies(blind_policy_vectors(pomdp), pomdp.n_observations)
    current = np.arange(len(graph))  # rows of V_n in the graph
    alphas, actions = graph.vectors, graph.actions
    b0 = pomdp.initial_belief
    deadline = None if config.time_limit is None else start + config.time_limit
    upper = SawtoothBound(pomdp, fast_informed_bound(pomdp))
    rows = _belief_rows(beliefs)
    values = (rows @ alphas.T).max(axis=1)  # V_n on the belief set
    known = {_belief_key(b) for b in beliefs}
    trace = [(clock() - start, float(dot(b0, alphas.T).max()))]
    bounds = _Bounds(trace[-1][1], float(upper.values(b0)[0]))

    def report(at_iteration: int, gain: float, n_beliefs: int | None = None) -> None:
        if progress is not None:
            seconds, count = clock() - start, len(beliefs) if n_beliefs is None else n_beliefs
            progress(
                SolverProgress(at_iteration, seconds, bounds.lower, len(graph), gain, bounds.upper, count)
            )

    report(0, np.inf)  # the bounds from the first instant: blind policies and the fast informed bound
    improvement, on_beliefs, iteration = np.inf, False, 0
    gamma = pomdp.discount
    bound = config.stop == "bound" and gamma > 0
    threshold = config.tolerance * (1.0 - gamma) / gamma if bound else config.tolerance
    max_beliefs = config.max_beliefs or (10 if deadline is not None else 3) * config.n_beliefs
    round_start, last_round = bounds, 0
    stage_gain, trial_wait, trial_skip = 0.0, 0, 0
    # beliefs backed up so far (stages, trials, full backups): what upper-bound rounds are sized by
    backups = 0
    stage_backups, trial_steps = 0, 0
    witness = np.full(len(current), -1)  # per row of current: a belief of B where it is best (-1: unknown)
    owner = None  # per belief of B: the row of current first best there (None: not known)
    old_rows = None  # per row of current: its values on B (None: not known)
    for iteration in range(1, config.max_iterations + 1):
        if deadline is not None and clock() > deadline:
            iteration -= 1
            break
        if (
            config.expand
            and trial_wait <= 0
            and (deadline is None or trial_steps * _TRIAL_BACKUPS <= stage_backups)
        ):
            # A trial from b0 before a stage (with a time limit, while trial steps stay within their share of
            # the stages' backups). A trial that raises V(b0) by less than the tolerance, or by less
            # than the last stage did, doubles the number of stages until the next one: a trial before every
            # stage would take stages from a time-limited solve where breadth pays (Tag), while a b0 far from
            # the goal (cit, sunysb) needs trials early.
            grown, steps = _lower_trial(operator, graph, current, upper, b0, config.precision)
            backups, trial_steps = backups + steps, trial_steps + steps
            if len(grown) > len(current):
                added = graph.vectors[grown[len(current) :]]
                witness = np.concatenate([witness, np.full(len(grown) - len(current), -1)])
                current, alphas, actions = grown, graph.vectors[grown], graph.actions[grown]
                owner, old_rows = None, None
                values = np.maximum(values, np.asarray(rows @ added.T).max(axis=1))
            lower_b0 = float(dot(b0, alphas.T).max())
            gain = lower_b0 - bounds.lower
            trial_skip = 0 if gain > config.tolerance and gain >= stage_gain else max(1, 2 * trial_skip)
            trial_wait = trial_skip
            bounds = _Bounds(lower_b0, float(upper.values(b0)[0]))
            trace.append((clock() - start, bounds.lower))
            if bounds.gap <= config.precision:
                break
        else:
            trial_wait -= 1
        seidel = _Seidel(graph, current, owner, old_rows) if config.update == "gauss-seidel" else None
        stage = _perseus_iteration(
            operator, beliefs, rows, alphas, actions, values, rng, config.batch_size, seidel
        )
        backups, stage_backups = backups + stage.n_backups, stage_backups + stage.n_backups
        if seidel is not None:  # the stage's new vectors are in the graph already; origin indexes extended
            current, witness = seidel.extended, np.concatenate([witness, seidel.new_witness])
        improvement = float(np.max(stage.values - values))
        current = _record(graph, current, stage, rows, witness)
        # (vectors x |B|) floats: a Gauss-Seidel stage reuses them for the vectors it keeps as they are.
        old_rows, stage.score_rows = stage.score_rows if config.update == "gauss-seidel" else None, None
        witness = stage.witness if stage.witness is not None else np.full(len(current), -1)
        owner = stage.owner
        alphas, actions, values = graph.vectors[current], graph.actions[current], stage.values
        lower_b0 = float(dot(b0, alphas.T).max())
        stage_gain, bounds = lower_b0 - bounds.lower, _Bounds(lower_b0, bounds.upper)
        trace.append((clock() - start, bounds.lower))
        report(iteration, improvement)
        if bounds.gap <= config.precision:
            break
        # Expansion also runs periodically, every max(10, iteration / 4) iterations (counted, so that the seed
        # alone fixes B).
        periodic = config.expand and iteration - last_round >= max(10, iteration // 4)
        if improvement > threshold and not periodic:
            continue
        if improvement <= threshold:
            # Perseus may stall on ties (a belief "improved" by an equal vector); the belief set has converged
            # only if a full backup of every belief confirms the Bellman residual on B is within tolerance.
            residual, fixes = _full_backup_check(operator, beliefs, rows, alphas, values, threshold, config)
            backups += len(beliefs)
            if residual > threshold:
                current = _record(graph, current, fixes.with_old(alphas, actions), rows, witness)
                witness, owner, old_rows = np.full(len(current), -1), None, None
                alphas, actions = graph.vectors[current], graph.actions[current]
                values = (rows @ alphas.T).max(axis=1)
                continue
            improvement, on_beliefs = residual, True
        # Tighten the upper bound along excess-gap paths (belief_expansion.py), and when expanding add half as
        # many beliefs as B holds, from the trajectories B was collected from (PBVI-like breadth: the set grows
        # geometrically). The excess-gap beliefs themselves are not added: chosen greedily on a loose upper bound
        # they cost backups without raising the lower bound.
        _explore(upper, _lower_values(alphas), b0, config.precision, _round_updates(backups))
        new: list[np.ndarray] = []
        if config.expand:
            count = len(beliefs) // 2 + 1
            new = _unknown(
                collect_beliefs(pomdp, count, rng, greedy_q=greedy_q, epsilon=config.epsilon), known
            )
        last_round = iteration
        bounds = _Bounds(bounds.lower, float(upper.values(b0)[0]))
        new = new[: max(0, max_beliefs - len(beliefs))]
        report(iteration, improvement, len(beliefs) + len(new))
        if bounds.gap <= config.precision:
            break
        if on_beliefs and config.expand and not new:
            # B is exhausted and converged: only the upper bound can still move; tighten it while it does, by
            # rounds of the same size (until the deadline, else until a round barely moves it).
            lower = _lower_values(alphas)
            while bounds.gap > config.precision and (deadline is None or clock() <= deadline):
                _explore(upper, lower, b0, config.precision, _round_updates(backups))
                moved = bounds.upper - float(upper.values(b0)[0])
                bounds = _Bounds(bounds.lower, bounds.upper - moved)
                report(iteration, improvement)
                if moved <= (0.0 if deadline is not None else 0.1 * config.tolerance):
                    break
            break
        if on_beliefs:
            if not config.expand:
                break
            if (
                deadline is None
                and round_start.lower + config.tolerance >= bounds.lower
                and (round_start.upper - config.tolerance <= bounds.upper)
            ):
                break  # a whole expansion round moved neither bound by more than the tolerance
            round_start = bounds
        if new:
            added = np.asarray(new)
            beliefs = np.vstack([beliefs, added])
            rows = _belief_rows(beliefs)
            values = np.concatenate([values, dot(added, alphas.T).max(axis=1)])
            on_beliefs, owner, old_rows = False, None, None
    report(iteration, improvement)  # the bounds as returned (a last upper-bound round may have moved them)
    stats = SolverStats(
        "perseus",
        iteration,
        clock() - start,
        bounds.gap <= config.precision,
        improvement,
        beliefs.shape[0],
        tuple(trace),
        lower=bounds.lower,
        upper=bounds.upper,
        converged_on_beliefs=on_beliefs,
        n_stage_vectors=len(current),
        discount=pomdp.discount,  # closed plan values: save() may store them rounded down (policy.py)
    )
    # The policy is the whole graph: V_n and every continuation its plans use (plan_graph.py: why).
    graph.keep_closure(current, force=True)
    return AlphaVectorPolicy(graph.vectors, graph.actions, stats=stats)


@dataclass(frozen=True)
class _Bounds:
    lower: float
    upper: float

    @property
    def gap(self) -> float:
        return self.upper - self.lower


def _lower_values(alphas: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    alphas_t = transposed(alphas)
    return lambda beliefs: dot(np.atleast_2d(beliefs), alphas_t).max(axis=1)


def _round_updates(backups: int) -> int:
    """Upper-bound updates of one round: a fixed share of the belief backups done so far (at least
    ``_ROUND_MIN_UPDATES``), so the upper bound's share of the work stays about constant as the solve goes on. A
    count, not seconds: the same seed gives the same rounds on a loaded host."""
    return max(_ROUND_MIN_UPDATES, math.ceil(_ROUND_SHARE * backups))


def _explore(
    upper: SawtoothBound,
    lower: Callable[[np.ndarray], np.ndarray],
    b0: np.ndarray,
    precision: float,
    updates: int,
) -> None:
    """Excess-gap paths from b0, each backing up the upper bound along it, for ``updates`` updates in all (the
    last path is cut to the updates left)."""
    max_depth = _max_depth(upper, lower, b0, precision)
    while updates > 0:
        # Paths aim at half the precision: they stop where the gap is within their target, and the lower bound
        # is not backed up along them, so aiming at the precision itself leaves a gap at b0 just above it.
        path = sample_path(upper, lower, b0, precision / 2, min(max_depth, updates))
        if not path:
            break  # the gap at b0 is within precision
        updates -= len(path)


def _max_depth(
    upper: SawtoothBound, lower: Callable[[np.ndarray], np.ndarray], b0: np.ndarray, precision: float
) -> int:
    """Beyond this depth any gap at b0's scale is within precision / gamma^depth, so paths end there anyway."""
    gamma, scale = upper.pomdp.discount, float(upper.values(b0)[0] - lower(b0[None, :])[0])
    return int(np.clip(np.log(max(precision, 1e-9) / max(scale, 1e-9)) / np.log(gamma), 20, 1000))


def _lower_trial(
    operator: BackupOperator,
    graph: PlanGraph,
    current: np.ndarray,
    upper: SawtoothBound,
    b0: np.ndarray,
    precision: float,
) -> tuple[np.ndarray, int]:
    """One excess-gap path from b0 (HSVI/SARSOP trial), then the lower bound backed up at its beliefs, deepest
    first, each against the set grown by the previous ones: value travels the whole path in one trial, where
    Perseus' synchronous stages move it one step per stage (cit, sunysb: V(b0) stayed at the blind policies' 0
    for about 15 stages). A backup is kept only where it raises the bound at its belief; its continuations are
    rows of the graph, so the set stays closed and every vector the value of a plan. Returns the grown rows and the
    number of beliefs backed up (the path's length)."""
    alphas = graph.vectors[current]
    lower = _lower_values(alphas)
    # Paths end at the effective horizon 1 / (1 - gamma) (20 steps at 0.95, 100 at 0.99): HSVI's gap rule alone
    # lets them run 130-670 steps while the upper bound is loose, at the cost of a few stages each.
    depth = min(_max_depth(upper, lower, b0, precision), math.ceil(1.0 / (1.0 - operator.discount)))
    path = sample_path(upper, lower, b0, precision / 2, depth)
    for belief in reversed(path):
        alphas = graph.vectors[current]
        vector, action, value, children = operator.backup(
            belief[None, :], alphas, with_children=True, project=False
        )
        if value[0] > float(dot(belief, alphas.T).max()) + 1e-12:
            current = np.append(current, graph.add(vector, action, current[children]))
    return current, len(path)


def _unknown(beliefs, known: set[bytes]) -> list[np.ndarray]:
    """The beliefs not in ``known`` (to 1e-9, as collect_beliefs dedupes), which are added to it."""
    fresh = []
    for belief in beliefs:
        key = _belief_key(belief)
        if key not in known:
            known.add(key)
            fresh.append(belief)
    return fresh


@dataclass
class _Stage:
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

    def with_old(self, alphas: np.ndarray, actions: np.ndarray) -> _Stage:
        """This stage together with every vector of V_n."""
        count = alphas.shape[0]
        return _Stage(
            np.vstack([self.vectors, alphas]),
            np.concatenate([self.actions, actions]),
            np.concatenate([self.origin, np.arange(count)]),
            np.vstack([self.children, np.zeros((count, self.children.shape[1]), dtype=np.int64)]),
            self.values,
        )


def _record(
    graph: PlanGraph,
    current: np.ndarray,
    stage: _Stage,
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
        # A belief of B per dropped vector: where it was best (kept from its stage; profile of the 626-state
        # model: finding them by a product with all of B was most of the 11.8 % spent here), else its argmax.
        witnesses = np.full(dropped.size, -1) if witness is None else witness[dropped_mask]
        unknown = witnesses < 0
        if unknown.any():
            witnesses[unknown] = np.asarray(np.argmax(rows @ old[unknown].T, axis=0)).ravel()
        if stage.score_rows is not None:  # the same products, kept from the stage
            scores = np.stack([row[witnesses] for row in stage.score_rows], axis=1)  # (dropped, new)
        else:
            scores = np.asarray(rows[witnesses] @ stage.vectors.T)
        candidates = np.argsort(-scores, axis=1)[:, :_DOMINANCE_CANDIDATES]
        dominates = np.all(stage.vectors[candidates] >= old[:, None, :], axis=2)  # (dropped, candidates)
        found = dominates.any(axis=1)
        if found.any():
            first = np.argmax(dominates[found], axis=1)
            replacement = np.arange(len(graph))
            replacement[dropped[found]] = new_rows[candidates[found, first]]
            graph.redirect(replacement)
    return graph.keep_closure(new_rows)


@dataclass
class _Seidel:
    """What a Gauss-Seidel stage (:func:`_perseus_iteration` with ``seidel``) reads and adds beyond a classic one.

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


def _perseus_iteration(
    operator: BackupOperator,
    beliefs: np.ndarray,
    rows: np.ndarray | sp.csr_matrix,
    alphas: np.ndarray,
    actions: np.ndarray,
    values: np.ndarray,
    rng: np.random.Generator,
    batch_size: int,
    seidel: _Seidel | None = None,
) -> _Stage:
    """One Perseus stage ``V_n -> V_{n+1}`` (its vectors, their plans, V_{n+1} on B, the beliefs backed up).

    ``rows`` is ``beliefs`` in the form used for value products (sparse when the beliefs are). With ``seidel`` a
    Gauss-Seidel stage: each batch is backed up against the vectors of V_n still best at a belief not improved yet
    (or kept as they are) and every new vector the stage accepted so far (same acceptance rule); the new vectors
    go into ``seidel.graph`` as they are accepted, and ``origin`` indexes ``seidel.extended`` (see :class:`_Seidel`).
    """
    n = beliefs.shape[0]
    count = alphas.shape[0]
    new_values = np.full(n, -np.inf)
    kept_vectors: list[np.ndarray] = []
    kept_actions: list[int] = []
    kept_origin: list[
        int
    ] = []  # index in V_n of a vector kept as it is; -1 (Gauss-Seidel: extended) for a backup
    kept_children: list[np.ndarray] = []
    no_children = np.zeros(operator.n_observations, dtype=np.int64)
    kept_old = np.zeros(count, dtype=bool)
    order = rng.permutation(n)
    if seidel is None:
        prepared = operator.prepare(alphas)
    else:
        scored = _ScoredSet(operator, alphas)
        owner = seidel.owner
        if owner is None:
            owner = np.asarray(np.argmax(rows @ alphas.T, axis=1)).ravel()
        extended = seidel.current  # V_n's rows, then the stage's new ones as they enter the graph
        new_witness: list[np.ndarray] = []
    # With a sparse (CSR) belief set, each batch's vectors are valued at every belief of B, not only the pending
    # ones: the row of each kept vector is then its value everywhere, and V_{n+1} on B, the stage's pruning and
    # _record's dominance candidates need no further product (each entry is the same CSR row product, so the
    # values are bit-identical to a product over the whole stage). A dense belief set keeps the pending products.
    everywhere = sp.issparse(rows)
    score_rows: list[np.ndarray] = []  # with `everywhere`: per kept vector, its values on B
    size = min(batch_size, 16)
    n_backups = 0
    while True:
        pending = order[new_values[order] < values[order]]  # B~: not improved yet, in random order
        if pending.size == 0:
            break
        if seidel is not None:
            alive = kept_old.copy()
            alive[owner[new_values < values]] = True
            prepared = scored.prepared_for(alive)
        # Growing batches: early in a stage a few vectors cover most beliefs, so small batches avoid
        # computing backups that the Perseus rule would discard; later batches amortise the fixed costs.
        batch = pending[:size]
        size = min(batch_size, 2 * size)
        vectors, vector_actions, _, children = operator.backup(beliefs[batch], prepared, with_children=True)
        n_backups += len(batch)
        if seidel is not None:
            children = scored.codes[children]
        pending_beliefs = rows[pending]
        # (P, m): pending beliefs' values under the new vectors
        candidate_values = operator.products(pending_beliefs, vectors.T)
        kept_here: list[
            int | np.ndarray
        ] = []  # with `everywhere`: a new vector's column j, or an old one's values
        accepted: list[int] = []
        pending_new = new_values[pending]
        pending_old = values[pending]
        for j, index in enumerate(batch):  # batch == pending[:m], so belief `index` sits at row j
            if pending_new[j] >= pending_old[j]:
                continue  # improved by a vector accepted earlier in this batch
            # candidate_values (not the backup's own value) so the test and the stored value agree to the bit.
            if candidate_values[j, j] >= pending_old[j]:
                kept_vectors.append(vectors[j])
                kept_actions.append(int(vector_actions[j]))
                kept_origin.append(-1 if seidel is None else count + scored.new.shape[0] + len(accepted))
                kept_children.append(children[j])
                accepted.append(j)
                np.maximum(pending_new, candidate_values[:, j], out=pending_new)
                kept_here.append(j)
            else:
                # V_n's best vector at b (b is pending: V_n's value there is still its value)
                old = int(np.argmax(dot(beliefs[index], alphas.T))) if seidel is None else int(owner[index])
                if not kept_old[old]:
                    kept_old[old] = True
                    kept_vectors.append(alphas[old])
                    kept_actions.append(int(actions[old]))
                    kept_origin.append(old)
                    kept_children.append(no_children)
                    if everywhere:
                        known = None if seidel is None or seidel.old_rows is None else seidel.old_rows[old]
                        kept_here.append(
                            np.asarray(rows @ alphas[old][:, None]).ravel() if known is None else known
                        )
                        np.maximum(pending_new, kept_here[-1][pending], out=pending_new)
                    else:
                        np.maximum(
                            pending_new, (pending_beliefs @ alphas[old][:, None]).ravel(), out=pending_new
                        )
                # V_n(b) is kept exactly (guards against a last-bit difference between matvec and matmul).
                pending_new[j] = max(pending_new[j], pending_old[j])
        new_values[pending] = pending_new
        if seidel is not None and accepted:
            added = seidel.graph.add(
                vectors[accepted], vector_actions[accepted], extended[children[accepted]]
            )
            extended = np.concatenate([extended, added])
            new_witness.append(batch[accepted])
            scored.add(vectors[accepted])
        if everywhere and kept_here:
            score_rows.extend(
                _values_everywhere(rows, vectors, kept_here, pending, candidate_values, operator.products)
            )
    if seidel is not None:
        seidel.extended = extended
        seidel.new_witness = np.concatenate(new_witness) if new_witness else np.zeros(0, dtype=np.int64)
    stage = _stack(
        kept_vectors,
        kept_actions,
        kept_origin,
        kept_children,
        (beliefs.shape[1], operator.n_observations),
        new_values,
    )
    # Exact V_{n+1} on B (beliefs that left B~ early were not re-evaluated against later vectors), and pruning
    # of the vectors maximal at no belief of B: V_{n+1} on B is unchanged and later backups get cheaper (the
    # plan graph still keeps those that remaining plans continue with).
    if everywhere:
        best, values = _first_max_over_rows(score_rows, n)
    else:
        scores = rows @ stage.vectors.T
        best = np.argmax(scores, axis=1)
        values = scores[np.arange(n), best]
    keep, witness = np.unique(best, return_index=True)
    return _Stage(
        stage.vectors[keep],
        stage.actions[keep],
        stage.origin[keep],
        stage.children[keep],
        values,
        witness=witness,
        score_rows=[score_rows[k] for k in keep] if everywhere else None,
        owner=np.searchsorted(keep, best),
        n_backups=n_backups,
    )


def _first_max_over_rows(rows: list[np.ndarray], n: int, block: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """``np.argmax(np.stack(rows), axis=0)`` and the maxima, by blocks of rows (stacking them all, then an argmax
    over the first axis, copied the (vectors x |B|) array twice: 5-7 % of a pursuit solve's samples). The first row
    of equal maxima wins, as with argmax."""
    best = np.zeros(n, dtype=np.int64)
    values = np.full(n, -np.inf)
    for first in range(0, len(rows), block):
        part = np.stack(rows[first : first + block])
        where = np.argmax(part, axis=0)
        top = part[where, np.arange(part.shape[1])]
        better = top > values
        best[better] = first + where[better]
        values[better] = top[better]
    return best, values


def _values_everywhere(
    rows: sp.csr_matrix,
    vectors: np.ndarray,
    kept: list[int | np.ndarray],
    pending: np.ndarray,
    candidate_values: np.ndarray,
    products: RowProducts,
) -> list[np.ndarray]:
    """The values on all of B of the vectors a batch kept (``kept``: a column of ``vectors``, or an old vector's
    values already computed), in order. The pending beliefs' values are ``candidate_values``; the others are
    computed on their rows alone (gathered), unless recomputing the pending ones costs less than that gather (a
    row gather costs about three products per entry)."""
    n = rows.shape[0]
    new = [j for j in kept if isinstance(j, int)]
    if not new:
        return list(kept)
    if len(new) * len(pending) < 3 * (n - len(pending)):
        everywhere = np.ascontiguousarray(products(rows, vectors[new].T).T)  # (new, n)
        by_column = dict(zip(new, everywhere, strict=True))
    else:
        others = np.ones(n, dtype=bool)
        others[pending] = False
        others = np.flatnonzero(others)
        rest = products(rows[others], vectors[new].T)
        by_column = {}
        for k, j in enumerate(new):
            row = np.empty(n)
            row[pending] = candidate_values[:, j]
            row[others] = rest[:, k]
            by_column[j] = row
    return [by_column[entry] if isinstance(entry, int) else entry for entry in kept]


def _blas_threads(count: int | None) -> contextlib.AbstractContextManager:
    """Limit BLAS threads: the backups' dense products are small, and threads then cost more than they give
    (they spin on cores that other threads or processes need). Needs ``threadpoolctl`` (optional)."""
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
) -> tuple[float, _Stage]:
    """Max over B of ``backup(b) - V(b)``, and a greedy cover of the beliefs that gain more than the tolerance."""
    prepared = operator.prepare(alphas)
    parts = [
        operator.backup(beliefs[i : i + config.batch_size], prepared, with_children=True)
        for i in range(0, len(beliefs), config.batch_size)
    ]
    vectors = np.vstack([part[0] for part in parts])
    actions = np.concatenate([part[1] for part in parts])
    children = np.vstack([part[3] for part in parts])
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
    chosen = np.asarray(chosen, dtype=np.int64)
    fixes = _Stage(vectors[chosen], actions[chosen], np.full(len(chosen), -1), children[chosen], current)
    return residual, fixes


def _belief_rows(beliefs: np.ndarray) -> np.ndarray | sp.csr_matrix:
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
) -> _Stage:
    n_states, n_obs = shape  # (S, Z)
    return _Stage(
        np.asarray(vectors).reshape(len(vectors), n_states),
        np.asarray(actions, dtype=np.int64),
        np.asarray(origin, dtype=np.int64),
        np.asarray(children, dtype=np.int64).reshape(len(children), n_obs),
        values,
    )


def _finite_horizon(
    pomdp: POMDP,
    config: PerseusConfig,
    operator: BackupOperator,
    beliefs: np.ndarray,
    start: float,
    progress: ProgressCallback | None,
) -> AlphaVectorPolicy:
    clock = config.timer
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
        seconds = clock() - start
        trace.append((seconds, float(dot(b0, vectors.T).max())))
        if progress is not None:
            progress(SolverProgress(stage, seconds, trace[-1][1], vectors.shape[0], float("nan")))
        if config.time_limit is not None and seconds > config.time_limit and stage < horizon:
            raise SolverError(
                f"finite-horizon Perseus reached only stage {stage} of {horizon} within the time limit "
                f"({config.time_limit} s); a partial finite-horizon policy is not usable: raise --time-limit "
                "or lower --beliefs"
            )
    stats = SolverStats(
        "perseus", horizon, clock() - start, True, float("nan"), beliefs.shape[0], tuple(trace)
    )
    return AlphaVectorPolicy(
        np.vstack(stage_alphas), np.concatenate(stage_actions), np.concatenate(stage_numbers), stats=stats
    )
