"""The vectorised point-based backup (decision/backup.py) against a naive per-belief, per-observation loop.

The continuation of each branch is chosen by float32 scores (support-restricted path) or float64 dense scores
(dense observation models); the vectors are built in float64 for the best action only. Each vector must be the
exact value of its plan, and its value at the belief must equal the exact backup's up to float32 near-ties.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from embodied_adhoc import paths
from embodied_adhoc.decision.backup import BackupOperator
from embodied_adhoc.decision.beliefs import collect_beliefs
from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.perseus import PerseusConfig, perseus
from embodied_adhoc.decision.pomdp_io import read_pomdp

CORPUS = Path(__file__).resolve().parents[2] / ".." / "shared" / "pomdp"


def _sparse_identity_pomdp(n_states: int = 60, n_actions: int = 3, seed: int = 4) -> POMDP:
    """Sparse O (the state is observed) with predicted beliefs dense enough that the old code took its sparse
    projection path: the support-restricted scores must cover it."""
    rng = np.random.default_rng(seed)
    transitions = []
    for _ in range(n_actions):
        matrix = rng.random((n_states, n_states)) * (rng.random((n_states, n_states)) < 0.4)
        matrix[np.arange(n_states), rng.integers(n_states, size=n_states)] += 0.3
        transitions.append(matrix / matrix.sum(axis=1, keepdims=True))
    noisy = 0.7 * np.eye(n_states) + 0.3 * np.roll(np.eye(n_states), 1, axis=1)
    return POMDP(
        transitions,
        rng.normal(size=(n_states, n_actions)),
        0.9,
        observations=[noisy] * n_actions,
        initial_belief=np.full(n_states, 1.0 / n_states),
    )


def _model(name: str) -> POMDP:
    if name == "sparse-identity":
        return _sparse_identity_pomdp()
    if name == "tiger.95.POMDP":
        return read_pomdp(paths.asset(f"data/{name}"))
    if not (CORPUS / name).is_file():
        pytest.skip(f"corpus file {CORPUS / name} not present")
    return read_pomdp(CORPUS / name)


def _naive_backup_values(pomdp: POMDP, beliefs: np.ndarray, alphas: np.ndarray) -> np.ndarray:
    """max_a [b . R_a + gamma sum_z max_k (b T_a O_z) . alpha_k], one belief, action and observation at a time."""
    values = []
    for belief in beliefs:
        best = -np.inf
        for action in range(pomdp.n_actions):
            predicted = pomdp.transitions[action].T @ belief
            observation = pomdp.observations[action].toarray()
            future = sum(float((alphas @ (predicted * observation[:, z])).max()) for z in range(pomdp.n_observations))
            best = max(best, float(belief @ pomdp.rewards[:, action]) + pomdp.discount * future)
        values.append(best)
    return np.asarray(values)


@pytest.mark.parametrize("name", ["tiger.95.POMDP", "hallway.POMDP", "sarsop-TagAvoid.pomdp", "sparse-identity"])
def test_backup_equals_the_naive_one_and_each_vector_is_its_plan(name):
    pomdp = _model(name)
    beliefs = collect_beliefs(pomdp, 24, np.random.default_rng(3))
    alphas = perseus(pomdp, PerseusConfig(n_beliefs=60, max_iterations=8, seed=0)).alphas
    vectors, actions, values, children = BackupOperator(pomdp).backup(beliefs, alphas, with_children=True)
    np.testing.assert_allclose(values, np.einsum("is,is->i", beliefs, vectors), rtol=0, atol=1e-9)
    exact = _naive_backup_values(pomdp, beliefs, alphas)
    scale = 1.0 + np.abs(exact)
    assert np.all(values <= exact + 1e-9 * scale)  # a plan's value never exceeds the exact backup
    assert np.all(values >= exact - 1e-5 * scale)  # float32 scores only lose on near-ties
    for vector, action, plan in zip(vectors, actions, children, strict=True):
        observation = pomdp.observations[action].toarray()
        continuation = sum(observation[:, z] * alphas[plan[z]] for z in range(pomdp.n_observations))
        rebuilt = pomdp.rewards[:, action] + pomdp.discount * (pomdp.transitions[action] @ continuation)
        np.testing.assert_allclose(vector, rebuilt, rtol=0, atol=1e-9)
