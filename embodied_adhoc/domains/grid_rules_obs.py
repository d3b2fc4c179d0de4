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


def _padded_layers(rules: GridRules, state: GridState, half: int) -> np.ndarray:
    """World-frame layers (N agents, M targets, boundary, levels), padded by ``half`` cells on every side:
    with the boundary marked beyond walls, or wrapped around on a torus."""
    cfg = rules.config
    layers = np.zeros((cfg.n_agents + cfg.n_targets + 2, cfg.rows, cfg.cols), dtype=np.float32)
    layers[np.arange(cfg.n_agents), state.agents[:, 0], state.agents[:, 1]] = 1.0
    live = np.flatnonzero(state.alive)
    layers[cfg.n_agents + live, state.targets[live, 0], state.targets[live, 1]] = 1.0
    levels = layers[-1]
    levels[state.agents[:, 0], state.agents[:, 1]] = state.agent_levels
    levels[state.targets[live, 0], state.targets[live, 1]] = state.target_levels[live]
    if cfg.toroidal:
        return np.pad(layers, ((0, 0), (half, half), (half, half)), mode="wrap")
    padded = np.pad(layers, ((0, 0), (half, half), (half, half)))
    padded[-2] = 1.0
    padded[-2, half:half + cfg.rows, half:half + cfg.cols] = 0.0
    return padded


def egocentric_observations(rules: GridRules, state: GridState, view: int = 5) -> np.ndarray:
    """Every agent's observation at once, ``(N, channels, view, view)`` (one padded world, N slices)."""
    if view < 1 or view % 2 == 0:
        raise ConfigError(f"view={view}: the field of view must be a positive odd number of cells")
    cfg = rules.config
    padded = _padded_layers(rules, state, view // 2)
    keep = -1 if cfg.domain == "pursuit" else None  # pursuit has no level channel
    out = np.empty((cfg.n_agents, observation_channels(rules), view, view), dtype=np.float32)
    for i, (r, c) in enumerate(state.agents.tolist()):
        window = padded[:keep, r:r + view, c:c + view]
        out[i, :cfg.n_agents - 1] = np.delete(window[:cfg.n_agents], i, axis=0)
        out[i, cfg.n_agents - 1:] = window[cfg.n_agents:]
    return out


def egocentric_observation(rules: GridRules, state: GridState, agent: int, view: int = 5) -> np.ndarray:
    """The ``(channels, view, view)`` observation of ``agent`` in ``state``."""
    if view < 1 or view % 2 == 0:
        raise ConfigError(f"view={view}: the field of view must be a positive odd number of cells")
    cfg = rules.config
    padded = _padded_layers(rules, state, view // 2)
    r, c = state.agents[agent].tolist()
    keep = -1 if cfg.domain == "pursuit" else None
    window = padded[:keep, r:r + view, c:c + view]
    return np.concatenate([np.delete(window[:cfg.n_agents], agent, axis=0), window[cfg.n_agents:]])
