"""Heuristic search value iteration (HSVI2, Smith & Simmons 2005): trials down the optimally reachable beliefs.

Two bounds on the optimal value (thesis Eq. 2.4) are kept: a lower bound ``L(b) = max_k alpha_k . b`` whose
vectors are exact values of conditional plans (:mod:`embodied_adhoc.decision.plan_graph`, started from the blind
policies), and the sawtooth upper bound over the fast informed bound
(:mod:`embodied_adhoc.decision.upper_bound`). A trial starts at ``b0`` with depth ``t = 0`` and, while the gap
``U(b) - L(b)`` exceeds its discounted target ``epsilon / gamma^t``, takes the action greedy on the upper bound
and the observation of largest weighted excess gap ``P(z | b, a) (U(b_az) - L(b_az) - epsilon / gamma^(t+1))``.
On the way back (deepest belief first) each visited belief gets a point-based backup of the lower bound
(:mod:`embodied_adhoc.decision.backup`; the vector is kept where it raises ``L(b)``, its continuations rows of the
graph, so the set stays closed and the greedy policy earns ``L``) and a sawtooth update of the upper bound.
``L(b0)`` never decreases, ``U(b0)`` never increases, and the solve is ``converged`` once their gap is at most
``epsilon``.

No random draw is made: the trials, and so the vectors, depend on the model and ``max_trials`` alone, and every
product that decides a choice is computed in one summation order (products.py), so a trial count gives the same
bytes on any host. ``time_limit`` is read between whole trials only: it decides where a solve stops, never what
a trial computes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.decision.backup import BackupOperator, blind_policy_vectors
from embodied_adhoc.decision.belief_expansion import excess_gap_path, max_depth
from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.perseus import CLOCKS, ProgressCallback, SolverProgress
from embodied_adhoc.decision.plan_graph import PlanGraph
from embodied_adhoc.decision.policy import AlphaVectorPolicy, SolverStats
from embodied_adhoc.decision.products import dot
from embodied_adhoc.decision.upper_bound import SawtoothBound, fast_informed_bound
from embodied_adhoc.errors import SolverError

_IMPROVES = 1e-12  # a backed-up vector is kept where it raises L(b) by more than this
_STALLS = 5  # trials in a row at the depth cut that leave the gap at b0 unchanged before the cut grows


@dataclass(frozen=True)
class HsviConfig:
    """HSVI options: stop at a gap ``<= epsilon`` at b0, after ``max_trials`` trials, or at ``time_limit``
    seconds of ``clock`` ("cpu": this process's CPU time, as SARSOP counts its timeout; "wall": elapsed)."""

    epsilon: float = 1e-3
    max_trials: int = 100_000
    time_limit: float | None = None
    clock: str = "cpu"
    # Deepest belief of a trial (None: HSVI's bound, the depth at which the initial gap is within its target,
    # at least 20 and at most 1000 steps, reached in steps of 1 / (1 - gamma) as trials stall: hsvi()).
    max_depth: int | None = None
    threads: int = (
        1  # threads of the backups' large products (backup.RowProducts: the same result for any count)
    )

    def __post_init__(self) -> None:
        checks = [
            (self.epsilon < 0, f"epsilon must be >= 0, got {self.epsilon}"),
            (self.max_trials < 1, f"max_trials must be >= 1, got {self.max_trials}"),
            (
                self.time_limit is not None and self.time_limit <= 0,
                f"time_limit must be positive seconds, got {self.time_limit}",
            ),
            (self.clock not in CLOCKS, f"clock must be one of {', '.join(CLOCKS)}, got {self.clock!r}"),
            (
                self.max_depth is not None and self.max_depth < 1,
                f"max_depth must be >= 1, got {self.max_depth}",
            ),
            (
                not isinstance(self.threads, int) or self.threads < 1,
                f"threads must be an integer >= 1, got {self.threads!r}",
            ),
        ]
        for invalid, message in checks:
            if invalid:
                raise SolverError(message)


class _LowerBound:
    """The plan graph's vectors with the parts the backups and value products read, grown in place.

    Every row of the graph is part of the bound (the blind policies, then each kept backup), so its vectors are a
    contiguous view; the backups' fallback scores are kept in buffers that grow by half when full, so a backup
    costs no rebuild of them. The backups' float32 scores and the value products read the float64 vectors on the
    states a belief reaches (or covers) alone, so no transpose of the whole set is kept: on models with thousands
    of states the vectors are most of a solve's memory, and a float32 copy of them would add half again."""

    def __init__(self, pomdp: POMDP, operator: BackupOperator) -> None:
        self.operator = operator
        self.graph = PlanGraph.of_blind_policies(blind_policy_vectors(pomdp), pomdp.n_observations)
        vectors = self.graph.vectors
        self._fallback = [np.array(scores) for scores in operator.fallback_scores(vectors)]  # (Z, capacity)

    def __len__(self) -> int:
        return len(self.graph)

    def values(self, beliefs: np.ndarray) -> np.ndarray:
        """``L(b)`` for each row of ``beliefs`` (n, S), summed over the states in increasing order (as the saved
        policy's value products sum, so the reported bound is the policy's value at b0 to the bit)."""
        beliefs = np.atleast_2d(beliefs)
        support = np.flatnonzero(beliefs.any(axis=0))
        rows = sp.csr_matrix(beliefs[:, support])
        return dot(rows, self.graph.vectors[:, support].T).max(axis=1)

    def back_up(self, belief: np.ndarray) -> bool:
        """A point-based backup at ``belief``; the vector joins the bound where it raises ``L(belief)``."""
        count = len(self)
        vector, action, value, children = self.operator.backup_one(
            belief,
            self.graph.vectors,
            None,
            tuple(scores[:, :count] for scores in self._fallback),
        )
        if value <= float(self.values(belief)[0]) + _IMPROVES:
            return False
        self.graph.add(vector[None, :], action, children[None, :])
        if count == self._fallback[0].shape[1]:
            self._fallback = [_wider(scores) for scores in self._fallback]
        for buffer, scores in zip(self._fallback, self.operator.fallback_scores(vector), strict=True):
            buffer[:, count] = scores[:, 0]
        return True


def _wider(buffer: np.ndarray) -> np.ndarray:
    grown = np.empty((buffer.shape[0], buffer.shape[1] + max(1, buffer.shape[1] // 2)), dtype=buffer.dtype)
    grown[:, : buffer.shape[1]] = buffer
    return grown


def hsvi(
    pomdp: POMDP, config: HsviConfig | None = None, progress: ProgressCallback | None = None
) -> AlphaVectorPolicy:
    """Solve ``pomdp`` (infinite horizon, ``gamma < 1``) by HSVI2 trials; the policy's ``stats`` hold the bounds
    at b0 (``lower`` is what the saved policy earns), the trial count and the trace of ``L(b0)``."""
    config = config or HsviConfig()
    if pomdp.discount >= 1.0:
        raise SolverError("discount is 1.0: HSVI needs gamma < 1; use --solver perseus with --horizon N")
    timer = CLOCKS[config.clock]
    start = timer()
    operator = BackupOperator(pomdp, threads=config.threads)
    try:
        lower = _LowerBound(pomdp, operator)
        upper = SawtoothBound(pomdp, fast_informed_bound(pomdp))
        b0 = pomdp.initial_belief
        bounds = [float(lower.values(b0)[0]), float(upper.values(b0)[0])]
        depth = config.max_depth or max_depth(upper, lower.values, b0, max(config.epsilon, 1e-9))
        # Without --max-depth, trials start cut at the effective horizon 1 / (1 - gamma): while the upper bound is
        # loose HSVI's own bound lets the first trials run hundreds of single-belief steps, most beyond where
        # their value reaches b0. The cut grows by one horizon after _STALLS trials in a row reach it and leave
        # the gap at b0 as it was, so it reaches HSVI's bound where the gap needs it and convergence holds.
        horizon = math.ceil(1.0 / (1.0 - pomdp.discount))
        limit = depth if config.max_depth else min(depth, horizon)
        trace = [(timer() - start, bounds[0])]
        visited, trials, stalled = 0, 0, 0
        while bounds[1] - bounds[0] > config.epsilon and trials < config.max_trials:
            if config.time_limit is not None and timer() - start > config.time_limit:
                break
            trials += 1
            steps = _trial(lower, upper, b0, config.epsilon, limit)
            visited += steps
            gap = bounds[1] - bounds[0]
            bounds = [max(bounds[0], float(lower.values(b0)[0])), min(bounds[1], float(upper.values(b0)[0]))]
            stalled = stalled + 1 if steps == limit and bounds[1] - bounds[0] >= gap else 0
            if stalled == _STALLS:
                limit, stalled = min(depth, limit + horizon), 0
            trace.append((timer() - start, bounds[0]))
            if progress is not None:
                progress(
                    SolverProgress(trials, trace[-1][0], bounds[0], len(lower), np.nan, bounds[1], visited)
                )
        converged = bounds[1] - bounds[0] <= config.epsilon
        stopped = (
            "converged" if converged else ("trial-limit" if trials >= config.max_trials else "time-limit")
        )
        stats = SolverStats(
            "hsvi",
            trials,
            timer() - start,
            converged,
            bounds[1] - bounds[0],
            visited,
            tuple(trace),
            lower=bounds[0],
            upper=bounds[1],
            n_stage_vectors=len(lower),
            discount=pomdp.discount,  # closed plan values: save() may store them rounded down (policy.py)
            stopped=stopped,
        )
        return AlphaVectorPolicy(lower.graph.vectors, lower.graph.actions, stats=stats)
    finally:
        operator.close()


def _trial(lower: _LowerBound, upper: SawtoothBound, b0: np.ndarray, epsilon: float, depth: int) -> int:
    """One HSVI2 trial from ``b0`` (module docstring); returns the number of beliefs it updated."""
    path = excess_gap_path(upper, lower.values, b0, epsilon, depth)
    for belief, successors in reversed(path):
        lower.back_up(belief)
        upper.update(belief, successors)
    return len(path)
