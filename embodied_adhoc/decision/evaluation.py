"""Monte-Carlo policy evaluation: mean discounted return with a 95 % confidence interval (Student t).

Each episode samples ``s0 ~ b0`` and runs ``horizon`` steps of the generative model, the policy acting on the
exact Bayesian belief (Eq. 2.3). Seeded: the same seed gives the same returns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from embodied_adhoc.decision.beliefs import BeliefStepper
from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.policy import AlphaVectorPolicy
from embodied_adhoc.errors import SolverError


@dataclass(frozen=True)
class EvaluationResult:
    mean: float  # mean discounted return
    ci95: float  # half-width of the 95 % confidence interval of the mean
    std: float
    episodes: int
    horizon: int
    returns: np.ndarray

    def as_dict(self) -> dict:
        return {
            "mean": self.mean,
            "ci95": self.ci95,
            "std": self.std,
            "episodes": self.episodes,
            "horizon": self.horizon,
        }


def evaluate_policy(
    pomdp: POMDP, policy: AlphaVectorPolicy, episodes: int, horizon: int, seed: int = 0
) -> EvaluationResult:
    """Simulate ``episodes`` episodes of ``horizon`` steps; a finite-horizon policy is used stage by stage."""
    if episodes < 1 or horizon < 1:
        raise SolverError(f"episodes and horizon must be >= 1, got {episodes} and {horizon}")
    if policy.n_states != pomdp.n_states:
        raise SolverError(f"policy has {policy.n_states} states, the model {pomdp.n_states}")
    if policy.horizon is not None and horizon > policy.horizon:
        raise SolverError(
            f"policy was solved for {policy.horizon} steps; evaluate with --horizon <= {policy.horizon}"
        )
    rng = np.random.default_rng(seed)
    stepper = BeliefStepper(pomdp)
    returns = np.empty(episodes)
    for episode in range(episodes):
        belief = pomdp.initial_belief
        state = pomdp.sample_initial_state(rng)
        total, weight = 0.0, 1.0
        for step in range(horizon):
            steps_to_go = horizon - step if policy.horizon is not None else None
            action = policy.action(belief, steps_to_go)
            state, observation, reward = pomdp.step(state, action, rng)
            total += weight * reward
            weight *= pomdp.discount
            belief = stepper.update(belief, action, observation)
            if belief is None:  # sampled an observation of probability 0: the model is inconsistent
                raise SolverError(
                    f"episode {episode}, step {step}: sampled observation {observation} has probability 0"
                )
        returns[episode] = total
    std = float(returns.std(ddof=1)) if episodes > 1 else 0.0
    half = float(stats.t.ppf(0.975, episodes - 1) * std / np.sqrt(episodes)) if episodes > 1 else float("inf")
    return EvaluationResult(float(returns.mean()), half, std, episodes, horizon, returns)
