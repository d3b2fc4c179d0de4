"""The one recorder over a frame source, without a simulator: frame instants, per-step frames, the held last frame,
the rerun camera's own clock, the heads-up lines in the presenter's order, and detaching from the world."""

import threading

import numpy as np
import pytest

from embodied_adhoc.episodes.frames import ArenaFrameSource, FrameSource
from embodied_adhoc.episodes.loop import EpisodeTrace, StepRecord
from embodied_adhoc.episodes.recording import Presenter, Recording, VideoSettings


class _Sink:
    """Stands in for the video writer and the rerun recorder."""

    def __init__(self):
        self.frames, self.cameras, self.texts, self.threads = [], [], [], set()
        self.frame_count, self.closed = 0, False

    def write(self, frame, overlay=None, repeat=1):
        self.threads.add(threading.current_thread().name)
        self.frames.extend([(int(frame[0, 0, 0]), overlay)] * repeat)
        self.frame_count += repeat

    def log_camera(self, name, frame, step=None, sim_time=None):
        self.cameras.append((name, step, round(sim_time, 6)))

    def set_time(self, step, sim_time):
        pass

    def log_text(self, channel, text, level="INFO"):
        self.texts.append((channel, text))

    def log_robots(self, poses, labels, colours):
        pass

    def close(self):
        self.closed = True


class _View:
    """A world whose picture is its simulated time in eighths of a second (one grey level per frame)."""

    def __init__(self):
        self.time = 0.0

    def render_top(self, size):
        return np.full((size, size, 3), round(self.time * 8) % 256, np.uint8)

    def poses(self):
        return np.zeros((2, 3))


class _Backend:
    on_tick = None


class _Presenter(Presenter):
    hud_keys = ("action", "posterior")
    frame_each_step = True
    step_cameras = ("robot",)

    def action_label(self, action):
        return ("left", "right")[action]

    def stepped(self, rerun, record, description):
        return {"posterior": None if record.step == 2 else f"P {record.step}"}


@pytest.fixture
def recording(tmp_path, monkeypatch):
    import embodied_adhoc.record.video as video

    sink, view, backend = _Sink(), _View(), _Backend()
    monkeypatch.setattr(video, "VideoWriter", lambda *args, **kwargs: sink)
    presenter = _Presenter()
    presenter.open_rerun = lambda path, name: sink
    settings = VideoSettings(16, 16, fps=8.0, speed=2.0, hold=0.375, overlay=True, camera_hz=1.0)
    source = ArenaFrameSource(view, backend, lambda: view.time, 16, settings.frame_period)
    files = {}
    recorder = Recording(source, presenter, settings, tmp_path, "test", files)
    return recorder, sink, view, backend, files


def _step(recorder, view, backend, step, action, seconds):
    recorder.action_chosen(step, action)
    for _ in range(round(seconds * 16)):  # control ticks of 1/16 s (exact in binary)
        view.time += 1 / 16
        backend.on_tick(view.time)
    recorder.step_finished(StepRecord(step, action, 7, 0.0, False, False, {}, None))


def test_frames_come_at_the_frame_instants_after_each_step_and_held_at_the_end(recording, tmp_path):
    recorder, sink, view, backend, files = recording
    assert isinstance(recorder.source, FrameSource)
    assert set(files) == {"video", "rerun"} and files["video"].parent == tmp_path
    recorder.episode_started({}, None)
    _step(recorder, view, backend, 1, 0, 1.0)
    _step(recorder, view, backend, 2, 1, 1.0)
    recorder.episode_finished(EpisodeTrace(actions=[0, 1], terminated=True))
    recorder.close()
    # one frame at the start, then one 0.25 simulated seconds (period = speed / fps) after the last picture, one
    # after each step, three held at the end (0.375 s at 8 fps)
    levels = [level for level, _ in sink.frames]
    assert levels == [0, 2, 4, 6, 8, 8, 10, 12, 14, 16, 16, 16, 16, 16]
    assert sink.frames[-1][1] == ("done after 2 steps: success", "t = 2.0 s")
    # the heads-up lines follow hud_keys; a None line is removed (step 2 has no posterior)
    assert sink.frames[5][1] == ("step 1: left", "P 1", "t = 1.0 s")
    assert sink.frames[9][1] == (
        "step 2: right",
        "P 1",
        "t = 2.0 s",
    )  # a frame instant, before the step's end
    assert sink.frames[10][1] == ("step 2: right", "t = 2.0 s")
    # the overhead camera on its own clock (1 Hz) and with every forced frame, the robot camera once a step
    overhead = [time for name, _, time in sink.cameras if name == "overhead"]
    assert overhead == sorted(overhead) and set(overhead) == {0.0, 1.0, 2.0}
    assert [(step, time) for name, step, time in sink.cameras if name == "robot"] == [(1, 1.0), (2, 2.0)]
    assert ("actions", "step 2: right") in sink.texts and (
        "events",
        "outcome: success after 2 steps",
    ) in sink.texts
    # drawn off the simulation thread, then detached from the world and closed
    assert sink.threads and threading.current_thread().name not in sink.threads
    assert backend.on_tick is None and sink.closed


def test_without_overlay_the_frames_carry_no_text(tmp_path, monkeypatch):
    import embodied_adhoc.record.video as video

    sink, view, backend = _Sink(), _View(), _Backend()
    monkeypatch.setattr(video, "VideoWriter", lambda *args, **kwargs: sink)
    presenter = _Presenter()
    presenter.open_rerun = lambda path, name: sink
    settings = VideoSettings(16, 16, fps=10.0, speed=2.0, overlay=False)
    recorder = Recording(
        ArenaFrameSource(view, backend, lambda: view.time, 16, 0.2), presenter, settings, tmp_path, "t", {}
    )
    recorder.episode_started({}, None)
    recorder.episode_finished(EpisodeTrace())
    recorder.close()
    assert sink.frames and all(overlay is None for _, overlay in sink.frames)
    assert len(sink.frames) == 1 + settings.hold_frames
