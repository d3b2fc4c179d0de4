"""Belief collection (decision/beliefs.py): sparse rows built as the beliefs come, the same beliefs as a plain
dense collection, and why a solve stopped (SolverStats.stopped)."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
import scipy.sparse as sp

from embodied_adhoc import paths
from embodied_adhoc.decision.beliefs import collect_belief_rows, collect_beliefs, digest
from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.perseus import PerseusConfig, perseus
from embodied_adhoc.decision.policy import AlphaVectorPolicy
from embodied_adhoc.decision.pomdp_io import read_pomdp


def _tiger() -> POMDP:
    return read_pomdp(paths.asset("data/tiger.95.POMDP"))


def _random_pomdp(n_states: int = 40, n_actions: int = 3, n_obs: int = 5, seed: int = 3) -> POMDP:
    """Sparse transitions and observations, so that beliefs have zeros the rows must leave out."""
    rng = np.random.default_rng(seed)
    transitions, observations = [], []
    for _ in range(n_actions):
        matrix = rng.random((n_states, n_states)) * (rng.random((n_states, n_states)) < 0.1)
        matrix[np.arange(n_states), rng.integers(n_states, size=n_states)] += 0.5
        transitions.append(matrix / matrix.sum(axis=1, keepdims=True))
        seen = rng.random((n_states, n_obs)) * (rng.random((n_states, n_obs)) < 0.5)
        seen[np.arange(n_states), rng.integers(n_obs, size=n_states)] += 0.5
        observations.append(seen / seen.sum(axis=1, keepdims=True))
    b0 = np.zeros(n_states)
    b0[:3] = 1.0 / 3.0
    rewards = rng.normal(size=(n_states, n_actions))
    return POMDP(transitions, rewards, 0.9, observations=observations, initial_belief=b0)


# (model, greedy) -> sha256 of the dense beliefs that the dense collection (before the rows were built as the
# beliefs came) gave for these settings: the rows must hold the same beliefs bit for bit.
DENSE_COLLECTION = {
    ("tiger", False): "9f8266c07a761b959451525ecd9b499f8ab43dcb6262fd296a4f41165934fbda",
    ("tiger", True): "e64f8f65262ab66f0874a5226947df308ede0efe4946930847a96e796ed6f4fb",
    ("random", False): "0e8bb4f43988afd85c65f679fc069e0f8b96ec11c854e134521fc8e97bd40310",
    ("random", True): "a72682c7fc7f3bb80b54dabaccf68973b37d52cc642f096d63039141c9b0ee4c",
}


@pytest.mark.parametrize("greedy", [False, True])
@pytest.mark.parametrize("model", ["tiger", "random"])
def test_rows_are_the_dense_collection_bit_for_bit(model, greedy):
    pomdp = _tiger() if model == "tiger" else _random_pomdp()
    greedy_q = np.random.default_rng(1).normal(size=(pomdp.n_states, pomdp.n_actions)) if greedy else None
    reference = collect_beliefs(
        pomdp, 200, np.random.default_rng(5), greedy_q=greedy_q, epsilon=0.5, max_depth=20
    )
    assert hashlib.sha256(reference.tobytes()).hexdigest() == DENSE_COLLECTION[model, greedy]
    rows, digests = collect_belief_rows(
        pomdp, 200, np.random.default_rng(5), greedy_q=greedy_q, epsilon=0.5, max_depth=20
    )
    expected = sp.csr_matrix(reference)
    assert rows.shape == expected.shape
    for name in ("data", "indices", "indptr"):
        built, wanted = getattr(rows, name), getattr(expected, name)
        assert built.dtype == wanted.dtype
        assert np.array_equal(built, wanted)
    assert digests == [digest(row) for row in reference]
    assert len(set(digests)) == len(digests)


def test_random_model_rows_leave_zeros_out():
    rows, _ = collect_belief_rows(_random_pomdp(), 100, np.random.default_rng(0))
    assert rows.shape[0] > 10
    assert rows.nnz < rows.shape[0] * rows.shape[1]
    assert np.all(rows.data != 0.0)
    assert np.allclose(np.asarray(rows.sum(axis=1)).ravel(), 1.0)


def test_digest_is_the_equality_to_1e_9():
    belief = np.array([0.25, 0.75])
    assert digest(belief) == digest(belief + np.array([1e-12, -1e-12]))
    assert digest(belief) != digest(np.array([0.25 + 1e-6, 0.75 - 1e-6]))
    assert len(digest(belief)) == 16


def test_stopped_says_why_perseus_ended(tmp_path):
    tiger = _tiger()
    cut = perseus(tiger, PerseusConfig(n_beliefs=50, expand=True, max_iterations=2, seed=0))
    assert cut.stats.stopped == "iteration-limit"
    fixed = perseus(tiger, PerseusConfig(n_beliefs=50, expand=False, seed=0))
    assert fixed.stats.stopped in {"beliefs-converged", "converged"}
    assert fixed.stats.stopped == ("converged" if fixed.stats.converged else "beliefs-converged")
    finite = perseus(tiger, PerseusConfig(n_beliefs=20, horizon=3, seed=0))
    assert finite.stats.stopped == "horizon"
    loaded = AlphaVectorPolicy.load(cut.save(tmp_path / "cut.npz"))
    assert loaded.stats.stopped == "iteration-limit"


def test_time_limit_stop_is_named(monkeypatch):
    import embodied_adhoc.decision.perseus as perseus_module

    readings = iter(range(1_000_000))  # a clock that advances one second per reading
    monkeypatch.setitem(perseus_module.CLOCKS, "cpu", lambda: float(next(readings)))
    config = PerseusConfig(n_beliefs=50, expand=True, seed=0, time_limit=5.0, clock="cpu")
    assert perseus(_tiger(), config).stats.stopped == "time-limit"
