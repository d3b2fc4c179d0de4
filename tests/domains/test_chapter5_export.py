"""`embodied-adhoc pomdp export DOMAIN --out DIR` through a subprocess: files that read back as the same models."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from embodied_adhoc.decision.pomdp_io import read_pomdp
from embodied_adhoc.domains.chapter5 import build_library

ROOT = Path(__file__).resolve().parents[2]


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_export_writes_models_that_read_back(tmp_path):
    result = run(
        "pomdp",
        "export",
        "panic-buttons",
        "--size",
        "3",
        "--teammate",
        "suboptimal",
        "--out",
        str(tmp_path),
        "--json",
    )
    assert result.returncode == 0, result.stderr
    document = json.loads(result.stdout)
    assert [m["states"] for m in document["models"]] == [82, 82, 82]
    assert json.loads((tmp_path / "library.json").read_text())["models"] == document["models"]
    library = build_library("panic-buttons", size=3, teammate="suboptimal")
    for k, original in enumerate(library.pomdps):
        loaded = read_pomdp(tmp_path / f"panic-buttons-m{k}.pomdp")
        assert loaded.state_names == original.state_names
        for a in range(original.n_actions):
            assert abs(loaded.transitions[a] - original.transitions[a]).max() < 1e-12
            assert abs(loaded.observations[a] - original.observations[a]).max() < 1e-12
        np.testing.assert_array_equal(loaded.rewards, original.rewards)


def test_power_plant_exports_each_task_at_its_own_size(tmp_path):
    result = run("pomdp", "export", "power-plant", "--out", str(tmp_path), "--json")
    assert result.returncode == 0, result.stderr
    assert [m["states"] for m in json.loads(result.stdout)["models"]] == [105, 97]
    assert read_pomdp(tmp_path / "power-plant-m1.pomdp").n_states == 97


def test_bad_map_and_foreign_flag_are_one_line_errors(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("S.G\nS*G\n")
    result = run("pomdp", "export", "map", "--map", str(bad), "--out", str(tmp_path / "out"))
    assert result.returncode == 2
    assert f"{bad}:2:2: bad character '*'" in result.stderr and result.stderr.count("\n") == 1
    result = run("pomdp", "export", "ntu", "--size", "4", "--out", str(tmp_path / "out"))
    assert result.returncode == 2 and "--size does not apply to domain ntu" in result.stderr
