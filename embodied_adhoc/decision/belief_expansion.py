"""Anytime belief expansion: sample the beliefs where the bounds at b0 are still loose (HSVI/SARSOP-style).

One path from ``b0``: at each belief take the action greedy on the upper bound, then the observation of largest
weighted excess gap ``P(z | b, a) (U(b_az) - L(b_az) - precision / gamma^(t+1))`` (Smith & Simmons 2004), until
the gap at the belief is within ``precision / gamma^t``. Those are the beliefs the optimal policy may reach and
the bounds disagree on: the upper bound is backed up along the path (deepest first), and the beliefs join
Perseus' belief set. Deterministic (no random draw), so the solve stays seeded by its belief collection alone.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from embodied_adhoc.decision.upper_bound import SawtoothBound, Successors


def excess_gap_path(
    upper: SawtoothBound,
    lower: Callable[[np.ndarray], np.ndarray],
    start: np.ndarray,
    precision: float,
    max_depth: int,
) -> list[tuple[np.ndarray, Successors]]:
    """The beliefs of one excess-gap path from ``start`` with their successors, at most ``max_depth`` of them;
    neither bound is changed. ``lower`` maps beliefs (n, S) to the lower bound's values.

    A path stops where the stored gap ``U(b) - L(b)`` is within ``precision / gamma^t``, not where
    ``min(U(b), max_a Q_U(b, a)) - L(b)`` is: a belief whose backup alone would close its gap must still be
    updated, or its parents keep reading its stale ``U(b)`` and the paths stall short of b0's target."""
    gamma = upper.pomdp.discount
    belief, path = start, []
    # The bounds at the current belief: computed at the start, then read off the previous step's successors (a
    # row's value does not depend on the rows beside it, and neither bound changes along the path).
    here = float(upper.values(belief)[0]), float(lower(belief[None, :])[0])
    for depth in range(max_depth):
        if here[0] - here[1] <= precision / gamma**depth:
            break
        successors = upper.successors(belief)
        q_upper, upper_values = upper.q_values_and_successor_values(belief, successors)
        path.append((belief, successors))
        action = int(np.argmax(q_upper))
        _, probabilities, posteriors = successors[action]
        if not len(probabilities):
            break
        target = precision / gamma ** (depth + 1)
        upper_next = upper_values[successors.bounds[action] : successors.bounds[action + 1]]
        lower_next = lower(posteriors)
        choice = int(np.argmax(probabilities * (upper_next - lower_next - target)))
        belief, here = posteriors[choice], (float(upper_next[choice]), float(lower_next[choice]))
    return path


def sample_path(
    upper: SawtoothBound,
    lower: Callable[[np.ndarray], np.ndarray],
    start: np.ndarray,
    precision: float,
    max_depth: int,
) -> list[np.ndarray]:
    """Beliefs of one :func:`excess_gap_path` from ``start``; the upper bound is backed up along it, deepest
    first, so each belief's update reads its child's new value."""
    path = excess_gap_path(upper, lower, start, precision, max_depth)
    for belief, successors in reversed(path):
        upper.update(belief, successors)
    return [belief for belief, _ in path]


def explore(
    upper: SawtoothBound,
    lower: Callable[[np.ndarray], np.ndarray],
    b0: np.ndarray,
    precision: float,
    updates: int,
) -> None:
    """Excess-gap paths from b0, each backing up the upper bound along it, for ``updates`` updates in all (the
    last path is cut to the updates left)."""
    depth = max_depth(upper, lower, b0, precision)
    while updates > 0:
        # Paths aim at half the precision: they stop where the gap is within their target, and the lower bound
        # is not backed up along them, so aiming at the precision itself leaves a gap at b0 just above it.
        path = sample_path(upper, lower, b0, precision / 2, min(depth, updates))
        if not path:
            break  # the gap at b0 is within precision
        updates -= len(path)


def max_depth(
    upper: SawtoothBound, lower: Callable[[np.ndarray], np.ndarray], b0: np.ndarray, precision: float
) -> int:
    """Beyond this depth any gap at b0's scale is within precision / gamma^depth, so paths end there anyway."""
    gamma, scale = upper.pomdp.discount, float(upper.values(b0)[0] - lower(b0[None, :])[0])
    return int(np.clip(np.log(max(precision, 1e-9) / max(scale, 1e-9)) / np.log(gamma), 20, 1000))
