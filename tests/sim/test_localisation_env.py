"""Localisation and faults through the physics env and the CLI: honest robot-node readings, fault kwargs and
options, the measured robot-node model (issue 17)."""

from __future__ import annotations

import json

import gymnasium
import numpy as np
import pytest

import embodied_adhoc.envs  # noqa: F401  (registers the ids)
from embodied_adhoc.cli import main
from embodied_adhoc.domains.lab import build_lab_library
from embodied_adhoc.episodes.presenters import localisation_events, localisation_fields
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.record.metrics import _localisation_summary
from embodied_adhoc.sim.lab_world import LabWorld

ENV_ID = "EmbodiedAdhoc/ToxicWaste-v0"
START = {"task": 0, "robot_node": 1, "human_node": 4}


def test_reading_is_unknown_when_the_particles_span_two_areas():
    world = LabWorld()
    world.reset(seed=0, robot_node=1, human_node=4, ball_nodes=(0, 1, 2))
    assert world.robot_node_reading() == 1
    # a cloud straddling the door / open-space border (y = -2): no area holds 95 % of the weight
    passage = world.layout.passage(0, 1).midpoint
    world.localiser.reset(np.random.default_rng(0), world.odometry.pose, (*passage, 0.0), spread=(0.4, 0.1))
    masses = world.localiser.area_weights(world.layout.node_at, 5)
    assert masses[0] > 0.1 and masses[1] > 0.1
    assert world.robot_node_reading() is None
    world.close()


def test_dead_lidar_degrades_to_odometry_in_the_env_info():
    env = gymnasium.make(ENV_ID, lidar_dropout=1.0, disable_env_checker=True)
    _, info = env.reset(seed=1, options=START)
    _, _, _, _, info = env.step(env.unwrapped.library.stay_action)  # stay: a whole second of scans
    assert info["localisation_mode"] == "odometry"
    assert "no lidar scans: localisation degraded to odometry" in localisation_events(info)
    fields = localisation_fields(info)
    assert fields["localisation_mode"] == "odometry" and fields["true_robot_node"] == 1
    env.close()


def test_localisation_off_uses_odometry_and_says_so():
    env = gymnasium.make(ENV_ID, localisation=False, disable_env_checker=True)
    _, info = env.reset(seed=1, options=START)
    assert info["localisation_mode"] == "off" and info["pose_covariance"] is None
    assert info["estimated_pose"] == info["odometry_pose"]
    env.close()


def test_speech_failure_loses_every_reply():
    env = gymnasium.make(
        ENV_ID, speech_failure=1.0, speech="perfect", human_epsilon=1.0, disable_env_checker=True
    )  # a human that never acts: a short step
    env.reset(seed=2, options=START)
    locate = env.unwrapped.library.locate_action
    observation, _, _, _, info = env.step(locate)
    assert observation[1] == 5  # no location heard
    assert info["utterances"][-1] == "(reply lost)"
    env.close()


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"lidar_dropout": 1.5}, "lidar_dropout"),
        ({"lidar_noise": -0.1}, "lidar_noise"),
        ({"speech_failure": "often"}, "speech_failure"),
        ({"reader_miss": 2.0}, "reader_miss"),
        ({"localisation": "yes"}, "localisation"),
        ({"localisation_model": 3}, "localisation_model"),
    ],
)
def test_bad_fault_kwargs_are_refused(kwargs, name):
    with pytest.raises(ConfigError, match=name):
        gymnasium.make(ENV_ID, disable_env_checker=True, **kwargs)


def test_measured_localisation_model_is_the_robot_factor(tmp_path):
    nodes = ["door", "open space", "robot station", "single workbench", "double workbench"]
    matrix = np.full((5, 6), 0.02)
    matrix[np.arange(5), np.arange(5)] = 0.8
    matrix[:, 5] = 1.0 - matrix[:, :5].sum(axis=1)
    path = tmp_path / "robot_node.json"
    path.write_text(json.dumps({"nodes": nodes, "matrix": matrix.tolist(), "provenance": {"source": "test"}}))
    library = build_lab_library(localisation_model=str(path))
    np.testing.assert_allclose(library.observation_model.robot(2), matrix[2])
    default = build_lab_library()
    assert default.observation_model.robot(2)[2] == pytest.approx(0.99)
    with pytest.raises(ConfigError, match="localisation_model=.*no such file"):
        build_lab_library(localisation_model=str(tmp_path / "missing.json"))


def test_localisation_summary_reports_every_failure():
    steps = [
        {
            "step": 1,
            "pose_error_m": 0.05,
            "odometry_error_m": 0.3,
            "localisation_mode": "lidar",
            "robot_node_reading": 1,
            "true_robot_node": 1,
            "blocked": False,
            "kidnaps": 0,
        },
        {
            "step": 2,
            "pose_error_m": 0.9,
            "odometry_error_m": 1.2,
            "localisation_mode": "lidar",
            "robot_node_reading": None,
            "true_robot_node": 3,
            "blocked": True,
            "kidnaps": 1,
        },
        {
            "step": 3,
            "pose_error_m": 0.1,
            "odometry_error_m": 1.3,
            "localisation_mode": "odometry",
            "robot_node_reading": 2,
            "true_robot_node": 3,
            "blocked": False,
            "kidnaps": 0,
        },
    ]
    summary = _localisation_summary(steps)
    assert summary["blocked_steps"] == [2] and summary["kidnaps"] == 1
    assert summary["worst_pose_error_m"] == 0.9 and summary["worst_odometry_error_m"] == 1.3
    assert summary["unknown_readings"] == 1 and summary["wrong_readings"] == 1
    assert summary["modes"] == ["lidar", "odometry"]
    assert _localisation_summary([{"step": 1}]) is None


def test_cli_refuses_bad_fault_options(capsys):
    assert main(["run", "toxic-waste", "--lidar-dropout", "2", "--no-progress"]) == 2
    assert "--lidar-dropout 2.0: must be [0, 1.0]" in capsys.readouterr().err
    code = main(["trials", "toxic-waste", "--backend", "abstract", "--wheel-slip", "0.01", "--episodes", "1"])
    assert code == 2
    assert "use --backend mujoco" in capsys.readouterr().err


def test_shipped_measured_localisation_model_has_provenance():
    from embodied_adhoc.domains.lab_observations import load_localisation_model

    model = load_localisation_model("measured")
    assert model.nodes == ("door", "open space", "robot station", "single workbench", "double workbench")
    np.testing.assert_allclose(model.matrix.sum(axis=1), 1.0)
    counts = np.array(model.provenance["pooled_counts"])
    assert (counts.sum(axis=1) > 0).all()  # every area was measured (no row is the smoothing's uniform guess)
    assert "scripts/bench_faults.py" in model.provenance["source"] and model.provenance["rows"]
    library = build_lab_library(localisation_model="measured")
    np.testing.assert_allclose(library.observation_model.robot(4), model.matrix[4])
