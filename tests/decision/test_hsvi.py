"""HSVI: both bounds hold and move monotonically, the saved policy earns its lower bound, trial counts reproduce."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from embodied_adhoc.cli import main
from embodied_adhoc.decision.evaluation import evaluate_policy
from embodied_adhoc.decision.hsvi import HsviConfig, hsvi
from embodied_adhoc.decision.policy import AlphaVectorPolicy
from embodied_adhoc.decision.pomdp_io import read_pomdp
from embodied_adhoc.errors import SolverError

ROOT = Path(__file__).resolve().parents[2]
TIGER = ROOT / "assets" / "data" / "tiger.95.POMDP"
FOUR_BY_THREE = ROOT.parent / "shared" / "pomdp" / "4x3.95.POMDP"
TIGER_OPTIMUM = 19.3710  # V*(b0) of tiger.95 (Cassandra's exact solution: 19.37)


@pytest.fixture(scope="module")
def tiger_run():
    pomdp = read_pomdp(TIGER)
    reports = []
    policy = hsvi(pomdp, HsviConfig(epsilon=1.0), progress=reports.append)
    return pomdp, policy, reports


def test_converges_on_tiger_with_bounds_around_the_optimum(tiger_run):
    _, policy, reports = tiger_run
    stats = policy.stats
    assert stats.solver == "hsvi" and stats.converged and stats.upper - stats.lower <= 1.0
    assert stats.stopped == "converged"
    assert stats.lower <= TIGER_OPTIMUM + 1e-3 and stats.upper >= TIGER_OPTIMUM - 1e-3
    lower = np.array([report.value_b0 for report in reports])
    upper = np.array([report.upper_b0 for report in reports])
    assert np.all(lower <= upper)
    assert np.all(np.diff(lower) >= 0.0) and np.all(np.diff(upper) <= 0.0)
    assert upper[-1] < upper[0] and lower[-1] > lower[0]  # both bounds moved, not only one


def test_saved_policy_earns_its_lower_bound(tiger_run, tmp_path):
    pomdp, policy, _ = tiger_run
    loaded = AlphaVectorPolicy.load(policy.save(tmp_path / "tiger-hsvi.npz"))
    assert loaded.stats.lower <= policy.stats.lower  # stored rounded down, never up
    assert loaded.value(pomdp.initial_belief) >= loaded.stats.lower
    result = evaluate_policy(pomdp, loaded, episodes=2000, horizon=200, seed=3)
    assert result.mean + result.ci95 >= loaded.stats.lower
    assert result.mean - result.ci95 <= policy.stats.upper


@pytest.mark.skipif(not FOUR_BY_THREE.is_file(), reason="the shared POMDP corpus is absent")
def test_trial_counts_reproduce_and_a_longer_run_passes_through_the_shorter_one():
    pomdp = read_pomdp(FOUR_BY_THREE)
    short = [hsvi(pomdp, HsviConfig(max_trials=1)) for _ in range(2)]
    assert short[0].alphas.tobytes() == short[1].alphas.tobytes()
    assert np.array_equal(short[0].actions, short[1].actions)
    reports = []
    longer = hsvi(pomdp, HsviConfig(max_trials=2), progress=reports.append)
    assert longer.stats.iterations == 2 and short[0].stats.iterations == 1
    assert short[0].stats.stopped == longer.stats.stopped == "trial-limit"
    assert (reports[0].value_b0, reports[0].upper_b0) == (short[0].stats.lower, short[0].stats.upper)
    assert longer.alphas[: short[0].n_vectors].tobytes() == short[0].alphas.tobytes()
    assert short[0].stats.lower <= longer.stats.lower <= longer.stats.upper <= short[0].stats.upper
    assert (
        longer.value(pomdp.initial_belief) == longer.stats.lower
    )  # the reported bound is the policy's value


def test_bad_settings_are_refused():
    with pytest.raises(SolverError, match="max_trials"):
        HsviConfig(max_trials=0)
    with pytest.raises(SolverError, match="clock"):
        HsviConfig(clock="sundial")


def test_cli_refuses_hsvi_with_a_horizon_and_trials_without_hsvi(capsys):
    assert main(["pomdp", "solve", str(TIGER), "--solver", "hsvi", "--horizon", "5"]) == 2
    assert "--solver hsvi" in capsys.readouterr().err
    assert main(["pomdp", "solve", str(TIGER), "--trials", "3"]) == 2
    assert "--trials" in capsys.readouterr().err
    assert main(["pomdp", "solve", str(TIGER), "--solver", "qmdp", "--max-depth", "3"]) == 2
    assert "--max-depth is an HSVI setting" in capsys.readouterr().err


def test_cli_solves_with_hsvi(capsys):
    import json

    flags = ["--solver", "hsvi", "--trials", "2", "--max-depth", "20", "--json", "--quiet"]
    assert main(["pomdp", "solve", str(TIGER), *flags]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["solver"] == "hsvi" and report["iterations"] == 2
    assert report["lower"] <= report["upper"] and report["value_b0"] == report["lower"]


def test_trials_start_cut_at_the_effective_horizon_and_max_depth_overrides_it():
    pomdp = read_pomdp(TIGER)  # gamma 0.95: the cut starts at 20 steps; HSVI's own bound is about 200 there
    first = hsvi(pomdp, HsviConfig(max_trials=1, epsilon=1e-6)).stats
    assert 1 <= first.n_beliefs <= 20
    deeper = hsvi(pomdp, HsviConfig(max_trials=1, epsilon=1e-6, max_depth=40)).stats
    assert 20 < deeper.n_beliefs <= 40
