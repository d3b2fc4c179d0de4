"""Alpha-vector policies: a piecewise-linear convex value function ``V(b) = max_k alpha_k . b`` (thesis Eq. 2.5).

Each vector carries the action that starts its conditional plan, so ``action(b)`` is the action of the
maximising vector. Finite-horizon solutions are time dependent: each vector also carries ``stages[k]``, the
number of steps to go it was computed for, and ``value``/``action`` take ``steps_to_go`` (default: the longest
stage, i.e. the start of an episode). Infinite-horizon policies have every stage equal to 0, meaning "any".

Saved as a compressed ``.npz`` (``allow_pickle=False`` on load), written atomically. A closed Perseus policy
(``stats.discount`` set, at most 0.999) is stored in float32 rounded *down* by a uniform margin, which keeps the
earned lower bound (:meth:`AlphaVectorPolicy.as_stored`, :func:`_float32_below`); other vectors are stored exactly
(float32 when they are float32 numbers, else float64). Old uncompressed float64
files (format 1) load unchanged.
"""

from __future__ import annotations

import dataclasses
import functools
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from embodied_adhoc.atomic import atomic_open
from embodied_adhoc.decision.products import dot, transposed
from embodied_adhoc.errors import ModelError

_FORMAT_VERSION = 2  # 1: uncompressed float64; 2: compressed, float32 rounded down for closed policies
_FLOAT32_MAX_DISCOUNT = 0.999  # above it the margin 2u/(1 - gamma) stops being small: keep float64


@dataclass(frozen=True)
class SolverStats:
    """How a solve went: for reports and benchmarks (saved with the policy as JSON metadata)."""

    solver: str
    iterations: int
    seconds: float
    converged: bool
    residual: float  # last improvement (Perseus: max over beliefs; VI/QMDP: Bellman sup-norm); nan if n/a
    n_beliefs: int = 0
    trace: tuple[tuple[float, float], ...] = ()  # (seconds since start, value at b0) after each iteration
    lower: float = float("nan")  # bounds on the optimal value at b0 (Perseus): the policy achieves lower
    upper: float = float("nan")
    converged_on_beliefs: bool = False  # the backups converged on the belief set (Perseus' own criterion)
    n_stage_vectors: int = 0  # vectors of the last stage V_n (the policy also keeps their continuations)
    # The model's discount when the vectors are a closed set of exact plan values (infinite-horizon Perseus), so
    # that greedy execution earns max_k alpha_k . b; nan otherwise. save() uses it to round down safely.
    discount: float = float("nan")
    # Why the solve ended: "converged" (the gap at b0 within the precision), "time-limit", "iteration-limit",
    # "trial-limit" (HSVI's --trials), "memory-cap" (the next iteration would pass --max-memory),
    # "beliefs-exhausted" (converged on a belief set that expansion no longer grows), "stalled" (a round on a
    # converged set moved neither bound), "beliefs-converged" (converged on a fixed set), "horizon" (every stage
    # of a finite horizon); "" when the solver does not say.
    stopped: str = ""

    @property
    def gap(self) -> float:
        return self.upper - self.lower

    def as_dict(self) -> dict:
        """JSON-ready summary (the trace as [seconds, value] pairs)."""
        fields = {name: getattr(self, name) for name in self.__dataclass_fields__}
        fields["trace"] = [list(point) for point in self.trace]
        fields["gap"] = self.gap
        return fields


