"""The env contract (``embodied_adhoc/envs/contract.py``, README "Env contract") on every registered id and on the
PettingZoo ``GridParallelEnv``: integer actions only, unknown or wrongly typed kwargs and reset options refused,
no step after the end, the step cap through the spec's TimeLimit, ``rgb_array`` rendering and ``render_fps``."""

import gymnasium
import numpy as np
import pytest

import embodied_adhoc.envs  # noqa: F401  (registers the ids)
from embodied_adhoc.envs.contract import EpisodeOverError
from embodied_adhoc.envs.multiagent import GridParallelEnv
from embodied_adhoc.envs.registry import ENV_SPECS, registered_cap
from embodied_adhoc.errors import ConfigError

IDS = [spec.id for spec in ENV_SPECS]
MUJOCO = {spec.id for spec in ENV_SPECS if spec.backend == "mujoco"}
POMDP_RULES = {
    "EmbodiedAdhoc/PursuitPairPomdpGrid-v0",
    "EmbodiedAdhoc/PursuitPairPomdp-v0",
}  # Fig. 7.12's POMDP
LAB = {"EmbodiedAdhoc/ToxicWasteAbstract-v0", "EmbodiedAdhoc/ToxicWaste-v0"}
TEAMWORK = {"EmbodiedAdhoc/Pursuit4Grid-v0", "EmbodiedAdhoc/Pursuit4-v0"}  # chapter 4's pursuit (no tasks)
SMALL = {
    "EmbodiedAdhoc/ToxicWaste-v0": {"width": 64, "height": 48}
}  # small frames keep the physics test fast

ACCEPTED_ACTIONS = [1, np.int8(1), np.uint16(1), np.int64(1), np.array(1), np.array(1, dtype=np.uint8)]
REFUSED_ACTIONS = [2.7, 2.0, "2", None, True, np.bool_(False), np.array([2]), np.float32(1.0), np.array(1.0)]


def make(env_id, **kwargs):
    return gymnasium.make(env_id, disable_env_checker=True, **{**SMALL.get(env_id, {}), **kwargs})


@pytest.fixture(scope="module", params=IDS)
def env(request):
    """One env per id for the whole module (the MuJoCo ids are slow to build)."""
    environment = make(request.param, max_episode_steps=3)
    yield environment
    environment.close()


def test_every_id_declares_rgb_array_and_render_fps():
    for env_id in IDS:
        module, name = gymnasium.spec(env_id).entry_point.split(":")
        cls = getattr(__import__(module, fromlist=[name]), name)
        assert "rgb_array" in cls.metadata["render_modes"], env_id
        assert cls.metadata["render_fps"] > 0, env_id
    assert (
        "rgb_array" in GridParallelEnv.metadata["render_modes"] and GridParallelEnv.metadata["render_fps"] > 0
    )


def test_actions_are_integers_of_any_width_and_nothing_else(env):
    env.reset(seed=0)
    for action in ACCEPTED_ACTIONS[:2]:
        env.step(action)
    env.reset(seed=0)
    steps = env.unwrapped.core.info()["steps"] if hasattr(env.unwrapped, "core") else None
    for action in REFUSED_ACTIONS:
        with pytest.raises(ConfigError, match="action"):
            env.step(action)
    if steps is not None:
        assert env.unwrapped.core.info()["steps"] == steps  # a refused action moves nothing
    for action in ACCEPTED_ACTIONS[2:5]:  # the TimeLimit (3) is reached after the third accepted action
        env.step(action)
    env.reset(seed=0)
    with pytest.raises(ConfigError, match="outside"):
        env.step(env.action_space.n)


def test_step_past_the_time_limit_raises_and_reset_starts_again(env):
    assert env.spec.max_episode_steps == 3
    env.reset(seed=1)
    truncated = [env.step(0)[3] for _ in range(3)]
    assert truncated[-1] and not any(truncated[:-1])
    with pytest.raises(EpisodeOverError, match="reset"):
        env.step(0)
    with pytest.raises(gymnasium.error.ResetNeeded):  # also gymnasium's own exception type
        env.step(0)
    env.reset(seed=1)
    env.step(0)


@pytest.mark.parametrize("env_id", IDS)
def test_registered_cap_is_the_time_limit_and_make_overrides_it(env_id):
    assert gymnasium.spec(env_id).max_episode_steps == registered_cap(env_id)
    assert registered_cap(env_id) == (100 if env_id in LAB | TEAMWORK else 150 if "Pair" in env_id else 200)
    if env_id not in MUJOCO:
        env = make(env_id, max_episode_steps=7)
        assert env.spec.max_episode_steps == 7
        env.close()


