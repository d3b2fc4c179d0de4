"""CLI smoke tests through a subprocess, as a user would run it."""

import os
import signal
import subprocess
import sys
import time

import pytest


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", *args], capture_output=True, text=True, timeout=120
    )


def test_top_level_help_lists_commands():
    result = run_cli("--help")
    assert result.returncode == 0, result.stderr
    assert "embodied-adhoc" in result.stdout


def test_every_subcommand_has_help():
    from embodied_adhoc.cli import build_parser

    parser = build_parser()
    subparsers = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    for name in subparsers.choices:
        result = run_cli(name, "--help")
        assert result.returncode == 0, (name, result.stderr)
        assert "usage:" in result.stdout


# ------------------------------------------------------------------------------------- clean failure (issue 11)
# Every bad input: exit status 2 and exactly one line on stderr that names the flag, before any work starts.
BAD_INPUT = [
    (["trials", "toxic-waste", "--seed", "-1"], "--seed"),
    (["run", "toxic-waste", "--seed", "-1"], "--seed"),
    (["render", "lab", "--seed", "-1", "--out", "{tmp}/x.png"], "--seed"),
    (["speech", "eval", "--seed", "-1"], "--seed"),
    (["render", "lab", "--width", "0", "--out", "{tmp}/x.png"], "--width"),  # was a silent 640-pixel default
    (["run", "toxic-waste", "--record", "{file}"], "--record"),  # an existing file
    (["run", "toxic-waste", "--record", "{file}/sub"], "--record"),  # under a file
    (["run", "toxic-waste", "--record", "/proc/embodied-adhoc/run"], "--record"),  # not writable
    (["trials", "toxic-waste", "--out", "{file}"], "--out"),
    (["trials", "toxic-waste", "--out", "{file}/sub"], "--out"),
    (["trials", "toxic-waste", "--out", "/proc/embodied-adhoc/trials"], "--out"),
    (["render", "lab", "--out", "{file}/x.png"], "--out"),
    (["render", "lab", "--out", "{tmp}"], "--out"),  # a folder where a file is wanted
    (["trials", "toxic-waste", "--workers", "-1", "--episodes", "1"], "--workers"),
    (["trials", "toxic-waste", "--agents", "nobody", "--episodes", "1"], "nobody"),
]


@pytest.mark.parametrize(("args", "named"), BAD_INPUT, ids=[" ".join(a) for a, _ in BAD_INPUT])
def test_bad_input_is_one_line_and_exit_2(tmp_path, args, named):
    file = tmp_path / "f"
    file.touch()
    result = run_cli(*(a.format(tmp=tmp_path, file=file) for a in args))
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert named in result.stderr and "Traceback" not in result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f"]  # nothing written, not even a probe


def test_json_into_a_closed_pipe_ends_quietly():
    # `embodied-adhoc envs --json | head -c 10`: the reader is gone before the output is written.
    process = subprocess.Popen(
        [sys.executable, "-m", "embodied_adhoc.cli", "envs", "--json"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    process.stdout.close()
    stderr = process.stderr.read().decode()
    assert process.wait(timeout=60) == 141
    assert stderr == ""


def test_render_chooses_egl_without_a_display(tmp_path):
    environment = {
        k: v for k, v in os.environ.items() if k not in ("DISPLAY", "MUJOCO_GL", "PYOPENGL_PLATFORM")
    }
    out = tmp_path / "lab.png"
    result = subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", "render", "lab", "--out", str(out), "--width", "64",
         "--height", "48", "--fast"],
        capture_output=True, text=True, timeout=300, env=environment,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "DISPLAY" not in result.stderr and "Traceback" not in result.stderr


def test_mujoco_trials_without_a_display_print_no_glfw_warning():
    environment = {
        k: v for k, v in os.environ.items() if k not in ("DISPLAY", "MUJOCO_GL", "PYOPENGL_PLATFORM")
    }
    result = subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", "trials", "foraging", "--backend", "mujoco", "--episodes", "1",
         "--agents", "random", "--max-steps", "5"],
        capture_output=True, text=True, timeout=300, env=environment,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "DISPLAY" not in result.stderr and "GLFW" not in result.stderr, result.stderr


def test_workers_are_capped_at_the_cpus_with_a_note():
    result = run_cli("trials", "toxic-waste", "--agents", "random", "--episodes", "2", "--workers", "1000")
    assert result.returncode == 0, result.stderr
    (note,) = result.stderr.strip().splitlines()
    assert note.startswith("embodied-adhoc: note: --workers 1000: using ")


def _start_sweep(out):
    """A long 2-worker sweep in its own process group (as a shell job), once it has committed a few trials."""
    process = subprocess.Popen(
        [sys.executable, "-m", "embodied_adhoc.cli", "trials", "toxic-waste", "--episodes", "20000",
         "--agents", "hotspot,random", "--workers", "2", "--out", str(out)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # a background job may inherit SIG_IGN
    )  # fmt: skip
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline:
        trials = out / "trials.csv"
        if trials.exists() and len(trials.read_text().splitlines()) > 5:
            return process
        assert process.poll() is None, process.stderr.read()
        time.sleep(0.2)
    process.kill()
    raise AssertionError("the sweep wrote no trials in 240 s")


def _group_is_gone(group: int, seconds: float = 20.0) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            os.killpg(group, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.1)
    os.killpg(group, signal.SIGKILL)
    return False


@pytest.mark.parametrize(
    ("signal_number", "to_group", "status", "message"),
    [
        (signal.SIGINT, True, 130, "interrupted"),  # Ctrl-C: the terminal signals the whole process group
        (signal.SIGTERM, False, 143, "terminated"),  # kill PID: only the main process
    ],
    ids=["ctrl-c", "sigterm"],
)
def test_interrupted_sweep_leaves_no_worker_and_one_line(tmp_path, signal_number, to_group, status, message):
    process = _start_sweep(tmp_path / "run")
    if to_group:
        os.killpg(process.pid, signal_number)
    else:
        process.send_signal(signal_number)
    stderr = process.stderr.read()
    assert process.wait(timeout=120) == status, stderr
    assert stderr.strip().splitlines() == [f"embodied-adhoc: {message} (finished work was kept)"]
    assert _group_is_gone(process.pid), "a pool worker outlived the sweep"


@pytest.mark.parametrize(
    ("environment", "expected"),
    [
        ({}, "egl egl"),  # headless, nothing chosen: EGL
        ({"MUJOCO_GL": "osmesa"}, "osmesa osmesa"),  # the user's choice wins
        ({"DISPLAY": ":0"}, "None None"),  # a display: MuJoCo's own default (GLFW)
    ],
)
def test_gl_platform_choice(environment, expected):
    if not sys.platform.startswith("linux"):
        pytest.skip("EGL is chosen on Linux only")
    clean = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "MUJOCO_GL")}
    code = "import os; from embodied_adhoc.gl import choose_gl_platform as c; print(c(), os.environ.get('MUJOCO_GL'))"
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env={**clean, **environment}, timeout=60
    )
    assert result.stdout.strip() == expected, result.stderr
