"""Signals and pool workers, with real processes: the workers of a parent killed by SIGKILL exit on their own; a
second signal while the command stops is one line, and the command keeps the first signal's exit status."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
LAUNCHER = (
    "import sys; sys.path.insert(0, sys.argv.pop(1));"
    "from embodied_adhoc.experiments.registry import register_trial_domain;"
    "register_trial_domain('slow', 'slow_trial_domain:DOMAIN');"
    "from embodied_adhoc.cli import main; sys.exit(main(sys.argv[1:]))"
)
BOUND_S = 60.0  # generous bounds on waits: the properties are "they exit", not how fast


def start(tmp_path, **environment) -> tuple[subprocess.Popen, Path]:
    pids = tmp_path / "pids"
    pids.mkdir()
    command = ["trials", "slow", "--agents", "random", "--episodes", "200", "--workers", "2"]
    process = subprocess.Popen(
        [sys.executable, "-c", LAUNCHER, str(HERE), *command, "--out", str(tmp_path / "run")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # signals go to the parent alone, as `kill PID` sends them
        env={**os.environ, "SLOW_DOMAIN_PIDS": str(pids), **environment},
    )
    deadline = time.monotonic() + BOUND_S
    while len(list(pids.iterdir())) < 2:
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, "the workers did not start"
        time.sleep(0.1)
    return process, pids


def worker_pids(pids: Path) -> list[int]:
    return [int(path.name) for path in pids.iterdir()]


def running(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in ("Z", "X")  # a zombie has exited (its reaper may be slow)


def wait_gone(pids: list[int], bound: float) -> list[int]:
    deadline = time.monotonic() + bound
    while any(running(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    return [pid for pid in pids if running(pid)]


def test_workers_exit_when_their_parent_is_killed(tmp_path):
    process, pids = start(tmp_path)
    workers = worker_pids(pids)
    try:
        os.kill(process.pid, signal.SIGKILL)
        process.wait(timeout=BOUND_S)
        # Each worker is in the middle of a trial of about 3 s with many more queued: only noticing its parent's
        # death ends it (before, such workers ran on for minutes).
        assert wait_gone(workers, 10.0) == []
    finally:
        for pid in workers:
            if running(pid):
                os.kill(pid, signal.SIGKILL)
        process.communicate()


def test_a_second_signal_while_stopping_is_one_line_and_the_first_status_stays(tmp_path):
    # workers that ignore SIGTERM keep the parent stopping for TERMINATE_GRACE_S: the SIGINT lands in that time
    process, pids = start(tmp_path, SLOW_DOMAIN_IGNORE_SIGTERM="1")
    workers = worker_pids(pids)
    try:
        os.kill(process.pid, signal.SIGTERM)
        time.sleep(0.5)
        os.kill(process.pid, signal.SIGINT)
        _, err = process.communicate(timeout=BOUND_S)
        assert process.returncode == 143, err
        assert "Traceback" not in err
        lines = err.strip().splitlines()
        assert (
            lines.count("embodied-adhoc: SIGINT received while stopping; the workers are being stopped") == 1
        )
        assert lines[-1] == "embodied-adhoc: terminated (finished work was kept)"
        assert wait_gone(workers, BOUND_S) == []  # killed after the grace time
    finally:
        for pid in workers:
            if running(pid):
                os.kill(pid, signal.SIGKILL)
        if process.poll() is None:
            process.kill()
            process.communicate()
