"""One trial: drive a Gymnasium env with an agent for one episode and record what the statistics need.

The loop (see :mod:`embodied_adhoc.experiments.registry` for the domain protocol)::

    obs, info = env.reset(seed=env_seed, options=session.reset_options(spec))
    agent.reset(agent_rng, state=info["state"] if agent.observes_state else None)
    repeat up to max_steps:  a = agent.act(); obs, r, terminated, truncated, info = env.step(a)
                             agent.observe(a, z, state=info["state"] if agent.observes_state else None)

``steps`` counts the env steps taken (the original implementation counted one extra; see hotspot-lab.md); a
trial that hits the cap (or that the env truncates) reports the steps it took and ``success = False``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from embodied_adhoc.experiments import seeding
from embodied_adhoc.experiments.stats import identify_step, normalised_entropies


@dataclass(frozen=True)
class TrialJob:
    """Everything a worker needs to run one trial (picklable; the domain is looked up by name)."""

    domain: str
    backend: str
    options: dict
    seed: int
    max_steps: int
    agent: str
    episode: int
    spec: dict


@dataclass(frozen=True)
class TrialResult:
    agent: str
    episode: int
    spec: dict
    success: bool
    steps: int
    total_reward: float
    actions: tuple[int, ...]
    observations: tuple[int, ...]
    rewards: tuple[float, ...]
    # Task posterior after each step, shape (steps + 1, n_tasks), row 0 = the prior; None if the agent keeps none.
    posteriors: np.ndarray | None = field(default=None)

    @property
    def true_task(self) -> int:
        return int(self.spec["task"])

    @property
    def entropies(self) -> np.ndarray | None:
        return None if self.posteriors is None else normalised_entropies(self.posteriors)

    @property
    def identify_step(self) -> int | None:
        return None if self.posteriors is None else identify_step(self.posteriors, self.true_task)

    @property
    def final_entropy(self) -> float:
        return math.nan if self.posteriors is None else float(normalised_entropies(self.posteriors[-1])[0])

    @property
    def true_task_probability(self) -> float:
        return math.nan if self.posteriors is None else float(self.posteriors[-1, self.true_task])


def _posterior(agent) -> np.ndarray | None:
    posterior = agent.task_posterior
    return None if posterior is None else np.array(posterior, dtype=np.float64, copy=True)


def run_trial(session, env, job: TrialJob) -> TrialResult:
    """Run one episode of ``job.agent`` in ``env`` (an env made by ``session``) and return its record."""
    agent = session.make_agent(job.agent, job.spec, seeding.agent_seed(job.seed, job.episode, job.agent))
    observation, info = env.reset(
        seed=seeding.env_seed(job.seed, job.episode, job.agent), options=session.reset_options(job.spec)
    )
    privileged = bool(getattr(agent, "observes_state", False))
    agent.reset(
        seeding.agent_rng(job.seed, job.episode, job.agent), state=info["state"] if privileged else None
    )
    posteriors = [_posterior(agent)]
    actions: list[int] = []
    observations: list[int] = []
    rewards: list[float] = []
    success = False
    for _ in range(job.max_steps):
        action = int(agent.act())
        observation, reward, terminated, truncated, info = env.step(action)
        observation_index = int(session.observation_index(observation, info))
        agent.observe(action, observation_index, state=info["state"] if privileged else None)
        actions.append(action)
        observations.append(observation_index)
        rewards.append(float(reward))
        posteriors.append(_posterior(agent))
        if terminated:
            success = True
            break
        if truncated:
            break
    has_posterior = posteriors[0] is not None
    return TrialResult(
        agent=job.agent,
        episode=job.episode,
        spec=dict(job.spec),
        success=success,
        steps=len(actions),
        total_reward=float(sum(rewards)),
        actions=tuple(actions),
        observations=tuple(observations),
        rewards=tuple(rewards),
        posteriors=np.stack(posteriors) if has_posterior else None,
    )
