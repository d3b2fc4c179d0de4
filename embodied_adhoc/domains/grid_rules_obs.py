"""Egocentric partial observation of the grid domains (thesis section 6.2.1, Fig. 6.4), for both twins.

An agent sees an ``f x f`` window centred on itself, as channels (each ``f x f``):
``N-1`` teammate channels (one per teammate, in agent order without the observer), ``M`` target channels (one
per apple/prey; emptied once it is foraged/captured), one boundary channel (1 where the window leaves the walled
grid; all 0 on a torus, where the window wraps) and, for LBF only, one level channel (the level of the observer,
teammates and apples on their cells). Total ``(N-1) + M + 1 (+1 for LBF)`` channels, float32.
"""

from __future__ import annotations

import numpy as np

from embodied_adhoc.domains.grid_rules import GridRules, GridState
from embodied_adhoc.errors import ConfigError


def observation_channels(rules: GridRules) -> int:
    cfg = rules.config
    return cfg.n_agents - 1 + cfg.n_targets + 1 + (1 if cfg.domain == "foraging" else 0)


def observation_high(rules: GridRules) -> float:
    """Upper bound of every channel: 1 for presence, the largest possible level for the level channel."""
    cfg = rules.config
    return float(max(1, cfg.n_agents * cfg.max_agent_level)) if cfg.domain == "foraging" else 1.0


def egocentric_observation(rules: GridRules, state: GridState, agent: int, view: int = 5) -> np.ndarray:
    """The ``(channels, view, view)`` observation of ``agent`` in ``state``."""
    if view < 1 or view % 2 == 0:
        raise ConfigError(f"view={view}: the field of view must be a positive odd number of cells")
    cfg = rules.config
    half = view // 2
    span = np.arange(-half, half + 1)
    window = state.agents[agent] + np.stack(np.meshgrid(span, span, indexing="ij"), axis=-1)  # (f, f, 2)
    cells, inside = rules.normalise(window)
    rows, cols = np.where(inside, cells[..., 0], 0), np.where(inside, cells[..., 1], 0)

    agent_at = np.full((cfg.rows, cfg.cols), -1, dtype=np.int64)
    agent_at[state.agents[:, 0], state.agents[:, 1]] = np.arange(cfg.n_agents)
    target_at = np.full((cfg.rows, cfg.cols), -1, dtype=np.int64)
    live = np.flatnonzero(state.alive)
    target_at[state.targets[live, 0], state.targets[live, 1]] = live
    seen_agent = np.where(inside, agent_at[rows, cols], -1)
    seen_target = np.where(inside, target_at[rows, cols], -1)

    obs = np.zeros((observation_channels(rules), view, view), dtype=np.float32)
    teammates = [i for i in range(cfg.n_agents) if i != agent]
    for channel, mate in enumerate(teammates):
        obs[channel] = seen_agent == mate
    base = len(teammates)
    for m in range(cfg.n_targets):
        obs[base + m] = seen_target == m
    obs[base + cfg.n_targets] = ~inside
    if cfg.domain == "foraging":
        levels = np.where(seen_agent >= 0, state.agent_levels[np.maximum(seen_agent, 0)], 0)
        levels = np.where(seen_target >= 0, state.target_levels[np.maximum(seen_target, 0)], levels)
        obs[base + cfg.n_targets + 1] = levels
    return obs
