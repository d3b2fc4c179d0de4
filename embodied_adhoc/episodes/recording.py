"""The recording observers of a recorded episode: video and rerun (:class:`Recording`), ``metrics.json``
(:class:`MetricsObserver`) and a progress callback (:class:`ProgressObserver`).

:class:`Recording` is the one recorder of every world: it takes its pictures from a
:class:`~embodied_adhoc.episodes.frames.FrameSource` and asks the domain's :class:`Presenter` what to show. Frames
come at the source's frame instants (``video_fps / video_speed`` per simulated second), after every step where the
presenter asks for it (``frame_each_step``), and at the end (the final state held ``video_hold`` seconds). The
simulation thread only takes each frame (:meth:`FrameSource.take`); one render thread (``record.worker``) draws it
and hands the picture to the video writer's thread (heads-up text, H.264) and to the rerun recorder's (JPEG).
The overhead camera goes to rerun on its own clock (``rerun_camera_hz``), with every forced frame, and each
camera the presenter lists in ``step_cameras`` once per step.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from embodied_adhoc.episodes.loop import EpisodeObserver, EpisodeTrace, StepRecord

__all__ = ["MetricsObserver", "Presenter", "ProgressObserver", "Recording", "VideoSettings", "entropy_of"]


def entropy_of(posterior) -> float | None:
    """The normalised entropy of a task posterior (None without one), clipped at 0 against rounding."""
    from embodied_adhoc.decision.agents.task_beliefs import normalised_entropy

    return None if posterior is None else max(0.0, float(normalised_entropy(posterior)))


@dataclass(frozen=True)
class VideoSettings:
    """How a recorded episode's video and rerun camera are taken (the ``run`` commands' recording flags)."""

    width: int
    height: int
    fps: float
    speed: float  # simulated seconds per second of video
    hold: float = 1.0  # seconds of video that show the final state
    overlay: bool = True  # heads-up text on the video
    camera_hz: float = 2.0  # overhead images per simulated second in the rerun recording

    @property
    def frame_period(self) -> float:
        """Simulated seconds between two frames of the video."""
        return self.speed / self.fps

    @property
    def hold_frames(self) -> int:
        return max(1, round(self.hold * self.fps))


class Presenter:
    """What a domain shows of its episodes: the rerun recorder and its static map, heads-up text, action and
    observation labels, per-frame poses, per-step logs and ``metrics.json``'s per-step fields. Hooks return the
    heads-up lines they change (``{key: text}``; None as text removes the line); ``hud_keys`` orders them on the
    video, the simulated time last."""

    hud_keys: tuple[str, ...] = ()
    outcomes: tuple[str, str] = ("success", "failure")  # the end of an episode: (success, not)
    frame_each_step: bool = False  # a video frame after every step, besides the frame instants
    step_cameras: tuple[str, ...] = ()  # cameras logged to rerun once per step

    def open_rerun(self, path: Path, name: str):
        """The rerun recorder of the episode, with the domain's static map logged."""
        from embodied_adhoc.record.rerun_recorder import RerunRecorder

        return RerunRecorder(path, recording_name=name)

    def describe(self, observation_index: int) -> str:
        """The observation in words (``metrics.json``, rerun, the heads-up text)."""
        return f"observation {observation_index}"

    def action_label(self, action: int) -> str:
        return str(action)

    def started(self, rerun, info: dict, posterior) -> dict:
        """After reset: log the start, return the first heads-up lines."""
        return {}

    def action_line(self, step: int, label: str) -> str:
        return f"step {step}: {label}"

    def log_frame(self, rerun, snapshot: dict, camera_due: bool) -> None:
        """The poses of a frame instant (``snapshot`` from the frame source); simulation thread."""

    def stepped(self, rerun, record: StepRecord, description: str) -> dict:
        """After a step: log it, return the heads-up lines it changes."""
        return {}

    def finished_line(self, trace: EpisodeTrace, outcome: str) -> dict:
        return {"action": f"done after {trace.steps} steps: {outcome}"}

    def metrics_step(self, metrics, record: StepRecord) -> None:
        """Record the step in ``metrics`` (:class:`~embodied_adhoc.record.metrics.EpisodeMetrics`)."""
        metrics.end_step(
            record.action,
            self.describe(record.observation_index),
            record.reward,
            float(record.info.get("sim_time", 0.0)),
            record.task_posterior,
            entropy_of(record.task_posterior),
        )

    def metrics_finished(self, metrics, trace: EpisodeTrace) -> None:
        """What the episode's end adds to ``metrics`` beyond its outcome (e.g. why a capped run did not finish)."""


class MetricsObserver(EpisodeObserver):
    """Feeds :class:`~embodied_adhoc.record.metrics.EpisodeMetrics` (``metrics.json``) from the loop's hooks; the
    presenter says what a step adds."""

    def __init__(self, metrics, presenter: Presenter):
        self.metrics, self.presenter = metrics, presenter

    def episode_started(self, info: dict, task_posterior) -> None:
        self.metrics.start_episode(task_posterior)

    def step_started(self, step: int) -> None:
        self.metrics.start_step()

    def step_finished(self, record: StepRecord) -> None:
        self.presenter.metrics_step(self.metrics, record)

    def episode_finished(self, trace: EpisodeTrace) -> None:
        self.metrics.finish(success=trace.success, truncated=trace.truncated)
        self.presenter.metrics_finished(self.metrics, trace)


class ProgressObserver(EpisodeObserver):
    """Calls ``progress(step, info)`` after every step (the commands' progress bars)."""

    def __init__(self, progress: Callable[[int, dict], None]):
        self.progress = progress

    def step_finished(self, record: StepRecord) -> None:
        self.progress(record.step, record.info)


