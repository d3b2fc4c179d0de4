"""The shared machinery of the foraging and pursuit envs: one core (rules + team + backend) under both the
single-agent Gymnasium envs (:mod:`embodied_adhoc.envs.foraging`, :mod:`embodied_adhoc.envs.pursuit`) and the
PettingZoo env (:mod:`embodied_adhoc.envs.multiagent`).

A *backend* executes a :class:`~embodied_adhoc.domains.grid_rules.StepPlan`: the ``abstract`` grid twin applies
it, the ``mujoco`` arena drives the robots there and reads the cells back from physics. Both feed the same
observation function, so an agent trained on one runs on the other unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np

from embodied_adhoc import checks
from embodied_adhoc.domains.grid_rules import GridConfig, GridRules, GridState, StepPlan, Task
from embodied_adhoc.domains.grid_rules_obs import (
    egocentric_observation,
    egocentric_observations,
    observation_channels,
    observation_high,
)
from embodied_adhoc.domains.grid_rules_team import TeamSpec, team_actions
from embodied_adhoc.errors import ConfigError

BACKENDS = ("abstract", "mujoco")
OBS_MODES = ("grid", "image")
RESET_OPTIONS = ("task", "team", "state")


class AbstractBackend:
    """The grid twin: the rules' plan is the next state."""

    def __init__(self, rules: GridRules) -> None:
        self.rules = rules

    def reset(self, state: GridState) -> GridState:
        return state.copy()

    def execute(self, state: GridState, plan: StepPlan) -> GridState:
        return self.rules.apply(state, plan)

    def close(self) -> None:
        pass


def make_backend(name: str, rules: GridRules, view: int, image_size: int = 64, physics=None):
    """The backend ``name``; ``image_size`` and ``physics`` (a ``sim.grid_arena_world.ArenaPhysics``) are options
    of the MuJoCo arena."""
    if name == "abstract":
        if physics is not None:
            raise ConfigError("physics: an option of the MuJoCo arena only (backend='mujoco')")
        return AbstractBackend(rules)
    if name == "mujoco":
        from embodied_adhoc.sim.grid_arena_world import GridArenaBackend

        return GridArenaBackend(rules, view=view, image_size=image_size, physics=physics)
    raise ConfigError(f"backend={name!r}: use one of {BACKENDS}")


def pick(name: str, chosen, library: dict | tuple) -> tuple:
    """Validate a user's selection against the library: task numbers (integers from 1) for a tuple library, team
    names for a dict; one value or a list of them. None selects the whole library."""
    valid = tuple(range(1, len(library) + 1)) if isinstance(library, tuple) else tuple(library)
    if chosen is None:
        return valid
    several = isinstance(chosen, (list, tuple)) or (isinstance(chosen, np.ndarray) and chosen.shape != ())
    items = tuple(chosen) if several else (chosen,)
    if not items:
        raise ConfigError(f"{name}=[]: choose from {list(valid)}")
    if isinstance(library, tuple):
        return tuple(checks.integer(name, item, 1, len(library)) for item in items)
    return tuple(checks.choice(name, item, valid) for item in items)


@dataclass
class Episode:
    task_number: int  # 1-based, as in the thesis
    team: str
    state: GridState
    steps: int = 0


