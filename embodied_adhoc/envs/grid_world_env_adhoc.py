"""Single-agent (ad hoc) Gymnasium env over :class:`GridWorldCore`; documented by its subclasses
:class:`~embodied_adhoc.envs.foraging.ForagingEnv` and :class:`~embodied_adhoc.envs.pursuit.PursuitEnv`."""

from __future__ import annotations

import gymnasium
import numpy as np

from embodied_adhoc import checks
from embodied_adhoc.domains.grid_rules import GridConfig, Task
from embodied_adhoc.domains.grid_rules_team import TeamSpec
from embodied_adhoc.envs import contract
from embodied_adhoc.envs.grid_world_env import OBS_MODES, GridWorldCore, draw_grid
from embodied_adhoc.errors import ConfigError

ACTION_MEANING = "0 up, 1 down, 2 left, 3 right, 4 interact"


def grid_sizes(**values) -> dict:
    """The integer kwargs of the grid envs (rows, cols, agent and target counts, levels), checked."""
    return {name: checks.integer(name, value, 1) for name, value in values.items()}


class AdhocGridEnv(gymnasium.Env):
    """Agent 0 is the ad hoc robot (the env's action); agents 1..N-1 follow the episode's team policy."""

    metadata = {"render_modes": list(contract.RENDER_MODES), "render_fps": 4}

    def __init__(
        self,
        config: GridConfig,
        tasks: tuple[Task, ...],
        teams: dict[str, TeamSpec],
        task_set=None,
        team_set=None,
        view: int = 5,
        backend: str = "abstract",
        obs_mode: str = "grid",
        image_size: int = 64,
        render_mode: str | None = None,
        physics=None,
    ) -> None:
        obs_mode = checks.choice("obs_mode", obs_mode, OBS_MODES)
        if obs_mode == "image" and backend != "mujoco":
            raise ConfigError("obs_mode='image' renders the MuJoCo arena's camera: use backend='mujoco'")
        self.render_mode = contract.render_mode(render_mode)
        self.core = GridWorldCore(
            config, tasks, teams, task_set, team_set, view, backend, image_size, physics
        )
        self.obs_mode = obs_mode
        self.action_space = gymnasium.spaces.Discrete(5)
        if obs_mode == "grid":
            self.observation_space = self.core.observation_space()
        else:
            self.observation_space = gymnasium.spaces.Box(0, 255, (image_size, image_size, 3), np.uint8)
        self._episode = contract.EpisodeGate(type(self).__name__)

    def _observation(self) -> np.ndarray:
        if self.obs_mode == "image":
            return self.core.backend.egocentric_image(0)
        return self.core.observe(0)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.core.reset(self.np_random, options)
        self._episode.open()
        return self._observation(), self.core.info()

    def step(self, action):
        self._episode.check()
        action = contract.action(action, 5, ACTION_MEANING)
        n = self.core.config.n_agents
        actions = np.concatenate([[action], self.core.scripted_actions(range(1, n))])
        completed = self.core.step(actions)
        terminated = not self.core.episode.state.alive.any()
        self._episode.close_if(terminated)
        reward = 1.0 if terminated else 0.0
        info = self.core.info()
        info["completed"] = int(completed.sum())
        info["teammate_actions"] = actions[1:].tolist()
        return self._observation(), reward, terminated, False, info

    def privileged_state(self) -> dict:
        """The true state, as ``info["state"]`` holds it: the one channel through which the episode loop gives it to
        privileged agents (``observes_state``); agents never read ``info``."""
        return self.core.episode.state.as_dict()

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self.core.episode is None:
            raise contract.EpisodeOverError(f"{type(self).__name__}.render(): call reset() first")
        if self.core.backend_name == "mujoco":
            return self.core.backend.render_top()
        return draw_grid(self.core.rules, self.core.episode.state)

    def close(self) -> None:
        self.core.backend.close()
