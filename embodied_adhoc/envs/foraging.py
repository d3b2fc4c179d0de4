"""Level-based foraging envs: ``EmbodiedAdhoc/ForagingGrid-v0`` (grid twin) and ``EmbodiedAdhoc/Foraging-v0``
(MuJoCo arena)."""

from __future__ import annotations

from embodied_adhoc import checks
from embodied_adhoc.domains.foraging import foraging_config, foraging_tasks
from embodied_adhoc.envs import contract
from embodied_adhoc.envs.grid_world_env_adhoc import AdhocGridEnv, grid_sizes
from embodied_adhoc.teammates.foraging_teams import FORAGING_TEAMS


class ForagingEnv(AdhocGridEnv):
    """Level-based foraging with an unknown team and task (thesis sections 6.2.1-6.2.2).

    ## Description
    N foragers (the ad hoc robot, agent 0, plus N-1 scripted teammates) and M apples on an R x C grid. An apple
    is foraged when every forager stands at its task position around it (task 1: agents 0..3 north, south,
    west, east; tasks 2-4 rotate that by 90 degrees), all execute *Forage* in the same step and their levels
    sum to at least the apple's level. The episode ends when every apple is foraged. The team type (tau0
    closest apple/greedy, tau1 highest-level apple/collision-avoiding, tau2 encircling) and the task are drawn
    at reset from ``tasks`` x ``teams`` and appear only in ``info``.

    ## Action space
    ``Discrete(5)``: 0 up (row - 1), 1 down, 2 left (column - 1), 3 right, 4 forage. A move into a wall, an
    occupied cell or a cell another agent also enters fails (the agent stays).

    ## Observation space
    ``obs_mode="grid"``: ``Box(0, N * max_agent_level, (C, f, f), float32)``, egocentric ``f x f`` view
    (``view``, default 5) with ``C = (N-1) + M + 2`` channels: one per teammate, one per apple, the boundary
    (cells outside the walls) and the levels of the foragers and apples in view.
    ``obs_mode="image"`` (``backend="mujoco"`` only): ``Box(0, 255, (image_size, image_size, 3), uint8)``, an
    offscreen render of a camera above the ad hoc robot, world-aligned, covering about ``f x f`` cells.

    ## Rewards
    Sparse: 1.0 on the step the last apple is foraged, else 0.0.

    ## Starting state
    Apples on interior cells (walled grids keep them off the border and the interior corners so every task
    position exists and no corner can be sealed), foragers on random free cells; agent levels uniform in
    ``1..max_agent_level``, apple levels uniform in ``1..sum of agent levels``.

    ## Episode end
    Terminated when all apples are foraged. Truncated by the registered ``TimeLimit`` (200 steps: the thesis
    states no cap for chapter 6; ``gymnasium.make(id, max_episode_steps=N)`` changes it). ``step`` after the end
    raises (``envs.contract``).

    ## Arguments
    ``gymnasium.make("EmbodiedAdhoc/ForagingGrid-v0", tasks=(1, 2, 3, 4), teams=("tau0", "tau1", "tau2"),
    rows=5, cols=5, n_agents=4, n_apples=1, max_agent_level=2, toroidal=False, view=5, backend="abstract",
    obs_mode="grid", image_size=64, render_mode=None, physics=None)``; ``physics`` (a
    ``sim.grid_arena_world.ArenaPhysics``) and ``image_size`` are MuJoCo-arena options.
    ``toroidal=True`` gives the thesis's wrap-around
    grid (grid twin only). ``reset(options={"task": 2, "team": "tau1", "state": {...}})`` imposes any of them.

    ## Info
    ``task`` (1-based), ``task_name``, ``team``, ``state`` (cells and levels of everything, ground truth for
    evaluation only), ``steps``, ``remaining`` apples; after a step also ``completed`` and ``teammate_actions``.

    ## Version history
    v0: initial release (grid twin and MuJoCo arena share rules and observation function).
    """

    @contract.keywords()
    def __init__(
        self,
        tasks=None,
        teams=None,
        rows: int = 5,
        cols: int = 5,
        n_agents: int = 4,
        n_apples: int = 1,
        max_agent_level: int = 2,
        toroidal: bool = False,
        view: int = 5,
        backend: str = "abstract",
        obs_mode: str = "grid",
        image_size: int = 64,
        render_mode: str | None = None,
        physics=None,
    ):
        sizes = grid_sizes(
            rows=rows, cols=cols, n_agents=n_agents, n_targets=n_apples, max_agent_level=max_agent_level
        )
        config = foraging_config(toroidal=checks.flag("toroidal", toroidal), **sizes)
        super().__init__(
            config,
            foraging_tasks(config.n_agents),
            FORAGING_TEAMS,
            tasks,
            teams,
            view,
            backend,
            obs_mode,
            image_size,
            render_mode,
            physics,
        )
