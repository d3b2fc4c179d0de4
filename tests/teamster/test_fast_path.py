"""TEAMSTER's fast path gives what the straightforward code gives: the fused pursuit simulator against
``team.probs`` + ``sample_rows`` + ``LearnedEnvironment.step``, the batched UCT with waves of one against the
plain per-node UCT, and a TEAMSTER agent's decisions with and without the fused simulator (a seeded trial of
the protocol against itself: ``test_learned_models.py``)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from embodied_adhoc.decision.agents.teamwork import sample_rows
from embodied_adhoc.decision.uct import BatchedUct, PlainUct, UctConfig
from embodied_adhoc.domains.pursuit4 import ExactEnvironment, ExactTeam, Pursuit4
from embodied_adhoc.learning.blocks import NumpyMlp, softmax
from embodied_adhoc.learning.teamster import (
    Features,
    LearnedEnvironment,
    LearnedTeam,
    PackedMlp,
    PursuitSimulator,
    sample_logits,
)
from embodied_adhoc.learning.teamster_agents import build_agent

torch.set_num_threads(1)


def _trained(world: Pursuit4, steps: int = 60):
    """A team and an environment model after ``steps`` Adam steps on the teammate-aware team (so that neither
    is at its initial weights)."""
    features = Features(world)
    team = LearnedTeam(world, np.random.default_rng(0), features=features)
    env = LearnedEnvironment(world, np.random.default_rng(1), features=features)
    rng = np.random.default_rng(2)
    state = world.sample_states(rng, 1)[0]
    for _ in range(steps):
        joint = sample_rows(world.team_policy("teammate-aware", state[None], agents=(0, 1, 2, 3))[0], rng)
        nxt, reward, done = world.step(state[None], joint[None], rng)
        env.update(state, joint, float(reward[0]), nxt[0], bool(done[0]))
        team.update(state, joint[1:])
        state = world.sample_states(rng, 1)[0] if done[0] else nxt[0]
    return team, env


def _composed(team, env):
    def simulate(states, actions, rng):
        mates = sample_rows(team.probs(states), rng)
        return env.step(states, np.concatenate([actions[:, None], mates], axis=1), rng)

    return simulate


def test_draws_from_logits_are_the_draws_from_their_softmax():
    """The same uniforms against unnormalised instead of normalised cumulative weights: the same draws but where
    a uniform falls within rounding of a boundary (none in 20,000 rows here), and the softmax's frequencies."""
    logits = np.random.default_rng(0).normal(0.0, 3.0, size=(20_000, 5)).astype(np.float32)
    first, second = np.random.default_rng(1), np.random.default_rng(1)
    assert np.mean(sample_logits(logits, first) != sample_rows(softmax(logits), second)) <= 1e-3
    assert first.random() == second.random()  # one uniform per row in both
    row = np.array([[2.0, -1.0, 0.5, 0.0, -30.0]], dtype=np.float32)
    draws = sample_logits(np.repeat(row, 40_000, axis=0), np.random.default_rng(2))
    frequencies, p = np.bincount(draws, minlength=5) / draws.size, softmax(row)[0]
    assert np.all(np.abs(frequencies - p) <= 4.0 * np.sqrt(p * (1 - p) / draws.size) + 1e-12)
    extreme = np.array([[-1e4, 80.0, -1e4, -1e4, -1e4]], dtype=np.float32)  # no overflow, no NaN
    assert set(sample_logits(np.repeat(extreme, 100, axis=0), np.random.default_rng(3))) == {1}


