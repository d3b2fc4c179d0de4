"""MP4 writer: H.264 (libx264), yuv420p, fixed frame rate, through the ffmpeg binary bundled by imageio-ffmpeg.

Frames are encoded off the caller's thread: :meth:`VideoWriter.write` checks a frame and puts it on a bounded
queue; a writer thread draws the heads-up text (``record.overlay``) and streams it to ffmpeg. The simulation thread
therefore pays only for rendering, and the queue bound (``queue_frames``) keeps memory flat: when ffmpeg falls
behind, ``write`` waits. The file is written under a temporary name and renamed to its final name by
:meth:`VideoWriter.close`, so an mp4 that exists is complete; closing after an interruption keeps the frames
written so far. An error on the writer thread is raised by the next ``write`` or by ``close``.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from embodied_adhoc.atomic import publish, temporary_sibling
from embodied_adhoc.errors import ConfigError

_DONE = object()


class VideoWriter:
    """Write RGB frames (``uint8``, shape ``(height, width, 3)``) to an H.264 mp4 at ``fps`` frames per second.

    ``width`` and ``height`` must be even (yuv420p subsamples chroma by two); frames of another shape are an
    error rather than being silently resized. Use as a context manager or call :meth:`close`.
    """

    def __init__(
        self,
        path: str | Path,
        width: int,
        height: int,
        fps: float = 15.0,
        quality: float = 7.0,
        queue_frames: int = 16,
    ):
        if width <= 0 or height <= 0 or width % 2 or height % 2:
            raise ConfigError(
                f"video size {width}x{height}: width and height must be positive and even (H.264 yuv420p); "
                "pass e.g. --width 640 --height 480"
            )
        if not fps > 0:
            raise ConfigError(f"video fps={fps}: must be > 0 (e.g. --video-fps 15)")
        if int(queue_frames) < 1:
            raise ConfigError(f"VideoWriter queue_frames={queue_frames}: must be >= 1")
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
        self._queue: queue.Queue = queue.Queue(maxsize=int(queue_frames))
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._encode, name=f"video {self.path.name}", daemon=True)
        self._thread.start()
        self._closed = False

    def write(self, frame: np.ndarray, overlay: Sequence[str] | None = None, repeat: int = 1) -> None:
        """Append ``frame`` ``repeat`` times (e.g. to hold the final state), with ``overlay`` lines of heads-up
        text drawn on it; raises ``ConfigError`` if its shape or dtype differs from the writer's. The frame is
        encoded later, on the writer thread: do not modify it after passing it here."""
        if self._closed:
            raise RuntimeError(f"VideoWriter for {self.path} is closed")
        self._raise_writer_error()
        frame = np.asarray(frame)
        if frame.shape != (self.height, self.width, 3) or frame.dtype != np.uint8:
            raise ConfigError(
                f"video frame {self.frame_count} has shape {frame.shape} dtype {frame.dtype}; expected "
                f"({self.height}, {self.width}, 3) uint8 (render at the writer's size)"
            )
        if int(repeat) < 1:
            raise ConfigError(f"VideoWriter.write repeat={repeat}: must be >= 1")
        self._put((frame, None if overlay is None else tuple(overlay), int(repeat)))
        self.frame_count += int(repeat)

    def close(self) -> Path | None:
        """Finish the stream and publish the mp4; returns its path, or None if no frame was written."""
        if self._closed:
            return self.path if self.path.exists() else None
        self._closed = True
        self._put(_DONE)
        self._thread.join()
        try:
            self._writer.close()
        finally:
            if self._error is not None or self.frame_count == 0:
                self._temporary.unlink(missing_ok=True)
        self._raise_writer_error()
        if self.frame_count == 0:
            return None
        return publish(self._temporary, self.path)

    # ------------------------------------------------------------------------------------------ internals
    def _put(self, item) -> None:
        while True:  # a dead writer thread must not leave the caller blocked on a full queue
            if not self._thread.is_alive():
                return
            try:
                self._queue.put(item, timeout=0.5)
                return
            except queue.Full:
                continue

    def _raise_writer_error(self) -> None:
        if self._error is not None:
            error, self._error = self._error, None
            raise RuntimeError(f"encoding {self.path} failed: {error}") from error

    def _encode(self) -> None:
        from embodied_adhoc.record.overlay import annotate

        try:
            while True:
                item = self._queue.get()
                if item is _DONE:
                    return
                frame, overlay, repeat = item
                image = np.ascontiguousarray(frame if overlay is None else annotate(frame, overlay))
                for _ in range(repeat):
                    self._writer.send(image)
        except BaseException as error:  # reported on the caller's thread by write() or close()
            self._error = error

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
