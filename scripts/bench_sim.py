"""Benchmark and odometry report of the MuJoCo lab.

Prints, all measured in this run on this machine:
  1. real-time factor of LabWorld tours (simulated seconds per second of this process's CPU time, headless,
     controller + odometry + human + RFID included; CPU time, not wall time, so that other jobs on a shared
     machine do not distort it: on an idle machine the two agree);
  2. the same model stepped raw (mj_step, constant controls) and the controller/bookkeeping overhead as a ratio;
  3. offscreen rendering frames per second per camera;
  4. dead-reckoning drift after each full tour (every edge both ways) and the node-estimate accuracy at every
     arrival (thesis Metric 7), at the default encoder noise and wheel slip;
  5. a scripted 10-macro-step episode bare and recorded as ``run --record`` records it (overhead frames with the
     belief markers at the rate the video keeps, rendered on the render thread, heads-up text and H.264 on the writer
     thread; rerun poses, localisation, overhead camera at 2 Hz and the robot camera each macro step), and their
     ratio, in wall and CPU time.

Usage: MUJOCO_GL=egl .venv/bin/python scripts/bench_sim.py [--tours 5] [--render-frames 30] [--width 640 --height 480]
       [--video-fps 10 --video-speed 4] [--episode-only]
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402

from embodied_adhoc.episodes.frames import LabFrameSource  # noqa: E402
from embodied_adhoc.episodes.loop import EpisodeTrace, StepRecord  # noqa: E402
from embodied_adhoc.episodes.presenters import LabPresenter  # noqa: E402
from embodied_adhoc.episodes.recording import Presenter, Recording  # noqa: E402
from embodied_adhoc.experiments.recorded import EpisodeConfig  # noqa: E402
from embodied_adhoc.experiments.script_args import parse_dataclass_args  # noqa: E402
from embodied_adhoc.sim.lab_world import HumanCommand, LabWorld, LabWorldConfig  # noqa: E402
from embodied_adhoc.sim.odometry import OdometryConfig  # noqa: E402

TOUR = (1, 2, 1, 3, 4, 3, 1, 0)  # from the door, every edge in both directions


@dataclass(frozen=True)
class Args:
    tours: int = 5
    """number of full tours (seeds 0..tours-1) for drift and Metric 7"""
    raw_seconds: float = 20.0
    """simulated seconds of raw mj_step for the reference rate"""
    render_frames: int = 30
    """frames per camera for the render rate"""
    width: int = EpisodeConfig.width
    """image width of the render rates and the recorded episode (``run --width``'s default)"""
    height: int = EpisodeConfig.height
    video_fps: float = EpisodeConfig.video_fps
    """frames per second of the recorded episode's video (``run --video-fps``'s default)"""
    video_speed: float = EpisodeConfig.video_speed
    """simulated seconds per video second (``run --video-speed``'s default): frames rendered per simulated second
    are video_fps / video_speed"""
    noise_free: bool = False
    """tours with encoder noise and wheel slip set to 0 (the drift left is the physics' own)"""
    episode_only: bool = False
    """only the scripted episode with and without video"""


def parse_args() -> Args:
    return parse_dataclass_args(Args, __doc__)


def run_tours(world: LabWorld, tours: int) -> tuple[list[dict], float, float]:
    rows, sim_total, cpu_total = [], 0.0, 0.0
    for seed in range(tours):
        world.reset(seed=seed, robot_node=0, human_node=4, ball_nodes=(0, 1, 2))
        correct, contacts, arrived, worst_arrival = 0, 0, 0, 0.0
        start = time.process_time()
        sim = 0.0
        for target in TOUR:
            result = world.step_macro(target, HumanCommand.stay())
            sim += result.sim_seconds
            correct += result.odometry_node == result.true_robot_node
            contacts += result.wall_contact
            arrived += result.robot_arrived
            goal = world.layout.node_waypoints[target]
            truth = world.ground_truth().robot_pose
            worst_arrival = max(worst_arrival, float(np.hypot(truth[0] - goal[0], truth[1] - goal[1])))
        cpu = time.process_time() - start
        sim_total, cpu_total = sim_total + sim, cpu_total + cpu
        rows.append(
            {
                "seed": seed,
                "distance_m": world.odometry.distance,
                "drift_m": world.odometry_error(),
                "node_correct": correct,
                "arrivals": arrived,
                "worst_arrival_m": worst_arrival,
                "wall_contacts": contacts,
                "rtf": sim / cpu,
            }
        )
    return rows, sim_total, cpu_total


def raw_step_rate(world: LabWorld, seconds: float) -> float:
    """Simulated seconds per CPU second of bare mj_step on the same model, robot driving on constant wheels."""
    world.reset(seed=0, robot_node=1, human_node=4, ball_nodes=(0, 1, 2))
    model, data = world.model, world.data
    data.ctrl[world.ids.wheel_actuators] = [3.0, 3.3]
    steps = int(seconds / model.opt.timestep)
    start = time.process_time()
    for _ in range(steps):
        mujoco.mj_step(model, data)
    return seconds / (time.process_time() - start)


def render_rate(world: LabWorld, camera: str, frames: int, width: int, height: int) -> float:
    world.render(camera, width, height)  # context creation excluded
    start = time.perf_counter()
    for _ in range(frames):
        world.render(camera, width, height)
    return frames / (time.perf_counter() - start)


# A scripted HOTSPOT episode (task 0,1,2; robot from the door, human in the open space): 10 macro steps in which
# the robot follows the human and every ball ends in the container.
EPISODE = (
    (1, HumanCommand.pick(1)),
    (None, HumanCommand.drop_into_container(1)),
    (2, HumanCommand.move_to(2)),
    (None, HumanCommand.pick(2)),
    (None, HumanCommand.drop_into_container(2)),
    (1, HumanCommand.move_to(1)),
    (0, HumanCommand.move_to(0)),
    (None, HumanCommand.pick(0)),
    (None, HumanCommand.drop_into_container(0)),
    (None, HumanCommand.stay()),
)


class ScriptedPresenter(Presenter):
    """Heads-up lines as long as ``run toxic-waste``'s (balls, action, observation, belief; the time is the
    recorder's), the lab's poses and localiser per frame, the robot camera each macro step."""

    hud_keys = ("balls", "action", "heard", "belief")
    step_cameras = ("robot",)
    log_frame = LabPresenter.log_frame

    def action_label(self, action: int) -> str:
        return f"move to {action % 5} open space"

    def stepped(self, rerun, record, description: str) -> dict:
        step = record.step
        return {
            "balls": f"hotspot | balls in container {min(3, step // 3)}/3",
            "heard": f"observed: robot at {step % 5} open space; human at none; rfid no",
            "belief": f"P(task): [0, 1, 2] {0.5 + step / 40:.2f}  [2, 1, 0] {0.5 - step / 40:.2f}",
        }


class ScriptedEnv:
    """What the lab's frame source reads of the physics env: the world, and a frame sink the episode feeds."""

    def __init__(self, world: LabWorld):
        self.world, self.sink = world, None

    def set_frame_sink(self, sink) -> None:
        self.sink = sink

    def frame(self, lab: LabWorld, step: int) -> None:
        truth = lab.ground_truth()
        self.sink(
            {
                "step": step,
                "sim_time": truth.time,
                "robot_pose": truth.robot_pose,
                "odometry_pose": lab.odometry_pose(),
                "estimated_pose": lab.pose_estimate(),
                "particles": lab.localiser.particles[:, :2].copy(),
                "human_position": truth.human_pose[:2],
                "ball_positions": np.array(truth.ball_positions),
            }
        )


def run_episode(world: LabWorld, args: Args, folder: Path | None) -> tuple:
    """Wall seconds, CPU seconds (all threads of this process and the ffmpeg child, so software rendering and
    encoding count), simulated seconds, frames and final ball states of the scripted episode, and the wall and CPU
    seconds of opening the recorders (0 without ``folder``): the video writer (ffmpeg started), the rerun file and
    the render thread with its GL context, timed apart as a one-off per recording. With ``folder`` it is
    recorded by ``run --record``'s recorder (``episodes.recording.Recording`` over the lab's frame source): the
    overhead camera with the belief markers at the rate the video keeps, each frame with five heads-up lines,
    rendered on the render thread into the mp4 writer; poses and the localiser's estimate into the rerun
    recording, its particles and the overhead image at ``rerun_camera_hz`` of simulated time, the robot camera
    after each macro step; the final state held for ``video_hold`` (``EpisodeConfig``'s defaults)."""
    count = [0]
    env, recording = ScriptedEnv(world), None

    world.reset(seed=0, robot_node=0, human_node=1, ball_nodes=(0, 1, 2))
    start, cpu_start, sim = time.perf_counter(), cpu_seconds(), 0.0
    if folder is not None:
        settings = EpisodeConfig(
            width=args.width, height=args.height, video_fps=args.video_fps, video_speed=args.video_speed
        ).video()
        source = LabFrameSource(env, args.width, args.height)
        recording = Recording(source, ScriptedPresenter(), settings, folder, "bench", {})
        recording.prepared.wait(timeout=60)
    opening, opening_cpu = time.perf_counter() - start, cpu_seconds() - cpu_start
    start, cpu_start = time.perf_counter(), cpu_seconds()

    def frame(lab: LabWorld) -> None:
        env.frame(lab, recording.step)
        count[0] += 1

    try:
        for index, (target, command) in enumerate(EPISODE, start=1):
            if recording is not None:
                recording.action_chosen(index, index)
            sim += world.step_macro(target, command, frame if recording is not None else None).sim_seconds
            if recording is not None:
                recording.step_finished(StepRecord(index, index, 0, 0.0, False, False, {}, None))
        if recording is not None:
            recording.episode_finished(EpisodeTrace(actions=list(range(len(EPISODE))), terminated=True))
    finally:
        if recording is not None:
            recording.close()
    wall, cpu = time.perf_counter() - start, cpu_seconds() - cpu_start
    return wall, cpu, sim, count[0], world.ground_truth().ball_states, opening, opening_cpu


def cpu_seconds() -> float:
    """CPU seconds of this process (all threads) and of its finished children (the ffmpeg encoder)."""
    times = os.times()
    return times.user + times.system + times.children_user + times.children_system


def recording_setup() -> float:
    """Wall seconds of what a process pays once before its first recorded episode, not per episode: importing
    rerun and imageio-ffmpeg. Done before the recorded episode is timed, as the world itself is built before the
    bare one is (the render thread's GL context is made inside the recorded episode)."""
    start = time.perf_counter()
    import imageio_ffmpeg  # noqa: F401
    import rerun  # noqa: F401

    return time.perf_counter() - start


def episode_pair(args: Args, base: LabWorldConfig) -> tuple[tuple, tuple, float]:
    """The scripted episode bare and recorded (frames at video_fps / video_speed per simulated second), and the
    one-off recording setup (excluded from the recorded episode's time)."""
    config = dataclasses.replace(base, video_fps=args.video_fps / args.video_speed)
    with LabWorld(config) as world, tempfile.TemporaryDirectory() as folder:
        bare = run_episode(world, args, None)
        setup = recording_setup()
        recorded = run_episode(world, args, Path(folder))
    return bare, recorded, setup


def print_episodes(args: Args, bare: tuple, recorded: tuple, setup: float) -> None:
    wall, cpu, sim, _, states, _, _ = bare
    print(
        f"| scripted episode, {len(EPISODE)} macro steps, {sim:.0f} sim s, no video: wall s / CPU s | "
        f"{wall:.2f} / {cpu:.2f} |"
    )
    rec_wall, rec_cpu, _, count, rec_states, opening, opening_cpu = recorded
    print(
        f"| same, recorded as `run --record` (video {args.width}x{args.height} at {args.video_fps:g} fps, "
        f"{args.video_speed:g}x time-lapse: {count} frames + 1 s hold; rerun): wall s / CPU s | "
        f"{rec_wall:.2f} / {rec_cpu:.2f} |"
    )
    print(f"| recorded / bare episode, wall (CPU) | {rec_wall / wall:.1f}x ({rec_cpu / cpu:.1f}x) |")
    print(
        "| opening the recorders (ffmpeg started, rerun file, render thread's GL context; not in the recorded "
        f"episode above), wall s / CPU s | {opening:.2f} / {opening_cpu:.2f} |"
    )
    print(
        "| recorded / bare episode with the recorders' opening, wall (CPU) | "
        f"{(rec_wall + opening) / wall:.1f}x ({(rec_cpu + opening_cpu) / cpu:.1f}x) |"
    )
    print(
        f"| one-off recording setup per process (rerun + imageio-ffmpeg imports; not in the recorded episode "
        f"above), wall s | {setup:.2f} |"
    )
    print(
        f"| ball states at the end of the episode (bare, recorded) | {', '.join(states)}; {', '.join(rec_states)} |"
    )


def main() -> None:
    args = parse_args()
    if args.episode_only:
        print("| measure | value |\n|---|---|")
        print_episodes(args, *episode_pair(args, LabWorldConfig()))
        return
    odometry = OdometryConfig(encoder_noise=0.0, wheel_slip=0.0) if args.noise_free else OdometryConfig()
    with LabWorld(LabWorldConfig(odometry=odometry)) as world:
        rows, sim_total, cpu_total = run_tours(world, args.tours)
        raw_rtf = raw_step_rate(world, args.raw_seconds)
        world.reset(seed=0, robot_node=1, human_node=1, ball_nodes=(0, 1, 2))
        fps = {}
        default_config = world.config
        for quality in ("fast", "high"):
            world.config = dataclasses.replace(default_config, render_quality=quality)
            for cam in ("overhead", "robot"):
                fps[f"{cam}, {quality}"] = render_rate(
                    world, cam, args.render_frames, args.width, args.height
                )
        world.config = default_config
    episodes = episode_pair(args, default_config)
    world_rtf = sim_total / cpu_total
    print(
        f"physics timestep {world.config.timestep * 1e3:.1f} ms, "
        f"control period {world.config.control_period * 1e3:.0f} ms"
    )
    print(
        "\n| seed | distance (m) | drift after tour (m) | node estimate correct | arrived | worst arrival error (m) "
        "| wall contacts | RTF |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for row in rows:
        print(
            f"| {row['seed']} | {row['distance_m']:.1f} | {row['drift_m']:.3f} | {row['node_correct']}/{len(TOUR)} | "
            f"{row['arrivals']}/{len(TOUR)} | {row['worst_arrival_m']:.3f} | {row['wall_contacts']} | "
            f"{row['rtf']:.1f} |"
        )
    drifts = np.array([row["drift_m"] for row in rows])
    accuracy = sum(row["node_correct"] for row in rows) / (len(rows) * len(TOUR))
    print(
        f"\ndrift after a full tour: mean {drifts.mean():.3f} m, max {drifts.max():.3f} m "
        f"({100 * drifts.mean() / np.mean([r['distance_m'] for r in rows]):.2f} % of distance)"
    )
    print(
        f"node-estimate accuracy (thesis Metric 7): {100 * accuracy:.1f} % over {len(rows) * len(TOUR)} arrivals"
    )
    print("\n| measure | value |")
    print("|---|---|")
    print(f"| LabWorld real-time factor (sim s / CPU s, headless) | {world_rtf:.1f} |")
    print(f"| raw mj_step real-time factor (sim s / CPU s), same model | {raw_rtf:.1f} |")
    print(f"| LabWorld cost per sim s / raw mj_step cost per sim s | {raw_rtf / world_rtf:.2f}x |")
    print_episodes(args, *episodes)
    for cam, rate in fps.items():
        print(f"| offscreen render {cam} quality {args.width}x{args.height} (frames/wall s) | {rate:.1f} |")


if __name__ == "__main__":
    main()
