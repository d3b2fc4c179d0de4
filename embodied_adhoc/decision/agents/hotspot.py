"""HOTSPOT's decision rule, TEBOPA (thesis section 7.1), generic over a library of POMDPs sharing S, A, Z.

Each library model is the POMDP of one task with the teammate averaged over its optimal actions (the P̄_m of
Eq. 7.1). The agent sees only its own actions and observation indices.

* Eq. 7.1, the task-dependent belief update, the task posterior ("Task inference") and Eq. 7.2, the average
  belief: :mod:`~embodied_adhoc.decision.agents.task_beliefs`.
* Sec. 7.1 "Decision-theoretic planning" (Melo & Ribeiro 2006), here: the normalised entropy H̄, the belief
  ``b_m,max(z, a)`` reached from the maximum-entropy belief, the information gain ``ΔH_m(z, a) = 1 - H̄(b_m,max)``,
  the reward gain ``ΔR_m(z, a) = max_a' sum_{x,y} P̄_m(y | x, a) O(z | y, a) r̄_m(y, a') / |X|``, the
  information-gathering reward ``r_m,info(x, a) = sum_z P(z | x, a, m) ΔH_m(z, a) ΔR_m(z, a)``, the two Q
  functions ``Q*_m`` and ``Q*_m,info`` by value iteration, and the entropy-weighted action choice
  ``argmax_a sum_m p(m) sum_x b(x) [(1 - H̄(b)) Q*_m(x, a) + H̄(b) Q*_m,info(x, a)]``.

Rewards are min-max normalised to [0, 1] over the library before planning (as the original implementation did).
An affine change of rewards leaves each Q*_m's greedy policy unchanged, but the heuristic needs it: ΔR must be
non-negative for ``ΔH ΔR`` to reward informative observations, and Q*_m and Q*_m,info must share a scale for
the entropy weighting to mean anything.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.decision.agents.base import AgentBase
from embodied_adhoc.decision.agents.selection import pick_best
from embodied_adhoc.decision.agents.task_beliefs import LibraryBeliefs, LibraryKernels, normalised_entropy
from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.products import dot
from embodied_adhoc.decision.value_iteration import value_iteration
from embodied_adhoc.errors import ConfigError

__all__ = ["HotspotAgent", "HotspotConfig", "HotspotPlan", "information_reward", "plan_hotspot"]


REWARD_GAINS = ("thesis", "conditional", "none")


@dataclass(frozen=True)
class HotspotConfig:
    """``belief_in_choice``: "average" uses Eq. 7.2's b_t in the action choice (the thesis); "task" uses each b_m."""

    belief_in_choice: str = "task"
    reward_gain: str = "conditional"
    normalise_rewards: bool = True
    vi_tolerance: float = 1e-6

    def __post_init__(self) -> None:
        if self.belief_in_choice not in ("average", "task"):
            raise ConfigError(
                f"HotspotConfig.belief_in_choice must be 'average' or 'task', got {self.belief_in_choice!r}"
            )
        if self.reward_gain not in REWARD_GAINS:
            raise ConfigError(
                f"HotspotConfig.reward_gain must be one of {REWARD_GAINS}, got {self.reward_gain!r}"
            )


@dataclass(frozen=True, eq=False)
class HotspotPlan:
    """Everything TEBOPA precomputes per library (shared by all agents on that library)."""

    kernels: LibraryKernels
    q_task: np.ndarray  # (M, S, A): Q*_m
    q_info: np.ndarray  # (M, S, A): Q*_m,info
    info_reward: np.ndarray  # (M, S, A): r_m,info
    config: HotspotConfig

    @functools.cached_property
    def stacked_q(self) -> np.ndarray:
        """``[Q*_m | Q*_m,info]`` as one (M * S, 2A) matrix: the action choice is one vector-matrix product."""
        m, s, a = self.q_task.shape
        return np.ascontiguousarray(np.concatenate([self.q_task, self.q_info], axis=2).reshape(m * s, 2 * a))


