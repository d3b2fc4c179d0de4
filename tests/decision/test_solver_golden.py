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
            "562619c592513502c68623e3f15a5cb54ea7d135bb5407682d258cf3858b61c8",
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
            "64134dd07898bdaa01862b23f7d3d4febd6358b19413e39fdda2c855775060bc",
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
            "7110756e5123b898955fe64609aaee39c859912eabb6bbc66672d1dd6d5d6f58",
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
