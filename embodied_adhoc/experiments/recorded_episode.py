"""One recorded toxic-waste episode on physics: what ``embodied-adhoc run toxic-waste`` runs.

Seeds, episode draw, agent construction and the loop are exactly those of the trial runner (the ``toxic-waste``
trial domain and :func:`embodied_adhoc.experiments.episode.run_episode_loop`), so ``run --seed S`` replays
episode 0 of ``trials toxic-waste --backend mujoco --seed S`` for the same agent. On top, an observer records every
step: video frames (overhead camera at the rate the video keeps, the final state held for ``video_hold`` seconds),
a rerun recording and ``metrics.json``. Recorders are closed in ``finally``: an interrupted run keeps what it
finished.

The simulation thread only copies what each kept frame shows (``sim.lab_render``: ``mj_copyData`` and the belief
markers, microseconds); :class:`LabFrames` renders it on a render thread, which hands the picture to the video
writer's thread (heads-up text, H.264 through ffmpeg) and to the rerun recorder's (JPEG). Rendering (MuJoCo releases
the GIL while it draws), the text, the JPEGs and the encoder thus run beside the simulation instead of after it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from embodied_adhoc.domains.confusion import DEFAULT_CONFUSION
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.episode import EpisodeObserver, EpisodeTrace, StepRecord, run_episode_loop

ENV_ID = "EmbodiedAdhoc/ToxicWaste-v0"
HUD_ORDER = ("balls", "action", "heard", "belief")


@dataclass(frozen=True)
class EpisodeConfig:
    """What one ``run toxic-waste`` episode is (CLI flags map one to one)."""

    agent: str = "hotspot"
    seed: int = 0
    task: int | None = None
    robot_node: int | None = None
    human_node: int | None = None
    human_epsilon: float = 0.05
    communication: bool = True
    speech: str = "channel"
    confusion: str = DEFAULT_CONFUSION
    max_steps: int = 100
    record_dir: Path | None = None
    # 10 frames per 4 simulated seconds: the robot moves ~20 cm a frame, each macro step's heads-up text stays
    # ~2 s on screen, and recording costs a small multiple of the bare episode (scripts/bench_sim.py)
    video_fps: float = 10.0
    video_speed: float = 4.0  # simulated seconds per second of video (time-lapse keeps rendering affordable)
    video_hold: float = 1.0  # seconds of video that show the final state
    render_quality: str = "fast"
    width: int = 640
    height: int = 480
    rerun_camera_hz: float = 2.0
    video_overlay: bool = True  # heads-up text (step, action, what was heard, task belief) on the video
    env_kwargs: dict = field(default_factory=dict)
    faults: dict = field(default_factory=dict)  # experiments.domains.toxic_waste.FAULTS name -> value
    localisation: bool = True  # False: wheel odometry alone
    localisation_model: str | None = None  # the agent's robot-node model: None (thesis), "measured" or a path
    model_rfid_miss: float | None = None  # the agent's RFID miss model: None = the rfid_miss fault's value


@dataclass
class EpisodeOutcome:
    metrics: dict[str, Any]
    files: dict[str, Path]
    video_frames: int = 0


def describe_observation(library, observation_index: int) -> str:
    """The decoded observation in words: odometry node, human node heard, RFID."""
    z = library.decode_observation(observation_index)
    names = library.graph.names
    robot = "unknown" if z.robot_node is None else f"{z.robot_node} {names[z.robot_node]}"
    human = "none" if z.human_node is None else f"{z.human_node} {names[z.human_node]}"
    return f"robot at {robot}; human at {human}; rfid {'YES' if z.rfid else 'no'}"


def action_label(library, action: int, target: int | None) -> str:
    """A macro action by what it does: a move by the node it drives to (``env.move_target``), else its name."""
    if target is None:
        return library.action_names[action]
    return f"move to {target} {library.graph.names[target]}"


class _Progress(EpisodeObserver):
    def __init__(self, progress: Callable[[int, dict], None]):
        self.progress = progress

    def step_finished(self, record: StepRecord) -> None:
        self.progress(record.step, record.info)


def localisation_fields(info: dict) -> dict:
    """The localisation outcome of a physics step for ``metrics.json``: errors (m), mode, blocked, kidnaps."""
    return {
        "pose_error_m": round(float(info["pose_error"]), 4),
        "odometry_error_m": round(float(info["odometry_error"]), 4),
        "localisation_mode": info["localisation_mode"],
        "robot_node_reading": info["robot_node_reading"],
        "true_robot_node": info["robot_node"],
        "blocked": bool(info["blocked"]),
        "kidnaps": int(info["kidnaps"]),
    }


def localisation_events(info: dict) -> list[str]:
    """Lines for the recording's event log: a blocked robot, a lost localiser, a lidar that gives nothing."""
    lines = []
    if info.get("blocked"):
        lines.append(
            f"robot blocked: it could not reach its waypoint (pose error {info['pose_error']:.2f} m)"
        )
    if info.get("kidnaps"):
        lines.append(f"localiser lost: re-localised globally {info['kidnaps']} time(s)")
    if info.get("localisation_mode") == "odometry":
        lines.append("no lidar scans: localisation degraded to odometry")
    return lines


