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

from embodied_adhoc.decision.upper_bound import SawtoothBound


def sample_path(
    upper: SawtoothBound,
    lower: Callable[[np.ndarray], np.ndarray],
    start: np.ndarray,
    precision: float,
    max_depth: int,
) -> list[np.ndarray]:
    """Beliefs of one excess-gap path from ``start``, at most ``max_depth`` of them (the upper bound is updated
    along it); ``lower`` maps beliefs (n, S) to the lower bound's values."""
    gamma = upper.pomdp.discount
    belief, path = start, []
    for depth in range(max_depth):
        successors = upper.successors(belief)
        q_upper = upper.q_values(belief, successors)
        gap = min(float(upper.values(belief)[0]), float(q_upper.max())) - float(lower(belief[None, :])[0])
        if gap <= precision / gamma**depth:
            break
        path.append((belief, successors))
        _, probabilities, posteriors = successors[int(np.argmax(q_upper))]
        if not len(probabilities):
            break
        excess = probabilities * (
            upper.values(posteriors) - lower(posteriors) - precision / gamma ** (depth + 1)
        )
        belief = posteriors[int(np.argmax(excess))]
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
