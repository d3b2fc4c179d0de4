"""One trial: drive a Gymnasium env with an agent for one episode and record what the statistics need.

The loop is the project's one episode loop, :func:`embodied_adhoc.episodes.loop.run_episode_loop` (see
:mod:`embodied_adhoc.experiments.registry` for the domain protocol that supplies env, agent and reset options).

``steps`` counts the env steps taken (the original implementation counted one extra; see docs/hotspot-original.md); a
trial that hits the cap (or that the env truncates) reports the steps it took and ``success = False``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from embodied_adhoc.episodes.loop import EpisodeObserver, run_episode_loop
from embodied_adhoc.experiments import seeding
from embodied_adhoc.experiments.registry import build_agent, get_trial_domain
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
    # The session's per-trial columns (its ``trial_columns``, e.g. fault counts); empty for sessions without them.
    extras: dict = field(default_factory=dict)

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


class _LastInfo(EpisodeObserver):
    """Keeps the env's last ``info``: a session's ``trial_extras(trace, info)`` reads the episode's outcome there."""

    info: dict = {}

    def episode_started(self, info: dict, task_posterior) -> None:
        self.info = info

    def step_finished(self, record) -> None:
        self.info = record.info


def run_trial(session, env, job: TrialJob) -> TrialResult:
    """Run one episode of ``job.agent`` in ``env`` (an env made by ``session``) and return its record."""
    domain = get_trial_domain(job.domain)
    agent = build_agent(
        domain, session, job.agent, job.spec, seeding.agent_seed(job.seed, job.episode, job.agent)
    )
    extras = getattr(session, "trial_extras", None)
    last = _LastInfo()
    trace = run_episode_loop(
        env,
        agent,
        env_seed=seeding.env_seed(job.seed, job.episode, job.agent),
        agent_rng=seeding.agent_rng(job.seed, job.episode, job.agent),
        reset_options=session.reset_options(job.spec),
        max_steps=job.max_steps,
        observation_index=session.observation_index,
        observers=(last,) if extras else (),
    )
    return TrialResult(
        agent=job.agent,
        episode=job.episode,
        spec=dict(job.spec),
        success=trace.success,
        steps=trace.steps,
        total_reward=float(sum(trace.rewards)),
        actions=tuple(trace.actions),
        observations=tuple(trace.observations),
        rewards=tuple(trace.rewards),
        posteriors=trace.posterior_history(),
        extras=extras(trace, last.info) if extras else {},
    )