class MetricsObserver(EpisodeObserver):
    """Feeds :class:`~embodied_adhoc.record.metrics.EpisodeMetrics` (``metrics.json``) from the loop's hooks; each
    recorded run's subclass says what a step adds (``step_finished``)."""

    def __init__(self, metrics):
        self.metrics = metrics

    def episode_started(self, info: dict, task_posterior) -> None:
        self.metrics.start_episode(task_posterior)

    def step_started(self, step: int) -> None:
        self.metrics.start_step()

    def episode_finished(self, trace: EpisodeTrace) -> None:
        self.metrics.finish(success=trace.success, truncated=trace.truncated)


class _Metrics(MetricsObserver):
    """The toxic-waste step: decoded observation, utterances and, on physics, the localisation outcome."""

    def __init__(self, metrics, library):
        super().__init__(metrics)
        self.library = library

    def step_finished(self, record: StepRecord) -> None:
        from embodied_adhoc.decision.agents.task_beliefs import normalised_entropy

        posterior = record.task_posterior
        entropy = None if posterior is None else max(0.0, float(normalised_entropy(posterior)))
        self.metrics.end_step(
            record.action,
            describe_observation(self.library, record.observation_index),
            record.reward,
            record.info["sim_time"],
            posterior,
            entropy,
            record.info["utterances"],
        )
        if "pose_error" in record.info:
            self.metrics.per_step[-1].update(localisation_fields(record.info))
        if "faults" in record.info:
            self.metrics.faults = dict(record.info["faults"])

    def episode_finished(self, trace: EpisodeTrace) -> None:
        super().episode_finished(trace)
        if self.metrics.faults is not None:
            from embodied_adhoc.experiments.domains.toxic_waste import cap_reason

            capped = trace.truncated and not trace.success
            code, detail = cap_reason(trace.actions, self.metrics.faults, self.library.action_names, capped)
            self.metrics.cap_reason = {"code": code, "detail": detail} if code else None


