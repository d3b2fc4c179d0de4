"""BOPA (thesis section 5.1): Bayesian online prediction for ad hoc teamwork with the state observed.

Library: MDPs sharing S and A (each a task/teammate MMDP reduced by the teammate's policy), solved by value
iteration for ``pi_m`` (uniform over the optimal actions of ``Q*_m``).

* Eq. 5.1: the model posterior ``p_{t+1}(m) = P_m(x_{t+1} | x_t, a_t) p_t(m) / rho`` from observed transitions.
* Eq. 5.2: the action distribution ``pi_t(a | x) = sum_m pi_m(a | x) p_t(m)``; the agent samples from it
  (``greedy=True``: takes its argmax instead).

A transition impossible under every model with positive probability leaves the posterior unchanged and is
counted in ``impossible_transitions``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from embodied_adhoc.decision.agents.base import AgentBase
from embodied_adhoc.decision.agents.selection import draw_action
from embodied_adhoc.decision.agents.task_beliefs import check_library
from embodied_adhoc.decision.models import MDP
from embodied_adhoc.decision.products import dot
from embodied_adhoc.errors import ConfigError, ModelError

__all__ = ["BopaAgent", "optimal_policies"]


def optimal_policies(q_values: np.ndarray, tolerance: float = 1e-9) -> np.ndarray:
    """``pi_m(a | x)`` uniform over ``argmax_a Q*_m(x, a)`` (ties within ``tolerance`` relative); (M, S, A)."""
    best = q_values.max(axis=-1, keepdims=True)
    optimal = q_values >= best - tolerance * np.maximum(1.0, np.abs(best))
    return optimal / optimal.sum(axis=-1, keepdims=True)


class BopaAgent(AgentBase):
    """BOPA over a library of MDPs with Q* tables ``q_values`` (M, S, A); observes the state."""

    observes_state = True

    def __init__(
        self,
        mdps: Sequence[MDP],
        q_values: np.ndarray,
        prior: np.ndarray | None = None,
        greedy: bool = False,
        name: str = "bopa",
    ) -> None:
        check_library(mdps)
        self.mdps = tuple(mdps)
        self.policies = optimal_policies(np.asarray(q_values))
        if self.policies.shape != (len(mdps), mdps[0].n_states, mdps[0].n_actions):
            raise ModelError(f"q_values has shape {np.shape(q_values)}, expected (M, S, A) for this library")
        m = len(mdps)
        self.prior = np.full(m, 1.0 / m) if prior is None else np.asarray(prior, dtype=np.float64)
        self.greedy, self.name = greedy, name
        self.rng = np.random.default_rng(0)
        self.state: int | None = None
        self.posterior = self.prior.copy()
        self.impossible_transitions = 0

    def reset(self, rng: np.random.Generator, state: int | None = None) -> None:
        if state is None:
            raise ConfigError(
                f"agent '{self.name}' observes the state: the runner must pass state= to reset()"
            )
        self.rng, self.state = rng, int(state)
        self.posterior = self.prior.copy()
        self.impossible_transitions = 0

    def action_distribution(self) -> np.ndarray:
        """Eq. 5.2 at the current state."""
        return dot(
            self.posterior, self.policies[:, self.state, :]
        )  # fixed summation order: ties decided alike on any host

    def act(self) -> int:
        return draw_action(self.action_distribution(), self.rng, self.greedy)

    def observe(self, action: int, observation: int, state: int | None = None) -> None:
        """Eq. 5.1 on the observed transition ``(x_t, a_t, x_{t+1})``."""
        if state is None:
            raise ConfigError(
                f"agent '{self.name}' observes the state: the runner must pass state= to observe()"
            )
        likelihoods = np.array([mdp.transitions[action][self.state, int(state)] for mdp in self.mdps])
        weighted = likelihoods * self.posterior
        if weighted.sum() > 0.0:
            self.posterior = weighted / weighted.sum()
        else:
            self.impossible_transitions += 1
        self.state = int(state)

    @property
    def task_posterior(self) -> np.ndarray:
        return self.posterior.copy()
