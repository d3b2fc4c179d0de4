"""What the live browser tests share: the server as a user starts it, and waiting in the page's simulated time,
so that a loaded host (the suite's other worker, a slow CI machine) slows a test down instead of failing it.

The server paces the simulation against the wall clock and re-anchors when it falls behind
(``RealtimeClock``), so under load fewer simulated seconds pass per wall second. A deadline in wall seconds then
expires while the episode is still on time in its own clock. Deadlines here count the simulated seconds the page
has seen (``window.liveStats.lastState.sim_time``); a wall-clock stall limit still ends a test whose simulation
stopped (no frames, a crashed server).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time

STALL_S = 120.0  # wall seconds without the simulated clock moving before a wait gives up


class LiveServer:
    """``embodied-adhoc live toxic-waste --port 0 ARGUMENTS`` in a subprocess. Its output is read on a thread
    from the start, so a full pipe never blocks the server, and kept for failure messages."""

    def __init__(self, arguments: list[str]):
        command = [
            sys.executable,
            "-m",
            "embodied_adhoc.cli",
            "live",
            "toxic-waste",
            "--port",
            "0",
            *arguments,
        ]
        environment = {**os.environ, "MUJOCO_GL": "egl", "PYTHONUNBUFFERED": "1"}
        self.process = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=environment
        )
        self.lines: list[str] = []
        self._announced = threading.Event()
        self.url: str | None = None
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        if not self._announced.wait(STALL_S) or self.url is None:
            self.kill()
            raise AssertionError("the server did not announce its URL:\n" + self.output())

    def _read(self) -> None:
        for line in self.process.stdout:
            self.lines.append(line)
            found = self.url is None and re.search(r"live: open (http://127\.0\.0\.1:\d+/)", line)
            if found:
                self.url = found.group(1)
                self._announced.set()
        self._announced.set()  # the server exited before announcing

    def output(self) -> str:
        return "".join(self.lines)

    def tail(self, lines: int = 30) -> str:
        return "".join(self.lines[-lines:])

    def interrupt(self) -> str:
        """Stop the server as Ctrl-C does; everything it printed."""
        self.process.send_signal(signal.SIGINT)
        self.process.wait(STALL_S)
        self._reader.join(STALL_S)
        return self.output()

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait(STALL_S)


class SimClock:
    """Simulated seconds the page has shown, summed over episodes.

    ``sim_time`` restarts at 0 with each episode and the page keeps the last episode's state until the next
    frame, so a backward jump is a new episode and counts its new time as progress.
    """

    def __init__(self, driver, context=None):
        self.driver = driver
        self.context = context  # called for what a failure message adds (the server's last output lines)
        self.elapsed = 0.0
        self._last: float | None = None
        self.moved_at = time.monotonic()

    def read(self) -> float:
        value = self.driver.execute_script(
            "const s = window.liveStats && window.liveStats.lastState; return s ? s.sim_time : null;"
        )
        self.observe(value)
        return self.elapsed

    def observe(self, sim_time) -> None:
        """Take a ``sim_time`` already read from a frame (saves a round trip to the page)."""
        if sim_time is None:
            return
        sim_time = float(sim_time)
        if self._last is None or sim_time < self._last:
            step = sim_time if self._last is not None else 0.0
        else:
            step = sim_time - self._last
        self._last = sim_time
        if step > 0:
            self.elapsed += step
            self.moved_at = time.monotonic()

    def deadline(self, sim_seconds: float, what: str, stall_s: float = STALL_S) -> Deadline:
        return Deadline(self, sim_seconds, what, stall_s)

    def wait(self, condition, sim_seconds: float, what: str, stall_s: float = STALL_S, poll: float = 0.05):
        """The first truthy value of ``condition()`` within ``sim_seconds`` of simulated time."""
        deadline = self.deadline(sim_seconds, what, stall_s)
        while True:
            value = condition()
            if value:
                return value
            deadline.check()
            time.sleep(poll)


class Deadline:
    """``sim_seconds`` of simulated time from now, or ``stall_s`` wall seconds without the clock moving."""

    def __init__(self, clock: SimClock, sim_seconds: float, what: str, stall_s: float):
        self.clock, self.sim_seconds, self.what, self.stall_s = (
            clock,
            float(sim_seconds),
            what,
            float(stall_s),
        )
        self.start = clock.read()
        self._waiting_since = time.monotonic()

    def passed(self, read: bool = True) -> float:
        """Simulated seconds since the deadline was set (``read=False``: as last observed, no page round trip)."""
        return (self.clock.read() if read else self.clock.elapsed) - self.start

    def check(self, detail: str = "", read: bool = True) -> None:
        """Raise if the simulated budget is spent or the clock stalled."""
        spent = self.passed(read)
        stalled = time.monotonic() - max(self.clock.moved_at, self._waiting_since)
        if spent > self.sim_seconds:
            problem = f"{self.sim_seconds:g} simulated s passed"
        elif stalled > self.stall_s:
            problem = f"the simulated clock stood still for {stalled:.0f} wall s"
        else:
            return
        context = f"\n{self.clock.context()}" if self.clock.context else ""
        raise AssertionError(f"{problem} waiting for {self.what}{detail}{context}")
