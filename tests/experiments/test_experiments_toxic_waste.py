"""The toxic-waste trial domain on the abstract backend (the lab engineer's env, models and agents)."""

import json
import subprocess
import sys

import pytest

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.registry import get_trial_domain
from embodied_adhoc.experiments.runner import SweepConfig, run_sweep

DOMAIN = get_trial_domain("toxic-waste")


def sweep(**changes) -> SweepConfig:
    fields = {"domain": "toxic-waste", "backend": "abstract", "options": DOMAIN.options(),
              "agents": ("hotspot", "oracle"), "episodes": 4, "seed": 11}  # fmt: skip
    fields.update(changes)
    return SweepConfig(**fields)


def test_episode_specs_cover_start_nodes_and_tasks():
    import numpy as np

    from embodied_adhoc.experiments.seeding import episode_rng

    options = DOMAIN.options()
    specs = [DOMAIN.episode_spec(options, episode_rng(0, e)) for e in range(200)]
    assert {s["task"] for s in specs} == {0, 1}
    pairs = {(s["robot_node"], s["human_node"]) for s in specs}
    assert len(pairs) == 25  # uniform over the 25 node pairs, as the models' initial belief
    fixed = [DOMAIN.episode_spec(DOMAIN.options(task=1), episode_rng(0, e)) for e in range(200)]
    assert all(s["task"] == 1 for s in fixed)
    # fixing the task does not move the start nodes
    assert [(s["robot_node"], s["human_node"]) for s in fixed] == [
        (s["robot_node"], s["human_node"]) for s in specs
    ]
    assert np.mean([s["task"] for s in specs]) == pytest.approx(0.5, abs=0.1)


def test_hotspot_and_oracle_finish_and_workers_do_not_matter(tmp_path):
    serial = run_sweep(sweep(), out=tmp_path / "serial")
    assert all(r.success for r in serial.records)
    assert all(r.identify_step is not None for r in serial.records if r.agent == "hotspot")
    pooled = run_sweep(sweep(), out=tmp_path / "pool", workers=2)
    assert sorted((tmp_path / "serial" / "trials.csv").read_text().splitlines()) == sorted(
        (tmp_path / "pool" / "trials.csv").read_text().splitlines()
    )
    assert serial.records == pooled.records


def test_step_cap_above_the_env_default_is_honoured():
    result = run_sweep(sweep(agents=("random",), episodes=10, max_steps=150, seed=1))
    assert all(r.success or r.steps == 150 for r in result.records)  # not truncated at the env's default 100
    assert any(r.steps > 100 for r in result.records)


def test_option_errors():
    with pytest.raises(ConfigError, match="--task 2 is outside"):
        DOMAIN.options(task=2)
    with pytest.raises(ConfigError, match="human-epsilon"):
        DOMAIN.options(human_epsilon=1.5)


def test_cli_smoke_json():
    command = [sys.executable, "-m", "embodied_adhoc.cli", "trials", "toxic-waste", "--agents", "hotspot,random",
               "--episodes", "2", "--seed", "3", "--no-communication", "--json"]  # fmt: skip
    result = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    document = json.loads(result.stdout)
    assert set(document["agents"]) == {"hotspot", "random"}
    assert document["config"]["options"]["communication"] is False
    assert document["agents"]["hotspot"]["trials"] == 2
