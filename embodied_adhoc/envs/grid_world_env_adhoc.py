"""Single-agent (ad hoc) Gymnasium env over :class:`GridWorldCore`; documented by its subclasses
:class:`~embodied_adhoc.envs.foraging.ForagingEnv` and :class:`~embodied_adhoc.envs.pursuit.PursuitEnv`."""

from __future__ import annotations

import gymnasium
import numpy as np

from embodied_adhoc.domains.grid_rules import GridConfig, Task
from embodied_adhoc.domains.grid_rules_team import TeamSpec
from embodied_adhoc.envs.grid_world_env import BACKENDS, OBS_MODES, GridWorldCore, draw_grid
from embodied_adhoc.errors import ConfigError


class AdhocGridEnv(gymnasium.Env):
    """Agent 0 is the ad hoc robot (the env's action); agents 1..N-1 follow the episode's team policy."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(self, config: GridConfig, tasks: tuple[Task, ...], teams: dict[str, TeamSpec],
                 task_set=None, team_set=None, view: int = 5, backend: str = "abstract", obs_mode: str = "grid",
                 image_size: int = 64, render_mode: str | None = None, **backend_kwargs) -> None:
        if obs_mode not in OBS_MODES:
            raise ConfigError(f"obs_mode={obs_mode!r}: use one of {OBS_MODES}")
        if obs_mode == "image" and backend != "mujoco":
            raise ConfigError("obs_mode='image' renders the MuJoCo arena's camera: use backend='mujoco'")
        if backend not in BACKENDS:
            raise ConfigError(f"backend={backend!r}: use one of {BACKENDS}")
        if render_mode not in (None, "rgb_array"):
            raise ConfigError(f"render_mode={render_mode!r}: only 'rgb_array' (or None) is supported")
        if backend == "mujoco":
            backend_kwargs.setdefault("image_size", image_size)
        self.core = GridWorldCore(config, tasks, teams, task_set, team_set, view, backend, **backend_kwargs)
        self.obs_mode, self.render_mode = obs_mode, render_mode
        self.action_space = gymnasium.spaces.Discrete(5)
        if obs_mode == "grid":
            self.observation_space = self.core.observation_space()
        else:
            self.observation_space = gymnasium.spaces.Box(0, 255, (image_size, image_size, 3), np.uint8)

    def _observation(self) -> np.ndarray:
        if self.obs_mode == "image":
            return self.core.backend.egocentric_image(0)
        return self.core.observe(0)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.core.reset(self.np_random, options)
        return self._observation(), self.core.info()

    def step(self, action):
        if self.core.episode is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        if not self.action_space.contains(action):
            raise ConfigError(f"action {action!r}: must be an integer in 0..4 (up, down, left, right, interact)")
        n = self.core.config.n_agents
        actions = np.concatenate([[int(action)], self.core.scripted_actions(range(1, n))])
        completed = self.core.step(actions)
        terminated = not self.core.episode.state.alive.any()
        reward = 1.0 if terminated else 0.0
        info = self.core.info()
        info["completed"] = int(completed.sum())
        info["teammate_actions"] = actions[1:].tolist()
        return self._observation(), reward, terminated, False, info

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self.core.backend_name == "mujoco":
            return self.core.backend.render_top()
        return draw_grid(self.core.rules, self.core.episode.state)

    def close(self) -> None:
        self.core.backend.close()
