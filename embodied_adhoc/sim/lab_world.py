"""The embodied HOTSPOT lab: MuJoCo physics, the container robot on wheel odometry, the human, balls and RFID.

``LabWorld`` is what the embodied Gymnasium env drives, one macro step (one abstract-model step) at a time::

    world = LabWorld(LabWorldConfig())
    world.reset(seed=0, robot_node=0, human_node=1, ball_nodes=(0, 1, 2))
    result = world.step_macro(robot_target=1, human_command=HumanCommand.move_to(3))
    result.odometry_node, result.rfid_events, world.ground_truth(), world.render("overhead")

During a macro step the robot drives to ``robot_target`` with the waypoint controller tracking its *pose
estimate*, while the human executes its command; the step ends when both are done, when the robot is blocked (its
estimate made no progress for ``stall_seconds``, or the controller gave up short of the goal), or at the timeout.
The estimate is the Monte Carlo localiser's (``sim.localisation``: wheel odometry + the 2D lidar against the
scene's map) or, with ``localisation=None``, wheel odometry alone. The robot-node reading
(``MacroStepResult.robot_node_reading``) is the localiser's area, None ("unknown") when its particles span more
than one area. Everything random (encoder noise, wheel slip, RFID misses, lidar noise, the particle filter)
derives from the reset seed: same seed, same run.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np

from embodied_adhoc.control.reference import wrap_angle
from embodied_adhoc.control.waypoint_controller import ControllerConfig, WaypointController
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.sim.area_sensor import AreaSensor
from embodied_adhoc.sim.human import HumanCommand, HumanSenses, HumanWalker
from embodied_adhoc.sim.lab_layout import LAB_LAYOUT, LabLayout
from embodied_adhoc.sim.lab_model import LabIds, load_lab_model, yaw_of
from embodied_adhoc.sim.lab_render import MAX_PARTICLE_MARKERS, BeliefMarkers, LabRenderer, SnapshotRenderer
from embodied_adhoc.sim.lidar import Lidar, LidarConfig
from embodied_adhoc.sim.localisation import LikelihoodField, LocalisationConfig, MonteCarloLocaliser
from embodied_adhoc.sim.odometry import OdometryConfig, WheelOdometry
from embodied_adhoc.sim.sensing import RfidReader, WallContact

__all__ = ["GroundTruth", "HumanCommand", "LabWorld", "LabWorldConfig", "MacroStepResult"]

RENDER_QUALITIES = ("fast", "high")


@dataclass(frozen=True)
class LabWorldConfig:
    """Settings of the embodied lab.

    Attributes:
        timestep: physics step (s); the scene is tuned for 2-5 ms.
        control_period: controller/odometry/human/RFID tick (s), a whole multiple of ``timestep``.
        controller: waypoint controller limits, gains and arrival tolerance.
        odometry: encoder noise and wheel slip of dead reckoning.
        lidar: range window, noise and dropout of the 2D lidar (``enabled=False``: no scans).
        localisation: particle-filter settings; None = the controller and the robot-node reading use wheel
            odometry alone (no localiser).
        stall_seconds: a moving robot whose pose estimate advances less than 10 cm and 0.2 rad over a window of
            this many simulated seconds is blocked: the macro step ends with ``blocked=True``.
        rfid_miss_probability: chance that the reader misses a ball entering the container (one read per ball).
        area_accuracy: the robot's area sensor reports its area with this probability, else unknown
            (``sim.area_sensor``; the physics lab sets it to the lab model's ``robot_node_accuracy``).
        human_speed: walking speed of the human (m/s).
        macro_timeout: a macro step ends after this many simulated seconds even if unfinished.
        min_macro_seconds: a macro step lasts at least this long (a "stay" still lets time pass).
        sensor_period: the RFID reader and the wall-contact check run this often (s; a whole multiple of
            ``control_period``) and once more at the end of every macro step. A ball in the bin stays there, so
            no read is lost; a wall touch shorter than this can go unreported (it is a diagnostic).
        video_fps: rate (simulated frames per second) at which ``frame_callback`` is called.
        render_width, render_height: default image size of ``render``.
        render_quality: "fast" (no shadows, reflections, floor texture or anti-aliasing: software EGL without
            a GPU renders several times faster) or "high" (everything; what ``render lab`` uses for stills).
        scene: scene file in ``scenes/``.
    """

    timestep: float = 0.004
    control_period: float = 0.02
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    lidar: LidarConfig = field(default_factory=LidarConfig)
    localisation: LocalisationConfig | None = field(default_factory=LocalisationConfig)
    stall_seconds: float = 5.0
    rfid_miss_probability: float = 0.0
    area_accuracy: float = 1.0
    human_speed: float = 1.2
    macro_timeout: float = 60.0
    min_macro_seconds: float = 1.0
    sensor_period: float = 0.1
    video_fps: float = 15.0
    render_width: int = 640
    render_height: int = 512
    render_quality: str = "fast"
    scene: str = "lab.xml"

    def __post_init__(self) -> None:
        if not 0.0005 <= self.timestep <= 0.01:
            raise ConfigError(f"LabWorldConfig.timestep must be in [0.0005, 0.01] s, got {self.timestep}")
        ratio = self.control_period / self.timestep
        if ratio < 1 or abs(ratio - round(ratio)) > 1e-9:
            raise ConfigError(
                f"LabWorldConfig.control_period ({self.control_period}) must be a whole multiple of timestep "
                f"({self.timestep})"
            )
        sensing = self.sensor_period / self.control_period
        if sensing < 1 or abs(sensing - round(sensing)) > 1e-9:
            raise ConfigError(
                f"LabWorldConfig.sensor_period ({self.sensor_period}) must be a whole multiple of control_period "
                f"({self.control_period})"
            )
        if not 0.0 <= self.rfid_miss_probability <= 1.0:
            raise ConfigError(
                f"LabWorldConfig.rfid_miss_probability must be in [0, 1], got {self.rfid_miss_probability}"
            )
        if not 0.0 <= self.area_accuracy <= 1.0:
            raise ConfigError(f"LabWorldConfig.area_accuracy must be in [0, 1], got {self.area_accuracy}")
        if self.render_quality not in RENDER_QUALITIES:
            raise ConfigError(
                f"LabWorldConfig.render_quality must be one of {RENDER_QUALITIES}, got {self.render_quality!r}"
            )
        for name in ("human_speed", "macro_timeout", "video_fps", "stall_seconds"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"LabWorldConfig.{name} must be > 0, got {getattr(self, name)}")


@dataclass(frozen=True)
class MacroStepResult:
    """Outcome of one macro step. Only ``odometry_node`` and ``rfid_events`` are robot observations; the rest is
    ground truth / diagnostics for evaluation."""

    robot_arrived: bool  # the controller reached the target within tolerance (True for "stay")
    odometry_node: int | None  # node of the dead-reckoning pose (None outside every area)
    rfid_events: tuple[int, ...]  # balls read by the RFID reader during this step
    sim_seconds: float
    wall_contact: bool  # the robot touched a wall during this step
    true_robot_node: int | None
    human_node: int
    human_succeeded: bool
    human_status: str
    timed_out: bool
    odometry_error: float  # metres between dead-reckoning and true position at the end of the step
    mujoco_warnings: int  # MuJoCo warnings raised during this step (0 in a healthy run)
    robot_node_reading: int | None = None  # the robot's area reading: localiser (None: unknown) or odometry
    blocked: bool = False  # the robot could not reach its waypoint (stalled, or the controller gave up)
    pose_error: float = 0.0  # metres between the pose estimate the controller tracks and the true position
    localisation_mode: str = (
        "odometry"  # "lidar", "odometry" (localiser without scans) or "off" (no localiser)
    )
    kidnaps: int = 0  # times the localiser declared itself lost during this step


@dataclass(frozen=True)
class GroundTruth:
    """True state of the world (for evaluation and recording, never for the ad hoc agent)."""

    robot_pose: tuple[float, float, float]  # x, y, yaw
    robot_node: int | None
    human_pose: tuple[float, float, float]
    human_node: int
    ball_positions: tuple[tuple[float, float, float], ...]
    ball_states: tuple[str, ...]  # "ground", "held", "container"
    time: float


class LabWorld:
    """The MuJoCo lab world. See the module docstring for the macro-step protocol."""

    def __init__(self, config: LabWorldConfig | None = None, layout: LabLayout = LAB_LAYOUT):
        self.config = config or LabWorldConfig()
        self.layout = layout
        self.model = load_lab_model(self.config.scene)
        self.model.opt.timestep = self.config.timestep
        self.data = mujoco.MjData(self.model)
        self.ids = LabIds.resolve(self.model)
        self.substeps = int(round(self.config.control_period / self.config.timestep))
        # RFID and wall contact every sensor_ticks control ticks: polled every tick they cost a third of the
        # bookkeeping around mj_step (scripts/bench_sim.py, "LabWorld cost / raw mj_step cost")
        self.sensor_ticks = int(round(self.config.sensor_period / self.config.control_period))
        self.controller = WaypointController(self.config.controller)
        self.human = HumanWalker(layout, speed=self.config.human_speed)
        self.odometry = WheelOdometry(self.config.odometry, np.random.default_rng(0))
        self.lidar = Lidar(self.model, self.config.lidar)
        self.area_sensor = AreaSensor(self.config.area_accuracy)  # the robot's area as it observes it
        self._lidar_rng = np.random.default_rng(0)
        self._next_scan = 0.0
        self.localiser: MonteCarloLocaliser | None = None
        if self.config.localisation is not None:
            self.localiser = MonteCarloLocaliser(self._map(), self.config.localisation)
        self.rfid = RfidReader(
            self.model, self.ids, self.config.rfid_miss_probability, np.random.default_rng(0)
        )
        self._renderer = LabRenderer(self.model, self.ids)  # sim.lab_render: cameras, markers, fast quality
        self._next_frame = 0.0
        self._reset_done = False
        self.wall_contact = WallContact(self.ids)
        # control ticks since the reset: the sensors run at their period regardless of actions
        self._ticks = 0
        self._sensed_events: list[int] = []
        self._sensed_wall_contact = False
        self._action_target: int | None = None
        self._action_start = self._progress_time = 0.0
        self._progress_pose = (0.0, 0.0, 0.0)
        self._stalled = False
        self.current_route: tuple[tuple[float, float], ...] = ()
        """Waypoints (xy) the robot follows in the current/last macro step (empty when it stays)."""

    # ------------------------------------------------------------------------------------------ episode
    def reset(
        self, seed: int, robot_node: int, human_node: int, ball_nodes: Sequence[int], robot_yaw: float = 0.0
    ) -> GroundTruth:
        """Place robot, human and balls (ball i on the floor of area ``ball_nodes[i]``), settle the physics and
        start dead reckoning from the robot's known start pose. Returns the ground truth after settling."""
        layout, ids = self.layout, self.ids
        for node in (robot_node, human_node, *ball_nodes):
            layout.check_node(node)
        if len(ball_nodes) != len(ids.ball_bodies):
            raise ConfigError(f"reset: ball_nodes needs {len(ids.ball_bodies)} nodes, got {list(ball_nodes)}")
        # spawn(4)[:2] are the odometry and RFID streams spawn(2) gave before the lidar existed
        odometry_seed, rfid_seed, lidar_seed, localiser_seed = np.random.SeedSequence(int(seed)).spawn(4)
        self.odometry.rng = np.random.default_rng(odometry_seed)
        self._lidar_rng = np.random.default_rng(lidar_seed)
        self.lidar.reset_counts()
        self.rfid.reset(np.random.default_rng(rfid_seed))
        mujoco.mj_resetData(self.model, self.data)
        qpos = self.data.qpos
        x, y = layout.node_waypoints[robot_node]
        half_yaw = 0.5 * robot_yaw
        qpos[ids.root_qpos : ids.root_qpos + 7] = [x, y, 0.075, np.cos(half_yaw), 0, 0, np.sin(half_yaw)]
        for i, node in enumerate(ball_nodes):
            # balls sharing an area lie side by side
            repeat = sum(1 for other in ball_nodes[:i] if other == node)
            bx, by = layout.ball_spots[node]
            qpos[ids.ball_qpos[i] : ids.ball_qpos[i] + 7] = [bx + 0.2 * repeat, by, 0.06, 1, 0, 0, 0]
        self.data.eq_active[:] = 0
        self.human.reset(human_node)
        self.human._face_now(layout.node_waypoints[human_node])
        self.apply_human()
        self.controller.finished = True
        mujoco.mj_forward(self.model, self.data)
        self._physics(int(round(0.3 / self.config.timestep)))  # let wheels and balls settle on the floor
        self.odometry.reset(self.true_robot_pose(), self.data.qpos[ids.wheel_qpos])
        if self.localiser is not None:  # the start pose is known, as for dead reckoning
            self.localiser.reset(
                np.random.default_rng(localiser_seed),
                self.odometry.pose,
                self.true_robot_pose(),
                time=self.data.time,
            )
        self._next_scan = self._scan_time_after(self.data.time)
        self._next_frame = self.data.time
        self._ticks, self._sensed_events, self._sensed_wall_contact = 0, [], False
        self._action_target, self._stalled = None, False
        self._reset_done = True
        return self.ground_truth()

    def step_macro(
        self,
        robot_target: int | None,
        human_command: HumanCommand,
        frame_callback: Callable[[LabWorld], None] | None = None,
    ) -> MacroStepResult:
        """Drive the robot to ``robot_target`` (None: stay) while the human executes ``human_command``: one
        :meth:`start_action`, :meth:`tick` until both are done (or the timeout), then the result."""
        if not self._reset_done:
            raise ConfigError("LabWorld.step_macro called before reset()")
        config, data = self.config, self.data
        self.start_action(robot_target)
        self.human.start(human_command, self.senses())
        start, warnings_before = data.time, self.warning_count()
        kidnaps_before = 0 if self.localiser is None else self.localiser.kidnaps
        while True:
            elapsed = data.time - start
            done = self.controller.finished and self.human.finished and elapsed >= config.min_macro_seconds
            if done or elapsed >= config.macro_timeout:
                break
            self.tick(frame_callback=frame_callback)
        data.ctrl[self.ids.wheel_actuators] = 0.0
        return self.action_result(start, warnings_before, kidnaps_before, with_human=True)

    def action_result(
        self, start: float, warnings_before: int, kidnaps_before: int, with_human: bool
    ) -> MacroStepResult:
        """The outcome of the macro action begun at simulated time ``start``, read now (the RFID reads and wall
        contact since the previous :meth:`sensed`; warnings and re-localisations since the counts given).
        ``with_human``: the step also waited for the human (turn-based): it timed out unless both finished, and an
        unfinished human reads "unfinished (timeout)"; otherwise (real time) the robot's action alone and the
        human's current status."""
        data, controller, human = self.data, self.controller, self.human
        events, wall_contact = self.sensed()
        truth = self.ground_truth()
        estimate = self.pose_estimate()
        human_done = human.finished or not with_human
        return MacroStepResult(
            robot_arrived=controller.arrived,
            odometry_node=self.odometry_node(),
            rfid_events=events,
            sim_seconds=float(data.time - start),
            wall_contact=wall_contact,
            true_robot_node=truth.robot_node,
            human_node=truth.human_node,
            human_succeeded=human_done and human.succeeded,
            human_status=human.status if human_done else "unfinished (timeout)",
            timed_out=not (controller.finished and (human.finished or not with_human)),
            odometry_error=self.odometry_error(),
            mujoco_warnings=self.warning_count() - warnings_before,
            robot_node_reading=self.robot_node_reading(),
            blocked=self.action_blocked(),
            pose_error=float(np.hypot(estimate[0] - truth.robot_pose[0], estimate[1] - truth.robot_pose[1])),
            localisation_mode="off" if self.localiser is None else self.localiser.mode,
            kidnaps=0 if self.localiser is None else self.localiser.kidnaps - kidnaps_before,
        )

    # ------------------------------------------------------------------------------------------ control ticks
    def start_action(self, robot_target: int | None) -> None:
        """Start the robot's macro action: plan the route to ``robot_target`` from the pose estimate and hand it
        to the controller (None: stay, the controller is done at once). :meth:`tick` then drives it; the
        stall detector's window starts now. The human is commanded separately (``human.start``)."""
        if not self._reset_done:
            raise ConfigError("LabWorld.start_action called before reset()")
        estimate = self.pose_estimate()
        if robot_target is not None:
            self.layout.check_node(robot_target)
            self.current_route = tuple(self.layout.route_from(estimate[:2], robot_target))
            self.controller.start(estimate, self.current_route)
        else:
            self.current_route = ()
            self.controller.finished, self.controller.arrived = True, True
        self._action_target = robot_target
        self._action_start = self._progress_time = self.data.time
        self._progress_pose = estimate
        self._stalled = False

    def tick(
        self,
        drive: bool = True,
        human: Callable[[float], None] | None = None,
        frame_callback: Callable[[LabWorld], None] | None = None,
    ) -> None:
        """One control tick (``control_period`` of simulated time): the controller tracks the route of
        :meth:`start_action` on the pose estimate (``drive=False``: the wheels stop, e.g. while the agent
        decides), the human moves (``human(dt)`` if given, else :meth:`tick_human`), the physics runs,
        odometry and the localiser read their sensors (the lidar at its scan rate), and every ``sensor_period``
        the RFID reader and the wall-contact check run (collected by :meth:`sensed`). ``frame_callback`` is
        called once per due video frame.

        A moving robot whose estimate advanced less than 10 cm and 0.2 rad over ``stall_seconds`` is blocked: a
        robot pushing against an obstacle, its wheels spinning, gets lidar corrections that keep its estimate in
        place; the controller is stopped and :meth:`action_blocked` says so."""
        config, data, controller = self.config, self.data, self.controller
        wheels = (0.0, 0.0)
        if drive and not controller.finished:
            estimate = self.pose_estimate()
            if data.time - self._progress_time >= config.stall_seconds:
                pose = self._progress_pose
                moved = (
                    math.hypot(estimate[0] - pose[0], estimate[1] - pose[1]) >= 0.1
                    or abs(wrap_angle(estimate[2] - pose[2])) >= 0.2
                )
                if not moved:
                    controller.finished, controller.arrived = True, False
                    self._stalled = True
                self._progress_pose, self._progress_time = estimate, data.time
            wheels = controller.update(data.time - self._action_start, estimate)
        elif not controller.finished:
            # a robot held still (its agent deciding, a hand-over under way) resumes its route where it stopped:
            # the route's time reference and the stall window wait with it
            self._action_start += config.control_period
            self._progress_time += config.control_period
        data.ctrl[self.ids.wheel_actuators] = wheels
        if human is None:
            self.tick_human(config.control_period)
        else:
            human(config.control_period)
        self._physics(self.substeps)
        self.sense()
        self._ticks += 1
        if self._ticks % self.sensor_ticks == 0:
            self._sensed_events.extend(self.rfid.poll(data))
            self._sensed_wall_contact = self._sensed_wall_contact or self.wall_contact(data)
        while frame_callback is not None and data.time >= self._next_frame - 1e-9:
            frame_callback(self)  # once per due frame (repeats if video_fps exceeds the control rate)
            self._next_frame += 1.0 / config.video_fps

    def tick_human(self, dt: float) -> None:
        """Advance the walker's current command by ``dt`` seconds and apply its grasp/release events and pose
        (an idle human stands still: nothing to update)."""
        if self.human.finished:
            return
        for kind, ball in self.human.tick(dt, self.senses()):
            self.data.eq_active[self.ids.grasp_welds[ball]] = kind == "grasp"
        self.apply_human()

    def sensed(self) -> tuple[tuple[int, ...], bool]:
        """The RFID reads and whether the robot touched a wall since the previous call (or the reset), with one
        more reading now (whatever happened since the last sensor tick); clears both."""
        events = (*self._sensed_events, *self.rfid.poll(self.data))
        wall_contact = self._sensed_wall_contact or self.wall_contact(self.data)
        self._sensed_events, self._sensed_wall_contact = [], False
        return events, wall_contact

    def action_blocked(self) -> bool:
        """The current/last macro action could not reach its goal: the stall detector stopped it, or the
        controller gave up (or ran out of time) short of the goal. False for "stay"."""
        return self._stalled or (self._action_target is not None and not self.controller.arrived)

    def fault_counts(self) -> dict[str, int | float]:
        """The sensor faults injected since the reset, by what they did (diagnostics, never robot observations):

        ``rfid_reads`` balls that entered the container (one read attempt each), ``rfid_misses`` of those the
        reader missed; ``lidar_beams`` beams of the scans the localiser read, ``lidar_dropped_beams`` of those lost
        to dropout or a dead lidar; ``wheel_slip_m`` and ``encoder_noise_m`` metres of wheel travel the radius
        error and the encoder noise added to or removed from the odometry (``WheelOdometry``);
        ``relocalisations`` times the localiser declared itself lost and re-seeded."""
        return {
            "rfid_reads": self.rfid.attempts,
            "rfid_misses": self.rfid.misses,
            "lidar_beams": self.lidar.beams_read,
            "lidar_dropped_beams": self.lidar.dropped_beams,
            "wheel_slip_m": self.odometry.slip_distance,
            "encoder_noise_m": self.odometry.noise_distance,
            "relocalisations": 0 if self.localiser is None else self.localiser.kidnaps,
        }

    def warning_count(self) -> int:
        """MuJoCo warnings raised since the reset (0 in a healthy run)."""
        return int(self.data.warning.number.sum())

    # ------------------------------------------------------------------------------------------ state
    def true_robot_pose(self) -> tuple[float, float, float]:
        q = self.data.qpos[self.ids.root_qpos : self.ids.root_qpos + 7]
        return float(q[0]), float(q[1]), yaw_of(q[3:7])

    def odometry_pose(self) -> tuple[float, float, float]:
        """Dead-reckoning pose (x, y, yaw) from the wheel encoders."""
        return self.odometry.pose_tuple

    def pose_estimate(self) -> tuple[float, float, float]:
        """The pose the controller tracks: the localiser's estimate, or dead reckoning without a localiser."""
        if self.localiser is None:
            return self.odometry_pose()
        return self.localiser.pose

    def robot_node_reading(self) -> int | None:
        """The robot's own area reading: the localiser's area (None = unknown: its particles span more than one
        area, or lie outside every area), or the odometry pose's area without a localiser."""
        if self.localiser is None:
            return self.odometry_node()
        return self.localiser.area(self.layout.node_at, len(self.layout.nodes))

    def _map(self) -> LikelihoodField:
        """The localiser's likelihood field of this scene at the lidar's scan height (built once per world)."""
        data = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, data)
        height = float(data.xpos[self.lidar.body][2]) + self.lidar.height
        return LikelihoodField.from_scene(
            self.model,
            data,
            height,
            self.config.localisation,
            self.lidar.config.max_range,
            self.layout.room_extent,
        )

    def drive(self, wheels: tuple[float, float], seconds: float) -> None:
        """Open-loop: hold wheel speeds (rad/s, left/right) for ``seconds`` of simulated time, with odometry and
        localisation running (for tests and scripted checks; the human and the balls are not updated)."""
        if not self._reset_done:
            raise ConfigError("LabWorld.drive called before reset()")
        self.data.ctrl[self.ids.wheel_actuators] = wheels
        for _ in range(int(round(seconds / self.config.control_period))):
            self._physics(self.substeps)
            self.sense()
        self.data.ctrl[self.ids.wheel_actuators] = 0.0

    def sense(self) -> None:
        """The robot's sensing at a control tick, after its physics (:meth:`tick` and :meth:`drive` call it):
        encoders into odometry, a due lidar scan into the localiser (computed only when the localiser will use it;
        its random numbers are drawn either way). Public so that its cost can be timed apart from the physics
        (``scripts/bench_faults.py``)."""
        data = self.data
        pose = self.odometry.update(data.sensordata[self.ids.wheel_position_sensors])
        if self.localiser is not None:
            scan = None
            if data.time >= self._next_scan - 1e-9:
                if self.localiser.due(pose, data.time):
                    scan = self.lidar.scan(data, self._lidar_rng)
                else:
                    self.lidar.skip(self._lidar_rng)
                self._next_scan = self._scan_time_after(data.time)
            self.localiser.tick(pose, scan, data.time)

    def _scan_time_after(self, time: float) -> float:
        """Simulated time of the lidar's next scan after ``time`` (MuJoCo casts the beams every period)."""
        period = self.lidar.period or self.config.control_period
        return (math.floor(time / period + 1e-9) + 1) * period

    def odometry_node(self) -> int | None:
        """Node of the dead-reckoning pose from the area polygons (None outside every area)."""
        return self.layout.node_at(self.odometry.pose_tuple[:2])

    def odometry_error(self) -> float:
        """Distance (m) between the dead-reckoning and the true robot position."""
        x, y, _ = self.true_robot_pose()
        odometry_x, odometry_y, _ = self.odometry.pose_tuple
        return float(np.hypot(odometry_x - x, odometry_y - y))

    def ground_truth(self) -> GroundTruth:
        ids, data = self.ids, self.data
        robot = self.true_robot_pose()
        balls = data.xpos[ids.ball_bodies]
        inside = self.rfid.inside_mask(data).tolist()
        held = data.eq_active[ids.grasp_welds].tolist()
        states = tuple(
            "held" if held[i] else ("container" if inside[i] else "ground")
            for i in range(len(ids.ball_bodies))
        )
        return GroundTruth(
            robot_pose=robot,
            robot_node=self.layout.node_at(robot[:2]),
            human_pose=(float(self.human.xy[0]), float(self.human.xy[1]), float(self.human.yaw)),
            human_node=self.human.node,
            ball_positions=tuple(tuple(float(v) for v in p) for p in balls),
            ball_states=states,
            time=float(data.time),
        )

    # ------------------------------------------------------------------------------------------ rendering
    def render(
        self,
        camera: str = "overhead",
        width: int | None = None,
        height: int | None = None,
        markers: bool = False,
    ) -> np.ndarray:
        """An RGB image (uint8, H x W x 3) from a named camera ("overhead", "perspective", "robot").

        ``markers`` (overhead camera only): draw what the robot believes above it, beside the true robot: the
        localiser's particles (blue dots), its estimate (blue square with a heading bar) and the odometry pose
        (orange square with a heading bar); flat boxes, the cheapest geoms for software rendering."""
        width = width or self.config.render_width
        height = height or self.config.render_height
        high = self.config.render_quality == "high"
        markers_drawn = self.belief_markers() if markers else None
        return self._renderer.render(self.data, camera, width, height, high, markers_drawn)

    def belief_markers(self) -> BeliefMarkers:
        """What :meth:`render` draws with ``markers``: the localiser's particles (at most ``MAX_PARTICLE_MARKERS``,
        evenly strided) and estimate, and the odometry pose (copies)."""
        particles = estimate = None
        if self.localiser is not None:
            cloud = self.localiser.particles
            particles = cloud[:: max(1, len(cloud) // MAX_PARTICLE_MARKERS), :2].copy()
            estimate = tuple(float(v) for v in self.localiser.pose)
        return BeliefMarkers(particles, estimate, tuple(float(v) for v in self.odometry_pose()))

    def snapshot_renderer(self) -> SnapshotRenderer:
        """A renderer of this world's snapshots for another thread (``sim.lab_render``): ``take(world.data,
        world.belief_markers())`` on the simulation thread, ``render(...)`` on its own."""
        return SnapshotRenderer(self.model, self.ids)

    def close(self) -> None:
        """Release the offscreen renderers (their GL contexts)."""
        self._renderer.close()

    def __enter__(self) -> LabWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------------------------------ internals
    def _physics(self, steps: int) -> None:
        mujoco.mj_step(self.model, self.data, nstep=steps)

    def senses(self) -> HumanSenses:
        """What the human perceives now (ball and container positions, the robot's heading and area)."""
        ids, data = self.ids, self.data
        robot = self.true_robot_pose()
        return HumanSenses(
            ball_positions=data.xpos[ids.ball_bodies].copy(),
            container_position=data.site_xpos[ids.rfid_site].copy(),
            robot_yaw=robot[2],
            robot_node=self.layout.node_at(robot[:2]),
        )

    def apply_human(self) -> None:
        """Move the human's and its hand's mocap bodies to the walker's pose."""
        ids, data = self.ids, self.data
        data.mocap_pos[ids.human_mocap], data.mocap_quat[ids.human_mocap] = self.human.body_pose()
        data.mocap_pos[ids.hand_mocap], data.mocap_quat[ids.hand_mocap] = self.human.hand_pose()
