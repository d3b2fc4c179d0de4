"""Chapter-4 pursuit rules, exact team models, the batched UCT and the team belief (Algorithm 2)."""

from __future__ import annotations

import numpy as np
import pytest

from embodied_adhoc.decision.agents.teamwork import ModelBasedAgent, joint_likelihood, sample_rows
from embodied_adhoc.decision.uct import BatchedUct, PlainUct, UctConfig, update_team_belief
from embodied_adhoc.domains.pursuit4 import TEAMS, ExactEnvironment, ExactTeam, Pursuit4
from embodied_adhoc.errors import ConfigError

WORLD = Pursuit4()
LEFT = 2
# prey at (2, 2) = 12; teammates on its N (7), S (17) and W (11) sides; the ad hoc agent at (2, 4) = 14:
# moving left onto 13 surrounds the prey unless the prey slips right first (probability 1/8)
ONE_STEP = np.array([14, 7, 17, 11, 12])


def test_team_policies_are_distributions_and_rules_keep_agents_apart():
    rng = np.random.default_rng(3)
    states = WORLD.sample_states(rng, 64)
    assert not WORLD.captured(states).any()
    for team in TEAMS:
        probs = WORLD.team_policy(team, states, agents=(0, 1, 2, 3))
        assert probs.shape == (64, 4, 5) and np.allclose(probs.sum(-1), 1) and (probs >= 0).all()
    nxt, reward, done = WORLD.step(states, rng.integers(0, 5, size=(64, 4)), rng)
    assert all(len(set(row)) == 5 for row in nxt.tolist())  # a collision leaves the loser in place
    assert np.array_equal(reward, done.astype(float))
    with pytest.raises(ConfigError, match="team="):
        WORLD.team_policy("lazy", states)


def test_collision_has_a_random_winner():
    # two predators claim the same empty cell 12 from 11 (moving right) and 13 (moving left)
    state = np.array([[11, 13, 0, 4, 24]])
    winners = set()
    rng = np.random.default_rng(0)
    for _ in range(40):
        nxt, _, _ = WORLD.step(state, np.array([[3, 2, 4, 4]]), rng)
        winners.add(tuple(int(c == 12) for c in nxt[0, :2]))
    assert winners == {(1, 0), (0, 1)}


def test_changed_environment_moves_fail_with_the_slip_probability():
    rng = np.random.default_rng(2)
    states = WORLD.sample_states(rng, 2000)
    moved = {}
    for slip in (0.0, 0.6):
        nxt, _, _ = Pursuit4(slip=slip).step(states, np.zeros((2000, 4), dtype=np.int64), rng)  # all "up"
        moved[slip] = (nxt[:, :4] != states[:, :4]).mean()
    assert abs(moved[0.6] / moved[0.0] - 0.4) < 0.05
    with pytest.raises(ConfigError, match="slip"):
        Pursuit4(slip=1.0)


def test_mirrored_environment_moves_the_ad_hoc_agent_the_opposite_way_and_nobody_else():
    """--changed mirror: the ad hoc agent's up/down and left/right swap; same draws, so with its action mirrored
    the old rules give the same step; the teammates and the prey are unaffected."""
    rng = np.random.default_rng(7)
    states = WORLD.sample_states(rng, 500)
    actions = rng.integers(0, 5, size=(500, 4))
    swapped = actions.copy()
    swapped[:, 0] = np.array([1, 0, 3, 2, 4])[actions[:, 0]]
    mirrored = Pursuit4(mirror=True).step(states, actions, np.random.default_rng(3))
    expected = WORLD.step(states, swapped, np.random.default_rng(3))
    for got, want in zip(mirrored, expected, strict=True):
        assert np.array_equal(got, want)
    old = WORLD.step(states, actions, np.random.default_rng(3))[0]
    moving = actions[:, 0] != 4
    assert (old[moving, 0] != mirrored[0][moving, 0]).mean() > 0.5  # the old rules are wrong about agent 0
    # moving "up" from an empty neighbourhood: the old rules put it one row up, the mirrored world one row down
    lone = np.array([[12, 0, 4, 20, 24]])  # ad hoc agent in the centre, nobody next to it
    up = np.array([[0, 4, 4, 4]])
    assert WORLD.step(lone, up, np.random.default_rng(0))[0][0, 0] == 7
    assert Pursuit4(mirror=True).step(lone, up, np.random.default_rng(0))[0][0, 0] == 17


