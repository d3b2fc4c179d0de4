"""PettingZoo ``ParallelEnv`` over the foraging and pursuit worlds: every robot is controlled by the caller.

``GridParallelEnv(domain="foraging" | "pursuit", max_cycles=None, render_mode=None, **kwargs)`` takes the keyword
arguments of :class:`~embodied_adhoc.envs.foraging.ForagingEnv` / :class:`~embodied_adhoc.envs.pursuit.PursuitEnv`
(``backend="abstract" | "mujoco"``, grid size, ``n_agents``, ``tasks``, ``pairs``, ``view``, ...; unknown ones are
refused). It follows the env contract of :mod:`embodied_adhoc.envs.contract`.

Agents: ``agent_0`` .. ``agent_{N-1}`` (``possible_agents``); ``agent_0`` is the robot the single-agent envs call
the ad hoc one.

Spaces:

* ``observation_space(agent)``: ``Box(0, high, (C, f, f), float32)``, the agent's own egocentric ``f x f`` grid
  view (``view``, default 5), exactly the single-agent env's observation function and channels (teammates,
  targets, boundary, and in foraging the levels). The same space for every agent.
* ``action_space(agent)``: ``Discrete(5)``: 0 up, 1 down, 2 left, 3 right, 4 forage/capture (Stay in the pair
  variant). Actions are integers (see the contract); ``step`` needs one for every live agent and no others.
* ``state_space`` / ``state()``: the global state as one float32 vector: agent cells (N x (row, col)), agent
  levels (N), target cells (M x (row, col)), target levels (M), target present (M).

Reward: 1.0 to every agent on the step the last apple/prey is taken, else 0. The episode's task is drawn from
``tasks`` at reset and appears in every agent's ``info`` (``team`` is the type the single-agent env would script,
unused here). Episodes are truncated after ``max_cycles`` steps (default: the registered cap of the matching
single-agent id, 200; 150 for ``pairs=True``); ``step`` after the end raises.
"""

from __future__ import annotations

from collections.abc import Mapping

import gymnasium
import numpy as np
from pettingzoo import ParallelEnv

from embodied_adhoc import checks
from embodied_adhoc.envs import contract
from embodied_adhoc.envs.grid_world_env import draw_grid
from embodied_adhoc.envs.grid_world_env_adhoc import ACTION_MEANING
from embodied_adhoc.envs.registry import registered_cap
from embodied_adhoc.errors import ConfigError

GRID_IDS = {
    ("foraging", False): "EmbodiedAdhoc/ForagingGrid-v0",
    ("pursuit", False): "EmbodiedAdhoc/PursuitGrid-v0",
    ("pursuit", True): "EmbodiedAdhoc/PursuitPairGrid-v0",
}
"""The single-agent id whose registered step cap is the default ``max_cycles`` (same cap on both backends)."""
PETTINGZOO_PROBE = "options"
"""The reset option PettingZoo's API test sends to see that ``reset`` takes ``options``: accepted and ignored."""


