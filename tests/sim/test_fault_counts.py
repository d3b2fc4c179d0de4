"""Fault events are counted where they are injected (odometry, lidar, RFID reader) and reach the physics env's
``info["faults"]`` per episode, never its observations; a capped episode names the observation that stayed
uninformative."""

from __future__ import annotations

import math

import gymnasium
import numpy as np
import pytest

import embodied_adhoc.envs  # noqa: F401  (registers the ids)
from embodied_adhoc.envs.toxic_waste import FAULT_COUNTS
from embodied_adhoc.experiments.domains.toxic_waste import cap_reason
from embodied_adhoc.sim.lab_world import HumanCommand, LabWorld, LabWorldConfig
from embodied_adhoc.sim.odometry import OdometryConfig, WheelOdometry

ENV_ID = "EmbodiedAdhoc/ToxicWaste-v0"
START = {"task": 0, "robot_node": 1, "human_node": 4}


def _drive(config: OdometryConfig, seed: int = 3, ticks: int = 400) -> WheelOdometry:
    """Odometry fed a straight drive, both wheels turning 0.02 rad per tick (about 0.6 m in all)."""
    odometry = WheelOdometry(config, np.random.default_rng(seed))
    odometry.reset((0.0, 0.0, 0.0), np.zeros(2))
    for tick in range(1, ticks + 1):
        odometry.update(np.array([0.02 * tick, 0.02 * tick]))
    return odometry


def test_a_perfect_odometry_counts_no_slip_and_no_noise():
    odometry = _drive(OdometryConfig(encoder_noise=0.0, wheel_slip=0.0))
    assert odometry.slip_distance == 0.0 and odometry.noise_distance == 0.0
    assert odometry.distance > 0.5


def test_wheel_slip_distance_is_the_radius_error_times_the_travel():
    config = OdometryConfig(encoder_noise=0.0, wheel_slip=0.02)
    odometry = _drive(config)
    left, right = odometry._scale
    counted = (
        math.floor(0.02 * 400 / odometry._tick) * odometry._tick * config.wheel_radius
    )  # metres per wheel
    expected = 0.5 * (abs(left - 1.0) + abs(right - 1.0)) * counted
    assert odometry.noise_distance == 0.0
    assert odometry.slip_distance == pytest.approx(expected, rel=1e-6)
    assert odometry.slip_distance > 0.0


def test_encoder_noise_distance_grows_with_the_noise_and_leaves_the_stream_alone():
    small = _drive(OdometryConfig(encoder_noise=0.002, wheel_slip=0.0))
    large = _drive(OdometryConfig(encoder_noise=0.05, wheel_slip=0.0))
    assert 0.0 < small.noise_distance < large.noise_distance
    assert large.slip_distance == pytest.approx(0.0, abs=1e-12)
    # the counters only read the draws: the same seed gives the same pose and the same count
    again = _drive(OdometryConfig(encoder_noise=0.05, wheel_slip=0.0))
    assert again.pose_tuple == large.pose_tuple and again.noise_distance == large.noise_distance


@pytest.fixture(scope="module")
def world():
    lab = LabWorld(LabWorldConfig(rfid_miss_probability=1.0))
    yield lab
    lab.close()


def test_world_counts_rfid_misses_lidar_dropouts_and_starts_afresh_at_reset(world):
    world.reset(seed=0, robot_node=2, human_node=2, ball_nodes=(2, 0, 1))
    assert world.fault_counts()["rfid_reads"] == 0
    world.step_macro(None, HumanCommand.pick(0))
    result = world.step_macro(None, HumanCommand.drop_into_container(0))
    assert result.rfid_events == ()
    counts = world.fault_counts()
    assert counts["rfid_reads"] == 1 and counts["rfid_misses"] == 1
    assert counts["lidar_beams"] > 0 and counts["lidar_beams"] % world.lidar.n_beams == 0
    assert 0 <= counts["lidar_dropped_beams"] < counts["lidar_beams"]
    assert counts["relocalisations"] == 0
    world.reset(seed=0, robot_node=2, human_node=2, ball_nodes=(2, 0, 1))
    assert world.fault_counts() == {
        "rfid_reads": 0,
        "rfid_misses": 0,
        "lidar_beams": 0,
        "lidar_dropped_beams": 0,
        "wheel_slip_m": 0.0,
        "encoder_noise_m": 0.0,
        "relocalisations": 0,
    }


