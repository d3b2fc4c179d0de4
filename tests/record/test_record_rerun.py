"""The rerun recording: `rerun rrd verify` accepts it and every documented entity can be read back."""

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from embodied_adhoc.record.rerun_recorder import ENTITY_PATHS, RerunRecorder


def rerun_binary() -> str | None:
    candidate = Path(sys.executable).with_name("rerun")
    return str(candidate) if candidate.exists() else shutil.which("rerun")


def recorded_entities(path: Path) -> dict[str, set[str]]:
    """Entity path -> component column names, read back through rerun's chunk reader."""
    from rerun.chunk import RrdReader

    store = RrdReader(path).store()
    columns: dict[str, set[str]] = {}
    for chunk in store.stream().to_chunks():
        names = set(chunk.to_record_batch().schema.names)
        columns.setdefault(chunk.entity_path.lstrip("/"), set()).update(names)
    return columns


def write_small_recording(path: Path) -> None:
    square = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], float)
    with RerunRecorder(path) as recorder:
        recorder.log_lab(
            square * 5,
            {"door": square, "open space": square + 2},
            [(1, 1), (3, 3)],
            ["door", "open space"],
            [(0, 1)],
        )
        for step in range(3):
            recorder.set_time(step, 1.5 * step)
            recorder.log_poses((step, 0.0, 0.1), (step + 0.05, 0.0, 0.1), (3.0, 3.0), np.zeros((3, 3)))
            recorder.log_belief(np.array([0.4, 0.6]), 0.97)
            for channel in ("observations", "actions", "utterances", "events"):
                recorder.log_text(channel, f"{channel} {step}")
            recorder.log_camera("overhead", np.full((24, 32, 3), 40 * step, np.uint8))
        recorder.log_audio(b"RIFF\x24\x00\x00\x00WAVEfmt ")


def test_recording_verifies_and_reads_back(tmp_path):
    path = tmp_path / "episode.rrd"
    write_small_recording(path)
    assert path.exists() and not list(tmp_path.glob(".*partial*"))
    entities = recorded_entities(path)
    for entity in ENTITY_PATHS:
        assert any(name == entity or name.startswith(entity + "/") for name in entities), entity
    assert any("BarChart:values" in c for c in entities["belief/task"])
    assert any("EncodedImage:blob" in c for c in entities["camera/overhead"])
    assert {"step", "sim_time"} <= entities["world/robot"]
    binary = rerun_binary()
    if binary is None:
        pytest.fail("the rerun CLI (shipped in the rerun-sdk wheel) is missing")
    result = subprocess.run([binary, "rrd", "verify", str(path)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr


def test_unknown_text_channel_is_an_error(tmp_path):
    with RerunRecorder(tmp_path / "x.rrd") as recorder, pytest.raises(ValueError, match="observations"):
        recorder.log_text("chat", "hello")
