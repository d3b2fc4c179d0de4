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