@pytest.mark.parametrize("env_id", [i for i in IDS if i not in MUJOCO])
def test_step_after_termination_raises(env_id):
    env = make(env_id)
    core = getattr(env.unwrapped, "core", None)
    if (
        env_id in POMDP_RULES
    ):  # the oracle's policy (value iteration on the true task's MDP) captures the prey
        from embodied_adhoc.decision.agents.factory import mdp_q_values

        q_values = mdp_q_values(env.unwrapped.library)[0]
        env.reset(seed=0, options={"task": 0})
        policy = lambda: int(q_values[env.unwrapped.state].argmax())  # noqa: E731
    elif env_id in TEAMWORK:  # the teammate-aware team's own policy in the ad hoc seat captures the prey
        env.reset(seed=0, options={"team": "teammate-aware"})
        seat = env.unwrapped.models["teammate-aware"].seat
        policy = lambda: int(seat(env.unwrapped.state[None])[0].argmax())  # noqa: E731
    elif (
        core is None
    ):  # the lab: a human who never fails, and a robot that follows it (see test_lab_abstract_env)
        env = make(env_id, human_epsilon=0.0)
        env.reset(seed=0, options={"task": 0, "robot_node": 0, "human_node": 0})
        actions = iter((3, 3, 0, 3, 3, 1, 3, 3))
        policy = lambda: next(actions)  # noqa: E731
    else:
        env.reset(seed=0)
        policy = lambda: int(core.scripted_actions([0])[0])  # noqa: E731  (the team's own policy)
    total = 0.0
    for _ in range(100):
        _, reward, terminated, truncated, _ = env.step(policy())
        total += reward
        if terminated:
            break
    assert terminated and not truncated
    for _ in range(3):
        with pytest.raises(EpisodeOverError):
            env.step(0)
    if core is not None or env_id in POMDP_RULES | TEAMWORK:
        assert total == 1.0  # the grid pays once, at the end, and nothing for refused steps after it
    with pytest.raises(EpisodeOverError):  # the env itself, without gymnasium's wrappers
        env.unwrapped.step(0)
    env.close()


@pytest.mark.parametrize("env_id", IDS)
def test_unwrapped_env_refuses_step_before_reset(env_id):
    env = make(env_id)
    with pytest.raises(EpisodeOverError, match="reset"):
        env.unwrapped.step(0)
    env.close()


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"toroidl": True}, "did you mean 'toroidal'"),
        ({"n_apple": 2}, "unknown keyword 'n_apple'"),
        ({"robot_node_acuracy": 0.9}, "unknown keyword"),
    ],
)
def test_unknown_kwargs_are_refused(env_id, kwargs, match):
    if (env_id in LAB or env_id in POMDP_RULES | TEAMWORK) and "toroidl" in kwargs:
        match = "unknown keyword 'toroidl'"
    with pytest.raises(ConfigError, match=match):
        make(env_id, **kwargs)


@pytest.mark.parametrize("env_id", IDS)
def test_the_env_has_no_step_cap_kwarg_of_its_own(env_id):
    spec = gymnasium.spec(env_id)
    from dataclasses import replace

    with pytest.raises(ConfigError, match=r"gymnasium.make\(id, max_episode_steps=N\)"):
        gymnasium.make(replace(spec, kwargs={**spec.kwargs, "max_episode_steps": 50}))


LAB_BAD_KWARGS = [
    ({"communication": "no"}, "communication"),
    ({"human_epsilon": "0.1"}, "human_epsilon"),
    ({"task": 0.5}, "task"),
    ({"tasks": [[0, 1.5, 2]]}, r"tasks\[0\]\[1\]"),
    ({"render_mode": "rgb"}, "render_mode"),
]
GRID_BAD_KWARGS = [
    ({"toroidal": "no"}, "toroidal"),
    ({"rows": 5.5}, "rows"),
    ({"tasks": (1.9,)}, "tasks"),
    ({"teams": 3}, "teams"),
    ({"view": True}, "view"),
    ({"render_mode": "ansi"}, "render_mode"),
]


