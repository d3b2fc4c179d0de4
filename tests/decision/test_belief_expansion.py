"""Excess-gap paths stop on the stored gap (not on a backed-up one), and sample_path tightens the bound along them."""

from __future__ import annotations

import numpy as np

from embodied_adhoc.decision.backup import blind_policy_vectors
from embodied_adhoc.decision.belief_expansion import excess_gap_path, sample_path
from embodied_adhoc.decision.products import dot
from embodied_adhoc.decision.rocksample import rocksample
from embodied_adhoc.decision.upper_bound import SawtoothBound, fast_informed_bound


def _setup():
    pomdp = rocksample(3, 2, seed=2)
    alphas = blind_policy_vectors(pomdp)
    return pomdp, SawtoothBound(pomdp, fast_informed_bound(pomdp)), lambda b: dot(b, alphas.T).max(axis=1)


def test_a_path_runs_while_the_stored_gap_exceeds_its_target():
    pomdp, upper, lower = _setup()
    gamma, precision, depth = pomdp.discount, 0.5, 30
    path = excess_gap_path(upper, lower, pomdp.initial_belief, precision, depth)
    assert 0 < len(path) <= depth
    for step, (belief, successors) in enumerate(path):
        gap = upper.values(belief)[0] - lower(belief[None, :])[0]
        assert gap > precision / gamma**step
        assert np.allclose(successors.posteriors.sum(axis=1), 1.0)
    if len(path) < depth:  # it stopped: the next belief down the path is within its target
        belief, successors = path[-1]
        action = int(np.argmax(upper.q_values(belief, successors)))
        _, probabilities, posteriors = successors[action]
        target = precision / gamma ** (len(path) - 1 + 1)
        excess = probabilities * (upper.values(posteriors) - lower(posteriors) - target)
        chosen = posteriors[int(np.argmax(excess))]
        assert upper.values(chosen)[0] - lower(chosen[None, :])[0] <= precision / gamma ** len(path)


def test_sample_path_lowers_the_upper_bound_and_never_raises_it():
    pomdp, upper, lower = _setup()
    b0 = pomdp.initial_belief
    values = [upper.values(b0)[0]]
    for _ in range(5):
        sample_path(upper, lower, b0, 0.5, 30)
        values.append(upper.values(b0)[0])
    assert np.all(np.diff(values) <= 0.0) and values[-1] < values[0]
    assert upper.n_points > 0
