"""Output paths, render sizes, devices and voices are checked before any work starts.

Each case runs the real command in a subprocess and asserts exit 2 with one line naming the flag and the value,
and that nothing ran: no stdout (no report, no progress), no folder or file written.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest


def run_cli(*args: str) -> subprocess.CompletedProcess:
    environment = {**os.environ, "MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}
    return subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", *args],
        capture_output=True,
        text=True,
        timeout=300,
        env=environment,
    )


def assert_refused(result: subprocess.CompletedProcess, *names: str) -> str:
    assert result.returncode == 2, (result.returncode, result.stderr[-2000:])
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr[-2000:]  # a progress bar would add lines (carriage returns too)
    assert "\r" not in result.stderr and "Traceback" not in result.stderr
    for name in names:
        assert name in lines[0], (name, lines[0])
    return lines[0]


needs_espeak = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng is not installed")


def test_speech_eval_refuses_an_unwritable_out_before_measuring():
    result = run_cli("speech", "eval", "--out", "/proc/c.json", "--phrases", "1")
    assert_refused(result, "--out", "/proc/c.json", "cannot write")


@pytest.mark.parametrize("command", [["say", "where"], ["try", "I am at the door"]])
def test_speech_wav_outputs_are_checked_first(command):
    result = run_cli("speech", *command, "--wav", "/proc/x.wav")
    assert_refused(result, "--wav", "/proc/x.wav")


def test_train_refuses_an_existing_file_as_out(tmp_path):
    path = tmp_path / "weights"
    path.write_text("keep me\n")
    result = run_cli("train", "atlpo", "--domain", "foraging", "--set", "task", "--out", str(path))
    assert_refused(result, "--out", str(path), "not a folder")
    assert path.read_text() == "keep me\n"


def test_train_refuses_cuda_without_one_before_the_progress_bar(tmp_path):
    torch = pytest.importorskip("torch")
    if torch.cuda.is_available():
        pytest.skip("this host has CUDA: --device cuda is valid here")
    out = tmp_path / "library"
    result = run_cli(
        "train", "atlpo", "--domain", "foraging", "--set", "task", "--device", "cuda", "--out", str(out)
    )
    assert_refused(result, "cuda", "auto or cpu")
    assert not out.exists()


@pytest.mark.parametrize(
    ("width", "height", "expected"),
    [
        ("100000", "100000", "--width 100000 --height 100000: render size"),
        ("641", "480", "must be positive and even"),
    ],
    ids=["beyond-the-renderer", "odd-for-the-video"],
)
def test_run_refuses_a_frame_it_cannot_record_before_the_episode(tmp_path, width, height, expected):
    out = tmp_path / "episode"
    result = run_cli(
        "run", "toxic-waste", "--record", str(out), "--width", width, "--height", height, "--no-progress"
    )
    assert_refused(result, f"{width}x{height}", expected)
    assert not out.exists()


@pytest.mark.parametrize("size", ["100000", "481"])
def test_run_pursuit_refuses_a_frame_the_arena_cannot_render(tmp_path, size):
    out = tmp_path / "episode"
    result = run_cli("run", "pursuit", "--record", str(out), "--size", size, "--no-progress")
    assert_refused(result, "--size", "even size 2..640")
    assert not out.exists()


def test_the_scene_limit_is_the_renderers():
    """The early check reads the same offscreen buffer that the renderer enforces on the compiled model."""
    from embodied_adhoc.sim.lab_model import load_lab_model
    from embodied_adhoc.sim.lab_render import check_render_size

    model = load_lab_model()
    width, height = model.vis.global_.offwidth, model.vis.global_.offheight
    check_render_size(width, height)
    for size in ((width + 1, height), (width, height + 1), (0, height)):
        with pytest.raises(Exception, match="outside 1x1"):
            check_render_size(*size)


@needs_espeak
@pytest.mark.parametrize(
    ("voice", "expected"),
    [
        ("klingonx", "no voice 'klingonx'; installed languages: "),
        ("en-us+zzz", "no variant 'zzz'; installed variants: "),
        ("en-us+female3", "no variant 'female3'"),  # a display name: espeak-ng would ignore it silently
    ],
)
def test_speech_try_refuses_an_unknown_voice_with_the_installed_ones(voice, expected):
    line = assert_refused(run_cli("speech", "try", "I am at the door", "--voice", voice), "--voice", expected)
    assert "en-us" in line or "f3" in line


@needs_espeak
def test_speech_eval_refuses_an_unknown_voice_in_its_list():
    result = run_cli("speech", "eval", "--voices", "en-us,nope", "--phrases", "1", "--out", "none")
    assert_refused(result, "--voices 'nope'", "installed languages")


@needs_espeak
def test_every_default_voice_and_espeak_spelling_is_accepted():
    from embodied_adhoc.comms import synthesis

    for voice in (*synthesis.DEFAULT_VOICES, "EN-US", "gmw/en-US", "en", "English (America)", "en+Alex"):
        assert synthesis.check_voice(voice) == voice
