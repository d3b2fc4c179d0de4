"""Chapter-5 abandoned power plant: one state space per task (105 / 97), hand-checked moves and answers."""

from __future__ import annotations

import numpy as np
import pytest

from embodied_adhoc.domains.chapter5 import build_library
from embodied_adhoc.domains.chapter5.power_plant import LOCATE_HUMAN, STAY


@pytest.fixture(scope="module")
def library():
    return build_library("power-plant")


def test_sizes_follow_table_5_2(library):
    explore, clean = library.native_pomdps
    assert (explore.n_states, clean.n_states) == (105, 97)
    assert (library.n_actions, library.n_observations, library.n_models) == (6, 6, 2)
    assert not library.shares_states
    for pomdp in library.native_pomdps + library.pomdps:
        for a in range(6):
            np.testing.assert_allclose(pomdp.transitions[a].sum(axis=1), 1.0, atol=1e-9)
            np.testing.assert_allclose(pomdp.observations[a].sum(axis=1), 1.0, atol=1e-9)
    # padding: the clean model's extra states are unreachable
    padded = library.pomdps[1]
    assert padded.n_states == 105 and padded.initial_belief[97:].sum() == 0.0
    assert padded.transitions[0][:97, 97:].nnz == 0


def test_hand_checked_move_and_query(library):
    explore = library.native_pomdps[0]
    names = explore.state_names
    start = names.index("r0h0-100")  # both at the door (room 0 explored)
    assert explore.initial_belief[start] == 1.0
    # robot "move to neighbour 1" from the door: the open space (room 1, explorable) w.p. 0.8
    row = library.mmdps[0].transitions[0 * 4 + STAY][start]
    assert row[0, names.index("r1h0-110")] == pytest.approx(0.8)
    assert row[0, start] == pytest.approx(0.2)
    # asking where the human is: the right room w.p. 0.8, each other answer w.p. 0.04
    observation = explore.observations[LOCATE_HUMAN][names.index("r1h0-110")].toarray().ravel()
    np.testing.assert_allclose(observation, [0.04, 0.8, 0.04, 0.04, 0.04, 0.04])
    # after a move the robot reads its own room or nothing
    observation = explore.observations[0][names.index("r1h0-110")].toarray().ravel()
    np.testing.assert_allclose(observation, [0.2, 0.0, 0.8, 0.0, 0.0, 0.0])


def test_clean_needs_both_agents(library):
    clean = library.native_pomdps[1]
    names = clean.state_names
    assert "r2h2-00" not in names and "r2h2-10" in names
    x = names.index("r1h2-00")  # the human waits in dirty room 2; the robot moves in (neighbour 2 of node 1)
    row = library.mmdps[1].transitions[1 * 4 + STAY][x]
    assert row[0, names.index("r2h2-10")] == pytest.approx(0.8)
