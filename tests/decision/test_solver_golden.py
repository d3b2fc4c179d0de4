"""Golden solves: the exact alphas, plans, bounds and iteration count of a few fixed-length solves.

Each solve runs for a fixed number of iterations (never a time), with every mechanism of the infinite-horizon
driver at work between them: classic and Gauss-Seidel stages, trials from b0, upper-bound rounds, belief expansion
and the full-backup check. Every product that decides a choice sums in one fixed order (decision/products.py), so
these pins hold bit for bit on any host whatever its OpenBLAS kernel (the test command re-runs this file under two
other kernels); a change to the solver that is meant to give the same results must leave them unchanged.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from embodied_adhoc import paths
from embodied_adhoc.decision.perseus import PerseusConfig, perseus
from embodied_adhoc.decision.pomdp_io import read_pomdp

CORPUS = Path(__file__).resolve().parents[2] / ".." / "shared" / "pomdp"


def _chapter5_gridworld():
    from embodied_adhoc.domains.chapter5 import build_library
    from embodied_adhoc.experiments.domains.chapter5 import solver_settings

    library = build_library("gridworld", n_models=1)
    return library.pomdps[0], solver_settings(library, {"beliefs": 100, "solve_stages": 8})


def _corpus(name: str, **settings):
    path = paths.asset(f"data/{name}") if name == "tiger.95.POMDP" else CORPUS / name
    if not path.is_file():
        pytest.skip(f"corpus file {path} not present")
    return read_pomdp(path), settings


# name -> (model and settings, (alphas and actions sha256, iterations, lower, upper, beliefs))
GOLDEN = {
    # the CLI's defaults with expansion, cut at 20 iterations: trials, rounds, an exhausted belief set
    "tiger-expand": (
        lambda: _corpus("tiger.95.POMDP", n_beliefs=1000, expand=True, max_iterations=20),
        (
            "e10c547d10b2062bed05bb6187f22ed99f44ad860bdc5a9fae0e338da7bb63e9",
            20,
            16.218764919058906,
            24.333877887832273,
            7,
        ),
    ),
    # chapter 5's settings (classic stages, Table 5.4's tolerance) on its gridworld's first model
    "chapter5-gridworld": (
        _chapter5_gridworld,
        (
            "252d1974983781360a5bf0cf5fe159269db04bf6b9868b20184014f781c15ffd",
            8,
            50.54058624211393,
            72.78581064328074,
            100,
        ),
    ),
    # Gauss-Seidel stages with expansion and a time limit that never stops it (the limit's trial share)
    "hallway-gauss-seidel-expand": (
        lambda: _corpus(
            "hallway.POMDP",
            n_beliefs=100,
            expand=True,
            max_iterations=14,
            seed=2,
            time_limit=1e6,
            clock="cpu",
        ),
        (
            "c837386c9d61de6df8ec880498e259936999500188e0e2d51e11ec798a6d30ba",
            14,
            0.5549911435884515,
            1.2409469640829056,
            148,
        ),
    ),
    # Gauss-Seidel stages on a sparse-observation model, fixed belief set
    "tag-gauss-seidel": (
        lambda: _corpus("sarsop-TagAvoid.pomdp", n_beliefs=300, max_iterations=10, seed=1),
        (
            "a55549cf2320919c6a127d1f636a71859aabe49a8b5c47458bb0eec2186eebe4",
            10,
            -13.928805883553947,
            0.3294914578199974,
            300,
        ),
    ),
}


def golden_solve(name: str) -> tuple[str, int, float, float, int]:
    """The pinned quantities of one golden solve."""
    pomdp, settings = GOLDEN[name][0]()
    policy = perseus(pomdp, PerseusConfig(**settings))
    digest = hashlib.sha256(policy.alphas.tobytes() + policy.actions.tobytes()).hexdigest()
    stats = policy.stats
    return digest, stats.iterations, stats.lower, stats.upper, stats.n_beliefs


@pytest.mark.parametrize("name", list(GOLDEN))
def test_golden_solve_is_unchanged(name):
    assert golden_solve(name) == GOLDEN[name][1]