def test_teammate_aware_team_holds_its_ring_positions():
    probs = WORLD.team_policy("teammate-aware", ONE_STEP[None])
    assert np.allclose(probs[0, :, 4], 1.0)  # teammates already around the prey stay


@pytest.mark.parametrize("planner", [BatchedUct(UctConfig()), PlainUct(UctConfig())])
def test_uct_with_the_exact_model_finds_the_capture(planner):
    team, env = ExactTeam(WORLD, "teammate-aware"), ExactEnvironment(WORLD)

    def simulate(states, actions, rng):
        mates = sample_rows(team.probs(states), rng)
        return env.step(states, np.concatenate([actions[:, None], mates], axis=1), rng)

    for seed in range(3):
        assert planner.plan(ONE_STEP, simulate, np.random.default_rng(seed)) == LEFT


def _belief(observed: str, steps: int, **rule) -> np.ndarray:
    rng = np.random.default_rng(1)
    models = [ExactTeam(WORLD, team) for team in TEAMS]
    belief = np.full(3, 1 / 3)
    for state in WORLD.sample_states(rng, steps):
        mates = sample_rows(models[TEAMS.index(observed)].probs(state[None])[0], rng)
        probs = np.stack([m.probs(state[None])[0] for m in models])
        belief = update_team_belief(belief, joint_likelihood(probs, mates), **rule)
    return belief


@pytest.mark.parametrize("observed", TEAMS)
def test_team_belief_moves_to_the_observed_team(observed):
    belief = _belief(observed, 60, rule="bayes")
    assert belief.argmax() == TEAMS.index(observed) and belief.max() > 0.9
    if observed != "probabilistic-destinations":  # PLASTIC's bounded loss: see docs/teamster.md
        belief = _belief(observed, 100, eta=0.1)
        assert belief.argmax() == TEAMS.index(observed) and belief.max() > 0.5
    with pytest.raises(ConfigError, match="eta"):
        update_team_belief(belief, np.ones(3), eta=1.5)
    with pytest.raises(ConfigError, match="rule"):
        update_team_belief(belief, np.ones(3), rule="vote")


class _Fixed:
    """A stand-in online team model (the learned one lives in learning/): fixed, never updated."""

    def __init__(self, team):
        self.team = team

    def reset(self):
        pass

    def probs(self, states):
        return self.team.probs(states)

    def update(self, state, mates):
        pass


def test_same_seed_same_decisions():
    def decisions(seed):
        exact = {t: ExactTeam(WORLD, t) for t in TEAMS}
        agent = ModelBasedAgent("plastic-model", ExactEnvironment(WORLD), _Fixed(exact["greedy"]), exact)
        for team in TEAMS:
            agent.finish_team(team)
        agent.start_team(np.random.default_rng(seed))
        assert agent.belief.shape == (4,)
        rng = np.random.default_rng(seed + 100)
        out = []
        for state in WORLD.sample_states(rng, 5):
            action = agent.act(state)
            mates = sample_rows(WORLD.team_policy("greedy", state[None])[0], rng)
            joint = np.concatenate([[action], mates])
            nxt, reward, done = WORLD.step(state[None], joint[None], rng)
            agent.observe(state, joint, float(reward[0]), nxt[0], bool(done[0]))
            out.append(action)
        return out, agent.belief.copy()

    (a, belief_a), (b, belief_b) = decisions(4), decisions(4)
    assert a == b and np.array_equal(belief_a, belief_b)