def _straight_draws(logits: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """sample_logits's draws spelled out: shifted exponentials, their cumulative sums, the count of those at or
    below the scaled uniform, clipped to the last category."""
    weights = np.exp(logits.astype(np.float64) - logits.astype(np.float64).max(-1, keepdims=True))
    cumulative = np.cumsum(weights, -1)
    uniform = rng.random(weights.shape[:-1]) * cumulative[..., -1]
    return np.minimum((uniform[..., None] >= cumulative).sum(-1), weights.shape[-1] - 1)


@pytest.mark.parametrize("categories", [5, 3])
def test_draws_from_logits_are_the_straightforward_counts(categories):
    """The byte-summed count (five categories) and the plain count (others) are the clipped count of the
    cumulative weights at or below the uniform, bit for bit and with as many uniforms, also where categories
    tie, where weights underflow to zero and where a row is all equal."""
    source = np.random.default_rng(7)
    cases = [source.normal(0.0, scale, size=(40, 3, categories)) for scale in (1e-3, 1.0, 30.0, 1e3)]
    cases.append(source.integers(-2, 3, size=(200, categories)))  # many ties
    cases.append(np.zeros((30, 5, categories)))
    tied = source.normal(0.0, 1.0, size=(50, categories))
    tied[:, 1] = tied[:, 0]
    cases.append(tied)
    for case in cases:
        logits = case.astype(np.float32)
        for seed in range(5):
            first, second = np.random.default_rng(seed), np.random.default_rng(seed)
            got, expected = sample_logits(logits, first), _straight_draws(logits, second)
            assert np.array_equal(got, expected) and got.shape == logits.shape[:-1]
            assert first.random() == second.random()


@pytest.mark.parametrize("size", [5, 10])
def test_packed_transition_forward_is_the_torch_views_forward(size, tmp_path):
    """The pursuit simulator's transition network over contiguous copies gives the bits of the forward over the
    parameters' views for every batch of 1 to 20 states (5 to 100 rows), before and after Adam steps (the copies
    are refreshed by update) and after loading other weights."""
    world = Pursuit4(size)
    team, env = _trained(world, steps=5)
    views, packed = env.transition_forward, env.packed_transition
    assert isinstance(packed, PackedMlp) and isinstance(views, NumpyMlp)
    rng = np.random.default_rng(11)

    def same() -> bool:
        for count in range(1, 21):
            rows = env.features.transition(world.sample_states(rng, count), rng.integers(0, 5, (count, 4)))
            if not np.array_equal(packed(rows), views(rows)):
                return False
        return True

    rows = env.features.transition(world.sample_states(rng, 8), rng.integers(0, 5, (8, 4)))
    before = packed(rows)
    assert same()
    _, trained = _trained(world, steps=40)
    for weight, other in zip(
        env.transition_net.parameters(), trained.transition_net.parameters(), strict=True
    ):
        assert not torch.equal(weight, other)
    state = world.sample_states(rng, 1)[0]
    for _ in range(3):
        joint = rng.integers(0, 5, size=4)
        nxt, reward, done = world.step(state[None], joint[None], rng)
        env.update(state, joint, float(reward[0]), nxt[0], bool(done[0]))
        state = nxt[0]
    assert not np.array_equal(packed(rows), before) and same()
    trained.save(tmp_path)
    env.load(tmp_path)
    assert torch.equal(env.transition_net[0].weight, trained.transition_net[0].weight) and same()


@pytest.mark.parametrize("size", [5, 10])
def test_fused_simulator_gives_the_composed_models_draws(size):
    world = Pursuit4(size)
    team, env = _trained(world)
    fused, composed = env.simulator(team), _composed(team, env)
    assert isinstance(fused, PursuitSimulator)
    rng = np.random.default_rng(5)
    for count in (1, 7, 20, 20, 3):  # reused input arrays: sizes again and in another order
        states, actions = world.sample_states(rng, count), rng.integers(0, 5, size=count)
        first, second = np.random.default_rng(count), np.random.default_rng(count)
        expected, got = composed(states, actions, first), fused(states, actions, second)
        for a, b in zip(expected, got, strict=True):
            assert a.dtype == b.dtype and np.array_equal(a, b)
        assert first.random() == second.random()  # the same number of draws
    # an exact team model (learns-environment) or another encoding has no fused form
    assert env.simulator(ExactTeam(world, "greedy")) is None


@pytest.mark.parametrize("model", ["exact", "learned"])
def test_batched_uct_in_waves_of_one_is_the_plain_uct(model):
    """Same tree rules, same simulator calls, same draws in the same order: the same decisions and the same
    generator state after each."""
    world = Pursuit4()
    if model == "exact":
        team, env = ExactTeam(world, "greedy"), ExactEnvironment(world)
    else:
        team, env = _trained(world)
    simulate = _composed(team, env)
    for seed, state in enumerate(world.sample_states(np.random.default_rng(9), 6)):
        first, second = np.random.default_rng(seed), np.random.default_rng(seed)
        batched = BatchedUct(UctConfig(iterations=40, wave=1)).plan(state, simulate, first)
        plain = PlainUct(UctConfig(iterations=40)).plan(state, simulate, second)
        assert batched == plain and first.random() == second.random()


def test_teamster_agent_plans_with_the_fused_simulator_and_decides_as_without_it():
    world = Pursuit4()

    def decisions(fused: bool) -> list[int]:
        agent = build_agent("teamster", world, np.random.default_rng(3), 100, UctConfig(iterations=20))
        if not fused:
            agent.environment.simulator = lambda team: None
        agent.start_team(np.random.default_rng(4))
        rng, out = np.random.default_rng(6), []
        state = world.sample_states(rng, 1)[0]
        for _ in range(15):  # acting and learning: both models change between decisions
            action = agent.act(state)
            joint = np.concatenate([[action], sample_rows(world.team_policy("greedy", state[None])[0], rng)])
            nxt, reward, done = world.step(state[None], joint[None], rng)
            agent.observe(state, joint, float(reward[0]), nxt[0], bool(done[0]))
            out.append(action)
            state = world.sample_states(rng, 1)[0] if done[0] else nxt[0]
        return out

    environment = build_agent("teamster", world, np.random.default_rng(0), 10).environment
    stranger = LearnedTeam(world, np.random.default_rng(0), features=Features(world))
    assert environment.simulator(stranger) is None  # fused only over one shared encodings object
    assert decisions(True) == decisions(False)


def test_waves_of_twenty_capture_as_the_sequential_search_does_in_distribution():
    """Waves change the order in which simulations see each other's values, not what the search estimates:
    PLASTIC-Model (exact models of the three teams) with waves of 20 and of one (the sequential UCT) capture prey
    at rates whose 95 % CIs overlap, both far above a random ad hoc agent, over the same seeded episodes."""
    from embodied_adhoc.experiments.domains.teamster_protocol import play
    from embodied_adhoc.experiments.stats import summarise_sample

    world, team = Pursuit4(), ExactTeam(Pursuit4(), "teammate-aware")
    captures = {}
    for name, wave in (("plastic-model", 1), ("plastic-model", 20), ("random", 1)):
        counts = []
        for seed in range(5):
            agent = build_agent(
                name, world, np.random.default_rng(seed), 100, UctConfig(iterations=20, wave=wave)
            )
            for known in world.teams:
                agent.finish_team(known)
            agent.start_team(np.random.default_rng([seed, 1]))
            agent.set_evaluation(True)
            counts.append(play(agent, world, team, 50, np.random.default_rng([seed, 2])))
        captures[name, wave] = summarise_sample(counts)
    sequential, batched, random = (
        captures["plastic-model", 1],
        captures["plastic-model", 20],
        captures["random", 1],
    )
    assert batched.ci_low <= sequential.ci_high and sequential.ci_low <= batched.ci_high
    assert min(batched.mean, sequential.mean) > 2 * random.ci_high
