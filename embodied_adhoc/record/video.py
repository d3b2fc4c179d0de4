"""MP4 writer: H.264 (libx264), yuv420p, fixed frame rate, through the ffmpeg binary bundled by imageio-ffmpeg.

Frames stream to ffmpeg as they arrive (no episode-long buffer in memory). The file is written under a
temporary name and renamed to its final name by :meth:`VideoWriter.close`, so an mp4 that exists is complete;
closing after an interruption keeps the frames written so far.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from embodied_adhoc.atomic import publish, temporary_sibling
from embodied_adhoc.errors import ConfigError


class VideoWriter:
    """Write RGB frames (``uint8``, shape ``(height, width, 3)``) to an H.264 mp4 at ``fps`` frames per second.

    ``width`` and ``height`` must be even (yuv420p subsamples chroma by two); frames of another shape are an
    error rather than being silently resized. Use as a context manager or call :meth:`close`.
    """

    def __init__(self, path: str | Path, width: int, height: int, fps: float = 15.0, quality: float = 7.0):
        if width <= 0 or height <= 0 or width % 2 or height % 2:
            raise ConfigError(
                f"video size {width}x{height}: width and height must be positive and even (H.264 yuv420p); "
                "pass e.g. --width 640 --height 480"
            )
        if not fps > 0:
            raise ConfigError(f"video fps={fps}: must be > 0 (e.g. --video-fps 15)")
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
            quality=quality,
            macro_block_size=1,
            ffmpeg_log_level="error",
        )
        self._writer.send(None)  # start the ffmpeg process
        self._closed = False

    def write(self, frame: np.ndarray) -> None:
        """Append one frame; raises ``ConfigError`` if its shape or dtype differs from the writer's."""
        if self._closed:
            raise RuntimeError(f"VideoWriter for {self.path} is closed")
        frame = np.asarray(frame)
        if frame.shape != (self.height, self.width, 3) or frame.dtype != np.uint8:
            raise ConfigError(
                f"video frame {self.frame_count} has shape {frame.shape} dtype {frame.dtype}; expected "
                f"({self.height}, {self.width}, 3) uint8 (render at the writer's size)"
            )
        self._writer.send(np.ascontiguousarray(frame))
        self.frame_count += 1

    def close(self) -> Path | None:
        """Finish the stream and publish the mp4; returns its path, or None if no frame was written."""
        if self._closed:
            return self.path if self.path.exists() else None
        self._closed = True
        self._writer.close()
        if self.frame_count == 0:
            self._temporary.unlink(missing_ok=True)
            return None
        return publish(self._temporary, self.path)

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
