"""Factory, baselines, BOPA and ATPO on constructed histories."""

import numpy as np
import pytest

from embodied_adhoc.decision.agents.base import Agent
from embodied_adhoc.decision.agents.bopa import BopaAgent, optimal_policies
from embodied_adhoc.decision.agents.factory import AGENT_NAMES, hotspot_plan, make_agent, mdp_q_values
from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.domains.lab import build_lab_library
from embodied_adhoc.domains.lab_graph import GROUND, HELD
from embodied_adhoc.errors import ConfigError


@pytest.fixture(scope="module")
def library():
    return build_lab_library()


def test_factory_builds_every_cheap_agent(library):
    for name in ("hotspot", "known-task", "oracle", "random", "bopa"):
        agent = make_agent(name, library, true_task=1)
        assert isinstance(agent, Agent) and agent.name == name
    assert set(AGENT_NAMES) == {"hotspot", "known-task", "oracle", "random", "atpo", "bopa"}
    assert make_agent("oracle", library, true_task=0).observes_state
    assert not make_agent("hotspot", library).observes_state
    with pytest.raises(ConfigError):
        make_agent("known-task", library)
    with pytest.raises(ConfigError):
        make_agent("nope", library)
    with pytest.raises(ConfigError):
        make_agent("oracle", library, true_task=7)


def test_solutions_are_cached_per_library(library):
    assert hotspot_plan(library) is hotspot_plan(library)
    assert mdp_q_values(library) is mdp_q_values(library)


def test_known_task_posterior_is_fixed(library):
    agent = make_agent("known-task", library, true_task=1)
    agent.reset(np.random.default_rng(0))
    agent.observe(library.stay_action, 0)
    assert agent.task_posterior.tolist() == [0.0, 1.0]


def test_oracle_heads_for_the_human_holding_a_ball(library):
    agent = make_agent("oracle", library, true_task=0)
    # Human holds ball 2 at node 2; the robot at the door must go to node 1 (its only neighbour) then 2.
    agent.reset(np.random.default_rng(0), state=library.state_index(0, 2, (GROUND, GROUND, HELD)))
    action = agent.act()
    assert library.graph.move_target(0, action) == 1
    agent.observe(action, 0, state=library.state_index(1, 2, (GROUND, GROUND, HELD)))
    assert library.graph.move_target(1, agent.act()) == 2
    with pytest.raises(ConfigError):
        agent.reset(np.random.default_rng(0))


def test_bopa_posterior_from_a_transition_only_one_task_explains(library):
    agent = make_agent("bopa", library)
    start = library.state_index(3, 0, (GROUND, GROUND, GROUND))
    agent.reset(np.random.default_rng(0), state=start)
    np.testing.assert_allclose(agent.action_distribution().sum(), 1.0)
    # The human at the door picks ball 0 up: only task [0, 1, 2] has a ball at the door.
    agent.observe(library.stay_action, 0, state=library.state_index(3, 0, (HELD, GROUND, GROUND)))
    assert agent.task_posterior.tolist() == [1.0, 0.0]


def test_bopa_eq_5_1_by_hand():
    """Two one-action MDPs over 2 states: P_A(1 | 0) = 0.2, P_B(1 | 0) = 0.6; observing 0 -> 1 twice."""
    from embodied_adhoc.decision.models import MDP

    mdp_a = MDP([np.array([[0.8, 0.2], [0.2, 0.8]])], np.zeros((2, 1)), 0.9)
    mdp_b = MDP([np.array([[0.4, 0.6], [0.6, 0.4]])], np.zeros((2, 1)), 0.9)
    agent = BopaAgent([mdp_a, mdp_b], np.zeros((2, 2, 1)))
    agent.reset(np.random.default_rng(0), state=0)
    agent.observe(0, 0, state=1)
    np.testing.assert_allclose(agent.task_posterior, [0.2 / 0.8, 0.6 / 0.8])
    agent.observe(0, 0, state=1)  # 1 -> 1: P_A = 0.8, P_B = 0.4
    np.testing.assert_allclose(agent.task_posterior, np.array([0.25 * 0.8, 0.75 * 0.4]) / 0.5)


def test_optimal_policies_split_ties():
    policies = optimal_policies(np.array([[[1.0, 1.0, 0.0]]]))
    np.testing.assert_allclose(policies, [[[0.5, 0.5, 0.0]]])


def test_random_agent_covers_all_actions(library):
    agent = make_agent("random", library)
    agent.reset(np.random.default_rng(0))
    assert {agent.act() for _ in range(200)} == set(range(library.n_actions))
    assert agent.task_posterior is None


def test_atpo_with_perseus_on_a_small_library():
    """ATPO end to end (Perseus solves each model) on two 2-state POMDPs that differ in their dynamics."""

    def model(p: float) -> POMDP:
        transitions = [np.array([[p, 1 - p], [1 - p, p]]), np.eye(2)]
        observations = [np.array([[0.85, 0.15], [0.15, 0.85]])] * 2
        rewards = np.array([[0.0, 1.0], [1.0, 0.0]])
        return POMDP(
            transitions, rewards, 0.9, observations=observations, initial_belief=np.array([0.5, 0.5])
        )

    models = [model(1.0), model(0.0)]
    agent = make_agent("atpo", models, perseus={"n_beliefs": 50, "tolerance": 1e-2, "time_limit": 10.0})
    agent.reset(np.random.default_rng(0))
    for _ in range(5):  # action 0 keeps the state in model 0 and flips it in model 1; we keep seeing 0
        agent.observe(0, 0)
    assert agent.task_posterior[0] > 0.95
    assert agent.act() in (0, 1)
    losses = agent.losses()
    # Eq. 5.7 losses are >= 0 for the exact value; Perseus' V is a lower bound, which a one-step lookahead
    # can beat by up to the solver's tolerance.
    assert losses.shape == (2, 2) and (losses >= -1e-2).all()
