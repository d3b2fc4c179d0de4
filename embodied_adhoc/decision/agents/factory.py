"""Build agents by name over a model library; solved models are cached per library within a process.

``library`` is any object with ``pomdps`` (a sequence of POMDPs sharing S, A, Z; e.g. a ``LabLibrary``), or the
sequence itself. The cache holds, per library: the HOTSPOT plan (Q*_m, Q*_m,info), the value-iteration Q* of each
model's MDP (oracle, BOPA) and Perseus policies (ATPO, per solver configuration), so 32 trials x several agents
build and solve each model once.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from embodied_adhoc.decision.agents.atpo import AtpoAgent
from embodied_adhoc.decision.agents.base import Agent
from embodied_adhoc.decision.agents.baselines import OracleAgent, RandomAgent
from embodied_adhoc.decision.agents.bopa import BopaAgent
from embodied_adhoc.decision.agents.hotspot import HotspotAgent, HotspotConfig, HotspotPlan, plan_hotspot
from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.value_iteration import value_iteration
from embodied_adhoc.errors import ConfigError

__all__ = ["AGENT_NAMES", "DEFAULT_PERSEUS", "clear_cache", "hotspot_plan", "make_agent", "mdp_q_values"]

AGENT_NAMES: tuple[str, ...] = ("hotspot", "known-task", "oracle", "random", "atpo", "bopa")
"""Agents ``make_agent`` builds. ``oracle`` and ``bopa`` observe the state (``observes_state = True``)."""

DEFAULT_PERSEUS = {"n_beliefs": 200, "tolerance": 1e-2, "time_limit": 60.0, "seed": 0, "update": "perseus"}
"""ATPO's Perseus settings (``PerseusConfig`` fields) unless ``perseus`` is given (Table 5.2: tolerance 0.01; the
classic Perseus stage the thesis used, so the reproduced figures keep their policies).
The solver seed is part of these settings, not of ``rng_seed``, so every trial reuses the cached solution."""

_CACHE: dict[tuple[int, ...], dict] = {}


def _pomdps(library) -> tuple[POMDP, ...]:
    pomdps = getattr(library, "pomdps", library)
    if not isinstance(pomdps, Sequence) or not pomdps or not all(isinstance(p, POMDP) for p in pomdps):
        raise ConfigError(
            "library must have .pomdps (or be) a non-empty sequence of POMDPs sharing S, A and Z"
        )
    return tuple(pomdps)


def _entry(pomdps: tuple[POMDP, ...]) -> dict:
    key = tuple(id(p) for p in pomdps)
    entry = _CACHE.get(key)
    if entry is None:
        entry = _CACHE[key] = {"pomdps": pomdps}  # holding the models keeps their ids unique
    return entry


def clear_cache() -> None:
    """Forget every solved model (e.g. between benchmarks that time solving)."""
    _CACHE.clear()


def hotspot_plan(library, config: HotspotConfig | None = None) -> HotspotPlan:
    """The cached TEBOPA plan of a library."""
    config = config or HotspotConfig()
    entry = _entry(_pomdps(library))
    key = ("hotspot", config)
    if key not in entry:
        entry[key] = plan_hotspot(entry["pomdps"], config)
    return entry[key]


def mdp_q_values(library) -> np.ndarray:
    """Cached ``Q*_m`` (M, S, A) of each model's underlying MDP with its own rewards (oracle, BOPA)."""
    entry = _entry(_pomdps(library))
    if "q" not in entry:
        entry["q"] = np.stack([value_iteration(p, tolerance=1e-8).q_values for p in entry["pomdps"]])
    return entry["q"]


def _perseus_policies(library, settings: dict) -> tuple:
    from embodied_adhoc.decision.perseus import PerseusConfig, perseus

    entry = _entry(_pomdps(library))
    key = ("perseus", tuple(sorted(settings.items())))
    if key not in entry:
        entry[key] = tuple(perseus(p, PerseusConfig(**settings)) for p in entry["pomdps"])
    return entry[key]


def _true_task(name: str, true_task: int | None, n_models: int) -> int:
    if true_task is None:
        raise ConfigError(f"agent '{name}' knows the task: pass true_task= (0..{n_models - 1})")
    if not 0 <= int(true_task) < n_models:
        raise ConfigError(f"true_task={true_task} outside the library's tasks 0..{n_models - 1}")
    return int(true_task)


def make_agent(
    name: str,
    library,
    *,
    true_task: int | None = None,
    rng_seed: int = 0,
    hotspot: HotspotConfig | None = None,
    perseus: dict | None = None,
) -> Agent:
    """An agent by name (see ``AGENT_NAMES``). ``true_task`` is required by ``known-task`` and ``oracle``.

    ``rng_seed`` seeds the agent's generator until ``reset(rng)`` replaces it (episodes draw from that rng).
    ``perseus`` overrides ATPO's solver settings (``DEFAULT_PERSEUS``).
    """
    agent = _build(name, library, true_task, hotspot, perseus)
    agent.rng = np.random.default_rng(rng_seed)
    return agent


def _build(
    name: str, library, true_task: int | None, hotspot: HotspotConfig | None, perseus: dict | None
) -> Agent:
    pomdps = _pomdps(library)
    n_models = len(pomdps)
    if name == "hotspot":
        return HotspotAgent(hotspot_plan(library, hotspot), name=name)
    if name == "known-task":
        prior = np.zeros(n_models)
        prior[_true_task(name, true_task, n_models)] = 1.0
        return HotspotAgent(hotspot_plan(library, hotspot), prior=prior, name=name)
    if name == "oracle":
        return OracleAgent(mdp_q_values(library)[_true_task(name, true_task, n_models)], name=name)
    if name == "random":
        return RandomAgent(pomdps[0].n_actions, name=name)
    if name == "bopa":
        return BopaAgent(pomdps, mdp_q_values(library), name=name)
    if name == "atpo":
        policies = _perseus_policies(library, {**DEFAULT_PERSEUS, **(perseus or {})})
        return AtpoAgent(hotspot_plan(library, hotspot).kernels, policies, name=name)
    raise ConfigError(f"unknown agent '{name}'; choose from {', '.join(AGENT_NAMES)}")
