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

Anytime driver (infinite horizon): each iteration is a trial from b0 when one is due (``expand=True``: an
HSVI/SARSOP-style excess-gap path, the lower bound backed up along it deepest first), a stage
(:mod:`embodied_adhoc.decision.perseus_stages`), and, once the stages converge on B (confirmed by a full backup)
or periodically when expanding, a round: the sawtooth upper bound (:mod:`embodied_adhoc.decision.upper_bound`) is
backed up along excess-gap paths and, when expanding, B grows by beliefs sampled as it was. Every budget that
decides what is computed is a count (trials by the stages they wait and the backups they may take, rounds by
upper-bound updates in proportion to the belief backups so far), so a seed gives the same solve on any host and
under any load; ``time_limit`` only stops the solve, read between whole iterations (it may overrun by one).

Finite horizon (``horizon=H``, mandatory when the discount is 1.0): ``H`` exact point-based stages
``V_t = backup(V_{t-1})`` over every belief, from ``V_0 = 0``; the policy keeps each stage's vectors.
"""

from __future__ import annotations

import contextlib
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.decision.backup import DENSE_BLOCK_BYTES, BackupOperator, blind_policy_vectors, row_max
from embodied_adhoc.decision.belief_expansion import explore, max_depth, sample_path
from embodied_adhoc.decision.beliefs import collect_belief_rows, collect_beliefs
from embodied_adhoc.decision.memory import MB, default_cap_mb, resident_mb
from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.perseus_stages import (
    DenseRows,
    Seidel,
    Stage,
    belief_rows,
    full_backup_check,
    perseus_stage,
    record_stage,
)
from embodied_adhoc.decision.plan_graph import PlanGraph, Supports, observation_supports
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
# V_n's values on B are kept between Gauss-Seidel stages up to this many floats (32 MiB); beyond it they are
# recomputed where a stage keeps a vector as it is, so that a stage does not hold two (vectors x |B|) tables.
_OLD_ROWS_MAX_ENTRIES = 1 << 22


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
    # not improved yet and every vector the stage kept so far (perseus_stages.Seidel: fewer stages, the same
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
    # bit-identical results for any count; 1 (default) starts none, as parallel sweeps already use worker processes.
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
    # (time.process_time), as SARSOP's pomdpsol does (clock()). The clock never decides what is computed, only
    # after how many whole iterations the time limit stops the solve.
    clock: str = "wall"
    # Pruning of the plan graph (plan_graph.PlanGraph.prune_dominated with the model's observation supports): a
    # continuation into a row outside V_n that a vector of V_n dominates on the end states that can emit its
    # observation continues with that vector instead, and rows no plan continues with are dropped, whenever the
    # graph holds twice the rows it kept after the last pruning (after a stage), and once more on return. V_n, and
    # with it every bound the solve computes, is unchanged; every kept vector is still the value of a plan, so the
    # saved policy earns at least its value at every belief. False: keep every row reachable from V_n.
    prune: bool = True
    # Memory cap in MiB (infinite horizon): before each stage and each expansion the solve estimates what it
    # allocates (_stage_need, _expansion_need) and, when resident memory plus that would pass the cap, stops (a
    # stage) or stops expanding B (an expansion), keeping its bounds and saying why on stderr. None: the host's
    # default (memory.default_cap_mb: what the process holds plus 80 % of the available memory); math.inf: none.
    max_memory: float | None = None

    def __post_init__(self) -> None:
        for invalid, message in self._checks():
            if invalid():
                raise SolverError(message)

    def _checks(self) -> list[tuple[Callable[[], bool], str]]:
        """Per field, in order: a test that it is out of range, and the message that says so."""
        return [
            (lambda: self.n_beliefs < 1, f"n_beliefs must be >= 1, got {self.n_beliefs}"),
            (lambda: self.tolerance < 0, f"tolerance must be >= 0, got {self.tolerance}"),
            (
                lambda: self.stop not in STOP_RULES,
                f"stop must be one of {', '.join(STOP_RULES)}, got {self.stop!r}",
            ),
            (
                lambda: self.update not in UPDATES,
                f"update must be one of {', '.join(UPDATES)}, got {self.update!r}",
            ),
            (
                lambda: self.horizon is not None and self.horizon < 1,
                f"horizon must be a positive number of steps, got {self.horizon}",
            ),
            (lambda: not 0.0 <= self.epsilon <= 1.0, f"epsilon must lie in [0, 1], got {self.epsilon}"),
            (
                lambda: not isinstance(self.threads, int) or self.threads < 1,
                f"threads must be an integer >= 1, got {self.threads!r}",
            ),
            (lambda: self.batch_size < 1, f"batch_size must be >= 1, got {self.batch_size}"),
            (lambda: self.precision < 0, f"precision must be >= 0, got {self.precision}"),
            (
                lambda: self.time_limit is not None and self.time_limit <= 0,
                f"time_limit must be positive seconds, got {self.time_limit}",
            ),
            (
                lambda: self.max_memory is not None and not self.max_memory > 0,
                f"max_memory must be positive MiB, got {self.max_memory}",
            ),
            (
                lambda: self.clock not in CLOCKS,
                f"clock must be one of {', '.join(CLOCKS)}, got {self.clock!r}",
            ),
        ]

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
    options = {"greedy_q": greedy_q, "epsilon": config.epsilon}
    operator = BackupOperator(pomdp, threads=config.threads)
    try:
        if config.horizon is not None:
            # A finite-horizon solve only needs beliefs reachable within the horizon.
            beliefs = collect_beliefs(pomdp, config.n_beliefs, rng, max_depth=config.horizon, **options)
            return _finite_horizon(pomdp, config, operator, beliefs, start, progress)
        # The rows and digests of the dense beliefs, bit for bit: the dense set is never built (a solve would
        # hold it to its end).
        rows, digests = collect_belief_rows(pomdp, config.n_beliefs, rng, **options)
        return _infinite_horizon(pomdp, config, operator, (rows, digests), rng, greedy_q, start, progress)
    finally:
        operator.close()


def _infinite_horizon(
    pomdp: POMDP,
    config: PerseusConfig,
    operator: BackupOperator,
    beliefs: tuple[sp.csr_matrix, list[bytes]],
    rng: np.random.Generator,
    greedy_q: np.ndarray,
    start: float,
    progress: ProgressCallback | None,
) -> AlphaVectorPolicy:
    """Iterations of trial, stage and round (module docstring) until ``max_iterations``, a gap <= precision at b0,
    a round's stop rule, or the time limit, which is read between whole iterations only."""
    state = _Anytime.begin(pomdp, config, operator, beliefs, rng, greedy_q, start, progress)
    state.report(np.inf)  # the bounds from the first instant: blind policies and the fast informed bound
    for iteration in range(1, config.max_iterations + 1):
        if state.deadline is not None and state.clock() > state.deadline:
            state.stopped = "time-limit"
            break
        if not state.fits(_stage_need(state), f"stopped before iteration {iteration}"):
            state.stopped = "memory-cap"
            break
        state.iteration = iteration
        if _iterate(state):
            break
    return _finish(state)


