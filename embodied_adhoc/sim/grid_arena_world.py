"""The MuJoCo backend of the grid envs: executes a grid step physically and reads the cells back.

One macro step: the rules decide every robot's next cell (:class:`~embodied_adhoc.domains.grid_rules.StepPlan`);
each robot that must move gets a route to that cell's centre from the shared waypoint controller
(:mod:`embodied_adhoc.control`: ruckig reference + unicycle tracking law -> wheel speeds on velocity actuators);
physics runs until every route is finished (or ``max_step_time``); then the grid state is read back from the
robots' positions (nearest cell centre). A robot that does not make it is where physics left it. Foraged apples
and captured prey are removed from the arena.

Controllers track the simulator's true base pose (the arenas study teamwork, not localisation; the lab's robot
uses odometry instead).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from embodied_adhoc.control.reference import DriveLimits
from embodied_adhoc.control.tracking import DiffDriveGeometry
from embodied_adhoc.control.waypoint_controller import ControllerConfig, WaypointController
from embodied_adhoc.domains.grid_rules import GridRules, GridState, StepPlan
from embodied_adhoc.errors import ConfigError, SceneError
from embodied_adhoc.sim.grid_arena import ArenaLayout, apple_radius, apple_rgba, build_arena

# The grid robot's wheels (assets/robots/grid_robot): radius 0.03 m, 0.12 m apart.
GRID_ROBOT_GEOMETRY = DiffDriveGeometry(wheel_radius=0.03, track_width=0.12, max_wheel_speed=20.0)
GRID_ROBOT_LIMITS = DriveLimits(
    max_speed=0.4,
    max_acceleration=1.5,
    max_jerk=8.0,
    max_yaw_rate=5.0,
    max_yaw_acceleration=20.0,
    max_yaw_jerk=150.0,
)


@dataclass(frozen=True)
class ArenaPhysics:
    """Physics settings of the arena backend."""

    cell: float = 0.25  # m
    timestep: float = 0.005  # s
    control_period: int = 4  # physics steps per controller update (50 Hz)
    max_step_time: float = 6.0  # s of simulated time per macro step before giving up on a route
    arrival_tolerance: float = 0.02  # m


class GridArenaBackend:
    """Executes grid plans in a MuJoCo arena built for ``rules.config``."""

    def __init__(
        self, rules: GridRules, view: int = 5, image_size: int = 64, physics: ArenaPhysics | None = None
    ) -> None:
        self.rules, self.physics_config = rules, physics or ArenaPhysics()
        cfg = rules.config
        if cfg.toroidal:
            raise ConfigError(
                "toroidal=True: a physical arena has walls and cannot wrap around; use the grid twin "
                "(backend='abstract') for the thesis's toroidal grid"
            )
        self.layout = ArenaLayout(cfg.rows, cfg.cols, self.physics_config.cell)
        arena = build_arena(cfg, self.layout, self.physics_config.timestep)
        self.view = view
        try:
            self.model = mujoco.MjModel.from_xml_string(arena.to_xml_string(), arena.get_assets())
        except ValueError as error:
            raise SceneError(
                f"grid arena {cfg.domain} {cfg.rows}x{cfg.cols} does not compile: {error}"
            ) from None
        self.data = mujoco.MjData(self.model)
        self.robots = [f"agent{i}" for i in range(cfg.n_agents)]
        if cfg.domain == "pursuit":
            self.robots += [f"prey{m}" for m in range(cfg.n_targets)]
        joint = [self.model.joint(f"{name}/{name}_free/") for name in self.robots]
        self.qpos_adr = np.array([j.qposadr[0] for j in joint])
        self.qvel_adr = np.array([j.dofadr[0] for j in joint])
        self.actuators = np.array(
            [
                [self.model.actuator(f"{name}/{side}_wheel").id for side in ("left", "right")]
                for name in self.robots
            ]
        )
        self.apple_geoms = (
            [self.model.geom(f"apple{m}").id for m in range(cfg.n_targets)]
            if cfg.domain == "foraging"
            else []
        )
        controller_config = ControllerConfig(
            limits=GRID_ROBOT_LIMITS,
            geometry=GRID_ROBOT_GEOMETRY,
            arrival_tolerance=self.physics_config.arrival_tolerance,
            settle_time=1.0,
        )
        self.controllers = [WaypointController(controller_config) for _ in self.robots]
        self.image_size = image_size
        self._renderers: dict[tuple[int, int], mujoco.Renderer] = {}
        self.physics_steps = 0  # mj_step calls since construction (for benchmarks)
        # optional callable(sim_seconds_into_macro_step) after each control tick (used for recording)
        self.on_tick = None

    # -- poses ------------------------------------------------------------------------------------------------
    def poses(self) -> np.ndarray:
        """(robots, 3) true base poses x, y, yaw."""
        qpos = self.data.qpos
        xy = np.stack([qpos[self.qpos_adr], qpos[self.qpos_adr + 1]], axis=-1)
        w, z = qpos[self.qpos_adr + 3], qpos[self.qpos_adr + 6]
        x, y = qpos[self.qpos_adr + 4], qpos[self.qpos_adr + 5]
        yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
        return np.concatenate([xy, yaw[:, None]], axis=-1)

    def _place(self, robot: int, cell: np.ndarray, yaw: float = math.pi / 2) -> None:
        adr = self.qpos_adr[robot]
        self.data.qpos[adr : adr + 2] = self.layout.cell_xy(cell)
        self.data.qpos[adr + 2] = 0.0
        self.data.qpos[adr + 3 : adr + 7] = [math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)]
        self.data.qvel[self.qvel_adr[robot] : self.qvel_adr[robot] + 6] = 0.0

    def place(self, robot: int, cell: np.ndarray, yaw: float = math.pi / 2) -> None:
        """Put ``robot`` at rest on ``cell``'s centre with heading ``yaw`` (a teleport: resets, wrapped moves)."""
        self._place(robot, np.asarray(cell), float(yaw))

    def _park(self, robot: int, slot: int) -> None:
        """Move a captured prey out of the arena (beside the east wall)."""
        self._place(robot, np.array([slot, self.layout.cols + 1]))

    def _show_apples(self, state: GridState) -> None:
        top = self.rules.config.n_agents * self.rules.config.max_agent_level
        for m, geom in enumerate(self.apple_geoms):
            level = int(state.target_levels[m])
            body = self.model.geom_bodyid[geom]
            mocap = self.model.body_mocapid[body]
            radius = apple_radius(self.layout, level, top)
            self.model.geom_size[geom, 0] = radius
            self.model.geom_rgba[geom] = apple_rgba(level, top) if state.alive[m] else (0, 0, 0, 0)
            self.data.mocap_pos[mocap] = [*self.layout.cell_xy(state.targets[m]), radius]

    # -- backend protocol -------------------------------------------------------------------------------------
    def reset(self, state: GridState) -> GridState:
        mujoco.mj_resetData(self.model, self.data)
        n = self.rules.config.n_agents
        for i in range(n):
            self._place(i, state.agents[i])
        for m in range(len(self.robots) - n):
            if state.alive[m]:
                self._place(n + m, state.targets[m])
            else:
                self._park(n + m, m)
        self._show_apples(state)
        mujoco.mj_forward(self.model, self.data)
        return self.read_state(state, state.alive)

    def read_state(self, previous: GridState, alive: np.ndarray) -> GridState:
        """The grid state physics shows: robot cells from base positions; apples where they are."""
        cells = self.layout.xy_cell(self.poses()[:, :2])
        n = self.rules.config.n_agents
        targets = previous.targets.copy()
        if self.rules.config.domain == "pursuit":
            targets[alive] = cells[n:][alive]
        return GridState(
            cells[:n].copy(),
            previous.agent_levels.copy(),
            targets,
            previous.target_levels.copy(),
            alive.copy(),
        )

    def execute(self, state: GridState, plan: StepPlan) -> GridState:
        cfg, phys = self.rules.config, self.physics_config
        n = cfg.n_agents
        alive = state.alive & ~plan.completed
        goals = list(plan.agents)
        if cfg.domain == "pursuit":
            goals += list(plan.targets)
        poses = self.poses()
        active = []
        for robot, goal in enumerate(goals):
            if robot >= n and not alive[robot - n]:
                self.controllers[robot].finished = True
                continue
            xy = self.layout.cell_xy(goal)
            if np.hypot(*(xy - poses[robot, :2])) > phys.arrival_tolerance:
                self.controllers[robot].start(poses[robot], [xy])
                active.append(robot)
        ctrl = np.zeros((len(self.robots), 2))
        t, dt = 0.0, phys.timestep * phys.control_period
        while active and t < phys.max_step_time:
            poses = self.poses()
            for robot in active:
                ctrl[robot] = self.controllers[robot].update(t, poses[robot])
            active = [r for r in active if not self.controllers[r].finished]
            self.data.ctrl[self.actuators.ravel()] = ctrl.ravel()
            mujoco.mj_step(self.model, self.data, phys.control_period)
            self.physics_steps += phys.control_period
            t += dt
            if self.on_tick is not None:
                self.on_tick(t)
        self.data.ctrl[:] = 0.0
        for m in np.flatnonzero(plan.completed):
            if cfg.domain == "pursuit":
                self._park(n + m, m)
        next_state = self.read_state(state, alive)
        if cfg.domain == "foraging":
            self._show_apples(next_state)
        mujoco.mj_forward(self.model, self.data)
        return next_state

    # -- rendering --------------------------------------------------------------------------------------------
    def _render(self, camera, size: tuple[int, int]) -> np.ndarray:
        if size not in self._renderers:
            self._renderers[size] = mujoco.Renderer(self.model, height=size[0], width=size[1])
        renderer = self._renderers[size]
        renderer.update_scene(self.data, camera=camera)
        return renderer.render()

    def egocentric_image(self, agent: int = 0) -> np.ndarray:
        """Offscreen RGB image from straight above ``agent``, world-aligned (north up), covering about
        ``view x view`` cells: the image counterpart of the egocentric grid observation."""
        camera = mujoco.MjvCamera()
        camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        camera.lookat[:] = [*self.poses()[agent, :2], 0.0]
        half_fovy = math.radians(self.model.vis.global_.fovy) / 2
        camera.distance = (self.view * self.layout.cell / 2) / math.tan(half_fovy)
        camera.elevation, camera.azimuth = -90.0, 90.0
        return self._render(camera, (self.image_size, self.image_size))

    def render_top(self, size: int = 480) -> np.ndarray:
        """Offscreen RGB image of the overhead camera."""
        return self._render("overhead", (size, size))

    def close(self) -> None:
        for renderer in self._renderers.values():
            renderer.close()
        self._renderers.clear()
