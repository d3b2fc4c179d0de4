"""The sawtooth bound's batched successors and Q-values match the per-action definitions (Eq. 2.3)."""

from __future__ import annotations

import numpy as np

from embodied_adhoc.decision.beliefs import collect_beliefs
from embodied_adhoc.decision.rocksample import rocksample
from embodied_adhoc.decision.upper_bound import SawtoothBound, fast_informed_bound


def test_successors_and_q_values_match_one_belief_update_at_a_time():
    pomdp = rocksample(3, 2, seed=1)
    bound = SawtoothBound(pomdp, fast_informed_bound(pomdp))
    for belief in collect_beliefs(pomdp, 12, np.random.default_rng(0)):
        successors = bound.successors(belief)
        assert len(successors) == pomdp.n_actions
        expected_q = []
        for action in range(pomdp.n_actions):
            observations, probabilities, posteriors = successors[action]
            likelihoods = [pomdp.observation_likelihood(belief, action, z) for z in range(2)]
            assert observations.tolist() == [z for z in range(2) if likelihoods[z] > 0]
            assert np.allclose(probabilities, [likelihoods[z] for z in observations], atol=1e-12)
            for z, posterior in zip(observations, posteriors, strict=True):
                assert np.allclose(posterior, pomdp.belief_update(belief, action, int(z))[0], atol=1e-12)
            future = sum(p * bound.values(b)[0] for p, b in zip(probabilities, posteriors, strict=True))
            expected_q.append(belief @ pomdp.rewards[:, action] + pomdp.discount * future)
        q_values, values = bound.q_values_and_successor_values(belief, successors)
        assert np.allclose(q_values, expected_q, atol=1e-9)
        assert np.array_equal(values, bound.values(successors.posteriors))
        bound.update(belief, successors)  # points accumulate: later beliefs see a sawtooth, not only the FIB
    assert bound.n_points > 0


def test_sawtooth_values_by_blocks_of_points_are_the_whole_table(monkeypatch):
    """The (point, belief) support counts formed a few points at a time give the same values, to the bit, as the
    whole table at once; and each value is the direct formula's: min(FIB, corners + min_i phi_i(b) excess_i)."""
    from embodied_adhoc.decision import upper_bound as upper_bound_module

    pomdp = rocksample(3, 2, seed=1)
    bound = SawtoothBound(pomdp, fast_informed_bound(pomdp))
    beliefs = collect_beliefs(pomdp, 40, np.random.default_rng(0))
    for belief in beliefs:
        bound.update(belief)
    assert bound.n_points > 3
    whole = bound.values(beliefs)
    monkeypatch.setattr(upper_bound_module, "_COVER_BLOCK_ENTRIES", 1)  # one point a block
    assert np.array_equal(bound.values(beliefs), whole)
    monkeypatch.setattr(upper_bound_module, "_COVER_BLOCK_ENTRIES", 3 * len(beliefs))  # three points a block
    assert np.array_equal(bound.values(beliefs), whole)
    starts = np.append(bound._starts, len(bound._support))
    for belief, value in zip(beliefs, whole, strict=True):
        sawtooth = belief @ bound.corners
        for first, last, excess in zip(starts[:-1], starts[1:], bound._excess, strict=True):
            support, masses = bound._support[first:last], bound._masses[first:last]
            if np.all(belief[support] > 0.0):
                sawtooth = min(sawtooth, belief @ bound.corners + np.min(belief[support] / masses) * excess)
        assert np.isclose(value, min((belief @ bound.fib).max(), sawtooth), rtol=0, atol=1e-12)
