"""scripts/bench_solvers.py --side-by-side on a tiny model: without pomdpsol on the PATH it says that SARSOP is
absent and still writes this project's bounds, peak memory and vectors; the checkpoint reading and the time to a
target come from the solve's own trace."""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from embodied_adhoc import paths

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def script(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "scripts"))
    return importlib.import_module("bench_solvers")


@pytest.mark.parametrize("solver", ["hsvi", "perseus"])
def test_side_by_side_without_pomdpsol_says_so_and_writes_our_rows(tmp_path, solver):
    empty = tmp_path / "bin"
    empty.mkdir()
    out = tmp_path / "side.json"
    env = {**os.environ, "PATH": str(empty), "OPENBLAS_NUM_THREADS": "1"}
    tiger = paths.asset("data/tiger.95.POMDP")
    command = [sys.executable, str(ROOT / "scripts" / "bench_solvers.py"), "--side-by-side", str(tiger)]
    command += ["--checkpoints", "0.2", "2", "--solver", solver, "--json-out", str(out)]
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    assert "pomdpsol not on the PATH" in done.stdout
    (row,) = json.loads(out.read_text())["rows"]
    assert row["file"] == "tiger.95.POMDP" and row["solver"] == solver
    assert "sarsop" not in row and "time_ratio" not in row
    assert row["ours_vectors"] >= 1 and row["ours_peak_mb"] > 0.0
    assert set(row["ours"]) == {"0.2", "2"}
    lower, upper = row["ours"]["2"]  # a tiger trial or stage takes milliseconds: there is a point by 2 s
    assert -100.0 < lower <= upper < 1000.0
    assert f"| tiger.95.POMDP | 2 | 2 | {solver} |" in done.stdout


def test_side_by_side_refuses_a_missing_file(tmp_path):
    done = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "bench_solvers.py"), "--side-by-side", str(tmp_path / "no")],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 2
    assert "--side-by-side: no file" in done.stderr


def test_checkpoints_and_time_to_target_read_the_trace(script):
    trace = [(0.1, 1.0, 5.0), (0.4, 2.0, 4.0), (1.5, 3.0, 3.5)]
    assert script._at(trace, 0.05) is None
    assert script._at(trace, 0.4) == (2.0, 4.0)
    assert script._at(trace, 1.0) == (2.0, 4.0)
    assert script._reached(trace, 2.5) == 1.5
    assert script._reached(trace, 3.5) is None


def test_a_generated_model_is_written_for_both_solvers_and_its_convergence_recorded(tmp_path):
    """``rocksample:N,K`` is generated into a temporary file; the JSON document goes to stdout with ``-``, the
    table to stderr; a tiny model closes its gap, and the row says when."""
    empty = tmp_path / "bin"
    empty.mkdir()
    env = {**os.environ, "PATH": str(empty), "OPENBLAS_NUM_THREADS": "1"}
    command = [sys.executable, str(ROOT / "scripts" / "bench_solvers.py"), "--side-by-side", "rocksample:2,1"]
    command += ["--checkpoints", "2", "--json-out", "-"]
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    document = json.loads(done.stdout)
    assert document["pomdpsol"] is None and document["models"] == ["rocksample:2,1"]
    (row,) = document["rows"]
    assert row["file"] == "rocksample-2-1.pomdp" and row["model"] == "rocksample:2,1" and row["states"] == 9
    assert row["ours_converged"] and 0.0 <= row["ours_seconds_to_converge"] <= 2.0
    lower, upper = row["ours"]["2"]
    assert upper - lower <= 1e-3
    assert "| rocksample-2-1.pomdp | 9 | 2 |" in done.stderr and "yes (" in done.stderr


@pytest.mark.parametrize(
    ("spec", "said"),
    [
        ("export:nowhere", "no chapter-5 domain 'nowhere'"),
        ("rocksample:0,1", "no file"),
        ("random:3,2,4", "5 successors of 3 states"),
        ("random:100000,65,10", "actions = 65 exceeds 64"),
    ],
)
def test_a_bad_generated_model_is_refused_before_any_solve(spec, said):
    done = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "bench_solvers.py"), "--side-by-side", spec],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 2 and said in done.stderr and done.stderr.count("\n") == 1


def test_a_model_may_name_its_own_solver(script):
    assert script.split_solver("export:isr@hsvi", "auto") == ("export:isr", "hsvi")
    assert script.split_solver("rocksample:5,6", "perseus") == ("rocksample:5,6", "perseus")
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "scripts" / "bench_solvers.py"),
            "--side-by-side",
            "rocksample:2,1@sarsop",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 2 and "expected @auto, @hsvi or @perseus, got @sarsop" in done.stderr


def test_sarsop_s_printed_digits_set_how_close_counts_as_reaching_it(script):
    assert script.printed_resolution("13.3119") == pytest.approx(1e-4)
    assert script.printed_resolution("-6.2") == pytest.approx(0.1)
    assert script.printed_resolution("2.5e-03") == pytest.approx(1e-4)
    assert script.printed_resolution("20") == 1.0


def test_the_allocation_bench_runs_the_same_work_under_each_setting(tmp_path):
    """scripts/bench_solver_memory.py: one fresh process per setting, the same bounds in each, ratios to the first."""
    out = tmp_path / "rows.json"
    command = [
        sys.executable,
        str(ROOT / "scripts" / "bench_solver_memory.py"),
        "--job",
        "hsvi:rocksample:3,2:4",
    ]
    command += ["--setting", "1:8", "--setting", "4:2", "--json", str(out)]
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    first, second = json.loads(out.read_text())["rows"]
    assert (first["setting"], second["setting"]) == ("1:8", "4:2")
    assert (first["lower"], first["upper"]) == (second["lower"], second["upper"])
    assert first["cpu"] > 0 and first["peak_mb"] > 0 and first["faults"] >= 0
    assert "| hsvi:rocksample:3,2:4 | 1:8 | " in done.stdout and " | 1.00 | " in done.stdout
