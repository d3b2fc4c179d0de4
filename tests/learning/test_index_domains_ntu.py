"""The library-free agents on chapter 5's ntu map: the training env's episodes are the trials' (the same start
states, transitions, observations, rewards and step cap as ``LibraryEnv`` with the member as ``--teammate``), a
tiny training run of each agent writes weights the trials' ntu library loads, and the shipped agents run in
``trials ntu``."""

import csv

import numpy as np
import pytest
import torch

from embodied_adhoc.domains.chapter5 import build_library
from embodied_adhoc.domains.chapter5.teammates import world_with_teammate
from embodied_adhoc.learning.generalist import GeneralistTraining, load_generalist, train_generalist_run
from embodied_adhoc.learning.index_domains import (
    EPISODE_CAP,
    NTU,
    REWARD_SCALE,
    TEAMMATE_CLASSES,
    IndexAgent,
    IndexNetworkConfig,
    IndexVectorEnv,
    index_agent,
    input_indices,
    member_names,
)
from embodied_adhoc.learning.liam import LiamTraining, train_liam_run
from embodied_adhoc.learning.meliba import MelibaTraining, load_meliba, train_meliba_run
from embodied_adhoc.teammates.populations import members

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def library():
    return build_library(NTU)  # the trials' default ntu library (Table 5.2's settings)


def test_the_map_is_the_trials_ntu(library):
    from embodied_adhoc.experiments.domains.chapter5 import TABLE_5_2_HORIZON

    assert EPISODE_CAP[NTU] == TABLE_5_2_HORIZON[NTU] == library.horizon
    assert TEAMMATE_CLASSES[NTU] == (library.n_states, library.mmdps[0].n_actions // library.n_actions)
    assert REWARD_SCALE[NTU] == max(float(np.abs(p.rewards).max()) for p in library.pomdps)
    assert IndexVectorEnv(NTU, 1).n_observations == input_indices(library) == library.n_observations + 1


def test_a_rollout_is_an_episode_of_the_trials_world(library):
    """Every step the training env takes is one the trials' world can take from the same state: the start in
    the model's start states, ``y`` with ``P(y | x, a) > 0`` under the member's reduced world, ``z`` with
    ``O(z | y, a) > 0``, the reward ``R(x, a)`` scaled, the end at the absorbing state or the cap."""
    names = member_names(NTU)
    worlds = {name: world_with_teammate(library, spec.plugin) for name, spec in zip(
        names, members(NTU, "train"), strict=True)}  # fmt: skip
    env = IndexVectorEnv(NTU, 4, teammate_info=True)
    observation, _ = env.reset(seed=3)
    assert (observation == 0).all()  # LibraryEnv's -1 (no observation yet), plus one
    rng = np.random.default_rng(3)
    episodes, steps = 0, 0
    state = env.world.state.copy()
    for _ in range(300):
        for index in np.flatnonzero(env.steps == 0):
            assert state[index] in library.start_states(int(env.world.model[index]))
        model, member = env.world.model.copy(), env.member.copy()
        actions = rng.integers(0, 5, env.num_envs)
        observation, reward, terminated, truncated, infos = env.step(actions)
        stepped = infos["_teammate_observations"]
        for index in np.flatnonzero(stepped):
            world = worlds[names[member[index]]][int(model[index])]
            x, a, y = int(state[index]), int(actions[index]), int(env.world.state[index])
            assert infos["teammate_observations"][index, 0] == x
            assert world.transitions[a][x, y] > 0.0
            assert world.observations[a][y, int(observation[index]) - 1] > 0.0
            assert reward[index] == world.rewards[x, a] / REWARD_SCALE[NTU]
            assert terminated[index] == (y == library.absorbing(int(model[index])))
            assert truncated[index] == (not terminated[index] and env.steps[index] == EPISODE_CAP[NTU])
            steps += 1
        episodes += int((terminated | truncated).sum())
        state = env.world.state.copy()
    assert steps > 1000 and episodes > 10


def test_the_teammates_move_is_drawn_from_the_members_policy(library):
    """The joint draw (``b ~ pi(b | x)``, then ``y ~ P(. | x, a, b)``) has the trials' reduced world's
    distribution over ``y``: at a state where a stochastic member's move matters, 4000 draws lie within 0.05 of
    ``P(. | x, a)`` in total variation, and a wrong member's world is farther."""
    names = member_names(NTU)
    member = names.index("softmax-t03")
    env = IndexVectorEnv(NTU, 1)
    world = env.world
    reduced = world_with_teammate(library, members(NTU, "train")[member].plugin)
    lazy = world_with_teammate(library, members(NTU, "train")[names.index("lazy-p20")].plugin)
    x = int(library.start_states(0)[0])
    a = 4  # stay: the next state is the teammate's move alone
    world.model[0], world.member[0] = 0, member
    rng = np.random.default_rng(11)
    counts = np.zeros(library.n_states)
    for _ in range(4000):
        world.state[0] = x
        world.step(0, a, rng)
        counts[world.state[0]] += 1
    empirical = counts / counts.sum()
    expected = reduced[0].transitions[a][x].toarray().ravel()
    other = lazy[0].transitions[a][x].toarray().ravel()
    assert (expected > 0).sum() > 1  # the member's move is stochastic there
    assert 0.5 * np.abs(empirical - expected).sum() < 0.05
    assert 0.5 * np.abs(empirical - other).sum() > 0.5 * np.abs(empirical - expected).sum()


TINY = {"steps": 4 * 4 * 16, "envs": 4, "rollout": 16, "seed": 1, "teammates": 2}


@pytest.mark.parametrize(
    ("settings", "run", "kind", "loader"),
    [
        (GeneralistTraining, train_generalist_run, "ppo-generalist", load_generalist),
        (LiamTraining, train_liam_run, "liam", load_generalist),
        (MelibaTraining, train_meliba_run, "meliba", load_meliba),
    ],
)
def test_a_tiny_run_writes_weights_the_trials_library_loads(tmp_path, library, settings, run, kind, loader):
    report = run(settings(NTU, str(tmp_path), **TINY))
    assert report["finished"] and report["env_steps"] == 256
    weights = tmp_path / f"{NTU}-{kind}.safetensors"
    model, metadata = loader(weights, kind)
    assert isinstance(model.config, IndexNetworkConfig) and metadata["domain"] == NTU
    agent = index_agent(library, kind, weights)
    assert isinstance(agent, IndexAgent)
    agent.reset(np.random.default_rng(0))
    agent.start(-1)
    for observation in (0, 40, 80):
        agent.observe(agent.act(), observation)
    assert abs(agent.action_distribution().sum() - 1.0) < 1e-5  # float32 probabilities


def test_the_shipped_agents_run_in_trials_ntu(tmp_path):
    from embodied_adhoc.cli import main
    from embodied_adhoc.experiments.registry import get_trial_domain

    agents = "ppo-generalist,liam,meliba"
    domain = get_trial_domain(NTU)
    assert set(agents.split(",")) <= set(domain.agent_names)
    assert "liam" not in domain.default_agents
    out = tmp_path / "trials"
    code = main(["trials", NTU, "--agents", agents, "--episodes", "2", "--workers", "1", "--out", str(out)])
    assert code == 0
    rows = list(csv.DictReader((out / "trials.csv").open()))
    assert sorted({row["agent"] for row in rows}) == sorted(agents.split(","))
    assert len(rows) == 2 * 3