def information_reward(
    pomdp: POMDP, rewards: np.ndarray, reward_gain: str = HotspotConfig.reward_gain
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(r_info (S, A), ΔH (Z, A), ΔR (Z, A))`` of one model (Sec. 7.1, Melo & Ribeiro 2006), with sparse products.

    ``reward_gain`` defaults to :class:`HotspotConfig`'s (its one definition; see ``REWARD_GAINS``).

    ``rewards`` is ``r̄_m`` (S x A). For an observation impossible from the maximum-entropy belief, ΔH = ΔR = 0
    (it has probability 0 from every state, so it never contributes to r_info).
    """
    n_states, n_actions, n_obs = pomdp.n_states, pomdp.n_actions, pomdp.n_observations
    info = np.zeros((n_states, n_actions))
    delta_h = np.zeros((n_obs, n_actions))
    delta_r = np.zeros((n_obs, n_actions))
    log_states = np.log(n_states) if n_states > 1 else 1.0
    for a in range(n_actions):
        transition, observation = pomdp.transitions[a], pomdp.observations[a]
        reach = np.asarray(transition.sum(axis=0)).ravel() / n_states  # P(y | uniform x, a)
        unnormalised = sp.diags(reach) @ observation  # b_m,max(z, a) columns times rho_z
        unnormalised = unnormalised.tocsc()
        rho = np.asarray(unnormalised.sum(axis=0)).ravel()
        possible = rho > 0.0
        columns = np.repeat(np.arange(n_obs), np.diff(unnormalised.indptr))
        share = unnormalised.data / rho[columns]
        terms = np.where(share > 0.0, -share * np.log(np.where(share > 0.0, share, 1.0)), 0.0)
        entropy = np.bincount(columns, weights=terms, minlength=n_obs) / log_states
        delta_h[:, a] = np.where(possible, 1.0 - entropy, 0.0)
        if reward_gain == "none":
            delta_r[:, a] = possible
        else:
            gain = (unnormalised.T @ rewards).max(axis=1)
            if reward_gain == "conditional":
                gain = gain / np.where(possible, rho, 1.0)
            delta_r[:, a] = np.where(possible, gain, 0.0)
        info[:, a] = (transition @ observation) @ (delta_h[:, a] * delta_r[:, a])
    return info, delta_h, delta_r


def plan_hotspot(pomdps: Sequence[POMDP], config: HotspotConfig = HotspotConfig()) -> HotspotPlan:
    """Solve Q*_m and Q*_m,info for every model of the library (value iteration on the averaged MDPs)."""
    kernels = LibraryKernels.build(pomdps)
    rewards = [p.rewards for p in kernels.pomdps]
    if config.normalise_rewards:
        low = min(r.min() for r in rewards)
        span = max(r.max() for r in rewards) - low
        rewards = [(r - low) / span if span > 0 else np.zeros_like(r) for r in rewards]
    q_task, q_info, info_rewards = [], [], []
    for pomdp, reward in zip(kernels.pomdps, rewards, strict=True):
        info, _, _ = information_reward(pomdp, reward, config.reward_gain)
        q_task.append(value_iteration(pomdp, rewards=reward, tolerance=config.vi_tolerance).q_values)
        q_info.append(value_iteration(pomdp, rewards=info, tolerance=config.vi_tolerance).q_values)
        info_rewards.append(info)
    return HotspotPlan(kernels, np.stack(q_task), np.stack(q_info), np.stack(info_rewards), config)


class HotspotAgent(AgentBase):
    """TEBOPA. ``prior`` over the library (default uniform); a one-hot prior gives the known-task baseline."""

    observes_state = False

    def __init__(self, plan: HotspotPlan, prior: np.ndarray | None = None, name: str = "hotspot") -> None:
        self.plan = plan
        self.name = name
        self.tracker = LibraryBeliefs(plan.kernels, prior)
        self.rng = np.random.default_rng(0)

    def reset(self, rng: np.random.Generator, state: int | None = None) -> None:
        self.rng = rng
        self.tracker.reset()

    def action_values(self) -> np.ndarray:
        """The entropy-weighted values of Sec. 7.1's action choice, one per action."""
        tracker, plan = self.tracker, self.plan
        belief = tracker.average_belief()
        entropy = normalised_entropy(belief)
        if plan.config.belief_in_choice == "average":
            weights = np.outer(tracker.posterior, belief)  # p(m) b(x)
        else:
            weights = tracker.posterior[:, None] * tracker.beliefs  # p(m) b_m(x)
        values = dot(weights.ravel(), plan.stacked_q)  # fixed summation order: ties decided alike on any host
        n_actions = values.size // 2
        return (1.0 - entropy) * values[:n_actions] + entropy * values[n_actions:]

    def act(self) -> int:
        return pick_best(self.action_values(), self.rng)

    def observe(self, action: int, observation: int, state: int | None = None) -> None:
        self.tracker.update(action, observation)

    @property
    def task_posterior(self) -> np.ndarray:
        return self.tracker.posterior.copy()

    @property
    def belief(self) -> np.ndarray:
        """The average state belief b_t (Eq. 7.2)."""
        return self.tracker.average_belief()
