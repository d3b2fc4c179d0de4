"""The rerun recording: `rerun rrd verify` accepts it and every documented entity can be read back."""

import shutil
import subprocess
import sys
import time
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
            recorder.log_localisation((step + 0.01, 0.0, 0.1), np.full((5, 2), float(step)))
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


def test_frames_are_batched_and_images_keep_their_own_time(tmp_path):
    """Per-frame poses go out as columns and row data is compacted: a few chunks per entity, not one per 200 ms
    of wall time; camera images JPEG-encoded on the worker thread carry the time they were logged at."""
    from rerun.chunk import RrdReader

    path = tmp_path / "long.rrd"
    with RerunRecorder(path) as recorder:
        for frame in range(300):
            step = frame // 20 + 1
            recorder.set_time(step, 0.25 * frame)
            recorder.log_poses(
                (0.01 * frame, 0.0, 0.1), (0.01 * frame, 0.02, 0.1), (1.0, 1.0), np.zeros((3, 3))
            )
            cloud = np.full((4, 2), float(frame)) if frame % 10 == 0 else None
            recorder.log_localisation((0.01 * frame, 0.5, 0.0), cloud)
            if frame % 20 == 0:
                recorder.log_camera("overhead", np.full((24, 32, 3), frame % 250, np.uint8))
                recorder.log_text("actions", f"step {step}")
            # about 1 s of wall time in all: the SDK's default 200 ms flush tick would cut ~5 chunks
            time.sleep(0.003)
    chunks: dict[str, list] = {}
    for chunk in RrdReader(path).store().stream().to_chunks():
        chunks.setdefault(chunk.entity_path.lstrip("/"), []).append(chunk.to_record_batch())
    batched = ("world/robot", "world/balls", "metrics/odometry_error", "camera/overhead", "log/actions")
    for entity in (*batched, "world/localisation/estimate", "world/localisation/particles"):
        assert len(chunks[entity]) <= 2, (entity, len(chunks[entity]))

    def temporal(entity):  # (sim_time in s, positions) of the rows logged on the timeline
        rows = []
        for batch in chunks[entity]:
            if "sim_time" not in batch.schema.names:
                continue  # the static colours and radii
            column = next(name for name in batch.schema.names if name.endswith("Points3D:positions"))
            times = batch.column("sim_time").cast("int64").to_pylist()  # nanoseconds
            rows += [
                (t / 1e9, np.array(p)) for t, p in zip(times, batch.column(column).to_pylist(), strict=True)
            ]
        return sorted(rows, key=lambda row: row[0])

    estimates = temporal("world/localisation/estimate")
    assert len(estimates) == 300
    np.testing.assert_allclose(estimates[7][1], [[0.07, 0.5, 0.05]])
    clouds = temporal("world/localisation/particles")
    assert [t for t, _ in clouds] == [0.25 * f for f in range(0, 300, 10)]
    np.testing.assert_allclose(clouds[3][1], np.column_stack([np.full((4, 2), 30.0), np.full(4, 0.02)]))
    robot_rows = sum(batch.num_rows for batch in chunks["world/robot"])
    assert robot_rows == 300
    image_steps = sorted(
        int(value)
        for batch in chunks["camera/overhead"]
        if "step" in batch.schema.names
        for value in batch.column("step").to_pylist()
    )
    assert image_steps == list(range(1, 16))
