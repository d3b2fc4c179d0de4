"""Registered foraging/pursuit envs: check_env, seeded determinism, info contents, bad input."""

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import embodied_adhoc.envs  # noqa: F401
from embodied_adhoc.errors import ConfigError

GRID_IDS = [
    "EmbodiedAdhoc/ForagingGrid-v0",
    "EmbodiedAdhoc/PursuitGrid-v0",
    "EmbodiedAdhoc/PursuitPairGrid-v0",
]


def flat(obs) -> np.ndarray:
    """One array per observation (the pursuit pairs' Dict: the view, then the POMDP's observation index)."""
    if isinstance(obs, dict):
        return np.concatenate([np.ravel(obs["view"]), [obs["observation_index"]]])
    return np.ravel(obs).copy()


def rollout(env, seed, steps):
    obs, info = env.reset(seed=seed)
    trace = [flat(obs)]
    actions = np.random.default_rng(seed).integers(0, 5, size=steps)
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(int(action))
        trace.append(flat(obs))
        if terminated or truncated:
            obs, info = env.reset()
    return np.stack(trace), info


@pytest.mark.parametrize("env_id", GRID_IDS)
def test_grid_env_checks_and_determinism(env_id):
    env = gymnasium.make(env_id, render_mode="rgb_array")
    check_env(env.unwrapped, skip_render_check=False)
    a, info_a = rollout(env, 7, 60)
    b, info_b = rollout(env, 7, 60)
    c, _ = rollout(env, 8, 60)
    assert np.array_equal(a, b) and info_a == info_b
    assert not np.array_equal(a, c)
    assert env.render().ndim == 3
    env.close()


def test_info_carries_task_and_team_and_options_impose_them():
    env = gymnasium.make("EmbodiedAdhoc/ForagingGrid-v0", tasks=(2,), teams=("tau2",))
    _, info = env.reset(seed=0)
    assert info["task"] == 2 and info["team"] == "tau2" and "agents" in info["state"]
    _, info = env.reset(seed=0, options={"task": 2, "team": "tau2", "state": info["state"]})
    assert info["state"]["agents"] == env.unwrapped.core.info()["state"]["agents"]


def test_original_teammate_solves_through_the_env():
    env = gymnasium.make("EmbodiedAdhoc/PursuitGrid-v0")
    core = env.unwrapped.core
    for seed in range(3):
        env.reset(seed=seed)
        for _ in range(100):
            _, reward, terminated, truncated, _ = env.step(int(core.scripted_actions([0])[0]))
            if terminated:
                break
        assert terminated and reward == 1.0


def test_bad_kwargs_are_named():
    with pytest.raises(ConfigError, match="tasks"):
        gymnasium.make("EmbodiedAdhoc/ForagingGrid-v0", tasks=(5,))
    with pytest.raises(ConfigError, match="teams"):
        gymnasium.make("EmbodiedAdhoc/PursuitGrid-v0", teams=("greedy",))
    with pytest.raises(ConfigError, match="image"):
        gymnasium.make("EmbodiedAdhoc/ForagingGrid-v0", obs_mode="image")
    env = gymnasium.make("EmbodiedAdhoc/ForagingGrid-v0")
    with pytest.raises(ConfigError, match="state"):
        env.reset(seed=0, options={"state": {"agents": [[0, 0]]}})