class Recording(EpisodeObserver):
    """Video (``episode.mp4``) and rerun (``episode.rrd``) of one episode in ``folder`` (module docstring); the
    paths go into ``files``. :meth:`close` renders what is queued, then closes the video and rerun files."""

    def __init__(
        self,
        source,
        presenter: Presenter,
        settings: VideoSettings,
        folder: Path,
        name: str,
        files: dict[str, Path],
        max_queued: int = 128,
    ):
        from embodied_adhoc.record.video import VideoWriter
        from embodied_adhoc.record.worker import BackgroundWorker

        self.source, self.presenter, self.settings = source, presenter, settings
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        files["video"], files["rerun"] = folder / "episode.mp4", folder / "episode.rrd"
        self.video = VideoWriter(files["video"], source.width, source.height, fps=settings.fps)
        self.rerun = presenter.open_rerun(files["rerun"], name)
        self.hud: dict[str, str] = {}
        self.step = 0
        self.labels: dict[int, str] = {}
        self._next_camera = 0.0
        self._camera_period = 1.0 / settings.camera_hz if settings.camera_hz > 0 else float("inf")
        # the render thread makes its GL context as soon as it starts, not at the first frame (``prepared`` is set
        # then); at most max_queued frames wait (an MjData copy each for the lab: the simulation waits only when
        # rendering falls that far behind)
        self.prepared = threading.Event()
        self._worker = BackgroundWorker(
            self._render, f"render {files['video'].name}", max_queued, finish=source.release
        )
        self._worker.submit(None)
        source.listen(self._on_frame)

    # -- frames ---------------------------------------------------------------------------------------------
    def _overlay(self, sim_time: float) -> tuple[str, ...] | None:
        if not self.settings.overlay:
            return None
        return (
            *[self.hud[key] for key in self.presenter.hud_keys if key in self.hud],
            f"t = {sim_time:.1f} s",
        )

    def _update_hud(self, lines: dict) -> None:
        for key, text in lines.items():
            if text is None:
                self.hud.pop(key, None)
            else:
                self.hud[key] = text

    def _camera_due(self, sim_time: float) -> bool:
        """Whether the overhead camera's next rerun image is due; the camera keeps its own clock (frames may be
        sparser than its rate: 'one period after this frame' would drop every second image)."""
        due = sim_time + 1e-9 >= self._next_camera
        while self._next_camera <= sim_time + 1e-9:
            self._next_camera += self._camera_period
        return due

    def _submit(
        self, camera: str, markers: bool, sim_time: float, repeat: int, log_camera: bool, step: int
    ) -> None:
        """Take the picture now (simulation thread): ``repeat`` video frames with the heads-up text (0: none),
        and ``camera/<camera>`` in rerun at (step, sim_time) if ``log_camera``."""
        taken = self.source.take(camera, markers)
        overlay = self._overlay(sim_time) if repeat > 0 else None
        self._worker.submit((taken, overlay, int(repeat), (camera, step, sim_time) if log_camera else None))

    def _render(self, item: tuple | None) -> None:
        if item is None:
            self.source.prepare()
            self.prepared.set()
            return
        taken, overlay, repeat, camera_log = item
        frame = self.source.render(taken)
        if repeat > 0:
            self.video.write(frame, overlay, repeat=repeat)
        if camera_log is not None:
            name, step, sim_time = camera_log
            self.rerun.log_camera(name, frame, step=step, sim_time=sim_time)

    def _on_frame(self, snapshot: dict) -> None:
        sim_time = float(snapshot["sim_time"])
        step = int(snapshot.get("step", self.step))
        due = self._camera_due(sim_time)
        self._submit("overhead", True, sim_time, 1, due, step)
        self.rerun.set_time(step, sim_time)
        self.presenter.log_frame(self.rerun, snapshot, due)

    def _forced_frame(self, repeat: int = 1) -> None:
        sim_time = self.source.sim_time()
        self._camera_due(sim_time)
        self._submit("overhead", False, sim_time, repeat, True, self.step)

    # -- loop hooks -----------------------------------------------------------------------------------------
    def episode_started(self, info: dict, task_posterior) -> None:
        self.rerun.set_time(0, self.source.sim_time())
        self._update_hud(self.presenter.started(self.rerun, info, task_posterior))
        if self.presenter.frame_each_step:
            self._forced_frame()

    def action_chosen(self, step: int, action: int) -> None:
        label = self.presenter.action_label(action)
        self.step, self.labels[step] = step, label
        self.hud["action"] = self.presenter.action_line(step, label)

    def step_finished(self, record: StepRecord) -> None:
        sim_time = self.source.sim_time()
        self.rerun.set_time(record.step, sim_time)
        self.rerun.log_text("actions", f"step {record.step}: {self.labels[record.step]}")
        description = self.presenter.describe(record.observation_index)
        self._update_hud(self.presenter.stepped(self.rerun, record, description))
        for camera in self.presenter.step_cameras:
            self._submit(camera, False, sim_time, 0, True, record.step)
        if self.presenter.frame_each_step:
            self._forced_frame()

    def episode_finished(self, trace: EpisodeTrace) -> None:
        """The outcome in the log and on the last frame, held ``video_hold`` seconds in the video."""
        outcome = self.presenter.outcomes[0] if trace.success else self.presenter.outcomes[1]
        self.rerun.log_text("events", f"outcome: {outcome} after {trace.steps} steps")
        self._update_hud(self.presenter.finished_line(trace, outcome))
        self._forced_frame(repeat=self.settings.hold_frames)

    def close(self) -> None:
        self.source.listen(None)
        try:
            self._worker.close()
        finally:
            try:
                self.video.close()
            finally:
                self.rerun.close()
