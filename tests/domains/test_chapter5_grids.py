"""Chapter-5 gridworld, pursuit and Panic Buttons libraries: Table 5.2 sizes, hand-checked rules."""

from __future__ import annotations

import numpy as np
import pytest

from embodied_adhoc.domains.chapter5 import build_library
from embodied_adhoc.domains.chapter5.panic_buttons import build_panic_buttons
from embodied_adhoc.domains.chapter5.pursuit import _first_step, build_pursuit


def _assert_stochastic(library):
    for pomdp in library.pomdps:
        for a in range(pomdp.n_actions):
            np.testing.assert_allclose(pomdp.transitions[a].sum(axis=1), 1.0, atol=1e-9)
            np.testing.assert_allclose(pomdp.observations[a].sum(axis=1), 1.0, atol=1e-9)


def test_gridworld_size_rules_and_sensors():
    library = build_library("gridworld")
    assert (library.n_states, library.n_actions, library.n_observations, library.n_models) == (626, 5, 81, 4)
    _assert_stochastic(library)
    names = library.state_names
    mmdp = library.mmdps[0]
    x = names.index("ar2c2-tr4c4")
    # the agent moves up (succeeds w.p. 0.8), the teammate stays
    row = mmdp.transitions[0 * 5 + 4][x]
    assert row[0, names.index("ar1c2-tr4c4")] == pytest.approx(0.8)
    assert row[0, x] == pytest.approx(0.2)
    # both move: independent successes
    row = mmdp.transitions[0 * 5 + 2][x]
    assert row[0, names.index("ar1c2-tr4c3")] == pytest.approx(0.64)
    assert row[0, names.index("ar2c2-tr4c4")] == pytest.approx(0.04)
    # sensors in the top-left corner with the teammate on the right: wall, nothing, wall, teammate
    corner = names.index("ar0c0-tr0c1")
    z = 27 * 1 + 9 * 0 + 3 * 1 + 2
    assert library.pomdps[0].observations[0][corner, z] == pytest.approx(0.8**3)
    # a shared cell is not "adjacent": every sensor reads the walls only
    shared = names.index("ar2c2-tr2c2")
    assert library.pomdps[0].observations[0][shared, 0] == 1.0


def test_gridworld_task_draw_is_seeded():
    first = build_library("gridworld", n_models=8, task_seed=3).task_names
    assert first == build_library("gridworld", n_models=8, task_seed=3).task_names
    assert first != build_library("gridworld", n_models=8, task_seed=4).task_names
    assert len(set(first)) == 8


@pytest.mark.parametrize(
    "variant, models, noise",
    [("pursuit-task", 4, 0.2), ("pursuit-teammate", 2, 0.15), ("pursuit-both", 8, 0.15)],
)
def test_pursuit_sizes_follow_table_5_2(variant, models, noise):
    library = build_pursuit(variant)
    assert (library.n_states, library.n_actions, library.n_observations, library.n_models) == (
        626,
        5,
        81,
        models,
    )
    assert library.noise == noise
    _assert_stochastic(library)


def test_pursuit_capture_prey_moves_and_observation():
    library = build_pursuit("pursuit-task")
    names, pomdp = library.state_names, library.pomdps[0]  # task N+S
    # agent north of the prey (prey one row below), teammate south of it (two rows below): captured
    captured = names.index("t2_0-p1_0")
    assert pomdp.rewards[captured, 4] == 100.0
    assert pomdp.transitions[4][captured, library.absorbing_state] == 1.0
    # the prey moves uniformly: with agent and teammate staying, five successors of 1/5
    x = names.index("t0_2--p-2_0".replace("--", "-"))
    row = library.mmdps[0].transitions[4 * 5 + 4][x]
    assert sorted(np.round(row.data, 6)) == [0.2] * 5
    # teammate right of the agent, prey down-right: cells 5 and 8 seen w.p. 0.8 each
    seen = names.index("t0_1-p1_1")
    observations = pomdp.observations[0]
    assert observations[seen, 9 * 5 + 8] == pytest.approx(0.64)
    assert observations[seen, 9 * 4 + 8] == pytest.approx(0.16)
    assert observations[seen, 9 * 4 + 4] == pytest.approx(0.04)