class LabFrames:
    """The lab's pictures for the recorders, rendered on one render thread (``record.worker``) from snapshots the
    simulation thread takes (``LabWorld.snapshot_renderer``): a frame goes to ``video`` (with ``overlay`` lines,
    ``repeat`` times) and/or to ``rerun`` as ``camera/<name>`` at a given step and time. Frames are rendered in the
    order they were taken. The render thread makes its GL context as soon as it starts, not at the first frame
    (``prepared`` is set then; making it holds the GIL, which is slow with software EGL, once per recording). At
    most ``max_queued`` snapshots wait (an ``MjData`` copy each, ~40 kB for the lab; the simulation waits only when
    rendering falls that far behind). :meth:`close` renders what is queued and releases the GL context (the
    recorders are closed after it)."""

    def __init__(self, world, width: int, height: int, video, rerun, max_queued: int = 128):
        from embodied_adhoc.record.worker import BackgroundWorker

        self.world, self.video, self.rerun = world, video, rerun
        self.width, self.height = int(width), int(height)
        self.high = world.config.render_quality == "high"
        self.prepared = threading.Event()
        self._renderer = world.snapshot_renderer()
        self._worker = BackgroundWorker(
            self._render,
            f"render {video.path.name}",
            max_queued,
            finish=self._renderer.close,
        )
        self._worker.submit(None)  # make the GL context now, not at the first frame

    def submit(
        self,
        camera: str = "overhead",
        markers: bool = True,
        overlay: Sequence[str] | None = None,
        repeat: int = 1,
        camera_log: tuple[str, int, float] | None = None,
    ) -> None:
        """Take the world's picture now (``markers``: the belief drawn on the overhead camera), for the video
        (``repeat`` frames with ``overlay``; 0: not in the video) and, with ``camera_log`` = (name, step, sim_time),
        for rerun's ``camera/<name>``; simulation thread."""
        world = self.world
        snapshot = self._renderer.take(world.data, world.belief_markers() if markers else None)
        self._worker.submit(
            (snapshot, camera, markers, None if overlay is None else tuple(overlay), int(repeat), camera_log)
        )

    def _render(self, item: tuple | None) -> None:
        if item is None:
            self._renderer.prepare(self.width, self.height, self.high)
            self.prepared.set()
            return
        snapshot, camera, markers, overlay, repeat, camera_log = item
        frame = self._renderer.render(snapshot, camera, self.width, self.height, self.high, markers)
        if repeat > 0:
            self.video.write(frame, overlay, repeat=repeat)
        if camera_log is not None:
            name, step, sim_time = camera_log
            self.rerun.log_camera(name, frame, step=step, sim_time=sim_time)

    def close(self) -> None:
        self._worker.close()


