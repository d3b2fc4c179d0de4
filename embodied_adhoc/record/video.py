"""MP4 writer: H.264 (libx264, preset ultrafast), yuv420p, fixed frame rate, through imageio-ffmpeg's ffmpeg binary.

Frames are encoded off the caller's thread: :meth:`VideoWriter.write` checks a frame and puts it on a bounded
queue; a writer thread (``record.worker``) draws the heads-up text (``record.overlay``) and streams the frames to
ffmpeg, so the caller (for the lab, the render thread of ``episodes.recording.Recording``) only hands
frames over. The queue bound (``queue_frames``) keeps memory flat: when ffmpeg falls behind, ``write`` waits.
The file is written under a temporary name and renamed to its final name by
:meth:`VideoWriter.close`, so an mp4 that exists is complete; closing after an interruption keeps the frames
written so far. An error on the writer thread is raised by the next ``write`` or by ``close``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from embodied_adhoc import checks
from embodied_adhoc.atomic import publish, temporary_sibling
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.record.overlay import annotate
from embodied_adhoc.record.worker import BackgroundWorker


def check_video_settings(width: int, height: int, fps: float) -> None:
    """The refusals of :class:`VideoWriter` for its size and rate, callable before anything is built."""
    if width <= 0 or height <= 0 or width % 2 or height % 2:
        raise ConfigError(
            f"video size {width}x{height}: width and height must be positive and even (H.264 yuv420p); "
            "pass e.g. --width 640 --height 480"
        )
    if not fps > 0:
        raise ConfigError(f"video fps={fps}: must be > 0 (e.g. --video-fps 15)")


class VideoWriter:
    """Write RGB frames (``uint8``, shape ``(height, width, 3)``) to an H.264 mp4 at ``fps`` frames per second.

    ``width`` and ``height`` must be even (yuv420p subsamples chroma by two); frames of another shape are an
    error rather than being silently resized. ``crf`` is x264's constant quality (lower is better; 20 keeps the
    flat-shaded lab and the heads-up text crisp). Use as a context manager or call :meth:`close`.
    """

    def __init__(
        self,
        path: str | Path,
        width: int,
        height: int,
        fps: float = 15.0,
        crf: int = 20,
        queue_frames: int = 16,
    ):
        check_video_settings(width, height, fps)
        crf = checks.integer("VideoWriter crf (x264 constant quality: 0 lossless .. 51 worst)", crf, 0, 51)
        import imageio_ffmpeg

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.width, self.height, self.fps = int(width), int(height), float(fps)
        self.frame_count = 0
        self._temporary = temporary_sibling(self.path)
        self._writer = imageio_ffmpeg.write_frames(
            str(self._temporary),
            (self.width, self.height),
            fps=self.fps,
            codec="libx264",
            pix_fmt_in="rgb24",
            pix_fmt_out="yuv420p",
            quality=None,
            macro_block_size=1,
            ffmpeg_log_level="error",
            # x264's "ultrafast" preset on one thread at constant quality ``crf``: the least CPU per lab frame,
            # for files a few times larger than the slower presets give. One encoder thread: on a busy machine
            # more threads only add synchronisation.
            output_params=["-preset", "ultrafast", "-crf", str(crf), "-x264-params", "threads=1"],
        )
        self._writer.send(None)  # start the ffmpeg process
        self._worker = BackgroundWorker(self._encode, f"video {self.path.name}", int(queue_frames))
        self._closed = False

    def write(self, frame: np.ndarray, overlay: Sequence[str] | None = None, repeat: int = 1) -> None:
        """Append ``frame`` ``repeat`` times (e.g. to hold the final state), with ``overlay`` lines of heads-up
        text drawn on it; raises ``ConfigError`` if its shape or dtype differs from the writer's. The frame is
        encoded later, on the writer thread: do not modify it after passing it here."""
        if self._closed:
            raise RuntimeError(f"VideoWriter for {self.path} is closed")
        frame = np.asarray(frame)
        if frame.shape != (self.height, self.width, 3) or frame.dtype != np.uint8:
            raise ConfigError(
                f"video frame {self.frame_count} has shape {frame.shape} dtype {frame.dtype}; expected "
                f"({self.height}, {self.width}, 3) uint8 (render at the writer's size)"
            )
        if int(repeat) < 1:
            raise ConfigError(f"VideoWriter.write repeat={repeat}: must be >= 1")
        self._worker.submit((frame, None if overlay is None else tuple(overlay), int(repeat)))
        self.frame_count += int(repeat)

    def close(self) -> Path | None:
        """Finish the stream and publish the mp4; returns its path, or None if no frame was written."""
        if self._closed:
            return self.path if self.path.exists() else None
        self._closed = True
        try:
            self._worker.close()
        finally:
            try:
                self._writer.close()
            finally:
                if self._worker.failed or self.frame_count == 0:
                    self._temporary.unlink(missing_ok=True)
        if self._worker.failed or self.frame_count == 0:
            return None
        return publish(self._temporary, self.path)

    def _encode(self, item: tuple) -> None:
        """Worker thread: draw the heads-up text and stream the frame to ffmpeg."""
        frame, overlay, repeat = item
        image = np.ascontiguousarray(frame if overlay is None else annotate(frame, overlay))
        for _ in range(repeat):
            self._writer.send(image)

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
