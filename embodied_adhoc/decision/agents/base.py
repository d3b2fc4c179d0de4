"""The agent interface shared by every domain, backend and the trial runner.

An ad hoc agent sees only its own actions and observations (flat observation indices of its POMDP library).
It never sees the state, the task or the teammates' actions. Baselines that are *defined* by privileged access
(the full-observability oracle, BOPA which assumes the state is observed) declare ``observes_state = True``;
the runner then passes them ``state=`` (the true state index) and nothing else from ground truth. An agent that
is given the true task (``known-task``) receives it at construction, never through ``observe``.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Agent(Protocol):
    name: str
    observes_state: bool

    def reset(self, rng: np.random.Generator, state: int | None = None) -> None:
        """Start an episode. ``state`` is given only to agents with ``observes_state``."""

    def act(self) -> int:
        """The next action index (deterministic given the history and the reset rng)."""

    def observe(self, action: int, observation: int, state: int | None = None) -> None:
        """Incorporate the outcome of ``action``: the observation index (and the new state if ``observes_state``)."""

    @property
    def task_posterior(self) -> np.ndarray | None:
        """The current distribution over the task library, or None for agents that keep none."""
