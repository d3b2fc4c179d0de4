"""`embodied-adhoc pomdp ...` through a subprocess, as a user runs it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def run(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", "pomdp", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_info_json_of_a_shipped_name():
    result = run("info", "tiger.95.POMDP", "--json")
    assert result.returncode == 0, result.stderr
    info = json.loads(result.stdout)
    assert (info["states"], info["actions"], info["observations"], info["discount"]) == (2, 3, 2, 0.95)


def test_solve_perseus_json_with_simulation_and_saved_policy(tmp_path):
    policy_path = tmp_path / "tiger.npz"
    result = run(
        "solve", "assets/data/tiger.95.POMDP", "--json", "--simulate", "50", "--save-policy", str(policy_path)
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)  # stdout is exactly one JSON object
    assert report["value_b0"] == pytest.approx(19.37, abs=0.01)
    assert report["alpha_vectors"] >= 1 and report["seconds"] > 0
    assert report["simulation"]["episodes"] == 50
    assert "iteration" in result.stderr  # progress goes to stderr
    with np.load(policy_path, allow_pickle=False) as data:
        assert data["alphas"].shape == (report["alpha_vectors"], 2)


@pytest.mark.parametrize(("solver", "value"), [("qmdp", 189.0), ("vi", 200.0)])
def test_solve_qmdp_and_vi(solver, value):
    result = run("solve", "tiger.95.POMDP", "--solver", solver, "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["value_b0"] == pytest.approx(value, abs=1e-6)


def test_discount_one_without_horizon_is_a_clear_error(tmp_path):
    model = tmp_path / "undiscounted.pomdp"
    model.write_text("discount: 1\nstates: 2\nactions: 1\nobservations: 1\nT: * identity\nO: * uniform\n")
    result = run("solve", str(model))
    assert result.returncode == 2
    assert "--horizon N" in result.stderr and "Traceback" not in result.stderr
    ok = run("solve", str(model), "--horizon", "3", "--json", "--quiet")
    assert ok.returncode == 0, ok.stderr


def test_malformed_file_and_missing_file_errors(tmp_path):
    bad = tmp_path / "bad.pomdp"
    bad.write_text("discount: 0.9\nstates: 2\nactions: 1\nobservations: 1\nT: 0 : 5 : 0 1\n")
    result = run("info", str(bad))
    assert result.returncode == 2
    assert f"{bad}:5: found '5'" in result.stderr
    missing = run("info", "no-such-file.pomdp")
    assert missing.returncode == 2 and "shipped" in missing.stderr


def test_bare_group_prints_help():
    result = run()
    assert "info" in result.stdout and "solve" in result.stdout
