"""The MuJoCo arena under :class:`~embodied_adhoc.envs.pursuit_pomdp.PursuitPomdpEnv`: executes the pursuit
POMDP's sampled moves physically and reads the cells back.

It is the grid arena of :mod:`embodied_adhoc.sim.grid_arena_world` (5 x 5 cells, two predator robots and a prey
robot, the shared waypoint controller) with two changes that the POMDP's rules need:

* **the torus**: a move across an edge is executed as a teleport to the opposite edge's cell (heading kept); a
  physical floor cannot wrap, and the library's dynamics are toroidal;
* **no collisions**: the model lets two predators (or a predator and the prey) share a cell, so contacts between
  robots are disabled (each robot still touches the floor and the walls).

``predators=4`` is the same arena for chapter 4's pursuit (:class:`~embodied_adhoc.envs.teamwork.TeamworkEnv`),
whose rules keep agents on distinct cells: the rules resolve conflicts, so robots passing each other in a
chain move need no contacts either.
"""

from __future__ import annotations

import numpy as np

from embodied_adhoc.domains.grid_rules import GridConfig, GridRules, GridState, StepPlan
from embodied_adhoc.sim.grid_arena_world import ArenaPhysics, GridArenaBackend

__all__ = ["PursuitPomdpArena"]

SIZE = 5
ROBOT_CONTYPE, ROBOT_CONAFFINITY = 2, 1  # collide with the floor and walls (contype 1), never with each other


class PursuitPomdpArena:
    """Agent 0 (the ad hoc robot), the teammates (1 by default) and the prey robot, in the library's cell order."""

    def __init__(self, physics: ArenaPhysics | None = None, predators: int = 2) -> None:
        self.predators = predators
        config = GridConfig(
            domain="pursuit", rows=SIZE, cols=SIZE, n_agents=predators, n_targets=1, interact_required=False
        )
        self.backend = GridArenaBackend(GridRules(config), physics=physics)
        model = self.backend.model
        roots = {model.body(f"{name}/").id for name in self.backend.robots}
        robot_geoms = np.flatnonzero(
            np.isin(model.body_rootid[model.geom_bodyid], list(roots))
            & (model.geom_contype | model.geom_conaffinity > 0)
        )
        model.geom_contype[robot_geoms] = ROBOT_CONTYPE
        model.geom_conaffinity[robot_geoms] = ROBOT_CONAFFINITY
        self.teleports = 0  # edge crossings executed as teleports (since construction)

    def _grid_state(self, cells: np.ndarray) -> GridState:
        n = self.predators
        return GridState(
            cells[:n].copy(), np.ones(n, np.int64), cells[n : n + 1].copy(), np.ones(1, np.int64)
        )

    @staticmethod
    def _cells(state: GridState) -> np.ndarray:
        return np.vstack([state.agents, state.targets]).astype(np.int64)

    def reset(self, cells: np.ndarray) -> np.ndarray:
        """Place the robots on ``cells`` ((agent, teammates, prey) rows); returns the cells physics shows."""
        return self._cells(self.backend.reset(self._grid_state(np.asarray(cells))))

    def execute(self, cells: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Drive every robot from ``cells`` to ``target`` (edge crossings teleport); the cells read back."""
        yaw = self.backend.poses()[:, 2]
        for robot in np.flatnonzero((np.abs(target - cells) > 1).any(axis=1)):
            self.backend.place(robot, target[robot], yaw[robot])
            self.teleports += 1
        n = self.predators
        plan = StepPlan(target[:n].copy(), target[n : n + 1].copy(), np.zeros(1, dtype=bool))
        return self._cells(self.backend.execute(self._grid_state(cells), plan))

    def poses(self) -> np.ndarray:
        """(predators + 1, 3) true base poses (x, y, yaw) of the agent, the teammates and the prey."""
        return self.backend.poses()

    @property
    def sim_time(self) -> float:
        """Simulated seconds since the last reset."""
        return float(self.backend.data.time)

    @property
    def physics_steps(self) -> int:
        return self.backend.physics_steps

    def render_top(self, size: int = 480) -> np.ndarray:
        return self.backend.render_top(size)

    def close(self) -> None:
        self.backend.close()
