"""The seeded random POMDP of the solver benchmarks (``decision/random_pomdp.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from embodied_adhoc.decision.pomdp_io import read_pomdp, write_pomdp
from embodied_adhoc.decision.qmdp import qmdp
from embodied_adhoc.decision.random_pomdp import DISCOUNT, random_pomdp
from embodied_adhoc.errors import ConfigError


def test_rows_have_the_drawn_support_and_the_model_depends_on_its_seed_only(tmp_path):
    model = random_pomdp(250, 5, 10, seed=0, successors=5, emissions=3)
    assert (model.n_states, model.n_actions, model.n_observations) == (250, 5, 10)
    for transitions, emissions in zip(model.transitions, model.observations, strict=True):
        assert np.all(np.diff(transitions.indptr) == 5) and np.all(np.diff(emissions.indptr) == 3)
        for matrix in (transitions, emissions):  # distinct columns per row, weights a distribution
            rows = matrix.indices.reshape(matrix.shape[0], -1)
            assert np.all(np.diff(rows, axis=1) > 0)
            np.testing.assert_allclose(np.asarray(matrix.sum(axis=1)).ravel(), 1.0)
    assert model.rewards.min() >= 0.0 and model.rewards.max() < 1.0 and model.discount == DISCOUNT
    again, other = random_pomdp(250, 5, 10, seed=0), random_pomdp(250, 5, 10, seed=1)
    assert all((a != b).nnz == 0 for a, b in zip(model.transitions, again.transitions, strict=True))
    assert any((a != b).nnz for a, b in zip(model.transitions, other.transitions, strict=True))
    path = write_pomdp(model, tmp_path / "random.pomdp")
    read = read_pomdp(path)
    assert all(abs(a - b).max() == 0 for a, b in zip(model.transitions, read.transitions, strict=True))
    value = float(qmdp(read).alphas.max(axis=0) @ read.initial_belief)
    assert 0.0 <= value < 1.0 / (1.0 - DISCOUNT)


def test_dense_rows_and_bad_counts():
    dense = random_pomdp(4, 2, 3, seed=0, successors=4, emissions=3)
    assert all(matrix.nnz == 16 for matrix in dense.transitions)
    for counts, said in (
        ((3, 2, 4), "5 successors of 3 states"),
        ((0, 2, 4), "states must be an integer >= 1"),
        ((200_000, 2, 4), "exceed 100,000"),
        ((10, 2, 4, 0, 5, 65), "emissions = 65 exceeds 64"),
    ):
        with pytest.raises(ConfigError, match=said):
            random_pomdp(*counts)
