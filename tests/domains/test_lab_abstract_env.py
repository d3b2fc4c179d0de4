"""The abstract ToxicWaste env: Gymnasium API, seeded determinism, agreement with the lab model."""

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import embodied_adhoc.envs  # noqa: F401  (registers the ids)
from embodied_adhoc.domains.lab_graph import DISPOSED
from embodied_adhoc.domains.lab_observations import LabObservation
from embodied_adhoc.envs.toxic_waste_abstract import ToxicWasteAbstractEnv
from embodied_adhoc.errors import ConfigError


def test_check_env_passes():
    check_env(gymnasium.make("EmbodiedAdhoc/ToxicWasteAbstract-v0", render_mode="rgb_array").unwrapped)
    check_env(ToxicWasteAbstractEnv(communication=False), skip_render_check=True)


def test_registered_and_spaces():
    env = gymnasium.make("EmbodiedAdhoc/ToxicWasteAbstract-v0", communication=False)
    assert env.action_space.n == 4
    assert env.observation_space.nvec.tolist() == [6, 6, 2]
    env.close()


def _rollout(seed: int, actions) -> list:
    env = ToxicWasteAbstractEnv()
    obs, info = env.reset(seed=seed)
    trace = [(obs.tolist(), info["state"])]
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        trace.append((obs.tolist(), reward, info["state"], terminated))
        if terminated or truncated:
            break
    return trace


def test_same_seed_same_trajectory():
    actions = np.random.default_rng(0).integers(5, size=60)
    assert _rollout(11, actions) == _rollout(11, actions)
    assert _rollout(11, actions) != _rollout(12, actions)


def test_reset_options_and_info():
    env = ToxicWasteAbstractEnv()
    obs, info = env.reset(seed=1, options={"task": 1, "robot_node": 0, "human_node": 4})
    assert (info["task"], info["robot_node"], info["human_node"]) == (1, 0, 4)
    assert info["state"] == env.library.state_index(0, 4, (0, 0, 0))
    assert LabObservation.from_vector(obs).encode() == info["observation_index"]
    with pytest.raises(ConfigError):
        env.reset(options={"task": 5})
    with pytest.raises(ConfigError):
        env.reset(options={"start": 1})


def test_transitions_follow_the_model():
    """Empirical next-state frequencies from one state match the task model's P̄ row."""
    env = ToxicWasteAbstractEnv(human_epsilon=0.3)
    library = env.library
    counts = {}
    n = 4000
    for episode in range(n):
        env.reset(seed=episode, options={"task": 0, "robot_node": 2, "human_node": 1})
        _, _, _, _, info = env.step(
            1
        )  # robot 2 -> its 2nd neighbour (fallback to 1); human at 1 picks ball 1
        counts[info["state"]] = counts.get(info["state"], 0) + 1
    row = library.mdps[0].transitions[1][library.state_index(2, 1, (0, 0, 0))].toarray().ravel()
    for state, count in counts.items():
        assert count / n == pytest.approx(row[state], abs=0.03)
    assert set(counts) == set(np.flatnonzero(row))


def test_terminates_when_all_balls_disposed_and_truncates_at_cap():
    env = ToxicWasteAbstractEnv(human_epsilon=0.0)
    env.reset(seed=0, options={"task": 0, "robot_node": 0, "human_node": 0})
    # Human at 0 picks ball 0; the robot stays there, receives it; then follows the human (0 -> 1 -> 2).
    rfid = []
    for action in (3, 3, 0, 3, 3, 1, 3, 3):
        obs, reward, terminated, truncated, info = env.step(action)
        rfid.append(int(obs[2]))
        if terminated:
            break
    assert terminated and all(s == DISPOSED for s in info["ball_status"])
    assert sum(rfid) == 3
    with pytest.raises(ConfigError):
        env.step(3)  # terminated: no further step
    # The cap is the spec's TimeLimit (gymnasium's keyword), and stepping past it is refused.
    env = gymnasium.make("EmbodiedAdhoc/ToxicWasteAbstract-v0", max_episode_steps=5)
    env.reset(seed=0, options={"task": 0, "robot_node": 4, "human_node": 4})
    results = [env.step(0)[3] for _ in range(5)]
    assert results == [False] * 4 + [True]
    with pytest.raises(ConfigError):
        env.step(0)
    assert gymnasium.make("EmbodiedAdhoc/ToxicWasteAbstract-v0").spec.max_episode_steps == 100