class _Recording(EpisodeObserver):
    """Video and rerun recording of a physics episode, fed by the env's frame sink and the loop's hooks; the
    pictures are rendered off the simulation thread (:class:`LabFrames`)."""

    def __init__(self, config: EpisodeConfig, env, library, spec: dict, files: dict[str, Path]):
        from embodied_adhoc.record.rerun_recorder import RerunRecorder
        from embodied_adhoc.record.video import VideoWriter

        self.config, self.env, self.library, self.spec = config, env, library, spec
        folder = Path(config.record_dir)
        folder.mkdir(parents=True, exist_ok=True)
        files["video"] = folder / "episode.mp4"
        files["rerun"] = folder / "episode.rrd"
        self.video = VideoWriter(files["video"], config.width, config.height, fps=config.video_fps)
        name = f"toxic-waste {config.agent} seed {config.seed}"
        self.rerun = RerunRecorder(files["rerun"], recording_name=name)
        self.frames = LabFrames(env.unwrapped.world, config.width, config.height, self.video, self.rerun)
        self.hud: dict[str, str] = {}
        self.labels: dict[int, str] = {}
        self._sim_time = 0.0
        self._next_camera = 0.0
        self._camera_period = 1.0 / config.rerun_camera_hz if config.rerun_camera_hz > 0 else float("inf")
        env.unwrapped.set_frame_sink(self._on_frame)

    def _overlay(self, sim_time: float) -> list[str] | None:
        if not self.config.video_overlay:
            return None
        return [self.hud[key] for key in HUD_ORDER if key in self.hud] + [f"t = {sim_time:.1f} s"]

    def _hud_belief(self, posterior, info: dict) -> None:
        disposed = sum(1 for status in info["ball_status"] if status == 2)
        self.hud["balls"] = f"{self.config.agent} | balls in container {disposed}/{len(info['ball_status'])}"
        if posterior is not None:
            beliefs = "  ".join(
                f"{list(task)} {p:.2f}" for task, p in zip(self.library.tasks, posterior, strict=True)
            )
            self.hud["belief"] = f"P(task): {beliefs}"

    def _on_frame(self, snapshot: dict) -> None:
        """Every frame the env passes is a frame of the video (the overhead camera with the belief markers); rerun
        gets its poses, and the image of the first frame in each ``1 / rerun_camera_hz`` slot of simulated
        time."""
        camera_due = snapshot["sim_time"] + 1e-9 >= self._next_camera
        self.frames.submit(
            "overhead",
            markers=True,
            overlay=self._overlay(snapshot["sim_time"]),
            camera_log=("overhead", snapshot["step"], snapshot["sim_time"]) if camera_due else None,
        )
        self.rerun.set_time(snapshot["step"], snapshot["sim_time"])
        self.rerun.log_poses(
            snapshot["robot_pose"],
            snapshot["odometry_pose"],
            snapshot["human_position"],
            snapshot["ball_positions"],
        )
        if "estimated_pose" in snapshot:
            self.rerun.log_localisation(
                snapshot["estimated_pose"], snapshot["particles"] if camera_due else None
            )
        if camera_due:
            # the camera keeps its own clock: frames are sparser than its rate (10 fps at 4x: one every 0.4 s), so
            # "one period after this frame" would log every second frame only (1.25 Hz instead of 2)
            while self._next_camera <= snapshot["sim_time"] + 1e-9:
                self._next_camera += self._camera_period

    # -- loop hooks ---------------------------------------------------------------------------------------
    def episode_started(self, info: dict, task_posterior) -> None:
        from embodied_adhoc.decision.agents.task_beliefs import normalised_entropy

        self._hud_belief(task_posterior, info)
        self._sim_time = float(info["sim_time"])
        rerun, layout = self.rerun, self.env.unwrapped.layout
        x0, x1, y0, y1 = layout.room_extent
        rerun.log_lab(
            np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]),
            {
                f"{n} {name}": np.asarray(polygon)
                for n, (name, polygon) in enumerate(zip(layout.node_names, layout.area_polygons, strict=True))
            },
            layout.node_waypoints,
            layout.node_names,
            layout.edges,
        )
        rerun.set_time(0, info["sim_time"])
        rerun.log_poses(
            info["robot_pose"], info["odometry_pose"], info["human_position"], info["ball_positions"]
        )
        if task_posterior is not None:
            rerun.log_belief(task_posterior, float(normalised_entropy(task_posterior)))
        tasks = ", ".join(f"{k}: balls at {list(t)}" for k, t in enumerate(self.library.tasks))
        rerun.log_text(
            "events",
            f"start: robot at node {self.spec['robot_node']}, human at node {self.spec['human_node']}; "
            f"task library {tasks}",
        )

    def action_chosen(self, step: int, action: int) -> None:
        label = action_label(self.library, action, self.env.unwrapped.move_target(action))
        self.labels[step] = label
        self.hud["action"] = f"step {step}: {label}"

    def step_finished(self, record: StepRecord) -> None:
        from embodied_adhoc.decision.agents.task_beliefs import normalised_entropy

        step, info, posterior, rerun = record.step, record.info, record.task_posterior, self.rerun
        description = describe_observation(self.library, record.observation_index)
        rerun.set_time(step, info["sim_time"])
        rerun.log_text("actions", f"step {step}: {self.labels[step]}")
        rerun.log_text("observations", f"step {step}: {description}")
        for line in info.get("utterances", ()):
            rerun.log_text("utterances", line)
        if info.get("speech_audio") is not None:
            rerun.log_audio(info["speech_audio"])
        if info.get("rfid_event"):
            rerun.log_text("events", f"step {step}: a ball entered the container")
        for line in localisation_events(info):
            rerun.log_text("events", f"step {step}: {line}", level="WARN")
        if posterior is not None:
            rerun.log_belief(posterior, max(0.0, float(normalised_entropy(posterior))))
        self.frames.submit("robot", markers=False, repeat=0, camera_log=("robot", step, info["sim_time"]))
        self._hud_belief(posterior, info)
        self._sim_time = float(info["sim_time"])
        self.hud["heard"] = f"observed: {description}"

    def episode_finished(self, trace: EpisodeTrace) -> None:
        """The video ends on the final state (rendered now, with the final belief and ball count), held for
        ``video_hold`` seconds; rerun gets the outcome."""
        outcome = "success" if trace.success else "truncated"
        self.rerun.log_text("events", f"outcome: {outcome} after {trace.steps} steps")
        self.hud["action"] = f"done after {trace.steps} steps: {outcome}"
        hold = max(1, round(self.config.video_hold * self.config.video_fps))
        self.frames.submit("overhead", markers=False, overlay=self._overlay(self._sim_time), repeat=hold)

    def close(self) -> None:
        try:
            self.frames.close()
        finally:
            try:
                self.video.close()
            finally:
                self.rerun.close()