class GridWorldCore:
    """Rules, library of tasks/teams, backend and the current episode; steps with every agent's action."""

    def __init__(
        self,
        config: GridConfig,
        tasks: tuple[Task, ...],
        teams: dict[str, TeamSpec],
        task_set=None,
        team_set=None,
        view: int = 5,
        backend: str = "abstract",
        image_size: int = 64,
        physics=None,
    ) -> None:
        from embodied_adhoc.teammates.grid_plugins import with_plugin_teams

        self.config, self.rules = config, GridRules(config)
        self.tasks, self.teams = tasks, with_plugin_teams(teams, team_set, self.rules)  # user teams by spec
        self.task_set = pick("tasks", task_set, tasks)
        self.team_set = pick("teams", team_set, self.teams)
        if checks.integer("view", view, 1) % 2 == 0:
            raise ConfigError(f"view={view}: the field of view must be a positive odd number of cells")
        self.view = int(view)
        self.backend_name = checks.choice("backend", backend, BACKENDS)
        image_size = checks.integer("image_size", image_size, 1)
        self.backend = make_backend(backend, self.rules, self.view, image_size, physics)
        self.episode: Episode | None = None
        self.rng = np.random.default_rng(0)

    def observation_space(self) -> gymnasium.spaces.Box:
        shape = (observation_channels(self.rules), self.view, self.view)
        return gymnasium.spaces.Box(0.0, observation_high(self.rules), shape, np.float32)

    def reset(self, rng: np.random.Generator, options: dict | None = None) -> None:
        """Draw task, team and start state from ``rng`` (always, so seeds align); ``options`` may impose
        ``task`` (1-based), ``team`` or ``state`` (a dict as in ``info['state']``)."""
        options = dict(options or {})
        checks.refuse_unknown("reset options", options, RESET_OPTIONS, what="option")
        self.rng = rng
        task, team, state = self.draw_episode(rng)
        if "task" in options:
            task = checks.integer("reset option task", options["task"], 1, len(self.tasks))
        if "team" in options:
            team = checks.choice("reset option team", options["team"], tuple(self.teams))
        if "state" in options:
            state = state_from_dict(options["state"], self.rules)
        self.episode = Episode(int(task), str(team), self.backend.reset(state))

    def draw_episode(self, rng: np.random.Generator) -> tuple[int, str, GridState]:
        """The draws of :meth:`reset`, in its order: task number, team name and start state (the vector env
        calls it for its resetting sub-envs without building an :class:`Episode` each)."""
        task, team = self.draw_task_team(rng)
        return task, team, self.rules.sample_state(rng)

    def draw_task_team(self, rng: np.random.Generator) -> tuple[int, str]:
        """The episode's task number and team name, the first draws of :meth:`draw_episode`."""
        task = self.task_set[int(rng.integers(len(self.task_set)))]
        team = self.team_set[int(rng.integers(len(self.team_set)))]
        return task, team

    @property
    def task(self) -> Task:
        return self.tasks[self.episode.task_number - 1]

    def scripted_actions(self, members) -> np.ndarray:
        """The episode team's actions for ``members`` (they plan assuming every agent follows the team)."""
        ep = self.episode
        team = self.teams[ep.team]
        if not isinstance(team, TeamSpec):  # a user's policy (teammates.grid_plugins)
            return np.asarray(team.actions(ep.state, self.task, self.rng, list(members)), dtype=np.int64)
        return team_actions(self.rules, ep.state, self.task, team, self.rng, members)

    def step(self, actions: np.ndarray) -> np.ndarray:
        """Apply one joint action; returns the targets completed this step."""
        ep = self.episode
        plan = self.rules.plan(ep.state, self.task, np.asarray(actions, dtype=np.int64), self.rng)
        ep.state = self.backend.execute(ep.state, plan)
        ep.steps += 1
        return plan.completed

    def observe(self, agent: int) -> np.ndarray:
        return egocentric_observation(self.rules, self.episode.state, agent, self.view)

    def observe_all(self) -> np.ndarray:
        """Every agent's observation, ``(N, channels, view, view)``."""
        return egocentric_observations(self.rules, self.episode.state, self.view)

    def info(self) -> dict:
        ep = self.episode
        return {
            "task": ep.task_number,
            "task_name": self.task.name,
            "team": ep.team,
            "state": ep.state.as_dict(),
            "steps": ep.steps,
            "remaining": int(ep.state.alive.sum()),
        }


def state_from_dict(data: dict, rules: GridRules) -> GridState:
    """A state given as in ``info['state']``, checked against the rules (cells on the grid, no overlaps)."""

    def array(key: str, kinds: str, dtype) -> np.ndarray:
        values = np.asarray(data[key])
        if values.dtype.kind not in kinds:  # no silent truncation of 1.5 or "1" to a cell index
            raise TypeError(f"'{key}' holds {values.dtype} values, expected {dtype.__name__}")
        return values.astype(dtype)

    try:
        if not isinstance(data, dict):
            raise TypeError(f"a dict is needed, got {type(data).__name__}")
        state = GridState(
            *(array(k, "iu", np.int64) for k in ("agents", "agent_levels", "targets", "target_levels")),
            array("alive", "b", np.bool_) if "alive" in data else np.ones(len(data["targets"]), bool),
        )
    except (KeyError, TypeError, ValueError) as error:
        raise ConfigError(
            f"reset option 'state': {error!r}; give agents, agent_levels, targets, "
            "target_levels (and alive) as in info['state']"
        ) from None
    cfg = rules.config
    if state.agents.shape != (cfg.n_agents, 2) or state.targets.shape != (cfg.n_targets, 2):
        raise ConfigError(f"reset option 'state': need {cfg.n_agents} agent and {cfg.n_targets} target cells")
    _, inside = rules.normalise(np.concatenate([state.agents, state.targets]))
    cells = {tuple(c) for c in np.concatenate([state.agents, state.targets[state.alive]]).tolist()}
    if not inside.all() or len(cells) != cfg.n_agents + int(state.alive.sum()):
        raise ConfigError("reset option 'state': cells must lie on the grid and not overlap")
    return state


def draw_grid(rules: GridRules, state: GridState, cell_px: int = 32) -> np.ndarray:
    """A top-down RGB picture of the grid (the abstract twin's ``render``): agents blue (the ad hoc agent
    orange), apples green / prey red, shaded darker for higher levels."""
    cfg = rules.config
    image = np.full((cfg.rows * cell_px, cfg.cols * cell_px, 3), 235, dtype=np.uint8)
    image[::cell_px, :] = 180
    image[:, ::cell_px] = 180

    def fill(cell, colour, margin):
        r, c = int(cell[0]) * cell_px, int(cell[1]) * cell_px
        image[r + margin : r + cell_px - margin, c + margin : c + cell_px - margin] = colour

    top = max(1, int(state.target_levels.max()))
    for m in np.flatnonzero(state.alive):
        shade = 1.0 - 0.5 * (state.target_levels[m] - 1) / max(1, top - 1)
        colour = (40, int(200 * shade), 40) if cfg.domain == "foraging" else (int(220 * shade), 40, 40)
        fill(state.targets[m], colour, cell_px // 2 - 2 - cell_px // 6 * min(2, int(state.target_levels[m])))
    for i, cell in enumerate(state.agents):
        fill(cell, (240, 140, 20) if i == 0 else (40, 90, 220), cell_px // 5)
    return image