@dataclass(frozen=True)
class _Bounds:
    lower: float
    upper: float

    @property
    def gap(self) -> float:
        return self.upper - self.lower


@dataclass
class _Anytime:
    """The state of an infinite-horizon solve between its steps: V_n as rows of the plan graph, the belief set B
    with V_n's values on it, both bounds at b0, and the counts that decide when trials and rounds run."""

    pomdp: POMDP
    config: PerseusConfig
    operator: BackupOperator
    rng: np.random.Generator
    greedy_q: np.ndarray  # the MDP's Q*, which collect_beliefs explores with
    start: float
    progress: ProgressCallback | None
    graph: PlanGraph
    supports: Supports  # the model's observation supports (plan_graph.observation_supports), for pruning
    upper: SawtoothBound
    beliefs: DenseRows  # B, read as dense rows from `rows`
    rows: sp.csr_matrix  # the beliefs for value products (belief_rows)
    known: set[bytes]  # digests of the beliefs of B (beliefs.digest), so that expansion adds new ones only
    current: np.ndarray  # rows of V_n in the graph
    alphas: np.ndarray  # their vectors and actions
    actions: np.ndarray
    values: np.ndarray  # V_n on B
    bounds: _Bounds
    trace: list[tuple[float, float]]
    deadline: float | None
    threshold: float  # the stop rule's bound on one iteration's improvement
    max_beliefs: int
    witness: np.ndarray  # per row of current: a belief of B where it is best (-1: unknown)
    owner: np.ndarray | None = None  # per belief of B: the row of current first best there (None: not known)
    old_rows: list[np.ndarray] | None = None  # per row of current: its values on B (None: not known)
    iteration: int = 0
    improvement: float = np.inf
    on_beliefs: bool = False  # converged on B (confirmed by a full backup)
    round_start: _Bounds | None = None  # the bounds when the last round on a converged B ended
    last_round: int = 0
    stage_gain: float = 0.0  # what the last stage added to V(b0)
    trial_wait: int = 0  # stages until the next trial
    trial_skip: int = 0
    backups: int = 0  # beliefs backed up so far (stages, trials, full backups): what rounds are sized by
    stage_backups: int = 0
    trial_steps: int = 0
    pruned_size: int = 0  # the graph's rows after the last pruning (PerseusConfig.prune)
    cap_mb: float | None = None  # the memory cap (PerseusConfig.max_memory; None: none)
    expansion_capped: bool = False  # an expansion did not fit under the cap: B stays as it is
    stopped: str = "iteration-limit"  # why the solve ended (SolverStats.stopped), set where it ends

    @classmethod
    def begin(cls, pomdp, config, operator, beliefs, rng, greedy_q, start, progress) -> _Anytime:
        """V_0 (the blind policies), the fast informed bound, and the belief set as collected (``beliefs``: its
        rows and their digests, as beliefs.collect_belief_rows returns them)."""
        rows, digests = beliefs
        graph = PlanGraph.of_blind_policies(blind_policy_vectors(pomdp), pomdp.n_observations)
        alphas = graph.vectors
        deadline = None if config.time_limit is None else start + config.time_limit
        upper = SawtoothBound(pomdp, fast_informed_bound(pomdp))
        values = (rows @ alphas.T).max(axis=1)
        known = set(digests)
        trace = [(config.timer() - start, float(dot(pomdp.initial_belief, alphas.T).max()))]
        bounds = _Bounds(trace[-1][1], float(upper.values(pomdp.initial_belief)[0]))
        gamma = pomdp.discount
        bound = config.stop == "bound" and gamma > 0
        threshold = config.tolerance * (1.0 - gamma) / gamma if bound else config.tolerance
        max_beliefs = config.max_beliefs or (10 if deadline is not None else 3) * config.n_beliefs
        current = np.arange(len(graph))
        return cls(
            pomdp=pomdp,
            config=config,
            operator=operator,
            rng=rng,
            greedy_q=greedy_q,
            start=start,
            progress=progress,
            graph=graph,
            supports=observation_supports(pomdp.observations),
            upper=upper,
            beliefs=DenseRows(rows),
            rows=rows,
            known=known,
            current=current,
            alphas=alphas,
            actions=graph.actions,
            values=values,
            bounds=bounds,
            trace=trace,
            deadline=deadline,
            threshold=threshold,
            max_beliefs=max_beliefs,
            witness=np.full(len(current), -1),
            round_start=bounds,
            pruned_size=len(graph),
            cap_mb=_memory_cap(config),
        )

    @property
    def b0(self) -> np.ndarray:
        return self.pomdp.initial_belief

    def clock(self) -> float:
        return self.config.timer()

    def use(self, current: np.ndarray) -> None:
        """Make the graph rows ``current`` V_n."""
        self.current, self.alphas, self.actions = (
            current,
            self.graph.vectors[current],
            self.graph.actions[current],
        )

    def prune(self, force: bool = False) -> None:
        """Prune the plan graph of dominated rows once it doubled since the last pruning (or when ``force``d)."""
        if not self.config.prune or (not force and len(self.graph) < 2 * self.pruned_size):
            return
        self.use(self.graph.prune_dominated(self.current, self.supports))
        self.pruned_size = len(self.graph)

    def lower_b0(self) -> float:
        return float(dot(self.b0, self.alphas.T).max())

    def upper_b0(self) -> float:
        return float(self.upper.values(self.b0)[0])

    def record(self) -> None:
        """Append the lower bound at b0 to the trace."""
        self.trace.append((self.clock() - self.start, self.bounds.lower))

    def report(self, gain: float, n_beliefs: int | None = None) -> None:
        if self.progress is not None:
            seconds, count = self.clock() - self.start, len(self.beliefs) if n_beliefs is None else n_beliefs
            bounds = self.bounds
            self.progress(
                SolverProgress(
                    self.iteration, seconds, bounds.lower, len(self.graph), gain, bounds.upper, count
                )
            )

    def fits(self, need: float, what: str) -> bool:
        """Whether ``need`` more bytes keep resident memory within the cap; if not, say so on stderr (once)."""
        if self.cap_mb is None:
            return True
        resident = resident_mb()
        if resident + need / MB <= self.cap_mb:
            return True
        print(
            f"embodied-adhoc: note: perseus {what}: it needs about {need / MB:.0f} MB "
            f"beyond the {resident:.0f} MB in use, over the memory cap of {self.cap_mb:.0f} MB (--max-memory); "
            "the bounds so far are kept",
            file=sys.stderr,
        )
        return False

    def trial_due(self) -> bool:
        """A trial runs when the stages to wait are done and, with a time limit, while trial steps stay within
        their share of the stages' backups (``_TRIAL_BACKUPS``)."""
        if not self.config.expand or self.trial_wait > 0:
            return False
        return self.deadline is None or self.trial_steps * _TRIAL_BACKUPS <= self.stage_backups

    def add_beliefs(self, new: sp.csr_matrix) -> None:
        self.rows = sp.vstack([self.rows, new], format="csr")
        self.beliefs = DenseRows(self.rows)
        self.values = np.concatenate([self.values, self.operator.products(new, self.alphas.T, row_max)])
        self.on_beliefs, self.owner, self.old_rows = False, None, None


