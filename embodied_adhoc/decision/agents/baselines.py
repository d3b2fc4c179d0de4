"""Reference agents: ``oracle`` (sees the state, knows the task), ``random``, ``random-picker`` (chapter 5) and
:class:`StatePolicyAgent` (a given policy of the true state, e.g. the team's own policy in the robot's seat).

The third baseline, ``known-task`` (optimal under partial observability), is TEBOPA given the true task: a
:class:`~embodied_adhoc.decision.agents.hotspot.HotspotAgent` whose prior is one-hot on it (see ``factory``).
"""

from __future__ import annotations

import numpy as np

from embodied_adhoc.decision.agents.base import AgentBase
from embodied_adhoc.decision.agents.selection import pick_best
from embodied_adhoc.errors import ConfigError

__all__ = ["OracleAgent", "RandomAgent", "RandomPickerAgent", "StatePolicyAgent"]


class OracleAgent(AgentBase):
    """Greedy on ``Q*`` (value iteration) of the true task's teammate-averaged MDP; observes the state."""

    observes_state = True

    def __init__(self, q_values: np.ndarray, name: str = "oracle") -> None:
        self.q_values = np.asarray(q_values, dtype=np.float64)
        self.name = name
        self.state: int | None = None
        self.rng = np.random.default_rng(0)

    def reset(self, rng: np.random.Generator, state: int | None = None) -> None:
        if state is None:
            raise ConfigError(
                f"agent '{self.name}' observes the state: the runner must pass state= to reset()"
            )
        self.rng, self.state = rng, int(state)

    def act(self) -> int:
        return pick_best(self.q_values[self.state], self.rng)

    def observe(self, action: int, observation: int, state: int | None = None) -> None:
        if state is None:
            raise ConfigError(
                f"agent '{self.name}' observes the state: the runner must pass state= to observe()"
            )
        self.state = int(state)

    @property
    def task_posterior(self) -> None:
        return None


class RandomAgent(AgentBase):
    """Uniformly random actions."""

    observes_state = False

    def __init__(self, n_actions: int, name: str = "random") -> None:
        self.n_actions = int(n_actions)
        self.name = name
        self.rng = np.random.default_rng(0)

    def reset(self, rng: np.random.Generator, state: int | None = None) -> None:
        self.rng = rng

    def act(self) -> int:
        return int(self.rng.integers(self.n_actions))

    def observe(self, action: int, observation: int, state: int | None = None) -> None:
        return None

    @property
    def task_posterior(self) -> None:
        return None


class RandomPickerAgent(AgentBase):
    """ATPO's policies, but the model is picked uniformly at random at each episode start (section 5.2.4)."""

    observes_state = False

    def __init__(self, kernels, policies, name: str = "random-picker") -> None:
        from embodied_adhoc.decision.agents.atpo import AtpoAgent

        self.inner = AtpoAgent(kernels, policies, name=name)
        self.name = name
        self.rng = np.random.default_rng(0)

    def reset(self, rng: np.random.Generator, state: int | None = None) -> None:
        n_models = self.inner.kernels.n_models
        prior = np.zeros(n_models)
        prior[int(rng.integers(n_models))] = 1.0
        self.inner.tracker.prior = prior
        self.inner.reset(rng)
        self.rng = rng

    def act(self) -> int:
        return self.inner.act()

    def observe(self, action: int, observation: int, state: int | None = None) -> None:
        self.inner.observe(action, observation)

    @property
    def task_posterior(self):
        return None  # it keeps no posterior of its own: the picked model is not an inference


class StatePolicyAgent(AgentBase):
    """Acts by ``policy(state, rng) -> action`` on the true state (privileged: ``observes_state``), the state as
    the env's privileged channel gives it. The grid arenas' ``original`` agent is one: the team's own policy in
    the ad hoc robot's seat (thesis section 6.2.4), which knows the task and the team."""

    observes_state = True
    task_posterior = None

    def __init__(self, policy, name: str) -> None:
        self.policy, self.name = policy, name
        self.rng, self.state = np.random.default_rng(0), None

    def reset(self, rng: np.random.Generator, state=None) -> None:
        self.rng, self.state = rng, state

    def act(self) -> int:
        return int(self.policy(self.state, self.rng))

    def observe(self, action: int, observation, state=None) -> None:
        self.state = state