@dataclass
class EpisodeSetup:
    """What one ``run toxic-waste`` episode is built from (:func:`prepare_episode`): the trial domain's options, the
    episode drawn for seed ``config.seed`` (``spec``), the physics session and the env's keyword arguments."""

    options: dict
    spec: dict
    session: Any
    env_kwargs: dict


def prepare_episode(config: EpisodeConfig) -> EpisodeSetup:
    """Options, episode 0 of ``config.seed`` (start nodes overridden by the config), the physics session and the env
    kwargs (rendering only with a record folder, exactly the frames the video keeps) of ``config``: shared by
    :func:`run_episode` and the real-time episode (``live.episode``), so both start from the same state."""
    from embodied_adhoc.experiments import seeding
    from embodied_adhoc.experiments.registry import get_trial_domain

    if not (config.video_fps > 0 and config.video_speed > 0 and config.video_hold >= 0):
        raise ConfigError(
            f"--video-fps ({config.video_fps}) and --video-speed ({config.video_speed}) must be > 0, "
            f"video_hold ({config.video_hold}) >= 0"
        )
    domain = get_trial_domain("toxic-waste")
    options = domain.options(
        human_epsilon=config.human_epsilon,
        communication=config.communication,
        task=config.task,
        confusion=config.confusion,
        faults=config.faults,
        localisation=config.localisation,
        localisation_model=config.localisation_model,
        model_rfid_miss=config.model_rfid_miss,
    )
    spec = domain.episode_spec(options, seeding.episode_rng(config.seed, 0))
    for key in ("robot_node", "human_node"):
        if getattr(config, key) is not None:
            spec[key] = int(getattr(config, key))
    session = domain.open_session("mujoco", options)
    env_kwargs = {
        **session.env_kwargs,
        "render_mode": "rgb_array" if config.record_dir is not None else None,
        "width": int(config.width),
        "height": int(config.height),
        "speech": config.speech,
        "render_quality": config.render_quality,
        # the video keeps video_fps frames per video_speed simulated seconds: the env renders exactly those
        "frame_rate": config.video_fps / config.video_speed,
        **config.env_kwargs,
    }
    return EpisodeSetup(options, spec, session, env_kwargs)


def episode_metrics(config: EpisodeConfig, setup: EpisodeSetup, command: str, **settings):
    """The episode's :class:`~embodied_adhoc.record.metrics.EpisodeMetrics` (``metrics.json``), its configuration
    naming ``command`` and any further ``settings``."""
    from embodied_adhoc.experiments.stats import identify_step
    from embodied_adhoc.record.metrics import EpisodeMetrics

    return EpisodeMetrics(
        config={
            "command": command,
            "agent": config.agent,
            "seed": config.seed,
            "spec": setup.spec,
            "options": setup.options,
            "speech": config.speech,
            "max_steps": config.max_steps,
            **settings,
        },
        true_task=int(setup.spec["task"]),
        identify=identify_step,
    )


