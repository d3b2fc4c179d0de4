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
from embodied_adhoc.learning.teamster import Features, LearnedEnvironment, LearnedTeam, PursuitSimulator
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


@pytest.mark.parametrize("size", [5, 10])
def test_fused_simulator_gives_the_composed_models_draws_bit_for_bit(size):
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