@pytest.mark.filterwarnings(
    "ignore:.*render_mode.*:UserWarning"
)  # gymnasium's own warning before the env refuses
@pytest.mark.parametrize("env_id", [i for i in IDS if i not in MUJOCO or i in LAB])
def test_wrongly_typed_kwargs_are_refused(env_id):
    for kwargs, match in LAB_BAD_KWARGS if env_id in LAB else GRID_BAD_KWARGS:
        with pytest.raises(ConfigError, match=match):
            make(env_id, **kwargs)


def test_wrongly_typed_reset_options_are_refused(env):
    env_id = env.spec.id
    lab = env_id in LAB
    bad = [{"task": "a"}, {"task": 1.9}, {"task": True}, {"tasks": 1}]
    bad += (
        [{"robot_node": 2.5}, {"human_node": "1"}, {"robot_node": None}]
        if lab
        else [{"team": 3}, {"state": {"agents": [[0.5, 1]]}}, {"state": "x"}]
    )
    for options in bad:
        with pytest.raises(ConfigError, match=next(iter(options))):
            env.reset(seed=0, options=options)
    good = {"task": np.int64(1), "robot_node": np.uint8(2)} if lab else {"task": np.int32(2), "team": "tau1"}
    if "Pair" in env_id:
        good["team"] = "greedy"
    if env_id in POMDP_RULES:  # the task is the only option of both kinds (no teams: the library's teammate)
        good = {"task": np.int32(2)}
    if env_id in TEAMWORK:  # the team is the only unknown (no tasks)
        _, info = env.reset(seed=0, options={"team": "greedy", "state": np.array([0, 1, 2, 3, 24], np.int16)})
        assert info["team"] == "greedy" and info["state"].tolist() == [0, 1, 2, 3, 24]
        return
    _, info = env.reset(seed=0, options=good)
    assert info["task"] == (1 if lab else 2)


def test_every_env_renders_rgb_array():
    for env_id in IDS:
        env = make(env_id, render_mode="rgb_array")
        env.reset(seed=0)
        frame = env.render()
        assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3 and frame.std() > 0
        env.close()


def test_the_abstract_lab_picture_follows_the_state():
    env = make("EmbodiedAdhoc/ToxicWasteAbstract-v0", render_mode="rgb_array")
    env.reset(seed=0, options={"task": 0, "robot_node": 0, "human_node": 4})
    first = env.render()
    env.reset(seed=0, options={"task": 0, "robot_node": 3, "human_node": 4})
    assert not np.array_equal(first, env.render())
    env.reset(seed=5, options={"task": 0, "robot_node": 0, "human_node": 4})
    assert np.array_equal(first, env.render())  # the picture is a function of the state


# ------------------------------------------------------------------------------------------------ PettingZoo
def parallel(**kwargs):
    return GridParallelEnv(**{"domain": "pursuit", **kwargs})


def test_parallel_env_refuses_unknown_and_wrongly_typed_kwargs():
    for kwargs, match in [
        ({"team": ("tau1",)}, "did you mean 'teams'"),
        ({"n_apple": 2}, "n_apple"),
        ({"max_steps": 5}, "max_cycles"),
        ({"toroidal": "no"}, "toroidal"),
        ({"max_cycles": 2.5}, "max_cycles"),
        ({"domain": "chess"}, "domain"),
        ({"render_mode": "ansi"}, "render_mode"),
        ({"obs_mode": "image"}, "grid"),
    ]:
        with pytest.raises(ConfigError, match=match):
            parallel(**kwargs)


def test_parallel_env_refuses_unknown_reset_options_but_pettingzoos_probe():
    env = parallel()
    for options, match in [
        ({"tsk": 0}, "did you mean 'task'"),
        ({"task": 0, "robot_node": 1}, "robot_node"),
        ({"task": 1.5}, "task"),
        (["task"], "dict"),
    ]:
        with pytest.raises(ConfigError, match=match):
            env.reset(seed=0, options=options)
    _, infos = env.reset(
        seed=0, options={"options": 1, "task": 2}
    )  # what pettingzoo's parallel_api_test sends
    assert infos["agent_0"]["task"] == 2
    _, infos = env.reset(seed=0, options={"options": 1})
    _, plain = env.reset(seed=0)
    assert infos["agent_0"]["task"] == plain["agent_0"]["task"]


