"""Trial domains: the plug-in protocol through which every domain (and backend) reaches the one trial runner.

A *trial* is one episode of one agent: the runner resets a Gymnasium env with the episode's spec, resets the
agent, then alternates ``agent.act()`` -> ``env.step(action)`` -> ``agent.observe(action, z, state=...)`` until the
env terminates (success) or the step cap is hit. ``z`` is :meth:`TrialSession.observation_index` of the env's
observation; ``state=`` (the env's ``privileged_state()``) is given only to agents with ``observes_state`` (see
:mod:`embodied_adhoc.decision.agents.base`). Nothing of ``info`` reaches an agent.

Plugging a domain in
--------------------
Register it by name with an import string (so that importing the registry, and ``embodied-adhoc --help``, imports
nothing heavy)::

    register_trial_domain("foraging", "embodied_adhoc.experiments.domains.foraging:DOMAIN")

The object behind the string implements :class:`TrialDomain`; its module must import only light modules
(argparse, dataclasses, numpy) at top level, because the CLI imports it to build ``trials <domain> --help``.
Heavy work (building and solving models, creating MuJoCo envs) happens in :meth:`TrialDomain.open_session`,
which the runner calls once per worker process and caches.

:class:`TrialDomain` (light, one per domain)
    ``name``, ``description``, ``backends`` (e.g. ``("abstract", "mujoco")``), ``agent_names`` (what
    ``make_agent`` accepts), ``default_agents``, optionally ``privileged_agents`` (those that observe the state,
    marked in the tables);
    ``add_arguments(parser)``: the domain's own CLI flags (e.g. ``--human-epsilon``, ``--team``);
    ``options_from_args(args) -> dict``: those flags as a JSON-able dict (validated; raise ``ConfigError``);
    ``episode_spec(options, rng) -> dict``: one episode's draw (task, start positions, ...) as flat JSON scalars,
    including the key ``"task"`` (the true task index); drawn once per episode and shared by every agent;
    ``open_session(backend, options) -> TrialSession``.

:class:`TrialSession` (heavy, cached per process and per (domain, backend, options))
    ``task_names``: names of the task library (posterior columns);
    ``make_env(max_steps) -> gymnasium.Env`` (created once per process, reused across trials; it must not
    truncate episodes before ``max_steps``, the runner's cap; backend chosen here by env id/kwargs: e.g.
    ``EmbodiedAdhoc/ToxicWasteAbstract-v0`` vs ``EmbodiedAdhoc/ToxicWaste-v0``);
    ``reset_options(spec) -> dict``: the ``options`` of ``env.reset`` that impose the spec;
    ``make_agent(name, spec, seed) -> Agent``: a fresh agent (``spec["task"]`` only for agents defined to know it);
    ``observation_index(observation) -> int``: the flat observation index the agents consume, computed from the
    env's observation alone (``info`` is ground truth: it never reaches an agent).

Agents by name or as plug-ins
----------------------------
``--agents`` takes the domain's ``agent_names`` and any plug-in spec of :mod:`embodied_adhoc.plugins`
(``module:callable``, ``path/to/file.py:callable`` or an installed ``embodied_adhoc.agents`` entry point). Every
caller builds agents through :func:`build_agent`: a built-in name goes to ``session.make_agent``; a plug-in's
factory is called as ``factory(library, rng_seed=seed)``, where ``library`` is the session's ``agent_library`` if
it has one, else its ``library`` (the domain's model library), else the session itself. Either way the agent is
checked against the Agent protocol (:func:`~embodied_adhoc.decision.agents.base.protocol_gaps`) once, when built.

Everything a trial needs is derived from ``(seed, episode, agent)`` (see :mod:`embodied_adhoc.experiments.seeding`),
so results are identical whatever the number of workers or the executor.
"""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import numpy as np

from embodied_adhoc.errors import ConfigError


@runtime_checkable
class TrialSession(Protocol):
    task_names: tuple[str, ...]

    def make_env(self, max_steps: int) -> Any: ...

    def reset_options(self, spec: dict) -> dict: ...

    def make_agent(self, name: str, spec: dict, seed: int) -> Any: ...

    def observation_index(self, observation: Any) -> int: ...


@runtime_checkable
class TrialDomain(Protocol):
    name: str
    description: str
    backends: tuple[str, ...]
    agent_names: tuple[str, ...]
    default_agents: tuple[str, ...]

    def add_arguments(self, parser: argparse.ArgumentParser) -> None: ...

    def options_from_args(self, args: argparse.Namespace) -> dict: ...

    def episode_spec(self, options: dict, rng: np.random.Generator) -> dict: ...

    def open_session(self, backend: str, options: dict) -> TrialSession: ...


def agent_plugin(domain: TrialDomain, spec: str, flag: str = "--agents"):
    """The :class:`~embodied_adhoc.plugins.Plugin` that ``spec`` names for ``domain`` (built-in names first);
    ConfigError listing the domain's agents, the installed ones and the plug-in forms otherwise."""
    from embodied_adhoc.plugins import resolve

    return resolve("agent", spec, builtin=domain.agent_names, flag=flag)


