"""The agent interface shared by every domain, backend, the trial runner and the recorded runs.

An ad hoc agent sees only its own actions and observations. It never sees the state, the task or the teammates'
actions. The episode loop (:func:`embodied_adhoc.episodes.loop.run_episode_loop`) drives it::

    agent.reset(rng, state=s0 if agent.observes_state else None)
    agent.start(obs0)                                 # every agent; a no-op unless it reads raw observations
    repeat:  a = agent.act(); obs, r, ... = env.step(a)
             agent.observe(a, z, state=s if agent.observes_state else None,
                           **({"reward": r, "terminated": done} if agent.observes_reward else {}))

``z`` is the flat observation index of the domain's POMDP library, or the env's raw observation for agents that
declare ``observes_raw``. Capability flags say what else an agent receives; each is a class attribute:

- ``observes_state`` (privileged): the loop passes the true state index (``state=``) to ``reset`` and
  ``observe``. Baselines that are *defined* by it (the full-observability oracle, value iteration on the state,
  BOPA) declare it, and the tables mark them. It is the one channel through which ground truth reaches an agent.
- ``observes_raw``: ``observe`` and ``start`` get the env's raw observation (arrays) instead of the index
  (learned agents).
- ``observes_reward``: ``observe`` also gets ``reward=`` and ``terminated=`` (agents that learn online).

An agent that is given the true task (``known-task``) receives it at construction, never through ``observe``.

Writing one: subclass :class:`AgentBase` (it declares every flag ``False``, ``start`` as a no-op and
``task_posterior`` as ``None``) and write ``reset``, ``act`` and ``observe``; ``docs/plugins.md`` has a worked
example. :func:`protocol_gaps` lists what an object lacks; agent plug-ins are checked with it once, when built.

``isinstance(agent, Agent)`` inspects the class and the instance's attributes without running them
(``inspect.getattr_static``, the behaviour of Python 3.12's ``typing`` that ``typing_extensions`` gives 3.11):
with the plain 3.11 ``typing.Protocol`` it would *call* the ``task_posterior`` property, so an agent whose
posterior reads a belief that ``reset`` creates would not be an ``Agent`` until it had been reset.
"""

from __future__ import annotations

import inspect

import numpy as np
from typing_extensions import Protocol, runtime_checkable

__all__ = ["AGENT_FLAGS", "AGENT_METHODS", "Agent", "AgentBase", "protocol_gaps"]


@runtime_checkable
class Agent(Protocol):
    name: str
    """The agent's label in tables, CSVs and plots."""
    observes_state: bool
    """Privileged: ``reset`` and ``observe`` get ``state=`` (the true state index)."""
    observes_raw: bool
    """``start`` and ``observe`` get the env's raw observation instead of the observation index."""
    observes_reward: bool
    """``observe`` also gets ``reward=`` (float) and ``terminated=`` (bool)."""

    def reset(self, rng: np.random.Generator, state: int | None = None) -> None:
        """Start an episode: draw every random choice from ``rng`` from now on (it is seeded per trial).
        ``state`` is the true initial state, given only to agents with ``observes_state``."""

    def start(self, observation) -> None:
        """The episode's first observation, after ``reset`` (the env's ``reset`` output: raw for agents that
        declare ``observes_raw``; agents over observation indices get it too and usually ignore it)."""

    def act(self) -> int:
        """The next action index (deterministic given the history and the reset rng)."""

    def observe(self, action: int, observation, state: int | None = None, **outcome) -> None:
        """Incorporate the outcome of ``action``: the observation (index, or raw with ``observes_raw``), the new
        state with ``observes_state``, and ``reward=``/``terminated=`` with ``observes_reward``."""

    @property
    def task_posterior(self) -> np.ndarray | None:
        """The current distribution over the task library (shape ``(n_tasks,)``, sums to 1), or None for agents
        that keep none. Read after ``reset`` (the prior) and after every ``observe``."""


AGENT_METHODS = ("reset", "start", "act", "observe")
AGENT_FLAGS = ("observes_state", "observes_raw", "observes_reward")


class AgentBase:
    """Defaults of the :class:`Agent` protocol: no privileged channel, observation indices, no rewards, no
    task posterior. Subclasses write ``reset``, ``act`` and ``observe`` and set ``name``."""

    name: str = "agent"
    observes_state: bool = False
    observes_raw: bool = False
    observes_reward: bool = False

    def start(self, observation) -> None:
        return None

    @property
    def task_posterior(self) -> np.ndarray | None:
        return None


def protocol_gaps(agent) -> list[str]:
    """What ``agent`` lacks of the :class:`Agent` protocol (empty when it conforms): missing methods, a flag
    that is missing or not a bool, a missing ``name`` or ``task_posterior``. Nothing is called."""
    gaps = []
    for method in AGENT_METHODS:
        if not callable(_static(agent, method)):
            gaps.append(f"method {method}()")
    for flag in AGENT_FLAGS:
        value = _static(agent, flag)
        if not isinstance(value, (bool, np.bool_)):
            gaps.append(
                f"flag {flag} (a bool)" if value is _MISSING else f"flag {flag} = {value!r} (not a bool)"
            )
    if _static(agent, "task_posterior") is _MISSING:
        gaps.append("task_posterior (a property: array or None)")
    if not isinstance(_static(agent, "name"), (str, property)):
        gaps.append("name (a str)")
    return gaps


_MISSING = object()


def _static(obj, attribute: str):
    try:
        return inspect.getattr_static(obj, attribute)
    except AttributeError:
        return _MISSING
