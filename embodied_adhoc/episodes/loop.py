"""The one episode loop: an agent acting in any env of the project, step by step, with observers attached.

Shared by the trial runner (``experiments.trial.run_trial``: ``trials``), the recorded runs
(:func:`embodied_adhoc.episodes.recorded.run_recorded`: ``run toxic-waste|foraging|pursuit``) and the live mode, so
that every command runs an episode the same way::

    obs, info = env.reset(seed=env_seed, options=reset_options)
    agent.reset(agent_rng, state=env.unwrapped.privileged_state() if agent.observes_state else None)
    agent.start(obs)                          # a no-op unless the agent reads raw observations (ATLPO)
    repeat up to max_steps:  a = agent.act(); obs, r, terminated, truncated, info = env.step(a)
                             agent.observe(a, z, state=<privileged state> if agent.observes_state else None)

The observation contract: the agent's observation is ``obs`` and nothing else. ``z`` is
``observation_index(obs)`` (the tabular agents' observation index, computed from ``obs`` alone), or ``obs`` itself
for agents that declare ``observes_raw`` (learned agents over egocentric arrays); the trace records the index
either way. ``info`` (ground truth and diagnostics) goes to the observers, never to the agent. The one privileged
channel is the env's ``privileged_state()`` (the true state, as ``info["state"]`` holds it), read only for agents
that declare ``observes_state`` (the oracle, value iteration, BOPA; see
:mod:`embodied_adhoc.decision.agents.base`). Agents that learn from rewards (chapter 4's, through
:class:`~embodied_adhoc.decision.agents.teamwork.EpisodeSeat`) declare ``observes_reward`` and also get
``reward=r, terminated=...`` in ``observe``.

Recorders and progress bars are :class:`EpisodeObserver` objects: the loop calls them, they never drive the
episode. Envs stay pure Gymnasium and neither ``envs/`` nor ``record/`` imports this layer (``tests/test_layers.py``).
``steps`` counts the env steps taken; an episode that hits the cap (or that the env truncates) reports the steps
it took and ``success = False``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["EpisodeObserver", "EpisodeTrace", "StepRecord", "run_episode_loop"]


@dataclass(frozen=True)
class StepRecord:
    """One finished step as the loop saw it (``info`` is the env's ground truth, for evaluation only)."""

    step: int  # 1-based
    action: int
    observation_index: int
    reward: float
    terminated: bool
    truncated: bool
    info: dict
    task_posterior: np.ndarray | None  # the agent's posterior after observing this step (None: it keeps none)


@dataclass
class EpisodeTrace:
    """What an episode produced: per-step actions, observations, rewards and the task-posterior history."""

    actions: list[int] = field(default_factory=list)
    observations: list[int] = field(default_factory=list)
    rewards: list[float] = field(default_factory=list)
    # posteriors[0] is the prior; posteriors[t] the posterior after t steps; None entries for agents without one
    posteriors: list[np.ndarray | None] = field(default_factory=list)
    terminated: bool = False
    truncated: bool = False
    reset_info: dict = field(default_factory=dict)

    @property
    def steps(self) -> int:
        return len(self.actions)

    @property
    def success(self) -> bool:
        return self.terminated

    def posterior_history(self) -> np.ndarray | None:
        """Posteriors stacked, shape (steps + 1, n_tasks); None if the agent keeps no task posterior."""
        if not self.posteriors or self.posteriors[0] is None:
            return None
        return np.stack(self.posteriors)


class EpisodeObserver:
    """Hooks the loop calls; override what you need (recorders, progress bars, live displays)."""

    def episode_started(self, info: dict, task_posterior: np.ndarray | None) -> None:
        """After ``env.reset`` and ``agent.reset``: the reset info and the agent's prior."""

    def step_started(self, step: int) -> None:
        """Before the agent chooses the action of ``step`` (1-based)."""

    def action_chosen(self, step: int, action: int) -> None:
        """After ``agent.act()``, before ``env.step`` executes it (e.g. to label the frames it renders)."""

    def step_finished(self, record: StepRecord) -> None:
        """After ``env.step`` and ``agent.observe``."""

    def episode_finished(self, trace: EpisodeTrace) -> None:
        """After the last step (terminated, truncated or the cap); not called when the loop raises."""


def _posterior(agent) -> np.ndarray | None:
    posterior = agent.task_posterior
    return None if posterior is None else np.array(posterior, dtype=np.float64, copy=True)


def _privileged_channel(env, agent) -> Callable[[], Any]:
    """The env's ``privileged_state`` method: the one way the true state reaches an ``observes_state`` agent."""
    from embodied_adhoc.errors import ConfigError

    channel = getattr(getattr(env, "unwrapped", env), "privileged_state", None)
    if channel is None:
        raise ConfigError(
            f"agent '{agent.name}' observes the state (observes_state = True), but {type(env).__name__} offers no "
            "privileged_state(): run it on an env that does, or declare observes_state = False"
        )
    return channel


def run_episode_loop(
    env,
    agent,
    *,
    env_seed: int,
    agent_rng: np.random.Generator,
    reset_options: dict | None,
    max_steps: int,
    observation_index: Callable[[Any], int],
    observers: Sequence[EpisodeObserver] = (),
) -> EpisodeTrace:
    """Run one episode of ``agent`` in ``env``; ``observation_index(observation)`` gives the agent's observation
    index. Agents that declare ``observes_state`` (BOPA, the oracle) also get the env's ``privileged_state()``;
    agents that declare ``observes_raw`` get the env's observations themselves, the first one through
    ``agent.start``."""
    trace = EpisodeTrace()
    observation, info = env.reset(seed=env_seed, options=reset_options)
    trace.reset_info = info
    # The capability flags of the Agent protocol (decision/agents/base.py), checked when the agent was built.
    privileged, raw = bool(agent.observes_state), bool(agent.observes_raw)
    rewarded = bool(agent.observes_reward)
    state_of = _privileged_channel(env, agent) if privileged else None
    agent.reset(agent_rng, state=state_of() if privileged else None)
    agent.start(observation)
    trace.posteriors.append(_posterior(agent))
    for observer in observers:
        observer.episode_started(info, trace.posteriors[0])
    for step in range(1, max_steps + 1):
        for observer in observers:
            observer.step_started(step)
        action = int(agent.act())
        for observer in observers:
            observer.action_chosen(step, action)
        observation, reward, terminated, truncated, info = env.step(action)
        index = int(observation_index(observation))
        outcome = {"reward": float(reward), "terminated": bool(terminated)} if rewarded else {}
        agent.observe(
            action, observation if raw else index, state=state_of() if privileged else None, **outcome
        )
        posterior = _posterior(agent)
        trace.actions.append(action)
        trace.observations.append(index)
        trace.rewards.append(float(reward))
        trace.posteriors.append(posterior)
        trace.terminated, trace.truncated = bool(terminated), bool(truncated) and not terminated
        record = StepRecord(
            step, action, index, float(reward), trace.terminated, trace.truncated, info, posterior
        )
        for observer in observers:
            observer.step_finished(record)
        if terminated or truncated:
            break
    else:
        trace.truncated = True  # the loop's own cap
    for observer in observers:
        observer.episode_finished(trace)
    return trace
