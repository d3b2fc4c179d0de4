"""TEBOPA's pieces against hand computations, and its behaviour on the lab."""

import numpy as np
import pytest

from embodied_adhoc.decision.agents.factory import make_agent
from embodied_adhoc.decision.agents.hotspot import HotspotConfig, information_reward, plan_hotspot
from embodied_adhoc.decision.agents.task_beliefs import LibraryBeliefs, LibraryKernels, normalised_entropy
from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.domains.lab import build_lab_library
from embodied_adhoc.domains.lab_observations import LabObservation
from embodied_adhoc.envs.toxic_waste_abstract import ToxicWasteAbstractEnv


def _two_state(stay_probability: float, accuracy: float) -> POMDP:
    """S = {0, 1}; one action (the state flips w.p. 1 - stay_probability); z = the state, right w.p. accuracy."""
    p = stay_probability
    transitions = [np.array([[p, 1 - p], [1 - p, p]])]
    observations = [np.array([[accuracy, 1 - accuracy], [1 - accuracy, accuracy]])]
    return POMDP(
        transitions,
        np.array([[1.0], [0.0]]),
        0.9,
        observations=observations,
        initial_belief=np.array([0.5, 0.5]),
    )


def test_belief_and_posterior_update_by_hand():
    model_a, model_b = _two_state(1.0, 0.8), _two_state(0.0, 0.8)
    tracker = LibraryBeliefs(LibraryKernels.build([model_a, model_b]))
    tracker.beliefs[:] = [[0.9, 0.1], [0.9, 0.1]]
    likelihoods = tracker.update(0, 0)
    # A: predicted (0.9, 0.1); times O(z=0|.) = (0.8, 0.2) -> (0.72, 0.02), rho = 0.74.
    # B: predicted (0.1, 0.9) -> (0.08, 0.18), rho = 0.26.
    np.testing.assert_allclose(likelihoods, [0.74, 0.26])
    np.testing.assert_allclose(tracker.beliefs[0], [0.72 / 0.74, 0.02 / 0.74])
    np.testing.assert_allclose(tracker.beliefs[1], [0.08 / 0.26, 0.18 / 0.26])
    np.testing.assert_allclose(tracker.posterior, [0.74, 0.26])  # prior 0.5 / 0.5
    np.testing.assert_allclose(
        tracker.average_belief(), 0.74 * tracker.beliefs[0] + 0.26 * tracker.beliefs[1]
    )


def test_normalised_entropy():
    assert normalised_entropy(np.full(8, 1 / 8)) == pytest.approx(1.0)
    assert normalised_entropy(np.eye(5)[2]) == 0.0
    assert normalised_entropy(np.array([0.5, 0.5, 0.0, 0.0])) == pytest.approx(0.5)


def _information_reward_loops(pomdp: POMDP, rewards: np.ndarray, gain: str) -> np.ndarray:
    """Sec. 7.1's r_info written with explicit sums over x, y, z (the reference for the vectorised version)."""
    n, a_count, z_count = pomdp.n_states, pomdp.n_actions, pomdp.n_observations
    transition = [m.toarray() for m in pomdp.transitions]
    observe = [m.toarray() for m in pomdp.observations]
    result = np.zeros((n, a_count))
    for a in range(a_count):
        for z in range(z_count):
            b_max = np.array(
                [sum(transition[a][x, y] * observe[a][y, z] / n for x in range(n)) for y in range(n)]
            )
            rho = b_max.sum()
            if rho == 0:
                continue
            b = b_max / rho
            dh = 1 + sum(v * np.log(v) for v in b if v > 0) / np.log(n)
            dr = max(sum(b_max[y] * rewards[y, a2] for y in range(n)) for a2 in range(a_count))
            dr = dr / rho if gain == "conditional" else (1.0 if gain == "none" else dr)
            for x in range(n):
                p_z = sum(transition[a][x, y] * observe[a][y, z] for y in range(n))
                result[x, a] += p_z * dh * dr
    return result


