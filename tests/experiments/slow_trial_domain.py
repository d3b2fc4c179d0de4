"""A test-only trial domain whose trials take seconds (the guess domain, slowed): for tests of signals and of the
worker processes, run as real subprocesses.

Environment variables read in the worker that creates the env: ``SLOW_DOMAIN_PIDS`` (a folder: each worker
touches a file named by its PID there) and ``SLOW_DOMAIN_IGNORE_SIGTERM`` (set: the worker ignores SIGTERM, as a
worker stuck in a C library would).
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

from fake_trial_domain import GuessDomain, GuessEnv, Session

STEP_SECONDS = 0.5


class SlowEnv(GuessEnv):
    def step(self, action):
        time.sleep(STEP_SECONDS)
        return super().step(action)


class SlowSession(Session):
    def make_env(self, max_steps):
        if os.environ.get("SLOW_DOMAIN_IGNORE_SIGTERM"):
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
        folder = os.environ.get("SLOW_DOMAIN_PIDS")
        if folder:
            (Path(folder) / str(os.getpid())).touch()
        return SlowEnv()


class SlowDomain(GuessDomain):
    name = "slow"
    description = "test domain: the guess domain with half-second steps"

    def open_session(self, backend, options):
        return SlowSession()


DOMAIN = SlowDomain()