class GridParallelEnv(ParallelEnv):
    metadata = {
        "name": "embodied_adhoc_grid_v0",
        "render_modes": list(contract.RENDER_MODES),
        "render_fps": 4,
        "is_parallelizable": True,
    }

    def __init__(
        self,
        domain: str = "foraging",
        max_cycles: int | None = None,
        render_mode: str | None = None,
        **kwargs,
    ):
        if checks.choice("domain", domain, ("foraging", "pursuit")) == "foraging":
            from embodied_adhoc.envs.foraging import ForagingEnv as SingleEnv
        else:
            from embodied_adhoc.envs.pursuit import PursuitEnv as SingleEnv
        if "max_steps" in kwargs or "max_episode_steps" in kwargs:
            raise ConfigError("GridParallelEnv: the step cap is max_cycles (PettingZoo's name)")
        accepted = [name for name in SingleEnv.__init__.accepted if name != "render_mode"]
        checks.refuse_unknown("GridParallelEnv", kwargs, ["domain", "max_cycles", "render_mode", *accepted])
        if kwargs.get("obs_mode", "grid") != "grid":
            raise ConfigError("GridParallelEnv observes the egocentric grid only (obs_mode='grid')")
        pairs = domain == "pursuit" and checks.flag("pairs", kwargs.get("pairs", False))
        cap = registered_cap(GRID_IDS[(domain, pairs)]) if max_cycles is None else max_cycles
        self.max_cycles = checks.integer("max_cycles", cap, 1)
        self.render_mode = contract.render_mode(render_mode)
        self._single = SingleEnv(**kwargs)
        self.core = self._single.core
        self.possible_agents = [f"agent_{i}" for i in range(self.core.config.n_agents)]
        self.agents: list[str] = []
        self._obs_space = self.core.observation_space()
        self._action_space = gymnasium.spaces.Discrete(5)
        self.state_space = self._state_space()

    def observation_space(self, agent: str) -> gymnasium.spaces.Box:
        """The egocentric grid view of ``agent`` (one shared, immutable space object for every agent)."""
        self._check_agent(agent)
        return self._obs_space

    def action_space(self, agent: str) -> gymnasium.spaces.Discrete:
        """``Discrete(5)``: 0 up, 1 down, 2 left, 3 right, 4 interact (Stay in the pair variant)."""
        self._check_agent(agent)
        return self._action_space

    def _check_agent(self, agent: str) -> None:
        if agent not in self.possible_agents:
            raise ConfigError(f"agent {agent!r}: use one of {', '.join(self.possible_agents)}")

    def _state_space(self) -> gymnasium.spaces.Box:
        cfg = self.core.config
        n, m = cfg.n_agents, cfg.n_targets
        foraging = cfg.domain == "foraging"
        agent_level = cfg.max_agent_level if foraging else 1
        target_level = n * cfg.max_agent_level if foraging else 1
        cell = [cfg.rows - 1, cfg.cols - 1]
        high = np.concatenate([cell * n, [agent_level] * n, cell * m, [target_level] * m, [1] * m])
        return gymnasium.spaces.Box(0.0, high.astype(np.float32), dtype=np.float32)

    def _observations(self) -> dict:
        return dict(zip(self.possible_agents, self.core.observe_all(), strict=True))

    def reset(self, seed: int | None = None, options: dict | None = None):
        """Start an episode; ``options`` are the single-agent env's (``task``, ``team``, ``state``): any other
        name is refused with one ConfigError (a typo gets a suggestion). The one exception is PettingZoo's API
        test (``pettingzoo.test.parallel_api_test``), which calls ``reset(seed=0, options={"options": 1})`` only
        to check that reset takes the keyword: the name ``options`` (``PETTINGZOO_PROBE``) is accepted and
        ignored."""
        if options is not None and not isinstance(options, Mapping):
            raise ConfigError(
                f"GridParallelEnv.reset options must be a dict of option name -> value, got {type(options).__name__}"
            )
        world_options = {k: v for k, v in (options or {}).items() if k != PETTINGZOO_PROBE}
        # the world refuses unknown and wrongly typed options (checks.refuse_unknown, with "did you mean")
        self._single.reset(seed=seed, options=world_options)  # seeds np_random, draws task/team/state
        self.agents = list(self.possible_agents)
        info = self.core.info()
        return self._observations(), {name: dict(info) for name in self.agents}

    def step(self, actions: dict):
        if not self.agents:
            raise contract.EpisodeOverError(
                "GridParallelEnv.step(): no episode is running (not reset yet, or it terminated or was "
                "truncated); call reset() first"
            )
        if not isinstance(actions, dict):
            raise ConfigError(f"step: actions must be a dict agent -> action, got {type(actions).__name__}")
        checks.refuse_unknown("step actions", actions, self.agents, what="agent")
        missing = sorted(set(self.agents) - set(actions))
        if missing:
            raise ConfigError(f"step: no action for {missing}; give one per live agent")
        joint = np.array(
            [contract.action(actions[name], 5, f"{name}: {ACTION_MEANING}") for name in self.possible_agents],
            dtype=np.int64,
        )
        self.core.step(joint)
        done = not self.core.episode.state.alive.any()
        truncated = not done and self.core.episode.steps >= self.max_cycles
        reward = 1.0 if done else 0.0
        info = self.core.info()
        observations = self._observations()
        names = self.agents
        self.agents = [] if done or truncated else names
        return (
            observations,
            {n: reward for n in names},
            {n: done for n in names},
            {n: truncated for n in names},
            {n: dict(info) for n in names},
        )

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self.core.episode is None:
            raise contract.EpisodeOverError("GridParallelEnv.render(): call reset() first")
        if self.core.backend_name == "mujoco":
            return self.core.backend.render_top()
        return draw_grid(self.core.rules, self.core.episode.state)

    def state(self) -> np.ndarray:
        """The global state (see ``state_space``)."""
        s = self.core.episode.state
        return np.concatenate(
            [s.agents.ravel(), s.agent_levels, s.targets.ravel(), s.target_levels, s.alive.astype(np.int64)]
        ).astype(np.float32)

    def close(self) -> None:
        self._single.close()
