"""Trial plug-ins of the arenas through the CLI (subprocess) and the runner's registry."""

import json
import subprocess
import sys

import pytest

from embodied_adhoc.experiments.registry import get_trial_domain


def run_cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", *args], capture_output=True, text=True, timeout=300
    )


@pytest.mark.parametrize(
    "argv",
    [
        (
            "trials",
            "foraging",
            "--backend",
            "abstract",
            "--team",
            "tau1",
            "--task",
            "2",
            "--episodes",
            "4",
            "--json",
        ),
        (
            "trials",
            "pursuit",
            "--backend",
            "abstract",
            "--pairs",
            "--team",
            "aware",
            "--episodes",
            "4",
            "--json",
        ),
        (
            "trials",
            "pursuit",
            "--backend",
            "mujoco",
            "--team",
            "tau2",
            "--task",
            "1",
            "--episodes",
            "1",
            "--agents",
            "original",
            "--json",
        ),
    ],
)
def test_trials_cli_runs_and_original_succeeds(argv):
    result = run_cli(*argv)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["agents"]["original"]["success_rate"] == 1.0


def test_bad_team_is_one_line_error():
    result = run_cli("trials", "foraging", "--team", "greedy", "--episodes", "1")
    assert result.returncode == 2 and "--team greedy" in result.stderr and "Traceback" not in result.stderr


def test_episode_spec_is_shared_and_seeded():
    import numpy as np

    domain = get_trial_domain("pursuit")
    options = {
        "domain": "pursuit",
        "teams": ["tau0", "tau2"],
        "task": None,
        "rows": 5,
        "cols": 5,
        "agents": 4,
        "toroidal": False,
        "pairs": False,
    }
    a = domain.episode_spec(options, np.random.default_rng(5))
    assert a == domain.episode_spec(options, np.random.default_rng(5))
    assert 0 <= a["task"] < 4 and a["team"] in ("tau0", "tau2") and json.loads(a["start"])["agents"]
