"""ATPO (thesis section 5.2): ad hoc teamwork under partial observability over a library of POMDPs.

Each library POMDP ``m_k`` is solved offline (Perseus, giving an alpha-vector policy ``pi_k``).

* Eq. 5.3 / 5.4: the posterior over models ``p_t(m_k)`` and per-model beliefs ``b_{k,t}``;
* Eq. 5.5 / 5.6: their updates, in :mod:`~embodied_adhoc.decision.agents.task_beliefs` (shared with HOTSPOT);
* the action distribution ``pi_t(a | h_t) = sum_k pi_k(a | b_{k,t}) p_t(m_k)``, sampled (or its argmax with
  ``greedy=True``);
* Eq. 5.7: the loss ``l_t(a | m_k) = v(b_{k,t}) - q(b_{k,t}, a)`` with ``q`` a one-step lookahead on ``v``
  (:meth:`AtpoAgent.losses`, for analysis).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from embodied_adhoc.decision.agents.base import AgentBase
from embodied_adhoc.decision.agents.selection import draw_action
from embodied_adhoc.decision.agents.task_beliefs import LibraryBeliefs, LibraryKernels
from embodied_adhoc.decision.products import dot
from embodied_adhoc.errors import ModelError

__all__ = ["AtpoAgent"]


class AtpoAgent(AgentBase):
    """ATPO over ``kernels`` (the library POMDPs) with one alpha-vector policy per model."""

    observes_state = False

    def __init__(
        self,
        kernels: LibraryKernels,
        policies: Sequence,
        prior: np.ndarray | None = None,
        greedy: bool = False,
        name: str = "atpo",
    ) -> None:
        if len(policies) != kernels.n_models:
            raise ModelError(f"{len(policies)} policies for a library of {kernels.n_models} models")
        self.kernels, self.policies = kernels, tuple(policies)
        self.tracker = LibraryBeliefs(kernels, prior)
        self.greedy, self.name = greedy, name
        self.rng = np.random.default_rng(0)

    def reset(self, rng: np.random.Generator, state: int | None = None) -> None:
        self.rng = rng
        self.tracker.reset()

    def action_distribution(self) -> np.ndarray:
        """``pi_t(a | h_t) = sum_k pi_k(a | b_k) p(k)`` with deterministic alpha-vector policies ``pi_k``."""
        distribution = np.zeros(self.kernels.pomdps[0].n_actions)
        for k, policy in enumerate(self.policies):
            distribution[policy.action(self.tracker.beliefs[k])] += self.tracker.posterior[k]
        return distribution

    def act(self) -> int:
        return draw_action(self.action_distribution(), self.rng, self.greedy)

    def observe(self, action: int, observation: int, state: int | None = None) -> None:
        self.tracker.update(action, observation)

    def losses(self) -> np.ndarray:
        """Eq. 5.7 for every model and action, (K, A): ``v(b_k) - q(b_k, a)``, ``q`` by one-step lookahead."""
        result = []
        for k, (pomdp, policy) in enumerate(zip(self.kernels.pomdps, self.policies, strict=True)):
            belief = self.tracker.beliefs[k]
            q = np.empty(pomdp.n_actions)
            for a in range(pomdp.n_actions):
                predicted = self.kernels.transposed[k][a] @ belief
                joint = pomdp.observations[a].T @ predicted  # P(z | b, a) for every z
                future = 0.0
                for z in np.flatnonzero(joint > 0.0):
                    posterior = self.kernels.column(k, a, int(z)) * predicted / joint[z]
                    future += joint[z] * policy.value(posterior)
                q[a] = dot(belief, pomdp.rewards[:, a]) + pomdp.discount * future  # host-independent bits
            result.append(policy.value(belief) - q)
        return np.array(result)

    @property
    def task_posterior(self) -> np.ndarray:
        return self.tracker.posterior.copy()