@dataclass(frozen=True, eq=False)
class AlphaVectorPolicy:
    """``alphas`` (K, S) float64, ``actions`` (K,) ints; optional ``stages`` (K,) steps-to-go (finite horizon)."""

    alphas: np.ndarray
    actions: np.ndarray
    stages: np.ndarray | None = None
    stats: SolverStats | None = None

    def __post_init__(self) -> None:
        alphas = np.ascontiguousarray(self.alphas, dtype=np.float64)
        actions = np.asarray(self.actions)
        if alphas.ndim != 2 or alphas.shape[0] == 0:
            raise ModelError(f"alphas must be a non-empty (K, S) array, got shape {alphas.shape}")
        if actions.shape != (alphas.shape[0],) or not np.issubdtype(actions.dtype, np.integer):
            raise ModelError(
                f"actions must be {alphas.shape[0]} integers, got {actions.dtype} {actions.shape}"
            )
        if not np.all(np.isfinite(alphas)):
            raise ModelError("alphas contain a non-finite entry")
        stages = np.zeros(len(actions), dtype=np.int64) if self.stages is None else np.asarray(self.stages)
        if stages.shape != actions.shape or not np.issubdtype(stages.dtype, np.integer) or stages.min() < 0:
            raise ModelError(
                f"stages must be {len(actions)} non-negative integers, got {stages.dtype} {stages.shape}"
            )
        object.__setattr__(self, "alphas", alphas)
        object.__setattr__(self, "actions", actions.astype(np.int64))
        object.__setattr__(self, "stages", stages.astype(np.int64))

    @functools.cached_property
    def _alphas_t(self) -> np.ndarray:
        """(S, K) C-contiguous: the right operand of the value products (products.py: the same bits on any host,
        so the same belief picks the same action whatever BLAS kernel the host runs)."""
        return transposed(self.alphas)

    def _scores(self, beliefs: np.ndarray, steps_to_go: int | None) -> np.ndarray:
        """``beliefs @ alphas[rows].T`` for the vectors of ``steps_to_go``, in products.py's fixed order."""
        rows = self._rows(steps_to_go)
        return dot(beliefs, self._alphas_t)[..., rows]

    @property
    def n_vectors(self) -> int:
        return self.alphas.shape[0]

    @property
    def n_states(self) -> int:
        return self.alphas.shape[1]

    @property
    def horizon(self) -> int | None:
        """The number of steps a finite-horizon policy plans for, or None for an infinite-horizon policy."""
        top = int(self.stages.max())
        return top if top > 0 else None

    def _rows(self, steps_to_go: int | None) -> np.ndarray | slice:
        if self.horizon is None:
            return slice(None)
        stage = self.horizon if steps_to_go is None else int(steps_to_go)
        rows = np.flatnonzero(self.stages == stage)
        if rows.size == 0:
            raise ModelError(
                f"this finite-horizon policy has no vectors for {stage} steps to go (1..{self.horizon})"
            )
        return rows

    def values(self, beliefs: np.ndarray, steps_to_go: int | None = None) -> np.ndarray:
        """``max_k alpha_k . b`` for each row of ``beliefs`` (N, S), batched."""
        return self._scores(np.atleast_2d(beliefs), steps_to_go).max(axis=1)

    def value(self, belief: np.ndarray, steps_to_go: int | None = None) -> float:
        return float(self.values(belief, steps_to_go)[0])

    def action(self, belief: np.ndarray, steps_to_go: int | None = None) -> int:
        scores = self._scores(np.asarray(belief, dtype=np.float64), steps_to_go)
        return int(self.actions[self._rows(steps_to_go)][int(np.argmax(scores))])

    def actions_of(self, beliefs: np.ndarray, steps_to_go: int | None = None) -> np.ndarray:
        """The action of each row of ``beliefs`` (N, S), batched."""
        scores = self._scores(np.atleast_2d(beliefs), steps_to_go)  # over each belief's support only
        return self.actions[self._rows(steps_to_go)][np.argmax(scores, axis=1)]

    # ------------------------------------------------------------------------------------------ files
    def as_stored(self) -> AlphaVectorPolicy:
        """The policy exactly as :meth:`save` writes it and :meth:`load` reads it back: a closed Perseus policy
        (``stats.discount`` in (0, 0.999]) rounded down to float32 with its lower bound lowered to match
        (:func:`_float32_below`; ``discount`` then nan, so a second call changes nothing), anything else unchanged.
        Callers that cache policies use it so that a fresh solve and a cache hit act identically."""
        stats = self.stats
        if stats is None or not 0.0 < stats.discount <= _FLOAT32_MAX_DISCOUNT:
            return self
        alphas, lowered = _float32_below(self.alphas, stats.discount)
        lower = float(np.nextafter(stats.lower - lowered, -np.inf))
        stats = dataclasses.replace(stats, lower=lower, discount=float("nan"))
        return AlphaVectorPolicy(alphas, self.actions, self.stages, stats=stats)

    def save(self, path: str | Path) -> Path:
        """Write the policy to exactly ``path`` (an .npz archive whatever the suffix) atomically; no pickle."""
        path = Path(path)
        stored = self.as_stored()
        alphas, stats = stored.alphas, stored.stats
        as_float32 = alphas.astype(np.float32)
        # exact in float32 (as_stored made it so): half the bytes, lossless
        if np.array_equal(as_float32, alphas):
            alphas = as_float32
        # The solver's report (bounds at b0, gap, convergence, trace) as a JSON string: metadata, not pickle.
        metadata = {} if stats is None else {"solver_stats": np.array(json.dumps(stats.as_dict()))}
        with atomic_open(path) as stream:  # a stream: numpy then adds no '.npz' to the name
            np.savez_compressed(
                stream,
                alphas=alphas,
                actions=self.actions,
                stages=self.stages,
                format_version=np.int64(_FORMAT_VERSION),
                **metadata,
            )
        return path

    @classmethod
    def load(cls, path: str | Path) -> AlphaVectorPolicy:
        """Read a policy written by :meth:`save`; a clear ModelError for a file that is not one."""
        try:
            with np.load(Path(path), allow_pickle=False) as data:
                missing = {"alphas", "actions", "stages"} - set(data.files)
                if missing:
                    raise ModelError(f"{path}: not an alpha-vector policy file (missing {sorted(missing)})")
                version = int(data["format_version"]) if "format_version" in data.files else 1
                if version > _FORMAT_VERSION:
                    raise ModelError(
                        f"{path}: policy format {version} is newer than this version reads ({_FORMAT_VERSION}):"
                        " update embodied-adhoc or solve again"
                    )
                stats = None
                if "solver_stats" in data.files:
                    fields = json.loads(str(data["solver_stats"]))
                    fields.pop("gap", None)
                    fields["trace"] = tuple(tuple(point) for point in fields["trace"])
                    stats = SolverStats(**fields)
                return cls(data["alphas"], data["actions"], data["stages"], stats=stats)
        except (OSError, ValueError, TypeError, KeyError) as error:
            if isinstance(error, ModelError):
                raise
            raise ModelError(f"{path}: cannot read an alpha-vector policy ({error})") from error


