"""The rule-built lab library: state counts, shared indexing, stochastic rows, human policy, observations."""

import numpy as np
import pytest

from embodied_adhoc.domains.lab import LabGraph, LabReward, apply_step, build_lab_library
from embodied_adhoc.domains.lab_graph import DISPOSED, GROUND, HELD
from embodied_adhoc.domains.lab_human import HumanOutcome, LabHuman
from embodied_adhoc.domains.lab_observations import LabObservation
from embodied_adhoc.errors import ConfigError


@pytest.fixture(scope="module")
def library():
    return build_lab_library()


def test_260_world_states_per_task_and_5_actions(library):
    for task in range(library.n_tasks):
        assert library.states.world_valid(task).sum() == 260
        assert library.states.valid[task].sum() == 272  # + 12 "ball just entered the container" states
    assert library.n_actions == 5
    assert library.n_observations == 72
    assert build_lab_library(communication=False).n_actions == 4


def test_rows_sum_to_one_everywhere(library):
    for models in (library.mmdps, library.mdps, library.pomdps):
        for model in models:
            for matrix in model.transitions:
                np.testing.assert_allclose(np.asarray(matrix.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    for matrix in library.pomdps[0].observations:
        np.testing.assert_allclose(np.asarray(matrix.sum(axis=1)).ravel(), 1.0, atol=1e-12)


def test_one_indexing_shared_by_all_tasks(library):
    states = library.states
    # Each index is one concrete state, the same in every task: the describe/index round trip is the identity.
    for s in range(states.n_states):
        assert states.index(*states.describe(s)) == s
    # A state valid in both tasks (no ball held) has the same index in both, and both task models use it.
    s = library.state_index(0, 3, (GROUND, DISPOSED, GROUND))
    assert states.valid[:, s].all()
    # Holding ball 0 at node 0 is valid only in task 0 (ball 0 at node 0); at node 1 only in task 1.
    assert states.valid[:, library.state_index(2, 0, (HELD, GROUND, GROUND))].tolist() == [True, False]
    assert states.valid[:, library.state_index(2, 1, (HELD, GROUND, GROUND))].tolist() == [False, True]


def test_invalid_states_unreachable_from_valid_ones(library):
    for task, mdp in enumerate(library.mdps):
        valid = library.states.valid[task]
        for matrix in mdp.transitions:
            assert matrix[valid][:, ~valid].nnz == 0


def test_human_policy_rules():
    graph = LabGraph()
    human = LabHuman(graph, (0, 1, 2), epsilon=0.05)
    assert human.optimal_actions(4, (GROUND, GROUND, GROUND)) == (0,)  # 4 -> 3 (its only neighbour)
    assert human.optimal_actions(1, (GROUND, GROUND, GROUND)) == (human.pick_action,)
    assert human.optimal_actions(1, (GROUND, HELD, GROUND)) == (human.stay_action,)
    # From node 1 with balls left at 0 and 2 (both at distance 1): both moves are optimal, chosen uniformly.
    assert human.optimal_actions(1, (GROUND, DISPOSED, GROUND)) == (0, 1)
    outcomes = {
        (o.next_node, o.picked_ball): o.probability
        for o in human.policy_outcomes(1, (GROUND, DISPOSED, GROUND))
    }
    assert outcomes == pytest.approx({(0, -1): 0.475, (2, -1): 0.475, (1, -1): 0.05})
    picked = {
        (o.next_node, o.picked_ball): o.probability
        for o in human.policy_outcomes(2, (DISPOSED, DISPOSED, GROUND))
    }
    assert picked == pytest.approx({(2, 2): 0.95, (2, -1): 0.05})


def test_hand_over_needs_colocation_and_stay_or_locate():
    graph = LabGraph()
    wait = HumanOutcome(1.0, 1)
    assert apply_step(graph, 1, 1, (DISPOSED, HELD, GROUND), 3, wait) == (
        1,
        1,
        (DISPOSED, DISPOSED, GROUND),
        True,
    )
    assert apply_step(graph, 1, 1, (DISPOSED, HELD, GROUND), 4, wait) == (
        1,
        1,
        (DISPOSED, DISPOSED, GROUND),
        True,
    )
    assert apply_step(graph, 1, 1, (DISPOSED, HELD, GROUND), 0, wait) == (
        0,
        1,
        (DISPOSED, HELD, GROUND),
        False,
    )
    assert apply_step(graph, 2, 1, (DISPOSED, HELD, GROUND), 3, wait) == (
        2,
        1,
        (DISPOSED, HELD, GROUND),
        False,
    )
    # Robot move actions: k-th lowest neighbour, k beyond the degree falls back to the lowest.
    assert [apply_step(graph, 3, 0, (GROUND,) * 3, a, HumanOutcome(1.0, 0))[0] for a in range(3)] == [1, 4, 1]


def test_rewards_and_initial_belief(library):
    pomdp = library.pomdps[0]
    assert pomdp.rewards[library.state_index(0, 1, (GROUND, HELD, DISPOSED)), 2] == -3.0
    assert pomdp.discount == 0.95
    start = np.flatnonzero(pomdp.initial_belief)
    assert len(start) == 25 and np.allclose(pomdp.initial_belief[start], 1 / 25)
    custom = build_lab_library(reward=LabReward(ground=-1.0, held=-3.0, disposed=0.0))
    assert custom.pomdps[0].rewards[library.state_index(0, 1, (GROUND, HELD, DISPOSED)), 0] == -4.0


def test_observation_encoding_round_trip():
    for index in range(72):
        observation = LabObservation.decode(index)
        assert observation.encode() == index
        assert LabObservation.from_vector(observation.to_vector()) == observation
    assert LabObservation(None, None, False).to_vector().tolist() == [5, 5, 0]
    with pytest.raises(ConfigError):
        LabObservation.decode(72)


def test_observation_model_semantics(library):
    pomdp = library.pomdps[0]
    s = library.state_index(2, 3, (GROUND, GROUND, GROUND))
    stay, locate = 3, 4
    row = pomdp.observations[stay][s].toarray().ravel()
    assert row[LabObservation(2, None, False).encode()] == pytest.approx(0.99)
    assert row[LabObservation(None, None, False).encode()] == pytest.approx(0.01)
    row = pomdp.observations[locate][s].toarray().ravel()
    confusion = library.observation_model.confusion.matrix[3]
    assert row[LabObservation(2, 3, False).encode()] == pytest.approx(0.99 * confusion[3])
    assert row[LabObservation(2, None, False).encode()] == pytest.approx(0.99 * confusion[5])
    disposed = library.state_index(1, 1, (DISPOSED, DISPOSED, GROUND), rfid_event=True)
    row = pomdp.observations[stay][disposed].toarray().ravel()
    assert row[LabObservation(1, None, True).encode()] == pytest.approx(0.99)
    # Without communication the human is seen only when co-located.
    silent = build_lab_library(communication=False)
    row = silent.pomdps[0].observations[stay][silent.state_index(1, 1, (GROUND,) * 3)].toarray().ravel()
    assert row[LabObservation(1, 1, False).encode()] == pytest.approx(0.99)
    row = silent.pomdps[0].observations[stay][silent.state_index(1, 2, (GROUND,) * 3)].toarray().ravel()
    assert row[LabObservation(1, None, False).encode()] == pytest.approx(0.99)


def test_generic_graph_and_tasks():
    graph = LabGraph(4, ((0, 1), (1, 2), (2, 3), (3, 0)), ("a", "b", "c", "d"))
    library = build_lab_library(graph, tasks=[[0, 2], [1, 3], [2, 2]], communication=False)
    assert library.n_tasks == 3 and library.n_actions == 3  # 2 moves + stay
    for task in range(3):
        # 16 node pairs x 4 free statuses + per ball: 4 robot nodes x 2 statuses of the other ball, held
        assert library.states.world_valid(task).sum() == 16 * 4 + 2 * 4 * 2
    with pytest.raises(ConfigError):
        build_lab_library(tasks=[[0, 1], [1, 2, 3]])
    with pytest.raises(ConfigError):
        build_lab_library(graph, tasks=[[0, 1]])  # the thesis confusion matrix has 5 nodes, this graph 4


def test_library_is_cached():
    assert build_lab_library() is build_lab_library()
