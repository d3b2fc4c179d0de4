"""On-disk cache of solved policies, keyed by the model's content, the solver settings and the BLAS kernel.

A key is the SHA-256 of the POMDP's arrays (every transition and observation matrix, rewards, discount, initial
belief), of the solver settings (JSON, sorted keys), of the solver's own source files: every module directly in
``embodied_adhoc/decision/`` (Perseus, backups, beliefs, ``plan_graph.py``, the bounds, the policy, the models, value
iteration and any solver module added there), so that a changed solver never serves an old answer, and of the BLAS
kernel class (:func:`embodied_adhoc.experiments.identity.blas_kernel`: a solve's sums, hence its ties and its
policy, can differ between the kernels OpenBLAS picks per CPU), so that a cache filled on one kernel never serves
another. Policies are ``AlphaVectorPolicy`` ``.npz`` files (no pickle), written atomically, under
``$XDG_CACHE_HOME/embodied-adhoc/policies`` (default ``~/.cache/embodied-adhoc/policies``), never inside the package.

An entry that does not load as a policy of its model (truncated, empty, a foreign file, vectors of another shape or
actions out of range) is solved again and overwritten, with a one-line note on stderr naming the file.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import sys
import zipfile
from pathlib import Path

import numpy as np

__all__ = [
    "cache_dir",
    "cache_key",
    "is_blind",
    "load_entry",
    "model_digest",
    "solve_cached",
    "solver_sources",
]


def cache_dir() -> Path:
    """The policy cache folder (XDG base directory specification)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "embodied-adhoc" / "policies"


def model_digest(pomdp) -> str:
    """SHA-256 of everything that defines ``pomdp`` (names excluded: they do not change a solution)."""
    digest = hashlib.sha256()
    digest.update(
        np.asarray([pomdp.n_states, pomdp.n_actions, pomdp.n_observations, pomdp.discount]).tobytes()
    )
    for matrices in (pomdp.transitions, pomdp.observations):
        for matrix in matrices:
            for array in (matrix.indptr, matrix.indices, matrix.data):
                digest.update(np.ascontiguousarray(array).tobytes())
    digest.update(np.ascontiguousarray(pomdp.rewards).tobytes())
    digest.update(np.ascontiguousarray(pomdp.initial_belief).tobytes())
    return digest.hexdigest()


@functools.lru_cache(maxsize=1)
def _solver_digest() -> str:
    """Digest of the solver's source files (every ``decision/*.py``, sorted by name; the agents' subpackage is
    left out: it does not change a solution), read once per process: the code this process runs (a file edited
    after the solver was imported must not label policies the old code solved)."""
    digest = hashlib.sha256()
    for path in solver_sources():
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def solver_sources() -> list[Path]:
    """The source files whose content is part of every cache key: ``embodied_adhoc/decision/*.py``, sorted."""
    import embodied_adhoc.decision as decision

    return sorted(Path(decision.__file__).parent.glob("*.py"))


def cache_key(pomdp, settings: dict) -> str:
    """The entry name of a solve: model, settings, solver sources and BLAS kernel class (module docstring)."""
    from embodied_adhoc.experiments.identity import blas_kernel

    parts = [model_digest(pomdp), json.dumps(settings, sort_keys=True), _solver_digest(), blas_kernel()]
    return hashlib.sha256("|".join(parts).encode()).hexdigest()


def load_entry(path: Path, pomdp) -> tuple[object | None, str]:
    """``(policy, "")`` when ``path`` holds a policy of ``pomdp`` (vectors over its states, its actions), else
    ``(None, what is wrong)``: a damaged or foreign entry is a reason to solve again, never an error."""
    from embodied_adhoc.decision.policy import AlphaVectorPolicy

    try:
        if path.stat().st_size == 0:
            return None, "is empty"
        policy = AlphaVectorPolicy.load(path)
    except (OSError, ValueError, EOFError, KeyError, TypeError, zipfile.BadZipFile) as error:
        text = (str(error).splitlines() or [""])[0].replace(f"{path}: ", "")[:120]
        return None, f"does not load ({type(error).__name__}: {text})"
    if policy.alphas.shape[1] != pomdp.n_states:
        return None, f"holds vectors over {policy.alphas.shape[1]} states, the model has {pomdp.n_states}"
    if policy.actions.min() < 0 or policy.actions.max() >= pomdp.n_actions:
        return None, f"names actions outside the model's 0..{pomdp.n_actions - 1}"
    return policy, ""


def is_blind(policy) -> bool:
    """Whether a Perseus solve stopped (its time limit) before completing one backup stage: the policy is then the
    blind-policy lower bound it starts from (one action for ever), not a solution."""
    stats = getattr(policy, "stats", None)
    return stats is not None and stats.iterations == 0 and not stats.converged


def solve_cached(pomdp, settings: dict, use_cache: bool = True) -> tuple[object, bool]:
    """``(policy, from_cache)``: Perseus with ``settings`` (``PerseusConfig`` fields) on ``pomdp``, loaded from the
    cache when a policy of the same model, settings and solver exists; solved and stored otherwise (a blind policy,
    :func:`is_blind`, is never stored: a later run with more time must solve again). ``use_cache`` False bypasses
    the cache entirely (neither read nor written)."""
    from embodied_adhoc.decision.perseus import PerseusConfig, perseus

    _solver_digest()  # fixed now, as the solver modules were just imported
    if not use_cache:  # as stored (float32 rounded down): a cache hit, a miss and no cache act identically
        return perseus(pomdp, PerseusConfig(**settings)).as_stored(), False
    path = cache_dir() / f"{cache_key(pomdp, settings)}.npz"
    if path.exists():
        policy, problem = load_entry(path, pomdp)
        if policy is not None:
            return policy, True
        print(f"embodied-adhoc: note: policy cache entry {path} {problem}; solving again", file=sys.stderr)
    policy = perseus(pomdp, PerseusConfig(**settings)).as_stored()
    if not is_blind(policy):
        path.parent.mkdir(parents=True, exist_ok=True)
        policy.save(path)
    return policy, False
