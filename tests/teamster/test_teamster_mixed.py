"""Section 4.1.5's Mixed team (one teammate-aware, one greedy, one probabilistic-destinations teammate) and the
protocol's Mixed phase (``ProtocolConfig.mixed_steps``, ``teamster --mixed-steps``)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from embodied_adhoc.domains.pursuit4 import TEAMS, ExactTeam, Pursuit4
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.domains.teamster_protocol import (
    MIXED,
    MIXED_SEATS,
    MixedPursuit,
    ProtocolConfig,
    run_trial,
)

torch.set_num_threads(1)


def test_each_mixed_seat_plays_its_own_teams_exact_policy():
    plain, mixed = Pursuit4(), MixedPursuit()
    states = plain.sample_states(np.random.default_rng(0), 64)
    probs = ExactTeam(mixed, MIXED).probs(states)
    assert probs.shape == (64, 3, 5) and np.allclose(probs.sum(-1), 1.0)
    for seat in (1, 2, 3):
        expected = plain.team_policy(MIXED_SEATS[seat], states, agents=(seat,))[:, 0]
        assert np.array_equal(probs[:, seat - 1], expected)
    assert np.array_equal(
        ExactTeam(mixed, MIXED).seat(states), ExactTeam(plain, "teammate-aware").seat(states)
    )
    # the three seats differ from every single team somewhere (it is a new team, not one of the library's)
    for team in TEAMS:
        assert not np.allclose(probs, plain.team_policy(team, states))
    for team in TEAMS:  # the other teams and the rules are pursuit's
        assert np.array_equal(mixed.team_policy(team, states), plain.team_policy(team, states))


def test_the_mixed_phase_follows_the_three_teams_and_is_evaluated_every_chunk():
    config = ProtocolConfig(steps=20, eval_steps=10, points=2, mixed_steps=30, seed=3)
    record = run_trial("plastic-model", 0, config)
    assert list(record["curves"]) == [*TEAMS, MIXED]
    assert [step for step, _ in record["curves"][MIXED]] == [0, 10, 20, 30]
    assert list(record["after"]) == list(TEAMS)
    assert all(list(row) == list(TEAMS) for row in record["after"].values())
    assert record["config"]["mixed_steps"] == 30
    again = run_trial("plastic-model", 0, config)
    again.pop("seconds"), record.pop("seconds")
    assert again == record  # seeded


def test_the_mixed_phase_leaves_the_other_phases_as_they_were():
    """Adding the last phase does not move the draws of the three teams' phases (own streams per phase)."""
    base = ProtocolConfig(steps=20, eval_steps=10, points=2, seed=1)
    with_mixed = ProtocolConfig(steps=20, eval_steps=10, points=2, seed=1, mixed_steps=10)
    a, b = run_trial("learns-team", 0, base), run_trial("learns-team", 0, with_mixed)
    assert a["after"] == b["after"] and all(a["curves"][t] == b["curves"][t] for t in TEAMS)
    assert "mixed_steps" not in base.as_dict()  # folders written without the option still resume


@pytest.mark.parametrize(
    "settings, word",
    [
        ({"mixed_steps": 15}, "multiple"),
        ({"mixed_steps": 20, "changed": "mirror"}, "changed"),
        ({"mixed_steps": 20, "domain": "ntu"}, "pursuit"),
    ],
)
def test_a_mixed_phase_that_cannot_run_is_refused(settings, word):
    with pytest.raises(ConfigError, match=word):
        ProtocolConfig(steps=20, eval_steps=10, points=2, **settings)
