"""Predator-prey envs: ``EmbodiedAdhoc/PursuitGrid-v0`` (grid twin), ``EmbodiedAdhoc/Pursuit-v0`` (MuJoCo arena)
and the two-predator variant of Fig. 7.12 (``EmbodiedAdhoc/PursuitPairGrid-v0``, ``EmbodiedAdhoc/PursuitPair-v0``)."""

from __future__ import annotations

import gymnasium
import numpy as np

from embodied_adhoc import checks
from embodied_adhoc.domains.pursuit import pursuit_config, pursuit_tasks, two_predator_config
from embodied_adhoc.envs import contract
from embodied_adhoc.envs.grid_world_env_adhoc import AdhocGridEnv, grid_sizes
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.teammates.pursuit_teams import PURSUIT_TEAMS

FOUR_PREDATOR_TEAMS = {k: PURSUIT_TEAMS[k] for k in ("tau0", "tau1", "tau2")}
TWO_PREDATOR_TEAMS = {k: PURSUIT_TEAMS[k] for k in ("greedy", "aware")}


class PursuitEnv(AdhocGridEnv):
    """Predator-prey with an unknown team and task (thesis sections 6.2.1-6.2.2, and 5.2.5 / Fig. 7.12).

    ## Description
    N predators (the ad hoc robot, agent 0, plus N-1 scripted teammates) and M prey on an R x C grid. The prey
    stays with probability ``prey_stay_probability`` (0.2), else tries one of the four moves uniformly (a move
    into a wall, an occupied cell, or, on walled grids, onto the border or an interior corner fails). A prey is
    captured when every predator stands at its task position around it (task 1: agents 0..3 north, south, west,
    east of the prey;
    tasks 2-4 rotate that) and all execute *Capture* in the same step; it ends when every prey is captured.
    Teams: tau0 (closest prey, greedy), tau1 (shortest paths around teammates), tau2 (encircling: joins its
    ray around the prey on a radius-2 circle, then closes in).
    ``pairs=True`` is the two-predator variant of Fig. 7.12: ``n_agents=2``, tasks N+S, W+E, SW+NE, NW+SE
    with interchangeable positions, teams ``greedy`` / ``aware`` (A*), and capture happens as soon as the pair
    is in position (action 4 means *Stay*).

    ## Action space
    ``Discrete(5)``: 0 up (row - 1), 1 down, 2 left (column - 1), 3 right, 4 capture (*Stay* when ``pairs``).

    ## Observation space
    ``obs_mode="grid"``: ``Box(0, 1, (C, f, f), float32)``, egocentric ``f x f`` view with
    ``C = (N-1) + M + 1`` channels: one per teammate, one per prey and the boundary.
    ``obs_mode="image"`` (``backend="mujoco"`` only): ``Box(0, 255, (image_size, image_size, 3), uint8)``.
    With ``pairs=True`` the observation is ``Dict({"view": <that space>, "observation_index": Discrete(81)})``:
    ``view`` as above, and ``observation_index`` the flat observation ``z = 9 t + p`` of the two-predator pursuit
    POMDP (thesis 5.2.5; :func:`~embodied_adhoc.domains.chapter5.pursuit.observation_distribution`, the function
    its ``O`` is built from): the teammate's (t) and the prey's (p) cell in the ad hoc robot's 3x3 neighbourhood,
    each seen with probability ``1 - observation_noise``, else 4; 40 (nothing seen) at reset. It is drawn from a
    generator spawned from the episode's, so it leaves every other draw of the env unchanged. Any agent of
    :mod:`embodied_adhoc.decision.agents` over a pursuit library can act on it; note that these envs keep the
    arena's rules (walls, collisions, the greedy/aware teams of ``grid_rules_team``), so for a planner they are
    a model mismatch; ``EmbodiedAdhoc/PursuitPairPomdpGrid-v0`` / ``PursuitPairPomdp-v0`` run the POMDP's own
    rules.

    ## Rewards
    Sparse: 1.0 on the step the last prey is captured, else 0.0.

    ## Starting state
    Prey on interior cells (off the border and interior corners on walled grids), predators on free cells.

    ## Episode end
    Terminated when all prey are captured; truncated by the registered ``TimeLimit`` (200 steps; 150 for the
    pair variant as in Fig. 7.12). ``step`` after the end raises (``envs.contract``).

    ## Arguments
    ``gymnasium.make("EmbodiedAdhoc/PursuitGrid-v0", tasks=None, teams=None, rows=5, cols=5, n_agents=4,
    n_prey=1, pairs=False, toroidal=False, prey_stay_probability=0.2, view=5, backend="abstract",
    obs_mode="grid", image_size=64, render_mode=None, physics=None, observation_noise=0.2)``
    (``observation_noise``: eps of ``obs["observation_index"]``, pairs only; 0.2 as pursuit-task, Table 5.2);
    ``reset(options={"task", "team", "state"})``.

    ## Info
    ``task`` (1-based), ``task_name``, ``team``, ``state`` (ground truth, evaluation only), ``steps``,
    ``remaining``; after a step ``completed`` and ``teammate_actions``.

    ## Version history
    v0: initial release.
    """

    @contract.keywords()
    def __init__(
        self,
        tasks=None,
        teams=None,
        rows: int = 5,
        cols: int = 5,
        n_agents: int | None = None,
        n_prey: int = 1,
        pairs: bool = False,
        toroidal: bool = False,
        prey_stay_probability: float = 0.2,
        view: int = 5,
        backend: str = "abstract",
        obs_mode: str = "grid",
        image_size: int = 64,
        render_mode: str | None = None,
        physics=None,
        observation_noise: float = 0.2,
    ):
        self.observation_noise = checks.number("observation_noise", observation_noise, 0.0, 1.0)
        common = dict(
            toroidal=checks.flag("toroidal", toroidal),
            prey_stay_probability=checks.number("prey_stay_probability", prey_stay_probability, 0.0, 1.0),
            **grid_sizes(rows=rows, cols=cols, n_targets=n_prey),
        )
        if checks.flag("pairs", pairs):
            if n_agents not in (None, 2):
                raise ConfigError(f"n_agents={n_agents}: the pair variant (pairs=True) has two predators")
            config, library, teams_lib = (
                two_predator_config(**common),
                pursuit_tasks(pairs=True),
                TWO_PREDATOR_TEAMS,
            )
        else:
            n_agents = 4 if n_agents is None else checks.integer("n_agents", n_agents, 1)
            config = pursuit_config(n_agents=n_agents, **common)
            library, teams_lib = pursuit_tasks(n_agents), FOUR_PREDATOR_TEAMS
        super().__init__(
            config,
            library,
            teams_lib,
            tasks,
            teams,
            view,
            backend,
            obs_mode,
            image_size,
            render_mode,
            physics,
        )
        if self.pairs:  # the POMDP's observation travels in obs, beside the view
            self.observation_space = gymnasium.spaces.Dict(
                {"view": self.observation_space, "observation_index": gymnasium.spaces.Discrete(81)}
            )

    @property
    def pairs(self) -> bool:
        """The two-predator variant of Fig. 7.12 (capture without an action)."""
        return not self.core.config.interact_required

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        observation, info = super().reset(seed=seed, options=options)
        if self.pairs:
            self._observation_rng = self.np_random.spawn(1)[0]
            observation = {"view": observation, "observation_index": 9 * 4 + 4}  # nothing seen yet
        return observation, info

    def step(self, action):
        observation, reward, terminated, truncated, info = super().step(action)
        if self.pairs:
            observation = {"view": observation, "observation_index": self._pair_observation()}
        return observation, reward, terminated, truncated, info

    def _pair_observation(self) -> int:
        """Draw ``z`` of the pursuit POMDP from the teammate's and the prey's offsets (wrapped on a torus)."""
        from embodied_adhoc.domains.chapter5.pursuit import observation_distribution

        config, state = self.core.config, self.core.episode.state
        offsets = np.vstack([state.agents[1], state.targets[0]]) - state.agents[0]
        if config.toroidal:
            size = np.array([config.rows, config.cols])
            offsets = (offsets + size // 2) % size - size // 2
        distribution = observation_distribution(offsets[:1], offsets[1:], self.observation_noise)[0]
        return int(self._observation_rng.choice(distribution.size, p=distribution))
