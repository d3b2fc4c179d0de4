"""TEAMSTER's learned models and PLASTIC-Policy's DQN: Eq. 4.3's factorisation, learning, weights, seeds."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from embodied_adhoc.decision.agents.teamwork import sample_rows
from embodied_adhoc.domains.pursuit4 import TEAMS, Pursuit4
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.domains.teamster_protocol import ProtocolConfig, run_trial
from embodied_adhoc.learning.blocks import NumpyMlp
from embodied_adhoc.learning.dqn import Dqn
from embodied_adhoc.learning.teamster import Features, LearnedEnvironment, LearnedTeam
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


def _joint_sums(factors: np.ndarray) -> np.ndarray:
    """Eq. 4.3: per (x, a) the sum over all 5**5 move combinations of the product of the five factors."""
    count = factors.shape[0]
    joint = np.ones((count,) + (1,) * 5)
    for n in range(5):
        shape = [count] + [1] * 5
        shape[n + 1] = 5
        joint = joint * factors[:, n].reshape(shape)
    return joint.reshape(count, -1).sum(-1)


def test_transition_factors_sum_to_one_and_define_a_distribution_over_next_states():
    env = LearnedEnvironment(WORLD, np.random.default_rng(0))
    for row in _stream("greedy", 40):
        env.update(*row)
    rng = np.random.default_rng(1)
    states = WORLD.sample_states(rng, 8)
    actions = rng.integers(0, 5, size=(8, 4))
    factors = env.transition_probs(states, actions)
    assert factors.shape == (8, 5, 5) and np.allclose(factors.sum(-1), 1.0, atol=1e-12)
    assert np.allclose(_joint_sums(factors), 1.0)
    nxt, reward, terminal = env.step(states, actions, rng)
    assert nxt.shape == (8, 5) and ((0 <= reward) & (reward <= 1)).all()
    assert (Features(WORLD).move_of[states, nxt] >= 0).all()  # every agent moved by at most one cell


def test_transition_model_relearns_the_mirrored_rules_and_its_factors_still_sum_to_one():
    """After the old rules, 300 steps of --changed mirror: the model moves towards the mirrored effect of the
    ad hoc agent's own action and P(x'|x,a) still sums to 1 over all 5**5 move combinations."""
    env = LearnedEnvironment(WORLD, np.random.default_rng(0))
    mirrored = Pursuit4(mirror=True)
    lone = np.array(
        [[12, 0, 4, 20, 24]]
    )  # nobody next to the ad hoc agent: "up" moves it up (7) or down (17)
    up = np.zeros((1, 4), dtype=np.int64)
    rng = np.random.default_rng(1)

    def p_up_moves_down():
        return env.transition_probs(lone, up)[0, 0, 1]  # agent 0's factor on the move class "down"

    for row in _stream("greedy", 300):
        env.update(*row)
    before = p_up_moves_down()
    state = mirrored.sample_states(rng, 1)[0]
    for _ in range(300):
        joint = sample_rows(mirrored.team_policy("greedy", state[None], agents=(0, 1, 2, 3))[0], rng)
        nxt, _, done = mirrored.step(state[None], joint[None], rng)
        env.update(state, joint, float(done[0]), nxt[0], bool(done[0]))
        state = mirrored.sample_states(rng, 1)[0] if done[0] else nxt[0]
    after = p_up_moves_down()
    assert before < 0.2 and after > before + 0.2
    factors = env.transition_probs(mirrored.sample_states(rng, 6), rng.integers(0, 5, size=(6, 4)))
    assert np.allclose(_joint_sums(factors), 1.0)


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
    mirror = run_trial(
        "random", 0, ProtocolConfig(steps=10, eval_steps=5, points=2, changed="mirror", changed_steps=20)
    )
    assert [p[0] for p in mirror["changed"]] == [0, 10, 20] and mirror["config"]["changed"] == "mirror"
    with pytest.raises(ConfigError, match="steps"):
        ProtocolConfig(steps=15, points=10)
    with pytest.raises(ConfigError, match="changed_steps"):
        ProtocolConfig(steps=10, points=2, changed=0.2, changed_steps=5)
    with pytest.raises(ConfigError, match="changed 'flip'"):
        ProtocolConfig(changed="flip")
    with pytest.raises(ConfigError, match="agent"):
        run_trial("oracle", 0, config)


def test_protocol_interaction_runs_the_rules_through_the_episode_loop():
    """play() steps TeamworkEnv episodes through run_episode_loop; with one generator for the configurations, the
    teammates and the rules it gives the captures of stepping the rules directly (a fresh configuration after
    each capture, drawn when needed)."""
    from embodied_adhoc.decision.agents.teamwork import OriginalTeammate
    from embodied_adhoc.domains.pursuit4 import ExactTeam
    from embodied_adhoc.experiments.domains.teamster_protocol import play

    team = ExactTeam(WORLD, "teammate-aware")
    agent = OriginalTeammate({"teammate-aware": team.seat})
    agent.rng = np.random.default_rng(1)
    captures = play(agent, WORLD, team, 300, np.random.default_rng(2))
    rng, mine = np.random.default_rng(2), np.random.default_rng(1)
    state, direct = WORLD.sample_states(rng, 1)[0], 0
    for _ in range(300):
        action = sample_rows(team.seat(state[None]), mine)[0]
        joint = np.concatenate([[action], sample_rows(team.probs(state[None])[0], rng)])
        nxt, _, done = WORLD.step(state[None], joint[None], rng)
        direct += int(done[0])
        state = WORLD.sample_states(rng, 1)[0] if done[0] else nxt[0]
    assert captures == direct and captures > 20


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
