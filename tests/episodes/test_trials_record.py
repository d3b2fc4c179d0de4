"""``trials --record``: episode 0 of every agent of a physics sweep recorded through the one recorded-run driver,
the same episode the sweep ran as its trial 0; refused with one line before any trial where nothing can be
recorded."""

import csv
import json
import subprocess
import sys

import pytest


def _trials(*args: str, timeout: int = 600) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", "trials", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def test_trials_record_writes_episode_zero_of_the_sweep(tmp_path):
    sweep = "toxic-waste --backend mujoco --agents hotspot --episodes 1 --seed 3 --max-steps 3".split()
    result = _trials(*sweep, "--out", str(tmp_path / "sweep"), "--record", str(tmp_path / "rec"))
    assert result.returncode == 0, result.stderr
    folder = tmp_path / "rec" / "hotspot"
    assert "recorded hotspot episode 0" in result.stdout and str(folder) in result.stdout
    assert {p.name for p in folder.iterdir()} >= {"episode.mp4", "episode.rrd", "metrics.json"}
    metrics = json.loads((folder / "metrics.json").read_text())
    with open(tmp_path / "sweep" / "trials.csv", newline="") as handle:
        (trial,) = list(csv.DictReader(handle))
    assert metrics["config"]["command"] == "trials toxic-waste --record"
    assert metrics["steps"] == int(trial["steps"]) and 1 <= metrics["steps"] <= 3
    assert metrics["success"] == (trial["success"] in ("1", "True", "true"))
    assert metrics["config"]["spec"]["task"] == int(trial["task"])
    with open(tmp_path / "sweep" / "steps.csv", newline="") as handle:
        actions = [int(row["action"]) for row in csv.DictReader(handle) if row["action"]]
    assert [step["action"] for step in metrics["per_step"]] == actions  # the trial's own trajectory


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("toxic-waste",), "--record records the physics episodes: add --backend mujoco"),
        (("pursuit", "--backend", "mujoco"), "add --pairs"),
        (("gridworld",), "--record: trials gridworld has no recorded physics episode"),
    ],
)
def test_trials_record_is_refused_before_any_trial(tmp_path, args, message):
    result = _trials(*args, "--episodes", "1", "--record", str(tmp_path / "rec"), timeout=120)
    assert result.returncode == 2 and message in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and not (tmp_path / "rec").exists()
