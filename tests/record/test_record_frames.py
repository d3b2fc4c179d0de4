"""Frames rendered off the simulation thread (``Recording`` over the lab's frame source, whose pictures come from
``LabWorld.snapshot_renderer``): the picture of a snapshot is the one the world renders at that instant; frames
reach the video and rerun in order; a recorded run takes the same trajectory as a bare one."""

import threading

import numpy as np
import pytest

from embodied_adhoc.episodes.frames import LabFrameSource
from embodied_adhoc.episodes.loop import EpisodeTrace
from embodied_adhoc.episodes.recording import Presenter, Recording, VideoSettings
from embodied_adhoc.experiments.recorded import EpisodeConfig, run_episode
from embodied_adhoc.sim.lab_world import HumanCommand, LabWorld


def _moving_world() -> LabWorld:
    world = LabWorld()
    world.reset(seed=3, robot_node=0, human_node=1, ball_nodes=(0, 1, 2))
    return world


def test_a_snapshot_renders_on_another_thread_as_the_world_rendered_it():
    pictures, snapshots = [], []
    with _moving_world() as world:
        renderer = world.snapshot_renderer()

        def grab(lab):
            if len(snapshots) < 3:  # three instants while the robot drives and the human walks
                pictures.append((lab.render("overhead", 96, 64, markers=True), lab.render("robot", 96, 64)))
                snapshots.append(renderer.take(lab.data, lab.belief_markers()))

        world.step_macro(1, HumanCommand.pick(1), grab)
        rendered = []

        def draw():
            try:
                for snapshot in snapshots:
                    overhead = renderer.render(snapshot, "overhead", 96, 64, False, markers=True)
                    rendered.append(overhead)
                # a recycled MjData holds a new copy: the robot camera of the last instant again
                again = renderer.take(world.data, None)
                rendered.append(renderer.render(again, "robot", 96, 64, False, markers=False))
            finally:
                renderer.close()

        thread = threading.Thread(target=draw)
        thread.start()
        thread.join()
        assert len(rendered) == 4
        for (expected, _), got in zip(pictures, rendered[:3], strict=True):
            np.testing.assert_array_equal(got, expected)
        assert not np.array_equal(rendered[0], rendered[2])  # the instants differ
        np.testing.assert_array_equal(rendered[3], world.render("robot", 96, 64))


class _Sink:
    """Stands in for the video writer and the rerun recorder: keeps what reaches them, and on which thread."""

    def __init__(self, *args, fail_at: int | None = None, **kwargs):
        self.frames, self.cameras, self.threads, self.fail_at = [], [], set(), fail_at
        self.frame_count = 0

    def write(self, frame, overlay=None, repeat=1):
        if self.fail_at is not None and len(self.frames) == self.fail_at:
            raise ValueError("encoder gone")
        self.threads.add(threading.current_thread().name)
        self.frames.extend([(frame, overlay)] * repeat)
        self.frame_count += repeat

    def log_camera(self, name, frame, step=None, sim_time=None):
        self.cameras.append((name, step, sim_time, frame.shape))

    def set_time(self, step, sim_time):
        pass

    def log_text(self, channel, text, level="INFO"):
        pass

    def close(self):
        pass


class _Env:
    """The part of the physics env a lab frame source uses: its world and its frame sink."""

    def __init__(self, world):
        self.world, self.sink = world, None

    def set_frame_sink(self, sink):
        self.sink = sink


def _recording(world, sink, tmp_path, monkeypatch, max_queued=128):
    import embodied_adhoc.record.video as video

    monkeypatch.setattr(video, "VideoWriter", lambda *args, **kwargs: sink)
    presenter = Presenter()
    presenter.hud_keys = ("action",)
    presenter.open_rerun = lambda path, name: sink
    env = _Env(world)
    settings = VideoSettings(64, 48, fps=10.0, speed=4.0, hold=0.3, overlay=True, camera_hz=1e6)
    recording = Recording(LabFrameSource(env, 64, 48), presenter, settings, tmp_path, "test", {}, max_queued)
    return env, recording


def test_lab_frames_reach_the_video_and_rerun_in_order_off_the_calling_thread(tmp_path, monkeypatch):
    sink = _Sink()
    with _moving_world() as world:
        env, recording = _recording(world, sink, tmp_path, monkeypatch, max_queued=2)
        expected = []

        def frame(lab):
            expected.append(lab.render("overhead", 64, 48, markers=True))
            env.sink({"sim_time": lab.data.time, "step": 1})

        world.step_macro(1, HumanCommand.stay(), frame)
        recording.episode_finished(EpisodeTrace(actions=[0], terminated=True))
        recording.close()
        final = world.render("overhead", 64, 48)
    hold = 3  # 0.3 s at 10 fps
    assert len(sink.frames) == len(expected) + hold and len(expected) > 5
    for (got, overlay), want in zip(sink.frames, expected, strict=False):
        np.testing.assert_array_equal(got, want)
        assert overlay[-1].startswith("t = ")
    assert all(np.array_equal(got, final) for got, _ in sink.frames[-hold:])
    assert sink.frames[-1][1][0] == "done after 1 steps: success"
    # every frame instant logs the overhead camera at camera_hz = 1e6, and so does the final frame
    assert [name for name, *_ in sink.cameras] == ["overhead"] * (len(expected) + 1)
    assert threading.current_thread().name not in sink.threads and len(sink.threads) == 1
    assert env.sink is None  # the recording detaches from the world when it closes


def test_an_error_on_the_render_thread_reaches_the_simulation_thread(tmp_path, monkeypatch):
    sink = _Sink(fail_at=2)
    with _moving_world() as world:
        env, recording = _recording(world, sink, tmp_path, monkeypatch, max_queued=1)
        with pytest.raises(RuntimeError, match="encoder gone"):
            for _ in range(50):
                env.sink({"sim_time": world.data.time})
        recording.close()  # already reported; the GL context is released on the render thread


def test_a_recorded_run_takes_the_bare_run_trajectory(tmp_path):
    common = dict(agent="hotspot", seed=4, task=1, robot_node=0, human_node=2, max_steps=3)
    bare = run_episode(EpisodeConfig(**common))
    recorded = run_episode(EpisodeConfig(**common, record_dir=tmp_path, width=64, height=48))
    assert recorded.video_frames > 0
    keys = ("steps", "success", "sim_time_s")
    assert {k: bare.metrics[k] for k in keys} == {k: recorded.metrics[k] for k in keys}

    def trajectory(metrics):
        return [{k: v for k, v in step.items() if k != "wall_time_s"} for step in metrics["per_step"]]

    assert trajectory(bare.metrics) == trajectory(recorded.metrics) and len(trajectory(bare.metrics)) == 3