def _float32_below(alphas: np.ndarray, discount: float) -> tuple[np.ndarray, float]:
    """``(stored, lowered)``: ``alphas`` in float32 with every entry below its exact value by a margin in
    ``[m, m + u]`` (``u``: the float32 spacing at the largest magnitude, ``m`` just above ``gamma u / (1 - gamma)``),
    and ``lowered``, the largest drop.

    Why the lower bound stays earned: the exact vectors are closed (each is ``r_a + gamma * sum T O`` of vectors in
    the set), so the backup of the stored set is at least ``alpha - gamma (m + u) >= alpha - m >= stored`` for each
    vector: the stored set is uniformly improvable, and greedy execution on it earns ``max_k stored_k . b`` (Pineau
    et al.'s argument behind the closed policy, plan_graph.py), which is at least the solver's bound minus
    ``lowered``. Comparisons between float32 and float64 are exact, so the rounding direction is checked, not hoped.
    """
    scale = max(float(np.abs(alphas).max()), 1.0)
    top = scale * (
        1.0 + 2.0**-20 / (1.0 - discount)
    )  # above every |alpha - m| (m < 2**-20 scale / (1 - gamma))
    spacing = float(np.spacing(np.float32(top)))  # >= the float32 spacing at any |x| <= top
    # m (1 - gamma) >= gamma u, with slack for the float64 rounding of alpha - m (about 1e-16 scale)
    margin = 1.01 * (discount * spacing + 1e-12 * scale) / (1.0 - discount)
    target = alphas - margin
    stored = target.astype(np.float32)
    above = stored.astype(np.float64) > target
    stored[above] = np.nextafter(stored[above], np.float32(-np.inf))
    return stored, float((alphas - stored.astype(np.float64)).max())
