"""One process at a time writes a run folder: a second is refused with the owner named; a lock left by a
process that died is taken over with a note. Real processes throughout."""

import os
import subprocess
import sys
from pathlib import Path

from test_experiments_cli import HERE, LAUNCHER, trials

HOLDER = (
    "import sys; from pathlib import Path;"
    "from embodied_adhoc.experiments.storage import RunLock;"
    "lock = RunLock(Path(sys.argv[1])); lock.acquire(); print('locked', flush=True); sys.stdin.read(); lock.release()"
)


def hold(folder: Path) -> subprocess.Popen:
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(folder)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert holder.stdout.readline().strip() == "locked"
    return holder


def test_a_second_process_is_refused_and_a_dead_owners_lock_is_taken_over(tmp_path):
    out = tmp_path / "run"
    command = ("guess", "--agents", "bayes,random", "--episodes", "3", "--out", str(out))
    holder = hold(out)
    try:
        refused = trials(*command)
        assert refused.returncode == 2
        assert refused.stderr.count("\n") == 1
        assert f"{out} is in use by PID {holder.pid} on " in refused.stderr
        assert not (out / "trials.csv").exists()  # refused before any work
    finally:
        holder.kill()
        holder.wait(timeout=30)
    taken = trials(*command)
    assert taken.returncode == 0, taken.stderr
    assert f"took over the lock left by PID {holder.pid}" in taken.stderr
    assert len((out / "trials.csv").read_text().splitlines()) == 1 + 6
    assert not (out / "run.lock").exists()  # released when the run ended
    again = trials(*command)
    assert again.returncode == 0 and "took over" not in again.stderr


def test_two_cli_runs_at_once_write_each_trial_once(tmp_path):
    out = tmp_path / "run"
    holder = hold(out)  # the first "run" holds the folder while the second starts
    second = subprocess.Popen(
        [sys.executable, "-c", LAUNCHER, str(HERE), "trials", "guess", "--episodes", "4", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    _, err = second.communicate(timeout=300)
    assert second.returncode == 2 and "is in use by" in err
    holder.stdin.close()  # the holder ends normally and releases the folder
    holder.wait(timeout=30)
    third = trials("guess", "--episodes", "4", "--out", str(out))
    assert third.returncode == 0, third.stderr
    assert "took over" not in third.stderr
    rows = (out / "trials.csv").read_text().splitlines()[1:]
    keys = [tuple(row.split(",")[:2]) for row in rows]
    assert len(keys) == len(set(keys)) == 4 * 4


def test_a_lock_naming_a_dead_pid_is_stale(tmp_path):
    # the PID of a process that has exited (and been reaped): nothing holds the lock file it names
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait(timeout=60)
    out = tmp_path / "run"
    out.mkdir()
    (out / "run.lock").write_text(f'{{"pid": {dead.pid}, "host": "{os.uname().nodename}"}}\n')
    result = trials("guess", "--agents", "bayes", "--episodes", "2", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert f"took over the lock left by PID {dead.pid}" in result.stderr
    assert not (out / "run.lock").exists()