def _iterate(state: _Anytime) -> bool:
    """One iteration: a trial from b0 when one is due, a stage, and, once B converged (or periodically when
    expanding), a round. True: the solve is done."""
    if state.trial_due():
        if _trial(state):
            return True
    else:
        state.trial_wait -= 1
    _stage(state)
    if _gap_closed(state):
        return True
    # Expansion also runs periodically, every max(10, iteration / 4) iterations (counted, so that the seed alone
    # fixes B).
    periodic = state.config.expand and state.iteration - state.last_round >= max(10, state.iteration // 4)
    if state.improvement > state.threshold:
        if not periodic:
            return False
    elif not _converged_on_beliefs(state):
        return False
    return _round(state)


def _trial(state: _Anytime) -> bool:
    """A trial from b0 (:func:`_lower_trial`) before a stage; True: the gap at b0 closed.

    A trial that raises V(b0) by less than the tolerance, or by less than the last stage did, doubles the number
    of stages until the next one: a trial before every stage takes stages from a time-limited solve where breadth
    pays (Tag), while a b0 far from the goal (cit, sunysb) needs trials early."""
    config = state.config
    grown, steps = _lower_trial(
        state.operator, state.graph, state.current, state.upper, state.b0, config.precision
    )
    state.backups, state.trial_steps = state.backups + steps, state.trial_steps + steps
    if len(grown) > len(state.current):
        added = state.graph.vectors[grown[len(state.current) :]]
        state.witness = np.concatenate([state.witness, np.full(len(grown) - len(state.current), -1)])
        state.use(grown)
        state.owner, state.old_rows = None, None
        state.values = np.maximum(state.values, state.operator.products(state.rows, added.T, row_max))
    lower_b0 = state.lower_b0()
    gain = lower_b0 - state.bounds.lower
    helped = gain > config.tolerance and gain >= state.stage_gain
    state.trial_skip = 0 if helped else max(1, 2 * state.trial_skip)
    state.trial_wait = state.trial_skip
    state.bounds = _Bounds(lower_b0, state.upper_b0())
    state.record()
    return _gap_closed(state)


def _stage(state: _Anytime) -> None:
    """One Perseus stage V_n -> V_{n+1} on B, recorded in the plan graph."""
    gauss_seidel = state.config.update == "gauss-seidel"
    # The graph grows here, if the stage's vectors (about as many as V_n holds) would not fit: its copy then
    # coincides with none of the stage's arrays.
    state.graph.reserve(len(state.current))
    stage = _run_stage(state, gauss_seidel)
    state.backups, state.stage_backups = (
        state.backups + stage.n_backups,
        state.stage_backups + stage.n_backups,
    )
    state.improvement = float(np.max(stage.values - state.values))
    current = record_stage(state.graph, state.current, stage, state.rows, state.witness)
    # (vectors x |B|) floats: a Gauss-Seidel stage reuses them for the vectors it keeps as they are (a cache: the
    # same CSR row products give the same bits), while they stay small beside the stage's own rows.
    reuse = gauss_seidel and len(stage.vectors) * len(state.beliefs) <= _OLD_ROWS_MAX_ENTRIES
    state.old_rows, stage.score_rows = stage.score_rows if reuse else None, None
    state.witness = stage.witness if stage.witness is not None else np.full(len(current), -1)
    state.owner = stage.owner
    state.use(current)
    state.prune()
    state.values = stage.values
    lower_b0 = state.lower_b0()
    state.stage_gain, state.bounds = lower_b0 - state.bounds.lower, _Bounds(lower_b0, state.bounds.upper)
    state.record()
    state.report(state.improvement)


def _run_stage(state: _Anytime, gauss_seidel: bool) -> Stage:
    """The stage strategy: classic (every backup against V_n) or Gauss-Seidel (:class:`Seidel`)."""
    arguments = (
        state.operator,
        state.beliefs,
        state.rows,
        state.alphas,
        state.actions,
        state.values,
        state.rng,
    )
    if not gauss_seidel:
        return perseus_stage(*arguments, state.config.batch_size)
    seidel = Seidel(state.graph, state.current, state.owner, state.old_rows)
    stage = perseus_stage(*arguments, state.config.batch_size, seidel)
    # The stage's new vectors are in the graph already; its origin indexes the extended rows.
    state.current, state.witness = seidel.extended, np.concatenate([state.witness, seidel.new_witness])
    return stage


def _converged_on_beliefs(state: _Anytime) -> bool:
    """Whether a full backup of B confirms the Bellman residual on B is within the stop rule's bound. Perseus may
    stall on ties (a belief "improved" by an equal vector); when the residual is larger, the backups that gain
    most join V_n (a greedy cover of the beliefs that gain more than the bound)."""
    arguments = (state.operator, state.beliefs, state.rows, state.alphas, state.values, state.threshold)
    residual, fixes = full_backup_check(*arguments, state.config.batch_size)
    state.backups += len(state.beliefs)
    if residual > state.threshold:
        current = record_stage(
            state.graph, state.current, fixes.with_old(state.alphas, state.actions), state.rows, state.witness
        )
        state.witness, state.owner, state.old_rows = np.full(len(current), -1), None, None
        state.use(current)
        state.values = state.operator.products(state.rows, state.alphas.T, row_max)
        return False
    state.improvement, state.on_beliefs = residual, True
    return True


def _round(state: _Anytime) -> bool:
    """An upper-bound round and, when expanding, new beliefs for B; True: the solve is done.

    The upper bound is tightened along excess-gap paths (belief_expansion.py); expansion adds half as many beliefs
    as B holds, from the trajectories B was collected from (PBVI-like breadth: the set grows geometrically). The
    excess-gap beliefs themselves are not added: chosen greedily on a loose upper bound they cost backups without
    raising the lower bound."""
    config = state.config
    explore(
        state.upper, _lower_values(state.alphas), state.b0, config.precision, _round_updates(state.backups)
    )
    new = belief_rows(np.zeros((0, state.pomdp.n_states)))
    count = len(state.beliefs) // 2 + 1
    if config.expand and not state.expansion_capped:
        # At max_beliefs the collection still runs (and is cut to nothing below): its draws on the generator are
        # part of the seed's schedule.
        if len(state.beliefs) < state.max_beliefs and not state.fits(
            _expansion_need(state, count), f"stopped expanding its belief set at iteration {state.iteration}"
        ):
            state.expansion_capped, state.max_beliefs = True, len(state.beliefs)
    if config.expand and not state.expansion_capped:
        collected, digests = collect_belief_rows(
            state.pomdp, count, state.rng, greedy_q=state.greedy_q, epsilon=config.epsilon
        )
        new = collected[_unknown(digests, state.known)]
        del collected
    state.last_round = state.iteration
    state.bounds = _Bounds(state.bounds.lower, state.upper_b0())
    new = new[: max(0, state.max_beliefs - len(state.beliefs))]
    state.report(state.improvement, len(state.beliefs) + new.shape[0])
    if _gap_closed(state):
        return True
    if state.on_beliefs and config.expand and not new.shape[0]:
        _tighten_upper(state)
        if not _gap_closed(state):
            state.stopped = "beliefs-exhausted"
        return True
    if state.on_beliefs and _last_round(state):
        state.stopped = "stalled" if config.expand else "beliefs-converged"
        return True
    if new.shape[0]:
        state.add_beliefs(new)
    return False


def _gap_closed(state: _Anytime) -> bool:
    """Whether the gap at b0 is within the precision (the solve ends converged)."""
    if state.bounds.gap > state.config.precision:
        return False
    state.stopped = "converged"
    return True


def _last_round(state: _Anytime) -> bool:
    """After a round on a converged B: whether the solve ends there (no expansion; or, without a time limit, a
    whole expansion round moved neither bound by more than the tolerance)."""
    if not state.config.expand:
        return True
    start, bounds, tolerance = state.round_start, state.bounds, state.config.tolerance
    if (
        state.deadline is None
        and start.lower + tolerance >= bounds.lower
        and start.upper - tolerance <= bounds.upper
    ):
        return True
    state.round_start = bounds
    return False


def _tighten_upper(state: _Anytime) -> None:
    """B is exhausted and converged: only the upper bound can still move; tighten it by rounds of the same size
    while they move it (until the time limit, else until a round moves it by a tenth of the tolerance or less)."""
    config, lower = state.config, _lower_values(state.alphas)
    least = 0.0 if state.deadline is not None else 0.1 * config.tolerance
    while state.bounds.gap > config.precision and (state.deadline is None or state.clock() <= state.deadline):
        explore(state.upper, lower, state.b0, config.precision, _round_updates(state.backups))
        moved = state.bounds.upper - state.upper_b0()
        state.bounds = _Bounds(state.bounds.lower, state.bounds.upper - moved)
        state.report(state.improvement)
        if moved <= least:
            break


def _finish(state: _Anytime) -> AlphaVectorPolicy:
    """The policy: the whole plan graph, V_n and every continuation its plans use (plan_graph.py: why)."""
    state.report(state.improvement)  # the bounds as returned (a last upper-bound round may have moved them)
    bounds = state.bounds
    stats = SolverStats(
        "perseus",
        state.iteration,
        state.clock() - state.start,
        bounds.gap <= state.config.precision,
        state.improvement,
        state.beliefs.shape[0],
        tuple(state.trace),
        lower=bounds.lower,
        upper=bounds.upper,
        converged_on_beliefs=state.on_beliefs,
        n_stage_vectors=len(state.current),
        discount=state.pomdp.discount,
        stopped=state.stopped,  # closed plan values: save() may store them rounded down (policy.py)
    )
    state.prune(force=True)
    state.graph.keep_closure(state.current, force=True)
    return AlphaVectorPolicy(state.graph.vectors, state.graph.actions, stats=stats)


def _memory_cap(config: PerseusConfig) -> float | None:
    if config.max_memory is None:
        return default_cap_mb()
    return None if math.isinf(config.max_memory) else float(config.max_memory)


def _stage_need(state: _Anytime) -> float:
    """Bytes the next iteration allocates at most, about (the rule of PerseusConfig.max_memory): a stage keeps
    about as many vectors as V_n holds (``k``), each with its values on B (``k x |B|`` floats beside V_n's, kept
    from the last stage), V_n's float32 copy and fallback scores, and two copies of the vectors a batch is backed
    up against; each belief of a batch predicts a belief per action and builds its vector (with dense observations,
    also a block of V_n projected on every observation and the batch's scores on it, and the branches' candidates
    and running maxima); and when the graph's
    rows outgrow its buffer, the grown buffer is allocated while the old one is still held."""
    pomdp, graph = state.pomdp, state.graph
    k, n_beliefs, n_states = len(state.current), state.rows.shape[0], pomdp.n_states
    values = k * n_beliefs * 8
    vectors = k * (2 * n_states * 8 + n_states * 4 + pomdp.n_actions * pomdp.n_observations * 8)
    batch = 2 * state.config.batch_size * pomdp.n_actions * n_states * 8
    if not all(state.operator.sparse_observations):  # backup._dense_choices' blocks and per-branch arrays
        batch += 3 * DENSE_BLOCK_BYTES + 6 * state.config.batch_size * pomdp.n_observations * 8
    return values + vectors + batch + graph.growth_bytes(k)


def _expansion_need(state: _Anytime, count: int) -> float:
    """Bytes an expansion by ``count`` beliefs allocates, about: collect_belief_rows builds them sparse (as dense
    as B so far: its buffers of 16 bytes a nonzero, then the CSR rows of 12 bytes) with a digest each (about 128
    bytes with the set and list that hold it), B takes the new ones (12 bytes a nonzero again), and the next
    stage values V_n and its new vectors on them."""
    rows = state.rows
    nonzeros = count * (rows.nnz / max(rows.shape[0], 1))
    return nonzeros * (16 + 12 + 12) + count * 128 + 2 * len(state.current) * count * 8


def _lower_values(alphas: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    alphas_t = transposed(alphas)
    return lambda beliefs: dot(np.atleast_2d(beliefs), alphas_t).max(axis=1)


def _round_updates(backups: int) -> int:
    """Upper-bound updates of one round: a fixed share of the belief backups done so far (at least
    ``_ROUND_MIN_UPDATES``), so the upper bound's share of the work stays about constant as the solve goes on. A
    count, not seconds: the same seed gives the same rounds on a loaded host."""
    return max(_ROUND_MIN_UPDATES, math.ceil(_ROUND_SHARE * backups))


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
    Perseus' synchronous stages move it one step per stage (where b0 is far from the goal, as in cit and sunysb,
    V(b0) stays at the blind policies' value for many stages). A backup is kept only where it raises the bound at
    its belief; its continuations are rows of the graph, so the set stays closed and every vector the value of a
    plan. Returns the grown rows and the number of beliefs backed up (the path's length)."""
    alphas = graph.vectors[current]
    lower = _lower_values(alphas)
    # Paths end at the effective horizon 1 / (1 - gamma) (20 steps at 0.95, 100 at 0.99): while the upper bound
    # is loose, HSVI's gap rule alone lets them run many times longer, each step a single-belief backup.
    depth = min(max_depth(upper, lower, b0, precision), math.ceil(1.0 / (1.0 - operator.discount)))
    path = sample_path(upper, lower, b0, precision / 2, depth)
    # The set grows by at most one vector a step: its vectors and fallback scores are kept in buffers with room for
    # the whole path, and each backup (backup_one: the bits of the batched support-restricted backup) reads the
    # reached states' columns alone, so no step prepares the whole set or its transposes anew.
    count = len(current)
    vectors = np.empty((count + len(path), alphas.shape[1]))
    vectors[:count] = alphas
    fallbacks = []
    for scores in operator.fallback_scores(alphas):
        fallbacks.append(np.empty((scores.shape[0], len(vectors))))
        fallbacks[-1][:, :count] = scores
    for belief in reversed(path):
        kept = vectors[:count]
        vector, action, value, children = operator.backup_one(
            belief, kept, None, tuple(buffer[:, :count] for buffer in fallbacks)
        )
        if value > float(dot(belief, kept.T).max()) + 1e-12:
            current = np.append(current, graph.add(vector[None, :], [action], current[children][None, :]))
            vectors[count] = vector
            for buffer, scores in zip(fallbacks, operator.fallback_scores(vector[None, :]), strict=True):
                buffer[:, count] = scores[:, 0]
            count += 1
    return current, len(path)


def _unknown(digests: list[bytes], known: set[bytes]) -> np.ndarray:
    """The indices of ``digests`` not in ``known`` (beliefs new to B, to 1e-9), which are added to it."""
    fresh = []
    for index, key in enumerate(digests):
        if key not in known:
            known.add(key)
            fresh.append(index)
    return np.asarray(fresh, dtype=np.int64)


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
        "perseus",
        horizon,
        clock() - start,
        True,
        float("nan"),
        beliefs.shape[0],
        tuple(trace),
        stopped="horizon",
    )
    return AlphaVectorPolicy(
        np.vstack(stage_alphas), np.concatenate(stage_actions), np.concatenate(stage_numbers), stats=stats
    )
