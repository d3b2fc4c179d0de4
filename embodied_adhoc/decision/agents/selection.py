"""Action selection shared by the agents: argmax with seeded tie-breaking, or a draw from a distribution."""

from __future__ import annotations

import numpy as np

__all__ = ["draw_action", "pick_best"]


def pick_best(values: np.ndarray, rng: np.random.Generator) -> int:
    """Argmax with ties (to 1e-9 relative) broken uniformly with ``rng``."""
    best = values.max()
    ties = np.flatnonzero(values >= best - 1e-9 * max(1.0, abs(best)))
    return int(ties[0]) if ties.size == 1 else int(rng.choice(ties))


def draw_action(distribution: np.ndarray, rng: np.random.Generator, greedy: bool) -> int:
    """Sample an action from ``distribution`` (its argmax with ``greedy``), using ``rng``."""
    if greedy:
        return pick_best(distribution, rng)
    return int(rng.choice(len(distribution), p=distribution / distribution.sum()))