def run_episode(config: EpisodeConfig, progress: Callable[[int, dict], None] | None = None) -> EpisodeOutcome:
    """Run (and, with ``config.record_dir``, record) one episode; ``progress(step, info)`` after each step."""
    import gymnasium

    import embodied_adhoc.envs  # noqa: F401  (registers the ids)
    from embodied_adhoc.experiments import seeding

    setup = prepare_episode(config)
    session, library = setup.session, setup.session.library
    # the step cap is the registered TimeLimit's, set to --max-steps
    env = gymnasium.make(
        ENV_ID, max_episode_steps=int(config.max_steps), disable_env_checker=True, **setup.env_kwargs
    )
    from embodied_adhoc.experiments.domains.toxic_waste import DOMAIN
    from embodied_adhoc.experiments.registry import build_agent

    agent = build_agent(
        DOMAIN, session, config.agent, setup.spec, seeding.agent_seed(config.seed, 0, config.agent)
    )
    human = {"human": config.env_kwargs["human"]} if "human" in config.env_kwargs else {}  # a plug-in human
    metrics = episode_metrics(config, setup, "run toxic-waste", **human)
    recording = config.record_dir is not None
    return play_recorded_episode(
        env,
        agent,
        session,
        setup.spec,
        config,
        metrics,
        [_Metrics(metrics, library)],
        (lambda files: _Recording(config, env, library, setup.spec, files)) if recording else None,
        progress,
    )


def play_recorded_episode(
    env,
    agent,
    session,
    spec: dict,
    config,
    metrics,
    observers: list[EpisodeObserver],
    open_recorder: Callable[[dict], EpisodeObserver] | None,
    progress: Callable[[int, dict], None] | None = None,
    later: Sequence[EpisodeObserver] = (),
    interruptions: tuple[type[BaseException], ...] = (),
) -> EpisodeOutcome:
    """Episode 0 of ``config.seed`` for ``config.agent`` (the trial runner's seeds) through the one loop, with
    ``observers``, a recorder from ``open_recorder(files)`` (it adds its files; None: no recording), a progress
    callback and ``later`` observers (called after the recorder); the recorder and the env are closed and
    ``metrics.json`` written even when the loop raises. An exception of a type in ``interruptions`` ends the episode
    as interrupted (``metrics.json`` says so; the recorders keep what they have) instead of propagating.
    ``run toxic-waste``, ``run pursuit``, ``run foraging`` and the real-time episode (``live.episode``) share it."""
    from embodied_adhoc.experiments import seeding

    files: dict[str, Path] = {}
    observers = list(observers)
    recorder = None
    try:
        if open_recorder is not None:
            recorder = open_recorder(files)
            observers.append(recorder)
        if progress is not None:
            observers.append(_Progress(progress))
        run_episode_loop(
            env,
            agent,
            env_seed=seeding.env_seed(config.seed, 0, config.agent),
            agent_rng=seeding.agent_rng(config.seed, 0, config.agent),
            reset_options=session.reset_options(spec),
            max_steps=config.max_steps,
            observation_index=session.observation_index,
            observers=[*observers, *later],
        )
    except interruptions:
        pass  # metrics.json says "interrupted"; the recorders keep what they have
    finally:
        try:
            if recorder is not None:
                recorder.close()
        finally:
            env.close()
            if open_recorder is not None:
                files["metrics"] = metrics.write(Path(config.record_dir) / "metrics.json")
    return EpisodeOutcome(metrics.summary(), files, 0 if recorder is None else recorder.video.frame_count)