def test_aware_teammate_walks_around_the_agent():
    # from (0, 0) to (0, -2) with the agent at (0, -1): the greedy teammate would step left into the agent,
    # the aware one goes right around the torus (3 steps) instead
    assert _first_step((0, -1), (0, -2), 5) == 3
    assert _first_step((2, 2), (0, -2), 5) == 2
    assert _first_step((0, -1), (0, -1), 5) is None
    library = build_pursuit("pursuit-teammate")
    greedy, aware = library.pomdps
    assert any((greedy.transitions[a] != aware.transitions[a]).nnz for a in range(5))


def test_pursuit_original_wrap_brings_edge_crossings_one_cell_too_close():
    """``wrap="original"``: the original generator's torus, in every offset sum (moves, capture test, teammates)."""
    from embodied_adhoc.domains.chapter5.library import reduce_joint
    from embodied_adhoc.errors import ConfigError

    original, modular = build_pursuit("pursuit-task", wrap="original"), build_pursuit("pursuit-task")
    names = original.state_names
    assert names == modular.state_names and original.settings["wrap"] == "original"
    # teammate two columns right, prey two up and two left; the agent steps left, the teammate stays: the teammate's
    # offset +3 becomes -1 (correct: -2), the prey's moving up -3 becomes +1 (correct: +2)
    x = names.index("t0_2-p-2_-2")
    assert original.pomdps[0].rewards[x, 0] < 0  # not a capture state
    left_stay = 2 * 5 + 4
    reached = {
        m: sorted(names[j] for j in library.mmdps[0].transitions[left_stay][x].indices)
        for m, library in (("original", original), ("modular", modular))
    }
    assert reached["original"] == [
        "t0_-1-p-1_-1",
        "t0_-1-p-2_-1",
        "t0_-1-p-2_-2",
        "t0_-1-p-2_0",
        "t0_-1-p1_-1",
    ]
    assert reached["modular"] == [
        "t0_-2-p-1_-1",
        "t0_-2-p-2_-1",
        "t0_-2-p-2_-2",
        "t0_-2-p-2_0",
        "t0_-2-p2_-1",
    ]
    # one mechanism: the world's transitions are its own MMDP with its own greedy teammate averaged out
    for m, pomdp in enumerate(original.pomdps):
        mmdp = original.mmdps[m]
        joint = [[mmdp.transitions[a * 5 + b] for b in range(5)] for a in range(5)]
        for ours, reduced in zip(
            pomdp.transitions, reduce_joint(joint, original.teammates["greedy"](m)), strict=True
        ):
            assert abs(ours - reduced).max() == 0.0
    with pytest.raises(ConfigError, match="wrap='sideways'"):
        build_pursuit("pursuit-task", wrap="sideways")
    with pytest.raises(ConfigError, match="odd size"):
        build_pursuit("pursuit-task", size=4, wrap="original")


@pytest.mark.parametrize("size, states", [(3, 82), (4, 257), (5, 626)])
def test_panic_buttons_sizes(size, states):
    library = build_panic_buttons(size, "optimal")
    assert (library.n_states, library.n_models, library.n_observations) == (states, 3, states)
    _assert_stochastic(library)


def test_panic_buttons_suboptimal_teammate_stays_three_times_in_ten():
    optimal = build_panic_buttons(3, "optimal")
    suboptimal = build_panic_buttons(3, "suboptimal")
    names = optimal.state_names
    x = names.index("ar1c1-tr2c2")  # far from pressing: the optimal teammate moves
    stay = 4
    optimal_row = optimal.pomdps[0].transitions[stay][x].toarray().ravel()
    suboptimal_row = suboptimal.pomdps[0].transitions[stay][x].toarray().ravel()
    assert optimal_row[x] == 0.0
    assert suboptimal_row[x] == pytest.approx(0.3)
    np.testing.assert_allclose(suboptimal_row, 0.7 * optimal_row + 0.3 * np.eye(len(names))[x])


def test_gridworld_libraries_are_nested():
    small = build_library("gridworld", n_models=2).task_names
    large = build_library("gridworld", n_models=32).task_names
    assert large[:2] == small and len(set(large)) == 32
