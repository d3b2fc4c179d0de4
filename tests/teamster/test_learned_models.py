"""TEAMSTER's learned models and PLASTIC-Policy's DQN: Eq. 4.3's factorisation, learning, weights, seeds."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from embodied_adhoc.decision.agents.teamwork import sample_rows
from embodied_adhoc.domains.pursuit4 import TEAMS, Pursuit4
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.blocks import NumpyMlp
from embodied_adhoc.learning.dqn import Dqn
from embodied_adhoc.learning.teamster import Features, LearnedEnvironment, LearnedTeam
from embodied_adhoc.learning.teamster_protocol import ProtocolConfig, run_trial
from embodied_adhoc.learning.weights import WeightsError

torch.set_num_threads(1)
WORLD = Pursuit4()


def _stream(team: str, steps: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    state = WORLD.sample_states(rng, 1)[0]
    for _ in range(steps):
        joint = sample_rows(WORLD.team_policy(team, state[None], agents=(0, 1, 2, 3))[0], rng)
        nxt, reward, done = WORLD.step(state[None], joint[None], rng)
        yield state, joint, float(reward[0]), nxt[0], bool(done[0])
        state = WORLD.sample_states(rng, 1)[0] if done[0] else nxt[0]


def test_transition_factors_sum_to_one_and_define_a_distribution_over_next_states():
    env = LearnedEnvironment(WORLD, np.random.default_rng(0))
    for row in _stream("greedy", 40):
        env.update(*row)
    rng = np.random.default_rng(1)
    states = WORLD.sample_states(rng, 8)
    actions = rng.integers(0, 5, size=(8, 4))
    factors = env.transition_probs(states, actions)
    assert factors.shape == (8, 5, 5) and np.allclose(factors.sum(-1), 1.0, atol=1e-12)
    # Eq. 4.3: the product of the factors over all 5**5 move combinations sums to 1 for each (x, a)
    joint = np.ones((8,) + (1,) * 5)
    for n in range(5):
        shape = [8] + [1] * 5
        shape[n + 1] = 5
        joint = joint * factors[:, n].reshape(shape)
    assert np.allclose(joint.reshape(8, -1).sum(-1), 1.0)
    nxt, reward, terminal = env.step(states, actions, rng)
    assert nxt.shape == (8, 5) and ((0 <= reward) & (reward <= 1)).all()
    assert (Features(WORLD).move_of[states, nxt] >= 0).all()  # every agent moved by at most one cell


def test_learned_models_fit_the_true_rules_and_team():
    env = LearnedEnvironment(WORLD, np.random.default_rng(0))
    team = LearnedTeam(WORLD, np.random.default_rng(1))
    for state, joint, reward, nxt, done in _stream("greedy", 600):
        env.update(state, joint, reward, nxt, done)
        team.update(state, joint[1:])
    rng = np.random.default_rng(5)
    states = WORLD.sample_states(rng, 300)
    exact = WORLD.team_policy("greedy", states)
    fresh = LearnedTeam(WORLD, np.random.default_rng(1)).probs(states)
    distance = 0.5 * np.abs(team.probs(states) - exact).sum(-1).mean()
    assert distance < 0.5 * 0.5 * np.abs(fresh - exact).sum(-1).mean()  # halved the untrained model's error
    actions = rng.integers(0, 4, size=(300, 4))
    nxt, _, _ = WORLD.step(states, actions, rng)
    factors = env.transition_probs(states, actions)
    true_move = np.take_along_axis(factors, Features(WORLD).move_of[states, nxt][..., None], 2)[..., 0]
    assert true_move[:, :4].mean() > 0.5  # predators mostly go where they were sent (uniform would be 0.2)


def test_weights_round_trip_as_safetensors_and_pickles_are_refused(tmp_path):
    team = LearnedTeam(WORLD, np.random.default_rng(0))
    for state, joint, *_ in _stream("teammate-aware", 40):
        team.update(state, joint[1:])
    path = team.save(tmp_path / "team.safetensors")
    other = LearnedTeam(WORLD, np.random.default_rng(9))
    assert other.load(path)["kind"] == "teamster-team"
    states = WORLD.sample_states(np.random.default_rng(2), 5)
    assert np.array_equal(team.probs(states), other.probs(states))
    env = LearnedEnvironment(WORLD, np.random.default_rng(0))
    env.save(tmp_path / "env")
    copy = LearnedEnvironment(WORLD, np.random.default_rng(3))
    copy.load(tmp_path / "env")
    actions = np.zeros((5, 4), dtype=np.int64)
    assert np.array_equal(env.transition_probs(states, actions), copy.transition_probs(states, actions))
    dqn = Dqn(40, 5, np.random.default_rng(0))
    dqn_path = dqn.save(tmp_path / "q.safetensors")
    again = Dqn(40, 5, np.random.default_rng(4))
    assert again.load(dqn_path)["kind"] == "dqn"
    features = np.eye(40, dtype=np.float32)[:3]
    assert [dqn.greedy(f) for f in features] == [again.greedy(f) for f in features]
    pickle = tmp_path / "pickled.safetensors"
    torch.save(team.net.state_dict(), pickle)
    with pytest.raises(WeightsError, match="pickled"):
        other.load(pickle)


def test_protocol_records_and_same_seed_same_result():
    config = ProtocolConfig(steps=10, eval_steps=5, points=2, iterations=10, depth=3, changed=0.2)
    first = run_trial("teamster", 0, config)
    second = run_trial("teamster", 0, config)
    first.pop("seconds"), second.pop("seconds")
    assert first == second
    assert set(first["curves"]) == set(TEAMS) and [p[0] for p in first["curves"]["greedy"]] == [0, 5, 10]
    assert set(first["after"]["greedy"]) == set(TEAMS) and len(first["changed"]) == 3
    with pytest.raises(ConfigError, match="steps"):
        ProtocolConfig(steps=15, points=10)
    with pytest.raises(ConfigError, match="agent"):
        run_trial("oracle", 0, config)


def test_numpy_inference_follows_the_torch_network_through_adam_steps():
    """The planner's numpy forward reads the parameters in place: after training it still equals torch's."""
    env = LearnedEnvironment(WORLD, np.random.default_rng(0))
    states = WORLD.sample_states(np.random.default_rng(3), 6)
    actions = np.random.default_rng(4).integers(0, 5, size=(6, 4))
    before = env.transition_probs(states, actions)
    for row in _stream("teammate-aware", 30):
        env.update(*row)
    after = env.transition_probs(states, actions)
    assert not np.allclose(before, after)  # the Adam steps reached the numpy forward without an export
    with torch.no_grad():
        logits = env.transition_net(torch.from_numpy(Features(WORLD).transition(states, actions)))
        capture = torch.sigmoid(env.reward_net(torch.from_numpy(Features(WORLD).reward(states))))[:, 0]
    assert np.allclose(after, torch.softmax(logits.double(), -1).numpy().reshape(6, 5, 5), atol=1e-6)
    assert np.allclose(env.capture_probability(states), capture.numpy(), atol=1e-6)
    with pytest.raises(ConfigError, match="Linear or ReLU"):
        NumpyMlp(torch.nn.Sequential(torch.nn.Linear(3, 3), torch.nn.Tanh()))
