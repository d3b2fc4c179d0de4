"""One recorded toxic-waste episode on physics: the loop behind ``embodied-adhoc run toxic-waste``.

Seeds, episode draw, agent construction and the act/step/observe loop are exactly those of the trial runner
(``experiments.trial.run_trial`` through the ``toxic-waste`` trial domain), so ``run --seed S`` replays episode 0
of ``trials toxic-waste --backend mujoco --seed S`` for the same agent. On top, every macro step is recorded:
video frames (overhead camera, fixed fps of simulated time), a rerun recording and ``metrics.json``.
Recorders are closed in ``finally``: an interrupted run keeps what it finished.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from embodied_adhoc.domains.confusion import DEFAULT_CONFUSION
from embodied_adhoc.errors import ConfigError

ENV_ID = "EmbodiedAdhoc/ToxicWaste-v0"


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
    video_fps: float = 15.0
    video_speed: float = 4.0  # simulated seconds per second of video (time-lapse keeps rendering affordable)
    render_quality: str = "fast"
    width: int = 640
    height: int = 480
    rerun_camera_hz: float = 2.0
    video_overlay: bool = True  # heads-up text (step, action, what was heard, task belief) on the video
    env_kwargs: dict = field(default_factory=dict)


@dataclass
class EpisodeOutcome:
    metrics: dict[str, Any]
    files: dict[str, Path]
    video_frames: int = 0


def _describe_observation(library, observation_index: int) -> str:
    z = library.decode_observation(observation_index)
    names = library.graph.names
    robot = "unknown" if z.robot_node is None else f"{z.robot_node} {names[z.robot_node]}"
    human = "none" if z.human_node is None else f"{z.human_node} {names[z.human_node]}"
    return f"robot at {robot}; human at {human}; rfid {'YES' if z.rfid else 'no'}"


def run_episode(config: EpisodeConfig, progress: Callable[[int, dict], None] | None = None) -> EpisodeOutcome:
    """Run (and, with ``config.record_dir``, record) one episode; ``progress(step, info)`` after each step."""
    import gymnasium

    import embodied_adhoc.envs  # noqa: F401  (registers the ids)
    from embodied_adhoc.decision.agents.task_beliefs import normalised_entropy
    from embodied_adhoc.experiments import seeding
    from embodied_adhoc.experiments.registry import get_trial_domain
    from embodied_adhoc.record.metrics import EpisodeMetrics

    domain = get_trial_domain("toxic-waste")
    options = domain.options(
        human_epsilon=config.human_epsilon,
        communication=config.communication,
        task=config.task,
        confusion=config.confusion,
    )
    spec = domain.episode_spec(options, seeding.episode_rng(config.seed, 0))
    if config.robot_node is not None:
        spec["robot_node"] = int(config.robot_node)
    if config.human_node is not None:
        spec["human_node"] = int(config.human_node)
    session = domain.open_session("mujoco", options)
    library = session.library
    recording = config.record_dir is not None
    if not (config.video_fps > 0 and config.video_speed > 0):
        raise ConfigError(
            f"--video-fps ({config.video_fps}) and --video-speed ({config.video_speed}) must be > 0"
        )
    kwargs = {
        **session.env_kwargs,
        "max_episode_steps": int(config.max_steps),
        "render_mode": "rgb_array" if recording else None,
        "width": int(config.width),
        "height": int(config.height),
        "speech": config.speech,
        "render_quality": config.render_quality,
        "frame_rate": config.video_fps / config.video_speed,
        **config.env_kwargs,
    }
    # max_episode_steps is the env's own kwarg (gymnasium.make keeps that keyword for TimeLimit): pass it by spec.
    spec_with_kwargs = dataclasses.replace(
        gymnasium.spec(ENV_ID), kwargs={**gymnasium.spec(ENV_ID).kwargs, **kwargs}
    )
    env = gymnasium.make(spec_with_kwargs, disable_env_checker=True)
    agent = session.make_agent(config.agent, spec, seeding.agent_seed(config.seed, 0, config.agent))
    metrics = EpisodeMetrics(
        config={
            "command": "run toxic-waste",
            "agent": config.agent,
            "seed": config.seed,
            "spec": spec,
            "options": options,
            "speech": config.speech,
            "max_steps": config.max_steps,
        },
        true_task=int(spec["task"]),
    )
    files: dict[str, Path] = {}
    video = rerun = None
    hud: dict[str, str] = {}
    try:
        if recording:
            video, rerun = _open_recorders(config, files)
            _attach_frame_sink(env, config, video, rerun, hud if config.video_overlay else None)
        _, info = env.reset(
            seed=seeding.env_seed(config.seed, 0, config.agent), options=session.reset_options(spec)
        )
        privileged = bool(getattr(agent, "observes_state", False))
        agent.reset(
            seeding.agent_rng(config.seed, 0, config.agent), state=info["state"] if privileged else None
        )
        prior = agent.task_posterior
        hud.update(_hud_belief(library, prior, info, config.agent))
        metrics.start_episode(prior)
        if rerun is not None:
            _log_start(rerun, env, info, library, spec, prior, normalised_entropy)
        for step in range(1, config.max_steps + 1):
            metrics.start_step()
            action = int(agent.act())
            hud["action"] = f"step {step}: {library.action_names[action]}"
            _, reward, terminated, truncated, info = env.step(action)
            observation_index = int(info["observation_index"])
            agent.observe(action, observation_index, state=info["state"] if privileged else None)
            posterior = agent.task_posterior
            entropy = (
                None if posterior is None else max(0.0, float(normalised_entropy(np.asarray(posterior))))
            )
            description = _describe_observation(library, observation_index)
            metrics.end_step(
                action, description, float(reward), info["sim_time"], posterior, entropy, info["utterances"]
            )
            if rerun is not None:
                _log_step(rerun, step, info, library.action_names[action], description, posterior, entropy)
                rerun.log_camera("robot", env.unwrapped.render_camera("robot"))
            hud.update(_hud_belief(library, posterior, info, config.agent))
            hud["heard"] = f"observed: {description}"
            if progress is not None:
                progress(step, info)
            if terminated or truncated:
                metrics.finish(success=bool(terminated), truncated=bool(truncated))
                break
        else:
            metrics.finish(success=False, truncated=True)
        if rerun is not None:
            rerun.log_text("events", f"outcome: {metrics.outcome} after {len(metrics.per_step)} steps")
    finally:
        env.close()
        if video is not None:
            video.close()
        if rerun is not None:
            rerun.close()
        if recording:
            files["metrics"] = metrics.write(Path(config.record_dir) / "metrics.json")
    return EpisodeOutcome(metrics.summary(), files, 0 if video is None else video.frame_count)


def _open_recorders(config: EpisodeConfig, files: dict[str, Path]):
    from embodied_adhoc.record.rerun_recorder import RerunRecorder
    from embodied_adhoc.record.video import VideoWriter

    folder = Path(config.record_dir)
    folder.mkdir(parents=True, exist_ok=True)
    files["video"] = folder / "episode.mp4"
    files["rerun"] = folder / "episode.rrd"
    video = VideoWriter(files["video"], config.width, config.height, fps=config.video_fps)
    name = f"toxic-waste {config.agent} seed {config.seed}"
    return video, RerunRecorder(files["rerun"], recording_name=name)


def _hud_belief(library, posterior, info: dict, agent: str) -> dict[str, str]:
    """Heads-up lines for the video: the task belief and the balls in the container so far."""
    disposed = sum(1 for status in info["ball_status"] if status == 2)
    lines = {"balls": f"{agent} | balls in container {disposed}/{len(info['ball_status'])}"}
    if posterior is not None:
        beliefs = "  ".join(f"{list(task)} {p:.2f}" for task, p in zip(library.tasks, posterior, strict=True))
        lines["belief"] = f"P(task): {beliefs}"
    return lines


def _attach_frame_sink(env, config: EpisodeConfig, video, rerun, hud: dict[str, str] | None) -> None:
    """Every rendered frame goes to the video (with the heads-up text unless ``hud`` is None); rerun gets the
    poses of every frame and the camera image at ``rerun_camera_hz`` of simulated time."""
    from embodied_adhoc.record.overlay import annotate

    state = {"next_camera": 0.0}
    camera_period = 1.0 / config.rerun_camera_hz if config.rerun_camera_hz > 0 else float("inf")
    order = ("balls", "action", "heard", "belief")

    def on_frame(frame: np.ndarray, snapshot: dict) -> None:
        if hud is None:
            video.write(frame)
        else:
            lines = [hud[key] for key in order if key in hud] + [f"t = {snapshot['sim_time']:.1f} s"]
            video.write(annotate(frame, lines))
        rerun.set_time(snapshot["step"], snapshot["sim_time"])
        rerun.log_poses(
            snapshot["robot_pose"],
            snapshot["odometry_pose"],
            snapshot["human_position"],
            snapshot["ball_positions"],
        )
        if snapshot["sim_time"] + 1e-9 >= state["next_camera"]:
            rerun.log_camera("overhead", frame)
            state["next_camera"] = snapshot["sim_time"] + camera_period

    env.unwrapped.set_frame_sink(on_frame)


def _log_start(rerun, env, info, library, spec, prior, normalised_entropy) -> None:
    layout = env.unwrapped.layout
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
    rerun.log_poses(info["robot_pose"], info["odometry_pose"], info["human_position"], info["ball_positions"])
    if prior is not None:
        rerun.log_belief(np.asarray(prior), float(normalised_entropy(np.asarray(prior))))
    tasks = ", ".join(f"{k}: balls at {list(t)}" for k, t in enumerate(library.tasks))
    rerun.log_text(
        "events",
        f"start: robot at node {spec['robot_node']}, human at node {spec['human_node']}; task library {tasks}",
    )


def _log_step(rerun, step, info, action_name, description, posterior, entropy) -> None:
    rerun.set_time(step, info["sim_time"])
    rerun.log_text("actions", f"step {step}: {action_name}")
    rerun.log_text("observations", f"step {step}: {description}")
    for line in info.get("utterances", ()):
        rerun.log_text("utterances", line)
    if info.get("speech_audio") is not None:
        rerun.log_audio(info["speech_audio"])
    if info.get("rfid_event"):
        rerun.log_text("events", f"step {step}: a ball entered the container")
    if posterior is not None:
        rerun.log_belief(np.asarray(posterior), entropy)
