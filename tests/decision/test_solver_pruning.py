"""Pruning of the plan graph: dominated rows go, the value at every belief stays, and the graph stays closed."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from embodied_adhoc import paths
from embodied_adhoc.decision.beliefs import collect_beliefs
from embodied_adhoc.decision.perseus import PerseusConfig, perseus
from embodied_adhoc.decision.plan_graph import PlanGraph
from embodied_adhoc.decision.pomdp_io import read_pomdp

CORPUS = Path(__file__).resolve().parents[2] / ".." / "shared" / "pomdp"


def _model(name: str):
    path = paths.asset(f"data/{name}") if name == "tiger.95.POMDP" else CORPUS / name
    if not path.is_file():
        pytest.skip(f"corpus file {path} not present")
    return read_pomdp(path)


def _random_graph(seed: int, n_states: int = 12, n_obs: int = 3, n_rows: int = 300) -> PlanGraph:
    """Blind rows, then rows continuing with earlier ones; every third row is a root minus noise (dominated)."""
    rng = np.random.default_rng(seed)
    graph = PlanGraph.of_blind_policies(rng.normal(size=(2, n_states)), n_obs)
    for _ in range(n_rows):
        size = len(graph)
        if size > 4 and rng.random() < 0.3:
            vector = graph.vectors[rng.integers(size)] - rng.random(n_states) * rng.integers(0, 2, n_states)
        else:
            vector = rng.normal(size=n_states)
        graph.add(vector[None, :], [int(rng.integers(3))], rng.integers(0, size, (1, n_obs)))
    return graph


def _upper_envelope(vectors: np.ndarray, beliefs: np.ndarray) -> np.ndarray:
    return (beliefs @ vectors.T).max(axis=1)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pruning_keeps_the_value_everywhere_and_the_closure(seed):
    graph = _random_graph(seed)
    rng = np.random.default_rng(100 + seed)
    roots = np.sort(rng.choice(len(graph), 40, replace=False))
    kept_before = graph.closure(roots)
    beliefs = rng.dirichlet(np.ones(graph.vectors.shape[1]) * 0.3, size=2000)
    before = _upper_envelope(graph.vectors[roots], beliefs)  # the lower bound claimed: the roots' values
    root_vectors = graph.vectors[roots].copy()
    new_roots = graph.prune_dominated(roots)
    # the roots are the same vectors, in the same order
    assert np.array_equal(graph.vectors[new_roots], root_vectors)
    # closure: every continuation of a kept row is a row, and every row is reachable from the roots
    assert graph.children.min() >= 0 and graph.children.max() < len(graph)
    assert np.array_equal(graph.closure(new_roots), np.arange(len(graph)))
    assert len(graph) <= kept_before.size
    # every kept row is the value of a plan, so the saved set is worth at least the roots at every belief
    assert np.all(_upper_envelope(graph.vectors, beliefs) >= before - 1e-12)
    # no remaining non-root row is dominated by a root at every state
    others = np.setdiff1d(np.arange(len(graph)), new_roots)
    dominated = np.all(graph.vectors[new_roots][None, :, :] >= graph.vectors[others][:, None, :], axis=2)
    assert not dominated.any()


def test_a_dominated_continuation_is_replaced_by_its_dominating_root():
    # rows 0, 1 blind; 2 = [0, 0] continues with 0; 3 = [1, 1] (root) continues with 2, which 3 dominates
    graph = PlanGraph.of_blind_policies(np.array([[-1.0, -2.0], [-2.0, -1.0]]), n_observations=1)
    graph.add(np.array([[0.0, 0.0]]), [0], np.array([[0]]))
    graph.add(np.array([[1.0, 1.0]]), [1], np.array([[2]]))
    roots = graph.prune_dominated(np.array([3]))
    assert len(graph) == 1 and graph.vectors[roots[0]].tolist() == [1.0, 1.0]
    assert graph.children.tolist() == [[roots[0]]]


def test_reserve_grows_the_buffers_before_the_rows_come_and_keeps_the_rows():
    """reserve(count) grows the graph as add would for count rows, so that adding them afterwards copies nothing
    (the solver reserves before a stage, where little else is held); the rows and plans are unchanged."""
    rng = np.random.default_rng(0)
    graph = PlanGraph.of_blind_policies(rng.normal(size=(3, 5)), n_observations=2)
    before = (graph.vectors.copy(), graph.actions.copy(), graph.children.copy())
    assert graph.growth_bytes(10) > 0
    graph.reserve(10)
    assert graph.growth_bytes(10) == 0
    buffer = graph._vectors
    for step in range(10):
        graph.add(rng.normal(size=(1, 5)), [step % 3], np.array([[0, 1]]))
    assert graph._vectors is buffer  # no growth, hence no copy, while the rows arrive
    np.testing.assert_array_equal(graph.vectors[:3], before[0])
    np.testing.assert_array_equal(graph.actions[:3], before[1])
    np.testing.assert_array_equal(graph.children[:3], before[2])
    assert len(graph) == 13 and graph.children[3:].tolist() == [[0, 1]] * 10
    graph.reserve(0)
    assert graph._vectors is buffer


@pytest.mark.parametrize(
    ("name", "settings"),
    [
        ("hallway.POMDP", dict(n_beliefs=60, expand=True, max_iterations=12, seed=3)),
        ("4x3.95.POMDP", dict(n_beliefs=100, expand=True, max_iterations=30, seed=3)),
        ("4x3.95.POMDP", dict(n_beliefs=100, max_iterations=40, seed=1, update="perseus")),
    ],
)
def test_pruned_solve_keeps_the_bound_at_every_sampled_belief(name, settings):
    pomdp = _model(name)
    pruned = perseus(pomdp, PerseusConfig(**settings))
    full = perseus(pomdp, PerseusConfig(prune=False, **settings))
    # pruning never changes what the solve computes, only which continuation rows it keeps
    assert pruned.stats.lower == full.stats.lower and pruned.stats.upper == full.stats.upper
    assert pruned.stats.iterations == full.stats.iterations
    assert len(pruned.alphas) < len(full.alphas)
    beliefs = collect_beliefs(pomdp, 500, np.random.default_rng(7))
    assert np.all(pruned.values(beliefs) >= full.values(beliefs) - 1e-12)
    # the same seed gives the same bytes
    again = perseus(pomdp, PerseusConfig(**settings))
    assert np.array_equal(again.alphas, pruned.alphas) and np.array_equal(again.actions, pruned.actions)


def _plan_backups(pomdp, vectors: np.ndarray, actions: np.ndarray, children: np.ndarray) -> np.ndarray:
    """Per row, ``R_a + gamma T_a sum_z O_{a,z} alpha_{c(z)}``: the value of doing its action, then its
    continuations (each row is a plan's value when it is at most this, with its continuations plans too)."""
    backups = np.empty_like(vectors)
    for row, (action, kids) in enumerate(zip(actions, children, strict=True)):
        observation = pomdp.observations[action].toarray()  # (S, Z)
        future = (observation * vectors[kids].T).sum(axis=1)
        backups[row] = pomdp.rewards[:, action] + pomdp.discount * (pomdp.transitions[action] @ future)
    return backups


def _solved_graph(pomdp, stages: int, seed: int) -> tuple[PlanGraph, np.ndarray]:
    """A plan graph built as Perseus builds one: blind rows, then backups of sampled beliefs, V_n the last ones."""
    from embodied_adhoc.decision.backup import BackupOperator, blind_policy_vectors

    operator = BackupOperator(pomdp)
    graph = PlanGraph.of_blind_policies(blind_policy_vectors(pomdp), pomdp.n_observations)
    beliefs = collect_beliefs(pomdp, 40, np.random.default_rng(seed))
    roots = np.arange(len(graph))
    for _ in range(stages):
        vectors, actions, _, children = operator.backup(beliefs, graph.vectors[roots], with_children=True)
        _, first = np.unique(vectors, axis=0, return_index=True)
        roots = graph.add(vectors[first], actions[first], roots[children[first]])
    return graph, roots


@pytest.mark.parametrize("name", ["hallway.POMDP", "4x3.95.POMDP"])
def test_support_pruning_keeps_every_plan_exact(name):
    from embodied_adhoc.decision.plan_graph import observation_supports

    pomdp = _model(name)
    graph, roots = _solved_graph(pomdp, stages=6, seed=4)
    root_vectors = graph.vectors[roots].copy()
    before = len(graph.closure(roots))
    new_roots = graph.prune_dominated(roots, observation_supports(pomdp.observations))
    assert np.array_equal(graph.vectors[new_roots], root_vectors)
    assert np.array_equal(graph.closure(new_roots), np.arange(len(graph)))
    assert len(graph) < before  # the model's observations let some continuation go
    # every kept row is still at most its plan's backup through the kept graph: the value of an executable plan
    backups = _plan_backups(pomdp, graph.vectors, graph.actions, graph.children)
    scale = float(np.abs(graph.vectors).max())
    assert np.all(graph.vectors <= backups + 1e-9 * scale)


def test_a_continuation_is_replaced_where_its_observation_can_happen_only():
    # two states; after action 0, observation 0 comes from state 0 only, observation 1 from state 1 only
    from embodied_adhoc.decision.plan_graph import observation_supports

    supports = observation_supports((sp_identity(2),))
    assert sorted(states.tolist() for states, _ in supports) == [[0], [1]]
    graph = PlanGraph.of_blind_policies(np.array([[-5.0, -5.0]]), n_observations=2)
    graph.add(np.array([[0.0, 3.0], [2.0, 0.0]]), [0, 0], np.array([[0, 0], [0, 0]]))  # rows 1, 2 (2 a root)
    graph.add(np.array([[1.0, 1.0]]), [0], np.array([[1, 1]]))  # row 3 (root) continues with row 1 twice
    roots = graph.prune_dominated(np.array([2, 3]), supports)
    # after z = 0 (state 0) root [2, 0] beats row 1's [0, 3]; after z = 1 (state 1) nothing beats its 3
    kids = graph.children[roots[1]]
    assert graph.vectors[kids[0]].tolist() == [2.0, 0.0] and graph.vectors[kids[1]].tolist() == [0.0, 3.0]


def sp_identity(n: int):
    import scipy.sparse as sp

    return sp.identity(n, format="csr")
