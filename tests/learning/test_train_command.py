"""``embodied-adhoc train atlpo`` through a subprocess, as a user runs it (tiny settings)."""

import json
import subprocess
import sys

import pytest

from embodied_adhoc.learning.atlpo import load_library


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", *args], capture_output=True, text=True, timeout=300
    )


@pytest.mark.slow  # three subprocesses that import torch and train three tiny members: ~20-40 s
def test_train_atlpo_writes_a_loadable_library_and_resumes(tmp_path):
    out = tmp_path / "library"
    args = (
        "train",
        "atlpo",
        "--domain",
        "pursuit",
        "--set",
        "team",
        "--steps",
        "64",
        "--envs",
        "2",
        "--episodes",
        "4",
        "--episode-steps",
        "6",
        "--iterations",
        "3",
        "--threads",
        "1",
        "--quiet",
        "--out",
        str(out),
    )
    result = run_cli(*args)
    assert result.returncode == 0, result.stderr
    library, classifier = load_library(out)
    assert [e.name for e in library.environments] == ["task1-tau0", "task1-tau1", "task1-tau2"]
    assert classifier is not None and classifier.config.environments == 3
    report = json.loads((out / "training.json").read_text())
    assert len(report["per_step"]) == 6 and report["members"] == ["task1-tau0", "task1-tau1", "task1-tau2"]
    before = {p.name: p.read_bytes() for p in out.glob("pursuit-task1-*.safetensors")}
    assert run_cli(*args).returncode == 0  # resumes: the members are not retrained
    assert before == {p.name: p.read_bytes() for p in out.glob("pursuit-task1-*.safetensors")}


def test_train_atlpo_refuses_bad_input(tmp_path):
    result = run_cli(
        "train", "atlpo", "--domain", "pursuit", "--set", "team", "--steps", "0", "--out", str(tmp_path)
    )
    assert (
        result.returncode == 2
        and "--steps 0" in result.stderr
        and len(result.stderr.strip().splitlines()) == 1
    )
    result = run_cli("train", "atlpo", "--domain", "lab", "--set", "team", "--out", str(tmp_path))
    assert result.returncode == 2 and "--domain" in result.stderr
