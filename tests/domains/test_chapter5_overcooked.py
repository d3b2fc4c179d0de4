"""Chapter-5 overcooked library: 1,730 states, hand-checked kitchen rules, the stubborn-cook bug fixed."""

from __future__ import annotations

import numpy as np
import pytest

from embodied_adhoc.domains.chapter5.overcooked import build_overcooked

NOOP, ACT = 2, 3


@pytest.fixture(scope="module")
def library():
    return build_overcooked()


def test_size_follows_table_5_2(library):
    assert (library.n_states, library.n_actions, library.n_observations, library.n_models) == (
        1730,
        4,
        1730,
        4,
    )
    for pomdp in library.pomdps:
        for a in range(4):
            np.testing.assert_allclose(pomdp.transitions[a].sum(axis=1), 1.0, atol=1e-9)
        assert pomdp.observations[0].diagonal().sum() == 1730  # fully observable
    assert library.pomdps[0].initial_belief.max() == pytest.approx(0.25)


def test_hand_checked_kitchen_steps(library):
    names, joint = library.state_names, library.mmdps[0].transitions
    # helper (top, holding an onion) acts: onion onto the empty top counter; the empty-handed cook acting finds
    # the counter empty at the start of the step and takes nothing
    x = names.index("h0c0-h1c0-t0b0-p0")
    assert joint[ACT * 4 + ACT][x, names.index("h0c0-h0c0-t1b0-p0")] == 1.0
    # the cook adds a third onion: the soup cooks
    x = names.index("h0c0-h0c1-t0b0-p2")
    assert joint[NOOP * 4 + ACT][x, names.index("h0c0-h0c0-t0b0-p3")] == 1.0
    # the cook serves the soup with a plate, then delivers it at the bottom: +100 then absorbing
    x = names.index("h0c0-h0c2-t0b0-p3")
    assert joint[NOOP * 4 + ACT][x, names.index("h0c0-h0c3-t0b0-p0")] == 1.0
    x = names.index("h0c1-h0c3-t0b0-p0")
    delivered = names.index("delivered")
    assert joint[NOOP * 4 + ACT][x, delivered] == 1.0
    assert library.pomdps[0].rewards[delivered, 0] == 100.0
    assert library.pomdps[0].transitions[0][delivered, names.index("absorbing")] == 1.0


def _cook_goes_up(library, model):
    """P(cook at the top next) for every state with an empty-handed cook at the bottom, helper noop."""
    names = library.state_names
    # names read "h{helper cell}c{cook cell}-h{helper hand}c{cook hand}-...": cook cell at [3], cook hand at [8]
    rows = [s for s, name in enumerate(names) if name[0] == "h" and name[3] == "1" and name[8] == "0"]
    matrix = library.pomdps[model].transitions[NOOP][rows].toarray()
    top = np.array([name[0] == "h" and name[3] == "0" for name in names])
    return matrix[:, top].sum(axis=1)


def test_stubborn_cook_insists_nine_times_in_ten(library):
    upper = library.task_names.index("upper")
    assert _cook_goes_up(library, upper).min() >= 0.9 - 1e-9


def test_original_frozen_half_coin_is_reproducible():
    buggy = build_overcooked(bug_compatible=True, bug_seed=0)
    upper = buggy.task_names.index("upper")
    insists = _cook_goes_up(buggy, upper) >= 1.0 - 1e-9
    assert 0.3 < insists.mean() < 0.7
    again = build_overcooked(bug_compatible=True, bug_seed=0)
    assert (again.pomdps[upper].transitions[NOOP] != buggy.pomdps[upper].transitions[NOOP]).nnz == 0
