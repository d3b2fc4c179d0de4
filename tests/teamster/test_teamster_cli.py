"""``embodied-adhoc teamster``: bad input is one line and exit 2; --out resumes; --json carries the curves."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from embodied_adhoc.cli import main

SMALL = ["--steps", "20", "--points", "2", "--eval-steps", "10", "--trials", "2", "--quiet"]


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["--agents", "oracle"], "--agents 'oracle'"),
        (["--steps", "45"], "--steps 45: must be a multiple of --points 10"),
        (["--changed", "1.5"], "--changed '1.5'"),
        (["--changed", "fail:x"], "--changed 'fail:x': give fail:P"),
        (["--changed", "0", "--changed-steps", "20"], "--changed-steps 20: only with a changed phase"),
        (["--trials", "0"], "--trials"),
        (["--size", "2"], "--size 2: pursuit's torus needs a side >= 3"),
        (["--wave", "0"], "--wave"),
        (["--mixed-steps", "750"], "--mixed-steps 750: must be a multiple of --steps / --points = 500"),
        (["--mixed-steps", "1000", "--changed", "mirror"], "--mixed-steps with --changed"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(argv, fragment):
    done = subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", "teamster", "pursuit", *argv],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2 and fragment in done.stderr and len(done.stderr.strip().splitlines()) == 1


def test_out_resumes_and_json_summary(tmp_path, capsys):
    argv = ["teamster", "pursuit", "--agents", "random,original", *SMALL, "--out", str(tmp_path)]
    assert main(argv + ["--json"]) == 0
    first = json.loads(capsys.readouterr().out)
    record = tmp_path / "runs" / "original" / "trial-1.json"
    stamp = record.stat().st_mtime_ns
    assert main(argv + ["--json"]) == 0  # resumed: nothing rerun, same summary
    assert json.loads(capsys.readouterr().out) == first and record.stat().st_mtime_ns == stamp
    curve = first["agents"]["original"]["curves"]["greedy"]
    assert [p["step"] for p in curve] == [0, 10, 20] and set(curve[0]["per_500"]) == {
        "mean",
        "ci",
        "n",
        "values",
    }
    cell = curve[0]["per_500"]
    assert len(cell["values"]) == cell["n"] and np.isclose(np.mean(cell["values"]), cell["mean"])
    assert (tmp_path / "curves.png").stat().st_size > 0 and "after learning" in (
        tmp_path / "table.md"
    ).read_text()
    assert (
        main(
            [
                "teamster",
                "pursuit",
                "--agents",
                "random",
                "--steps",
                "40",
                "--points",
                "2",
                "--eval-steps",
                "10",
                "--trials",
                "1",
                "--quiet",
                "--out",
                str(tmp_path),
            ]
        )
        == 2
    )
    assert "written with other settings" in capsys.readouterr().err


def test_changed_environment_table_tests_agents_on_their_trials_after_learning_began(tmp_path):
    from embodied_adhoc.experiments.domains.teamster import changed_table, plot_changed, summarise

    config = {"eval_steps": 50, "steps": 100, "points": 2}
    curves = {"teammate-aware": [[0, 1], [50, 2], [100, 3]]}

    def record(agent, trial, changed):
        return {
            "agent": agent,
            "trial": trial,
            "config": config,
            "curves": curves,
            "after": {},
            "changed": [[0, 9]] + [[50 * (i + 1), c] for i, c in enumerate(changed)],
            "seconds": 1.0,
        }

    records = [
        record("a", 0, [4, 6]),
        record("a", 1, [5, 5]),
        record("a", 2, [6, 8]),
        record("b", 0, [1, 1]),
        record("b", 1, [2, 0]),
        record("b", 2, [1, 3]),
    ]
    summary = summarise(records)
    assert summary["a"]["changed_after"] == [50.0, 50.0, 70.0]  # (4 + 6) / 2 captures per 50 steps -> per 500
    assert summary["b"]["changed_after"] == [10.0, 10.0, 20.0]  # the step-0 evaluation (9) is left out
    table = changed_table(summary)
    assert "a vs b" in table and "yes" in table.splitlines()[-1]
    no_phase = [{key: value for key, value in r.items() if key != "changed"} for r in records]
    assert changed_table(summarise(no_phase)) == ""
    for r, share in zip(records[:3], (0.2, 0.4, 0.6), strict=True):  # a learned model's fit, per point
        r["changed_fit"] = [[0, 0.1, 0.15], [50, share, 0.5], [100, 0.9, 0.8]]
    fit = summarise(records)["a"]["changed_fit"]
    assert [p["step"] for p in fit] == [0, 50, 100] and abs(fit[1]["share"]["mean"] - 0.4) < 1e-12
    assert "changed_fit" not in summarise(records)["b"]
    assert plot_changed(summarise(records), tmp_path / "changed.png").stat().st_size > 0


def test_larger_world_and_wave_are_recorded(tmp_path):
    """Section 4.1.5's 10x10 world and the planner's wave reach the trial (its record's settings); the default
    wave stays out of the record, so folders written without the option still resume."""
    small = [
        "--steps",
        "4",
        "--points",
        "2",
        "--eval-steps",
        "4",
        "--trials",
        "1",
        "--iterations",
        "10",
        "--quiet",
    ]
    argv = ["teamster", "pursuit", "--agents", "teamster", *small, "--size", "10", "--wave", "5"]
    assert main(argv + ["--out", str(tmp_path / "big")]) == 0
    config = json.loads((tmp_path / "big" / "runs" / "teamster" / "trial-0.json").read_text())["config"]
    assert config["size"] == 10 and config["wave"] == 5
    assert main(["teamster", "pursuit", "--agents", "random", *small, "--out", str(tmp_path / "plain")]) == 0
    assert (
        "wave"
        not in json.loads((tmp_path / "plain" / "runs" / "random" / "trial-0.json").read_text())["config"]
    )