def agent_library(session: Any) -> Any:
    """What a plug-in agent's factory receives: the session's ``agent_library``, else its ``library``, else the
    session itself."""
    for attribute in ("agent_library", "library"):
        if getattr(session, attribute, None) is not None:
            return getattr(session, attribute)
    return session


def build_agent(domain: TrialDomain, session: TrialSession, spec: str, episode_spec: dict, seed: int) -> Any:
    """A fresh agent for one episode: a built-in name from ``session.make_agent``, a plug-in from its factory;
    refused with one ConfigError line when it does not meet the Agent protocol."""
    from embodied_adhoc.decision.agents.base import protocol_gaps

    plugin = agent_plugin(domain, spec)
    if plugin.builtin:
        agent = session.make_agent(spec, episode_spec, seed)
    else:
        try:
            agent = plugin.factory(agent_library(session), rng_seed=seed)
        except ConfigError:
            raise
        except Exception as error:
            where = f" ({plugin.source})" if plugin.source else ""
            raise ConfigError(
                f"agent {spec!r}{where}: its factory failed, called as factory(library, rng_seed={seed}): "
                f"{type(error).__name__}: {error}"
            ) from error
    gaps = protocol_gaps(agent)
    if gaps:
        raise ConfigError(
            f"agent {spec!r}: {type(agent).__name__} does not meet the Agent protocol: it lacks {'; '.join(gaps)} "
            "(subclass embodied_adhoc.decision.agents.base.AgentBase; see docs/plugins.md)"
        )
    return agent


def privileged_agents(
    domain: TrialDomain, session: TrialSession, agents, episode_spec: dict, seed: int
) -> tuple:
    """Those of ``agents`` that observe the true state (``observes_state``), which the tables mark: a built-in
    name when the domain lists it in ``privileged_agents``, a plug-in when the agent it builds declares it."""
    declared = set(getattr(domain, "privileged_agents", ()))
    marked = []
    for name in agents:
        if agent_plugin(domain, name).builtin:
            privileged = name in declared
        else:
            privileged = bool(build_agent(domain, session, name, episode_spec, seed).observes_state)
        if privileged:
            marked.append(name)
    return tuple(marked)


_DOMAINS: dict[str, str | Callable[[], TrialDomain] | TrialDomain] = {}
_LOADED: dict[str, TrialDomain] = {}


def register_trial_domain(name: str, factory: str | Callable[[], TrialDomain] | TrialDomain) -> None:
    """Register a domain under ``name``: an import string ``"module:attribute"``, a zero-argument factory or
    the domain object itself. Re-registering a name replaces it (tests register fakes this way)."""
    _DOMAINS[name] = factory
    _LOADED.pop(name, None)


def trial_domain_names() -> tuple[str, ...]:
    return tuple(_DOMAINS)


def get_trial_domain(name: str) -> TrialDomain:
    """The domain registered as ``name`` (imported on first use); ConfigError listing the names otherwise."""
    if name in _LOADED:
        return _LOADED[name]
    if name not in _DOMAINS:
        raise ConfigError(
            f"unknown trial domain '{name}'; registered domains: {', '.join(_DOMAINS) or 'none'}"
        )
    factory = _DOMAINS[name]
    if isinstance(factory, str):
        module_name, _, attribute = factory.partition(":")
        obj = getattr(importlib.import_module(module_name), attribute)
        domain = obj() if callable(obj) and not isinstance(obj, TrialDomain) else obj
    elif isinstance(factory, TrialDomain):
        domain = factory
    else:
        domain = factory()
    if not isinstance(domain, TrialDomain):
        raise TypeError(f"trial domain '{name}' ({factory!r}) does not implement the TrialDomain protocol")
    _LOADED[name] = domain
    return domain


# Built-in domains. Other areas append theirs here (one line each) or call register_trial_domain at import.
register_trial_domain("toxic-waste", "embodied_adhoc.experiments.domains.toxic_waste:DOMAIN")
register_trial_domain("foraging", "embodied_adhoc.experiments.domains.foraging:DOMAIN")
register_trial_domain("pursuit", "embodied_adhoc.experiments.domains.pursuit:DOMAIN")
register_trial_domain("pursuit4", "embodied_adhoc.experiments.domains.teamster_trials:DOMAIN")  # chapter 4
# Chapter 5: one plug-in per library of embodied_adhoc.domains.chapter5
for _name in (
    "panic-buttons",
    "gridworld",
    "pursuit-task",
    "pursuit-teammate",
    "pursuit-both",
    "power-plant",
    "ntu",
    "isr",
    "mit",
    "pentagon",
    "cit",
    "overcooked",
    "map",
):
    register_trial_domain(
        _name, f"embodied_adhoc.experiments.domains.chapter5:DOMAIN_{_name.replace('-', '_')}"
    )
