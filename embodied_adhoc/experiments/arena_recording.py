"""Video and rerun recording of one grid-arena episode on physics, shared by ``run pursuit``
(:mod:`~embodied_adhoc.experiments.recorded_pursuit`) and ``run foraging``
(:mod:`~embodied_adhoc.experiments.recorded_foraging`): overhead frames while the robots move (``video_fps /
video_speed`` per simulated second, from the arena's control-tick hook) and after every step, a heads-up overlay,
robot poses and overhead camera frames in rerun. Subclasses add what their domain shows (HUD lines, posterior,
text logs) through the :class:`~embodied_adhoc.experiments.episode.EpisodeObserver` hooks.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.episode import EpisodeObserver

__all__ = ["ArenaRecording", "ArenaVideoConfig", "check_video_options"]


@dataclass(frozen=True)
class ArenaVideoConfig:
    """The recording settings of a ``run pursuit`` / ``run foraging`` episode (their configs extend it)."""

    record_dir: Path | None = None  # None: no recording
    video_fps: float = 12.0
    video_speed: float = 2.0  # simulated seconds per second of video
    video_hold: float = 1.0  # seconds of video that show the final state
    size: int = 480  # square video, pixels (even)
    video_overlay: bool = True
    rerun_camera_hz: float = 2.0


def check_video_options(config: ArenaVideoConfig) -> None:
    """``video_fps``, ``video_speed`` > 0 and ``size`` even and >= 16, else one line naming the flags."""
    if not (config.video_fps > 0 and config.video_speed > 0 and config.size >= 16 and config.size % 2 == 0):
        raise ConfigError(
            f"--video-fps ({config.video_fps}) and --video-speed ({config.video_speed}) must be > 0, "
            f"--size ({config.size}) even and >= 16"
        )


class ArenaRecording(EpisodeObserver):
    """``view`` renders (``render_top(size)``) and gives the robots' poses (``poses()``); ``backend`` is the
    arena's :class:`~embodied_adhoc.sim.grid_arena_world.GridArenaBackend` (cell layout, tick hook); ``clock()``
    the simulated time. ``hud`` lines listed in ``hud_keys`` are drawn on the video, then the time."""

    hud_keys: tuple[str, ...] = ()
    outcomes: tuple[str, str] = ("success", "failure")  # what the end of an episode is called: (success, not)

    def __init__(
        self,
        config,
        view,
        backend,
        clock: Callable[[], float],
        labels: Sequence[str],
        colours: Sequence[tuple[int, int, int]],
        name: str,
        files: dict[str, Path],
    ):
        from embodied_adhoc.record.arena_recorder import ArenaRerunRecorder
        from embodied_adhoc.record.video import VideoWriter

        self.config, self.view, self.backend, self.clock = config, view, backend, clock
        self.labels, self.colours = list(labels), list(colours)
        folder = Path(config.record_dir)
        folder.mkdir(parents=True, exist_ok=True)
        files["video"], files["rerun"] = folder / "episode.mp4", folder / "episode.rrd"
        self.video = VideoWriter(files["video"], config.size, config.size, fps=config.video_fps)
        self.rerun = ArenaRerunRecorder(files["rerun"], recording_name=name)
        layout = backend.layout
        self.rerun.log_cells(layout.rows, layout.cols, layout.cell)
        self.hud: dict[str, str] = {}
        self.step = 0
        self._frame_period = config.video_speed / config.video_fps
        self._camera_period = 1.0 / config.rerun_camera_hz if config.rerun_camera_hz > 0 else float("inf")
        self._next_frame = self._next_camera = 0.0
        backend.on_tick = self._on_tick

    def _overlay(self) -> list[str] | None:
        if not self.config.video_overlay:
            return None
        return [self.hud[k] for k in self.hud_keys if k in self.hud] + [f"t = {self.clock():.1f} s"]

    def _frame(self, force: bool = False, repeat: int = 1) -> None:
        sim_time = self.clock()
        if not force and sim_time + 1e-9 < self._next_frame:
            return
        self._next_frame = sim_time + self._frame_period
        frame = self.view.render_top(self.config.size)
        self.video.write(frame, self._overlay(), repeat=repeat)
        self.rerun.set_time(self.step, sim_time)
        self.rerun.log_robots(self.view.poses(), self.labels, self.colours)
        if force or sim_time + 1e-9 >= self._next_camera:
            self.rerun.log_camera("overhead", frame)
            self._next_camera = sim_time + self._camera_period

    def episode_finished(self, trace) -> None:
        """The outcome in the log and on the last frame, held ``config.video_hold`` seconds in the video."""
        outcome = self.outcomes[0] if trace.success else self.outcomes[1]
        self.rerun.log_text("events", f"outcome: {outcome} after {trace.steps} steps")
        self.hud["action"] = f"{self.config.agent} | done after {trace.steps} steps: {outcome}"
        self._frame(force=True, repeat=max(1, round(self.config.video_hold * self.config.video_fps)))

    def _on_tick(self, _seconds_into_step: float) -> None:
        self._frame()

    def close(self) -> None:
        self.backend.on_tick = None
        try:
            self.video.close()
        finally:
            self.rerun.close()
