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
    assert report["alpha_vectors"] >= 1 and report["seconds"] > 0 and report["cpu_seconds"] > 0
    assert report["simulation"]["episodes"] == 50
    assert "iteration" in result.stderr  # progress goes to stderr
    with np.load(policy_path, allow_pickle=False) as data:
        assert data["alphas"].shape == (report["alpha_vectors"], 2)


def test_update_chooses_the_stage_and_the_classic_one_reproduces_the_library(tmp_path):
    """`--update perseus` runs the classic stage: the same solve as the library's PerseusConfig(update="perseus")
    (the CLI's --threads default changes nothing: threads give bit-identical solves); the default is Gauss-Seidel.
    On the exported gridworld model (626 states, 50 beliefs) the two stages differ (39 and 35 stages)."""
    from embodied_adhoc.decision.perseus import PerseusConfig, perseus
    from embodied_adhoc.decision.pomdp_io import read_pomdp

    assert run("export", "gridworld", "--models", "1", "--out", str(tmp_path)).returncode == 0
    model = tmp_path / "gridworld-m0.pomdp"
    flags = ("solve", str(model), "--json", "--quiet", "--no-expand", "--beliefs", "50")
    reports = {
        update: json.loads(run(*flags, "--update", update).stdout) for update in ("perseus", "gauss-seidel")
    }
    assert reports["perseus"]["iterations"] != reports["gauss-seidel"]["iterations"]
    pomdp = read_pomdp(model)
    for update, report in reports.items():
        stats = perseus(pomdp, PerseusConfig(n_beliefs=50, seed=0, update=update)).stats
        assert (report["iterations"], report["lower"]) == (stats.iterations, stats.lower)
    default = json.loads(run(*flags).stdout)
    assert (default["iterations"], default["lower"]) == (
        reports["gauss-seidel"]["iterations"],
        reports["gauss-seidel"]["lower"],
    )


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


# ------------------------------------------------------------------ clean failure: exit 2, one line, no work lost
def assert_one_line_error(result: subprocess.CompletedProcess, *fragments: str) -> str:
    assert result.returncode == 2, (result.returncode, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert all(fragment in lines[0] for fragment in fragments), lines[0]
    return lines[0]


@pytest.mark.parametrize(
    ("flags", "fragments"),
    [
        (("--time-limit", "nan"), ("--time-limit", "nan is not a finite number of seconds > 0")),
        (("--time-limit", "-3"), ("--time-limit", "-3 is not")),
        (("--sim-steps", "0"), ("--sim-steps", "0 is not an integer >= 1")),
        (("--beliefs", "0"), ("--beliefs",)),
        (("--tolerance", "inf"), ("--tolerance", "inf is not a finite number > 0")),
        (("--simulate", "-1"), ("--simulate",)),
        (("--seed", "-1"), ("--seed", "negative")),
        (("--precision", "nan"), ("--precision", "nan is not a finite number >= 0")),
        (("--clock", "sundial"), ("--clock", "invalid choice: 'sundial'")),
        (("--threads", "0"), ("--threads", "0 is not an integer >= 1")),
        (("--update", "jacobi"), ("--update", "invalid choice: 'jacobi'")),
        (("--solver", "vi", "--save-policy", "vi.npz"), ("--save-policy needs an alpha-vector policy",)),
    ],
)
def test_bad_solve_options_fail_before_any_work(flags, fragments):
    assert_one_line_error(run("solve", "tiger.95.POMDP", *flags), *fragments)


def test_save_policy_writes_exactly_the_path_asked_or_fails_before_solving(tmp_path):
    """numpy appends '.npz' to a temporary name without it, so the policy file is written through a stream: PATH
    is written as given, with no '.p.partial-PID.bin.npz' left behind; a folder or a path under a file fails first."""
    target = tmp_path / "p.bin"
    ok = run("solve", "tiger.95.POMDP", "--solver", "qmdp", "--save-policy", str(target), "--json")
    assert ok.returncode == 0, ok.stderr
    assert json.loads(ok.stdout)["policy"] == str(target)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.bin"]
    from embodied_adhoc.decision.policy import AlphaVectorPolicy

    assert AlphaVectorPolicy.load(target).n_vectors == 3
    folder = assert_one_line_error(
        run("solve", "tiger.95.POMDP", "--save-policy", str(tmp_path)), "is a folder"
    )
    assert "iteration" not in folder
    assert_one_line_error(
        run("solve", "tiger.95.POMDP", "--save-policy", str(target / "policy.npz")), "is a file, not a folder"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.bin"]


def test_export_onto_a_file_fails_before_building(tmp_path):
    taken = tmp_path / "taken"
    taken.write_text("")
    assert_one_line_error(run("export", "gridworld", "--out", str(taken)), "--out", "is not a folder")


HEADER = "discount: 0.95\nstates: {states}\nactions: 2\nobservations: 1\nstart: 0\n"


@pytest.mark.parametrize(
    ("body", "line", "fragments"),
    [
        ("T: * uniform\nO: * uniform\n", 6, ("'T: *' uniform writes", "dense")),
        (
            "T: * identity\nT: 1 : 0 : 1 -0.5\nO: * uniform\n",
            7,
            ("T entry", "start state 0, end state 1", "negative"),
        ),
        ("T: * identity\nO: * uniform\nR: 1 : 0 : * : * 1e999\n", 8, ("reward is too large for a float",)),
    ],
)
def test_bad_model_files_are_one_line_naming_file_and_line(tmp_path, body, line, fragments):
    model = tmp_path / "model.pomdp"
    model.write_text(HEADER.format(states=200_000) + body)
    message = assert_one_line_error(run("info", str(model)), *fragments)
    assert f"{model}:{line}: " in message


def test_a_model_too_large_for_dense_arrays_is_read_sparse(tmp_path):
    """200,000 states with 'identity' would need dense 200,000 x 200,000 arrays: the model is read sparse."""
    model = tmp_path / "big.pomdp"
    model.write_text(HEADER.format(states=200_000) + "T: * identity\nO: * uniform\nR: * : 3 : * : * 1\n")
    result = run("info", str(model), "--json")
    assert result.returncode == 0, result.stderr
    info = json.loads(result.stdout)
    assert (info["states"], info["transition_nonzeros"], info["observation_nonzeros"]) == (
        200_000,
        400_000,
        400_000,
    )
