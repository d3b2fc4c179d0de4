"""Chapter 4's pursuit as an env (grid twin and MuJoCo arena) driven by the one episode loop, and
``trials pursuit4``."""

from __future__ import annotations

import subprocess
import sys

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import embodied_adhoc.envs  # noqa: F401  (registers the ids)
from embodied_adhoc.decision.agents.teamwork import EpisodeSeat
from embodied_adhoc.decision.uct import UctConfig
from embodied_adhoc.domains.pursuit4 import TEAMS, Pursuit4
from embodied_adhoc.episodes.loop import EpisodeObserver, run_episode_loop
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.blocks import one_thread
from embodied_adhoc.learning.teamster_agents import build_agent

START = {"team": "teammate-aware", "state": [0, 6, 12, 18, 24]}


class _States(EpisodeObserver):
    def __init__(self) -> None:
        self.rows: list[tuple[list[int], list[int]]] = []

    def step_finished(self, record) -> None:
        self.rows.append((record.info["state"].tolist(), record.info["intended_state"]))


def _plastic_model():
    """PLASTIC-Model knowing the three teams (exact library), learning paused."""
    world = Pursuit4()
    agent = build_agent("plastic-model", world, np.random.default_rng(0), 1)
    for team in TEAMS:
        agent.start_team(np.random.default_rng(1))
        agent.finish_team(team)
    return EpisodeSeat(agent, 5, evaluation=True)


def _episode(env, steps: int = 6):
    observer = _States()
    trace = run_episode_loop(
        env,
        _plastic_model(),
        env_seed=3,
        agent_rng=np.random.default_rng(4),
        reset_options=START,
        max_steps=steps,
        observation_index=env.unwrapped.observation_index,
        observers=[observer],
    )
    return trace, observer.rows


def test_physics_episode_with_plastic_model_is_reproducible_and_executes_the_rules():
    env = gymnasium.make("EmbodiedAdhoc/Pursuit4-v0")
    try:
        first, states = _episode(env)
        second, again = _episode(env)
    finally:
        env.close()
    assert first.actions == second.actions and first.observations == second.observations and states == again
    assert first.steps >= 1 and first.posteriors[0] is not None and len(first.posteriors[0]) == 4
    # the robots reached the cells the rules drew (physics executed every move of this short episode)
    assert all(shown == intended for shown, intended in states)
    grid = gymnasium.make("EmbodiedAdhoc/Pursuit4Grid-v0")
    twin, twin_states = _episode(grid)
    assert twin.actions == first.actions and twin_states == states  # same seed: the twin and physics agree


def test_grid_env_contract_and_one_line_errors():
    env = gymnasium.make("EmbodiedAdhoc/Pursuit4Grid-v0").unwrapped
    check_env(env, skip_render_check=False)
    obs, info = env.reset(seed=0, options=START)
    assert obs.tolist() == [0, 6, 12, 18, 24, 5, 5, 5] and info["team"] == "teammate-aware"
    obs, reward, terminated, truncated, info = env.step(4)
    assert obs[5:].tolist() == info["teammate_actions"] and reward == float(terminated)
    with pytest.raises(ConfigError, match="reset option state"):
        env.reset(options={"state": [0, 0, 1, 2, 3]})
    with pytest.raises(ConfigError, match="team"):
        env.reset(options={"team": "tau0"})
    with pytest.raises(ConfigError, match="slip"):
        gymnasium.make("EmbodiedAdhoc/Pursuit4Grid-v0", slip=1.5)


def test_trials_pursuit4_runs_chapter4_agents_and_refuses_bad_input():
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "embodied_adhoc.cli",
            "trials",
            "pursuit4",
            "--agents",
            "plastic-model,random",
            "--episodes",
            "2",
            "--learn-steps",
            "0",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert "plastic-model" in done.stdout and "random" in done.stdout
    bad = subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", "trials", "pursuit4", "--team", "tau9"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert bad.returncode == 2 and "--team 'tau9'" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1


def test_a_learning_seat_gets_the_env_rewards_through_the_loop():
    """Algorithm 1's lines 11-12 through the episode loop: the seat hands the env's reward and the teammates'
    observed actions to the agent, which stores them."""
    one_thread()
    env = gymnasium.make("EmbodiedAdhoc/Pursuit4Grid-v0", max_episode_steps=40)
    agent = build_agent(
        "learns-environment", Pursuit4(), np.random.default_rng(0), 40, uct=UctConfig(iterations=10, depth=2)
    )
    agent.start_team(np.random.default_rng(1))
    seat = EpisodeSeat(agent, 5)
    rewards = []

    class _Rewards(EpisodeObserver):
        def step_finished(self, record) -> None:
            rewards.append((record.reward, record.info["teammate_actions"]))

    trace = run_episode_loop(
        env,
        seat,
        env_seed=0,
        agent_rng=np.random.default_rng(2),
        reset_options=START,
        max_steps=40,
        observation_index=env.unwrapped.observation_index,
        observers=[_Rewards()],
    )
    buffer = agent.environment.buffer
    assert len(buffer) == trace.steps == agent.online.steps
    assert buffer.data["reward"][: trace.steps].tolist() == [r for r, _ in rewards]
    assert buffer.data["action"][: trace.steps, 1:].tolist() == [m for _, m in rewards]
