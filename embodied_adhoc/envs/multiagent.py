"""PettingZoo ``ParallelEnv`` over the foraging and pursuit worlds: every robot is controlled by the caller.

``GridParallelEnv(domain="foraging" | "pursuit", **kwargs)`` takes the keyword arguments of
:class:`~embodied_adhoc.envs.foraging.ForagingEnv` / :class:`~embodied_adhoc.envs.pursuit.PursuitEnv`
(``backend="abstract" | "mujoco"``, grid size, ``n_agents``, ``tasks``, ``pairs``, ``view``, ...). Agents are
``agent_0`` .. ``agent_{N-1}``; each observes its own egocentric grid view (the same function as the
single-agent envs) and acts in ``Discrete(5)``. The reward (1.0 when the last apple/prey is taken) is shared.
The episode's task is drawn from ``tasks`` at reset and appears in every agent's ``info`` (``team`` is the type
the single-agent env would script, unused here). Episodes are truncated after ``max_steps`` (default 200).
"""

from __future__ import annotations

import gymnasium
import numpy as np
from pettingzoo import ParallelEnv

from embodied_adhoc.envs.grid_world_env import draw_grid
from embodied_adhoc.errors import ConfigError


class GridParallelEnv(ParallelEnv):
    metadata = {"name": "embodied_adhoc_grid_v0", "render_modes": ["rgb_array"], "is_parallelizable": True}

    def __init__(self, domain: str = "foraging", max_steps: int = 200, render_mode: str | None = None, **kwargs):
        if domain == "foraging":
            from embodied_adhoc.envs.foraging import ForagingEnv as SingleEnv
        elif domain == "pursuit":
            from embodied_adhoc.envs.pursuit import PursuitEnv as SingleEnv
        else:
            raise ConfigError(f"domain={domain!r}: use 'foraging' or 'pursuit'")
        if kwargs.get("obs_mode", "grid") != "grid":
            raise ConfigError("GridParallelEnv observes the egocentric grid only (obs_mode='grid')")
        if max_steps < 1:
            raise ConfigError(f"max_steps={max_steps}: must be >= 1")
        self._single = SingleEnv(**kwargs)
        self.core = self._single.core
        self.render_mode, self.max_steps = render_mode, max_steps
        self.possible_agents = [f"agent_{i}" for i in range(self.core.config.n_agents)]
        self.agents: list[str] = []
        self._obs_space = self.core.observation_space()
        self._action_space = gymnasium.spaces.Discrete(5)

    def observation_space(self, agent: str) -> gymnasium.spaces.Box:
        return self._obs_space  # one shared (immutable) space object for every agent

    def action_space(self, agent: str) -> gymnasium.spaces.Discrete:
        return self._action_space

    def _observations(self) -> dict:
        return dict(zip(self.possible_agents, self.core.observe_all(), strict=True))

    def reset(self, seed: int | None = None, options: dict | None = None):
        # Only the world's own options (task, team, state) reach it; PettingZoo passes others (its API test
        # sends {"options": 1}) that belong to wrappers, so they are left for them rather than refused.
        known = {k: v for k, v in (options or {}).items() if k in ("task", "team", "state")}
        self._single.reset(seed=seed, options=known)  # seeds np_random, draws task/team/state
        self.agents = list(self.possible_agents)
        info = self.core.info()
        return self._observations(), {name: dict(info) for name in self.agents}

    def step(self, actions: dict):
        missing = set(self.agents) - set(actions)
        if missing:
            raise ConfigError(f"step: no action for {sorted(missing)}; give one per live agent")
        joint = np.array([int(actions[name]) for name in self.possible_agents], dtype=np.int64)
        self.core.step(joint)
        done = not self.core.episode.state.alive.any()
        truncated = not done and self.core.episode.steps >= self.max_steps
        reward = 1.0 if done else 0.0
        info = self.core.info()
        observations = self._observations()
        names = self.agents
        self.agents = [] if done or truncated else names
        return (observations, {n: reward for n in names}, {n: done for n in names},
                {n: truncated for n in names}, {n: dict(info) for n in names})

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self.core.backend_name == "mujoco":
            return self.core.backend.render_top()
        return draw_grid(self.core.rules, self.core.episode.state)

    def state(self) -> np.ndarray:
        """The global state as one vector: agent cells and levels, target cells, levels and presence."""
        s = self.core.episode.state
        return np.concatenate([s.agents.ravel(), s.agent_levels, s.targets.ravel(), s.target_levels,
                               s.alive.astype(np.int64)]).astype(np.float32)

    def close(self) -> None:
        self._single.close()
