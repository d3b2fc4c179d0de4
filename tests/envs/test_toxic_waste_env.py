"""EmbodiedAdhoc/ToxicWaste-v0: Gymnasium conformance, seeded determinism, observation semantics, a HOTSPOT win."""

import warnings

import gymnasium
import pytest

import embodied_adhoc.envs  # noqa: F401  (registers the ids)
from embodied_adhoc.domains.lab import LabObservation
from embodied_adhoc.errors import ConfigError

ENV_ID = "EmbodiedAdhoc/ToxicWaste-v0"
START = {"task": 0, "robot_node": 1, "human_node": 1}


def make(**kwargs):
    return gymnasium.make(ENV_ID, disable_env_checker=True, **kwargs).unwrapped


def test_check_env_passes_without_warnings():
    from gymnasium.utils.env_checker import check_env

    env = make(render_mode="rgb_array", width=64, height=48)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env)
        assert not [str(w.message) for w in caught]
        assert env.render().shape == (48, 64, 3)
    finally:
        env.close()


def rollout(seed: int, actions) -> list:
    env = make()
    try:
        observation, info = env.reset(seed=seed, options=START)
        trace = [(observation.tolist(), info["state"], info["robot_pose"], info["odometry_pose"])]
        for action in actions:
            observation, reward, terminated, truncated, info = env.step(action)
            trace.append(
                (
                    observation.tolist(),
                    reward,
                    info["state"],
                    info["robot_pose"],
                    info["odometry_pose"],
                    info["human_position"],
                    info["ball_positions"].tolist(),
                    info["sim_time"],
                )
            )
        return trace
    finally:
        env.close()


def test_same_seed_same_trajectory_and_other_seed_differs():
    actions = [4, 1, 4]  # locate, drive to the 2nd neighbour of the open space (robot station), locate
    first, second = rollout(3, actions), rollout(3, actions)
    assert first == second
    assert rollout(4, actions) != first  # odometry noise, speech draws and human choices depend on the seed


def test_observation_semantics_match_the_abstract_model():
    env = make(speech="perfect")
    try:
        observation, info = env.reset(seed=0, options={"task": 0, "robot_node": 0, "human_node": 3})
        assert env.observation_space.contains(observation)
        assert LabObservation.from_vector(observation).encode() == info["observation_index"]
        assert observation.tolist() == [0, 5, 0]  # odometry at the door, human not heard, no rfid
        observation, reward, *_, info = env.step(4)  # locate human: perfect speech hears the true node
        assert reward == -3.0
        assert observation[1] == info["human_node"]
        assert observation[0] == 0 and observation[2] == 0
        observation, *_, info = env.step(0)  # drive to the lowest-index neighbour of the door: open space
        assert info["robot_node"] == 1 and observation[0] == 1 and info["robot_arrived"]
        assert observation[1] == 5  # no question asked: no human reading
        assert info["odometry_error"] < 0.15
        with pytest.raises(ConfigError, match="outside"):
            env.step(7)
    finally:
        env.close()


def test_without_communication_the_human_is_seen_only_when_co_located():
    env = make(communication=False)
    try:
        assert env.action_space.n == 4
        observation, info = env.reset(seed=1, options={"task": 1, "robot_node": 2, "human_node": 2})
        assert info["robot_node"] == info["human_node"] == 2 and observation[1] == 2
        observation, *_, info = env.step(
            0
        )  # robot to the open space; the human picks the ball at the station
        assert info["robot_node"] == 1 and info["human_node"] == 2 and observation[1] == 5
    finally:
        env.close()


def test_a_hotspot_episode_succeeds():
    from embodied_adhoc.experiments.recorded import EpisodeConfig, run_episode

    outcome = run_episode(
        EpisodeConfig(agent="hotspot", seed=0, task=1, robot_node=1, human_node=1, max_steps=40)
    )
    metrics = outcome.metrics
    assert metrics["success"], metrics["per_step"]
    assert metrics["steps"] <= 40 and metrics["identify_step"] is not None
    assert metrics["per_step"][-1]["observation"].endswith("rfid YES")  # the last ball was read going in
    # Every "locate human" (action 4) keeps its dialogue; other steps have none.
    asked = [record for record in metrics["per_step"] if record["action"] == 4]
    assert asked and all(record["utterances"][0] == 'robot: "Where are you?"' for record in asked)
    assert all("utterances" not in record for record in metrics["per_step"] if record["action"] != 4)
    assert all(record["utterances"][-1].startswith("heard node: ") for record in asked)


def test_bad_kwargs_and_reset_options_are_clear_errors():
    with pytest.raises(ConfigError, match="speech"):
        make(speech="telepathy")
    from embodied_adhoc.envs.toxic_waste import ToxicWasteEnv

    with pytest.raises(ConfigError, match="render_mode"):
        ToxicWasteEnv(render_mode="ansi")
    env = make()
    try:
        with pytest.raises(ConfigError, match="unknown option .start."):
            env.reset(seed=0, options={"start": 1})
        with pytest.raises(ConfigError, match="0..4"):
            env.reset(seed=0, options={"robot_node": 9})
    finally:
        env.close()


def test_audio_speech_logs_the_dialogue_and_a_wav():
    pytest.importorskip("pocketsphinx")
    env = make(speech="audio")
    try:
        env.reset(seed=5, options={"task": 0, "robot_node": 1, "human_node": 3})
        observation, *_, info = env.step(4)
        lines = info["utterances"]
        assert lines[0] == 'robot: "Where are you?"' and lines[1].startswith("human: ")
        assert any(line.startswith("recognised: ") for line in lines)
        assert info["speech_audio"][:4] == b"RIFF" and b"WAVE" in info["speech_audio"][:16]
        heard = lines[-1].removeprefix("heard node: ")
        assert observation[1] == (5 if heard.startswith("no location") else int(heard.split()[0]))
    finally:
        env.close()