@pytest.mark.parametrize("gain", ["thesis", "conditional", "none"])
def test_information_reward_matches_explicit_sums(gain):
    rng = np.random.default_rng(3)
    n, a_count, z_count = 6, 3, 4
    transitions = [rng.dirichlet(np.ones(n) * 0.5, size=n) for _ in range(a_count)]
    observations = [rng.dirichlet(np.ones(z_count) * 0.5, size=n) for _ in range(a_count)]
    rewards = rng.random((n, a_count))
    pomdp = POMDP(transitions, rewards, 0.9, observations=observations, initial_belief=np.full(n, 1 / n))
    info, delta_h, delta_r = information_reward(pomdp, rewards, gain)
    np.testing.assert_allclose(info, _information_reward_loops(pomdp, rewards, gain), rtol=1e-10, atol=1e-12)
    assert (delta_h >= -1e-12).all() and (delta_h <= 1 + 1e-12).all()


@pytest.fixture(scope="module")
def library():
    return build_lab_library()


@pytest.mark.parametrize("name", ["hotspot", "atpo-qmdp"])
def test_hearing_the_human_at_a_node_only_one_task_explains(library, name):
    """Repeatedly hearing "the human is at the single workbench" (node 3) is explained by task [1, 2, 3] only."""
    agent = _agent(library, name)
    agent.reset(np.random.default_rng(0))
    heard = LabObservation(0, 3, False).encode()
    for _ in range(6):
        agent.observe(library.locate_action, heard)
    assert agent.task_posterior[1] > 0.95


@pytest.mark.parametrize("name", ["hotspot", "known-task", "atpo-qmdp"])
def test_rfid_at_the_door_identifies_the_task(library, name):
    """A ball entering the container at the door (node 0) is possible only in task [0, 1, 2]."""
    agent = _agent(library, name)
    agent.reset(np.random.default_rng(0))
    agent.observe(library.stay_action, LabObservation(0, None, False).encode())
    agent.observe(library.stay_action, LabObservation(0, None, True).encode())
    assert agent.task_posterior.tolist() == pytest.approx([1.0, 0.0])


def _agent(library, name):
    if name != "atpo-qmdp":
        return make_agent(name, library, true_task=0)
    from embodied_adhoc.decision.agents.atpo import AtpoAgent
    from embodied_adhoc.decision.agents.factory import hotspot_plan, mdp_q_values
    from embodied_adhoc.decision.policy import AlphaVectorPolicy

    # ATPO with hand-made alpha-vector policies (one Q*_m column per action: the QMDP vectors).
    q = mdp_q_values(library)
    policies = [
        AlphaVectorPolicy(q[m].T.copy(), np.arange(library.n_actions)) for m in range(library.n_tasks)
    ]
    return AtpoAgent(hotspot_plan(library).kernels, policies)


def _episode(env, agent, seed):
    obs, info = env.reset(seed=seed)
    agent.reset(np.random.default_rng(seed), state=info["state"] if agent.observes_state else None)
    actions = []
    for step in range(1, 101):
        action = agent.act()
        actions.append(action)
        obs, reward, terminated, truncated, info = env.step(action)
        agent.observe(
            action, info["observation_index"], state=info["state"] if agent.observes_state else None
        )
        if terminated:
            return step, actions, agent.task_posterior
    return 100, actions, agent.task_posterior


def test_hotspot_solves_episodes_and_identifies_the_task():
    env = ToxicWasteAbstractEnv()
    agent = make_agent("hotspot", env.library)
    results = [_episode(env, agent, seed) for seed in range(12)]
    steps = [r[0] for r in results]
    assert max(steps) < 40 and np.mean(steps) < 18
    correct = [r[2][env.reset(seed=seed)[1]["task"]] for seed, r in zip(range(12), results, strict=True)]
    assert np.mean(np.array(correct) > 0.5) >= 0.9


def test_agents_are_deterministic_given_the_seed():
    env = ToxicWasteAbstractEnv()
    for name in ("hotspot", "random", "bopa"):
        first = _episode(env, make_agent(name, env.library, true_task=0), 5)[1]
        second = _episode(env, make_agent(name, env.library, true_task=0), 5)[1]
        assert first == second


def test_thesis_literal_choice_runs():
    env = ToxicWasteAbstractEnv()
    plan = plan_hotspot(env.library.pomdps, HotspotConfig(belief_in_choice="average", reward_gain="thesis"))
    assert plan.q_info.shape == plan.q_task.shape == (2, env.library.n_states, 5)