def test_a_dead_lidar_drops_every_beam_it_is_read_for():
    env = gymnasium.make(ENV_ID, lidar_dropout=1.0, disable_env_checker=True)
    env.reset(seed=1, options=START)
    *_, info = env.step(env.unwrapped.library.stay_action)
    faults = info["faults"]
    assert faults["lidar_beams"] > 0 and faults["lidar_dropped_beams"] == faults["lidar_beams"]
    env.close()


def test_env_counts_lost_replies_and_moves_in_info_not_in_the_observation():
    env = gymnasium.make(ENV_ID, speech_failure=1.0, disable_env_checker=True)
    library = env.unwrapped.library
    observation, info = env.reset(seed=2, options=START)
    assert list(info["faults"]) == list(FAULT_COUNTS)
    assert info["faults"]["replies"] == 0 and info["faults"]["robot_node_readings"] == 1
    assert env.observation_space.contains(observation) and observation.shape == (3,)
    for _ in range(2):
        observation, _, _, _, info = env.step(library.locate_action)
        assert library.decode_observation(info["observation_index"]).human_node is None  # every reply lost
    observation, _, _, _, info = env.step(0)  # a move to a neighbour
    faults = info["faults"]
    assert faults["replies"] == faults["replies_lost"] == faults["replies_no_location"] == 2
    assert faults["moves"] == 1 and 0 <= faults["blocked_moves"] <= 1
    assert faults["robot_node_readings"] == 4
    assert faults["wheel_slip_m"] > 0.0 and faults["encoder_noise_m"] > 0.0  # the default odometry errors
    _, info = env.reset(seed=3, options=START)
    assert info["faults"]["replies"] == 0 and info["faults"]["moves"] == 0
    env.close()


def test_a_fault_free_reader_and_speech_count_no_misses_and_no_lost_replies():
    env = gymnasium.make(ENV_ID, speech="perfect", disable_env_checker=True)
    library = env.unwrapped.library
    env.reset(seed=2, options=START)
    *_, info = env.step(library.locate_action)
    faults = info["faults"]
    assert faults["replies"] == 1 and faults["replies_lost"] == 0 and faults["replies_no_location"] == 0
    assert faults["rfid_misses"] == 0
    env.close()


NAMES = ("move to neighbour 1", "move to neighbour 2", "move to neighbour 3", "stay", "locate human")
FAULTS = dict.fromkeys(FAULT_COUNTS, 0)


def test_cap_reason_names_the_action_and_the_uninformative_observation():
    faults = {**FAULTS, "rfid_reads": 3, "rfid_misses": 2, "replies": 96, "replies_no_location": 5}
    code, detail = cap_reason([4] * 96 + [3] * 4, faults, NAMES, capped=True)
    assert code == "rfid_missed"
    assert detail == (
        "cap reached: 'locate human' chosen 96/100 steps; RFID missed 2 of 3 reads; "
        "no location heard in 5 of 96 replies"
    )


def test_cap_reason_picks_the_worst_channel_and_says_when_none_failed():
    lost = {
        **FAULTS,
        "rfid_reads": 2,
        "rfid_misses": 0,
        "replies": 10,
        "replies_no_location": 6,
        "replies_lost": 5,
    }
    assert cap_reason([4] * 10, lost, NAMES, capped=True)[0] == "reply_lost"
    # a missed read is never repeated: it names the cap even where more replies than reads failed
    assert cap_reason([4] * 10, {**lost, "rfid_misses": 1}, NAMES, capped=True)[0] == "rfid_missed"
    unknown = {**FAULTS, "robot_node_readings": 11, "robot_node_unknown": 9, "moves": 10, "blocked_moves": 2}
    code, detail = cap_reason([0] * 10, unknown, NAMES, capped=True)
    assert code == "robot_node_unknown" and "blocked in 2 of 10 moves" in detail
    code, detail = cap_reason([3] * 5, FAULTS, NAMES, capped=True)
    assert code == "no_fault" and detail.endswith("every observation informative")
    assert cap_reason([3] * 5, lost, NAMES, capped=False) == ("", "")