def test_parallel_env_spaces_and_state():
    env = parallel(pairs=True)
    assert env.max_cycles == registered_cap("EmbodiedAdhoc/PursuitPairGrid-v0") == 150
    assert parallel().max_cycles == 200
    observations, _ = env.reset(seed=3)
    for agent in env.possible_agents:
        assert env.observation_space(agent).contains(observations[agent])
        assert env.action_space(agent) == gymnasium.spaces.Discrete(5)
    with pytest.raises(ConfigError, match="agent_0"):
        env.observation_space("agent_9")
    assert env.state_space.contains(env.state())
    foraging = GridParallelEnv("foraging", n_agents=3)
    foraging.reset(seed=0)
    assert (
        foraging.state_space.contains(foraging.state())
        and foraging.state_space.shape == foraging.state().shape
    )


def test_parallel_env_actions_and_episode_end():
    env = parallel(max_cycles=2, render_mode="rgb_array")
    with pytest.raises(EpisodeOverError):
        env.step({})
    env.reset(seed=0)
    assert env.render().ndim == 3
    good = {"agent_0": np.int8(0), "agent_1": np.array(1), "agent_2": np.uint64(2), "agent_3": 4}
    for bad_action in REFUSED_ACTIONS:
        with pytest.raises(ConfigError, match="action"):
            env.step({**good, "agent_1": bad_action})
    with pytest.raises(ConfigError, match="agent_3"):
        env.step({k: v for k, v in good.items() if k != "agent_3"})
    with pytest.raises(ConfigError, match="agent_7"):
        env.step({**good, "agent_7": 0})
    assert env.core.episode.steps == 0  # every refused step left the world alone
    env.step(good)
    *_, truncations, _ = env.step(good)
    assert all(truncations.values()) and env.agents == []
    state = env.state()
    for actions in ({}, good):
        with pytest.raises(EpisodeOverError, match="reset"):
            env.step(actions)
    assert np.array_equal(env.state(), state)  # the world did not advance after the end
    env.reset(seed=0)
    env.step(good)


# ------------------------------------------------------------------------------------------------ stable-baselines3
@pytest.mark.parametrize("env_id", IDS)
def test_sb3_make_vec_env_works_with_its_default_render_mode(env_id):
    env_util = pytest.importorskip("stable_baselines3.common.env_util")
    vec = env_util.make_vec_env(env_id, n_envs=2, seed=0, env_kwargs=SMALL.get(env_id))
    try:
        observations = vec.reset()
        if isinstance(
            vec.observation_space, gymnasium.spaces.Dict
        ):  # the pursuit pairs: view and POMDP index
            for key, space in vec.observation_space.spaces.items():
                assert observations[key].shape == (2, *space.shape), key
        else:
            assert observations.shape == (2, *vec.observation_space.shape)
        vec.step(np.array([vec.action_space.sample() for _ in range(2)]))
        assert vec.get_attr("render_mode") == ["rgb_array", "rgb_array"]  # SB3's default, accepted
    finally:
        vec.close()


@pytest.mark.slow
@pytest.mark.parametrize(
    "env_id", ["EmbodiedAdhoc/ToxicWasteAbstract-v0", "EmbodiedAdhoc/PursuitPairGrid-v0"]
)
def test_ppo_smoke_run(env_id):
    """A few hundred PPO steps through SB3's own vector env: the envs meet the contract RL libraries expect."""
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    vec = make_vec_env(env_id, n_envs=2, seed=0)
    # the pursuit pairs' Dict observation (view and POMDP index) takes SB3's multi-input policy
    policy = "MultiInputPolicy" if isinstance(vec.observation_space, gymnasium.spaces.Dict) else "MlpPolicy"
    model = PPO(policy, vec, n_steps=64, batch_size=64, n_epochs=2, seed=0, device="cpu")
    model.learn(total_timesteps=256)
    assert model.num_timesteps >= 256
    observation = vec.reset()
    actions, _ = model.predict(observation, deterministic=True)
    assert all(vec.action_space.contains(int(a)) for a in actions)
    vec.close()


# ------------------------------------------------------------------------------------------------ trials
@pytest.mark.parametrize(
    "command, env_id",
    [
        (["toxic-waste"], "EmbodiedAdhoc/ToxicWasteAbstract-v0"),
        (["foraging"], "EmbodiedAdhoc/ForagingGrid-v0"),
        (["pursuit", "--pairs"], "EmbodiedAdhoc/PursuitPairGrid-v0"),
    ],
)
def test_trials_default_cap_is_the_envs_registered_cap(command, env_id, capsys):
    import json

    from embodied_adhoc.cli import main

    status = main(["trials", *command, "--episodes", "1", "--agents", "random", "--json"])
    assert status == 0
    assert json.loads(capsys.readouterr().out)["config"]["max_steps"] == registered_cap(env_id)
