"""The Fig. 7.12 ablation: the original experiment's model emulated, differing from ours only in its torus wrap."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from embodied_adhoc.domains.chapter5.pursuit import build_pursuit, wrap_offsets
from embodied_adhoc.envs.pursuit_pomdp import pursuit_pair_library
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.domains.pursuit_pairs_ablation import (
    ablation_steps,
    original_library,
    with_locate,
)


def test_original_wrap_brings_far_offsets_one_cell_too_close():
    d = np.arange(-5, 6)
    assert wrap_offsets(d, 5, "modular").tolist() == [0, 1, 2, -2, -1, 0, 1, 2, -2, -1, 0]
    # the original's toroidal_check: +3 -> -1 and +4 -> -2 (should be -2 and -1), -3 -> 1, -4 -> 2
    assert wrap_offsets(d, 5, "original").tolist() == [0, 2, 1, -2, -1, 0, 1, 2, -1, -2, 0]
    with pytest.raises(ConfigError, match="wrap='sideways'"):
        wrap_offsets(d, 5, "sideways")


def test_original_library_with_the_modular_wrap_is_the_library_it_was_given():
    """``original_library`` rebuilds the library with its own settings (here a non-default noise and horizon): with the
    correct wrap, every transition, observation, reward and start distribution comes back exactly."""
    library = build_pursuit("pursuit-task", noise=0.1, horizon=40)
    rebuilt = original_library(library, "modular")
    assert (rebuilt.domain, rebuilt.noise, rebuilt.horizon) == ("pursuit-task-modular-wrap", 0.1, 40)
    for ours, emulated in zip(library.pomdps, rebuilt.pomdps, strict=True):
        for a in range(ours.n_actions):
            assert abs(ours.transitions[a] - emulated.transitions[a]).max() == 0.0
            assert abs(ours.observations[a] - emulated.observations[a]).max() == 0.0
        np.testing.assert_array_equal(ours.rewards, emulated.rewards)
        np.testing.assert_array_equal(ours.initial_belief, emulated.initial_belief)
    with pytest.raises(ConfigError, match="not a whole pursuit library"):
        original_library(library.subset([0, 1]), "original")


def test_original_wrap_library_is_the_deleted_emulation_bit_for_bit():
    """The original-wrap models equal, bit for bit, those of the original generator's separate emulation that this
    module had until the wrap became ``build_pursuit``'s switch: SHA-256 (first 16 hex digits) of each task's dense
    transition matrices, rewards and initial belief, recorded from that emulation before it was deleted."""
    emulation = ["e247eeef38d6e343", "fcaa859a5a6e0ad9", "afddac902508066e", "2be829a42dd93773"]
    digests = []
    for pomdp in original_library(pursuit_pair_library(), "original").pomdps:
        digest = hashlib.sha256()
        for matrix in pomdp.transitions:
            digest.update(matrix.toarray().tobytes())
        digest.update(np.ascontiguousarray(pomdp.rewards).tobytes())
        digest.update(pomdp.initial_belief.tobytes())
        digests.append(digest.hexdigest()[:16])
    assert digests == emulation


def test_original_wrap_adds_false_captures_and_keeps_stochastic_rows():
    library = pursuit_pair_library()
    original = original_library(library, "original", n_tasks=2)
    assert original.task_names == library.task_names[:2] and original.n_models == 2
    for pomdp, goals in zip(original_library(library, "original").pomdps, (4, 4, 8, 8), strict=True):
        assert int((pomdp.rewards[:, 0] > 0).sum()) == goals  # ours: 2 per task
        for matrix in pomdp.transitions:
            np.testing.assert_allclose(np.asarray(matrix.sum(axis=1)).ravel(), 1.0)
    with pytest.raises(ConfigError, match="n_tasks=5"):
        original_library(library, "original", n_tasks=5)


def test_ablation_steps_are_seeded_and_count_the_capture_reward_step():
    library = original_library(pursuit_pair_library(), "original", n_tasks=2)
    first = ablation_steps(library, ("oracle", "known-task"), episodes=4, seed=3)
    again = ablation_steps(library, ("oracle", "known-task"), episodes=4, seed=3)
    for agent in first:
        np.testing.assert_array_equal(first[agent], again[agent])
        assert first[agent].min() >= 2  # one move into the capture state, one step taken from it
    with pytest.raises(ConfigError, match="atpo"):
        ablation_steps(library, ("atpo",), episodes=1)


def test_locate_reads_the_teammate_direction_at_any_distance():
    library = pursuit_pair_library()
    located = with_locate(library)
    pomdp = located.pomdps[0]
    assert pomdp.n_actions == 6 and pomdp.action_names[-1] == "locate"
    assert abs(pomdp.transitions[5] - pomdp.transitions[4]).max() == 0.0
    np.testing.assert_allclose(np.asarray(pomdp.observations[5].sum(axis=1)).ravel(), 1.0)
    # teammate two rows up and two columns right (out of view), prey far: read as "up-right" w.p. 1 - eps
    state = ((-2 + 2) * 5 + (2 + 2)) * 25 + (2 + 2) * 5 + (2 + 2)
    row = pomdp.observations[5].getrow(state).toarray().ravel()
    assert row[9 * 2 + 4] == pytest.approx(1.0 - library.noise) and row[9 * 4 + 4] == pytest.approx(
        library.noise
    )
    assert pomdp.observations[0].getrow(state).toarray().ravel()[9 * 4 + 4] == pytest.approx(1.0)  # unseen


def test_thesis_numbers_convert_to_our_step_count():
    from embodied_adhoc.experiments.domains.pursuit_pairs import (
        THESIS_FIG_7_12,
        THESIS_TRIALS,
        thesis_in_our_count,
    )

    assert thesis_in_our_count("oracle") == pytest.approx(THESIS_FIG_7_12["oracle"][0] - 1.0)
    # random: 9 of the 32 trials hit the cap and count the same either way
    assert thesis_in_our_count("random") == pytest.approx(76.06 - 23 / THESIS_TRIALS)
