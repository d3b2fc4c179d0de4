"""One background thread with a bounded queue: how recorders move encoding off the simulation thread.

``submit(item)`` hands an item to ``handle(item)`` running on the worker thread and returns at once, unless the
queue is full (then it waits: memory stays bounded when the encoder falls behind). An exception raised by
``handle`` stops the worker and is raised once, wrapped in ``RuntimeError``, by the next ``submit`` or by ``close``;
``close`` drains the queue and joins the thread; ``finish()``, if given, runs last on the worker thread (e.g. to
release a GL context made there), after an error too. Used by ``record.video.VideoWriter`` (overlay + H.264),
``record.rerun_recorder.RerunRecorder`` (JPEG camera frames) and the recorded episodes' render thread
(``episodes.recording.Recording``).
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from typing import Any

_DONE = object()


class BackgroundWorker:
    """Run ``handle`` on every submitted item, in order, on one daemon thread named ``name``."""

    def __init__(
        self,
        handle: Callable[[Any], None],
        name: str,
        max_queued: int = 16,
        finish: Callable[[], None] | None = None,
    ):
        if int(max_queued) < 1:
            raise ValueError(f"BackgroundWorker max_queued={max_queued}: must be >= 1")
        self._handle, self._finish = handle, finish
        self._queue: queue.Queue = queue.Queue(maxsize=int(max_queued))
        self._error: BaseException | None = None
        self._reported = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()
        self._closed = False

    @property
    def failed(self) -> bool:
        return self._error is not None

    def submit(self, item: Any) -> None:
        """Queue ``item`` (waits while the queue is full); raises the worker's error if it has failed."""
        if self._closed:
            raise RuntimeError(f"{self._thread.name}: submit after close")
        self.raise_error()
        self._put(item)

    def close(self) -> None:
        """Let the worker finish every queued item, then stop it; raises its error, if any (idempotent)."""
        if not self._closed:
            self._closed = True
            self._put(_DONE)
            self._thread.join()
        self.raise_error()

    def raise_error(self) -> None:
        """Raise the worker's error once (``failed`` stays True afterwards)."""
        if self._error is not None and not self._reported:
            self._reported = True
            raise RuntimeError(f"{self._thread.name} failed: {self._error}") from self._error

    def _put(self, item: Any) -> None:
        while self._thread.is_alive():  # a stopped worker must not leave the caller blocked on a full queue
            try:
                self._queue.put(item, timeout=0.5)
                return
            except queue.Full:
                continue

    def _run(self) -> None:
        try:
            while (item := self._queue.get()) is not _DONE:
                self._handle(item)
        except BaseException as error:  # reported on the caller's thread by submit() or close()
            self._error = error
        finally:
            if self._finish is not None:
                try:
                    self._finish()
                except BaseException as error:
                    self._error = self._error or error
