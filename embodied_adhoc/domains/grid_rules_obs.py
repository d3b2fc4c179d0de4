"""Egocentric partial observation of the grid domains (thesis section 6.2.1, Fig. 6.4), for both twins.

An agent sees an ``f x f`` window centred on itself, as channels (each ``f x f``):
``N-1`` teammate channels (one per teammate, in agent order without the observer), ``M`` target channels (one
per apple/prey; emptied once it is foraged/captured), one boundary channel (1 where the window leaves the walled
grid; all 0 on a torus, where the window wraps) and, for LBF only, one level channel (the level of the observer,
teammates and apples on their cells). Total ``(N-1) + M + 1 (+1 for LBF)`` channels, float32.
"""

from __future__ import annotations

import weakref

import numpy as np

from embodied_adhoc.domains.grid_rules import GridBatch, GridRules, GridState
from embodied_adhoc.errors import ConfigError


def observation_channels(rules: GridRules) -> int:
    cfg = rules.config
    return cfg.n_agents - 1 + cfg.n_targets + 1 + (1 if cfg.domain == "foraging" else 0)


def observation_high(rules: GridRules) -> float:
    """Upper bound of every channel: 1 for presence, the largest possible level for the level channel."""
    cfg = rules.config
    return float(max(1, cfg.n_agents * cfg.max_agent_level)) if cfg.domain == "foraging" else 1.0


def _layers(rules: GridRules, batch: GridBatch) -> np.ndarray:
    """(B, N + M + 2, R + 1, C + 1) world-frame layers (N agents, M targets, boundary, levels) with one extra
    row and column, the *outside*: all zero but in the boundary layer, where it is 1. Window cells beyond the
    walls index it (see :func:`_window_index`)."""
    cfg = rules.config
    b = len(batch.agents)
    env = np.arange(b)[:, None]
    layers = np.zeros((b, cfg.n_agents + cfg.n_targets + 2, cfg.rows + 1, cfg.cols + 1), dtype=np.float32)
    layers[:, -2, -1, :] = 1.0
    layers[:, -2, :, -1] = 1.0
    layers[env, np.arange(cfg.n_agents), batch.agents[..., 0], batch.agents[..., 1]] = 1.0
    rows, live = np.nonzero(batch.alive)
    cells = batch.targets[rows, live]
    layers[rows, cfg.n_agents + live, cells[:, 0], cells[:, 1]] = 1.0
    layers[env, -1, batch.agents[..., 0], batch.agents[..., 1]] = batch.agent_levels
    layers[rows, -1, cells[:, 0], cells[:, 1]] = batch.target_levels[rows, live]
    return layers


def _window_index(size: int, view: int, toroidal: bool) -> np.ndarray:
    """(size, view): the layer row (or column) each window row (column) of an observer in row (column) ``i``
    reads: wrapped on a torus, else ``size`` (the outside) beyond the walls."""
    cells = np.arange(size)[:, None] + np.arange(view)[None, :] - view // 2
    return cells % size if toroidal else np.where((cells >= 0) & (cells < size), cells, size)


def observation_layers(rules: GridRules) -> np.ndarray:
    """(N, channels): for each observer, the padded layers its channels read, in order (its teammates, the
    targets, the boundary and, for LBF, the levels)."""
    cfg = rules.config
    n = cfg.n_agents
    rest = list(range(n, n + cfg.n_targets + (2 if cfg.domain == "foraging" else 1)))
    return np.array([[j for j in range(n) if j != i] + rest for i in range(n)], dtype=np.int64)


_WINDOWS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _windows(rules: GridRules, view: int) -> np.ndarray:
    """(N, R*C, channels, view, view): for observer ``i`` standing on flat cell ``c``, the flat index into one
    state's :func:`_layers` of every channel and window cell (built once per grid and view)."""
    tables = _WINDOWS.setdefault(rules, {})
    if view not in tables:
        cfg = rules.config
        rows = _window_index(cfg.rows, view, cfg.toroidal)  # (R, view)
        cols = _window_index(cfg.cols, view, cfg.toroidal)  # (C, view)
        cell_rows, cell_cols = np.divmod(np.arange(cfg.rows * cfg.cols), cfg.cols)
        plane = (
            rows[cell_rows][:, :, None] * (cfg.cols + 1) + cols[cell_cols][:, None, :]
        )  # (R*C, view, view)
        channels = observation_layers(rules) * ((cfg.rows + 1) * (cfg.cols + 1))  # (N, channels)
        tables[view] = channels[:, None, :, None, None] + plane[None, :, None, :, :]
    return tables[view]


def egocentric_batch(rules: GridRules, batch: GridBatch, observers: np.ndarray, view: int = 5) -> np.ndarray:
    """The observations of agents ``observers`` (B, K) in each of B states, ``(B, K, channels, view, view)``
    (one world per state, all windows gathered by one flat index)."""
    if view < 1 or view % 2 == 0:
        raise ConfigError(f"view={view}: the field of view must be a positive odd number of cells")
    layers = _layers(rules, batch)
    env = np.arange(len(observers))[:, None]
    cells = rules.flat(batch.agents[env, observers])  # (B, K)
    index = _windows(rules, view)[observers, cells] + (env * layers[0].size)[..., None, None, None]
    return layers.ravel()[index]


def egocentric_observations(rules: GridRules, state: GridState, view: int = 5) -> np.ndarray:
    """Every agent's observation at once, ``(N, channels, view, view)``."""
    observers = np.arange(rules.config.n_agents)[None]
    return egocentric_batch(rules, GridBatch.stack([state]), observers, view)[0]


def egocentric_observation(rules: GridRules, state: GridState, agent: int, view: int = 5) -> np.ndarray:
    """The ``(channels, view, view)`` observation of ``agent`` in ``state``."""
    return egocentric_batch(rules, GridBatch.stack([state]), np.array([[agent]]), view)[0, 0]
