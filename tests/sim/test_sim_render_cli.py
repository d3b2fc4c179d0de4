"""``embodied-adhoc render lab`` through the console script."""

from __future__ import annotations

import os
import subprocess
import sys

import imageio.v3 as iio


def _cli(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    return subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )


def test_render_lab_writes_an_image(tmp_path):
    out = tmp_path / "lab.png"
    done = _cli(
        "render", "lab", "--out", str(out), "--width", "96", "--height", "80", "--fast", "--task", "1,2,3"
    )
    assert done.returncode == 0, done.stderr
    image = iio.imread(out)
    assert image.shape == (80, 96, 3) and image.std() > 5
    assert not list(tmp_path.glob(".*partial*"))  # the temporary file was renamed


def test_render_rejects_bad_input_with_one_line(tmp_path):
    bad_pick = _cli("render", "lab", "--out", str(tmp_path / "x.png"), "--pick", "0", "--fast")
    assert bad_pick.returncode == 2 and "pick a ball in the human's area" in bad_pick.stderr
    bad_suffix = _cli("render", "lab", "--out", str(tmp_path / "x.gif"))
    assert bad_suffix.returncode == 2 and ".png or .jpg" in bad_suffix.stderr
    bare = _cli("render")
    assert bare.returncode == 2 and "lab" in bare.stdout
