"""Arena scripts: a short recording (mp4 + rrd) and the benchmark's rate helper."""

import importlib.util
import sys
from pathlib import Path

import numpy as np

from embodied_adhoc import paths


def load(name):
    path = Path(paths.__file__).resolve().parent.parent / "scripts" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"arena_script_{name}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[f"arena_script_{name}"] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def test_record_arena_writes_mp4_and_rrd(tmp_path):
    record = load("record_arena")
    record.main(record.Args(domain="pursuit", max_steps=2, fps=5.0, size=128, out=tmp_path))
    stem = tmp_path / "pursuit_tau1_task1"
    assert stem.with_suffix(".mp4").stat().st_size > 1000 and stem.with_suffix(".rrd").stat().st_size > 1000


def test_observation_picture_marks_self_and_boundary():
    record = load("record_arena")
    observation = np.zeros((5, 5, 5), dtype=np.float32)  # pursuit, 4 agents: 3 mates, 1 prey, boundary
    observation[4, 0, :] = 1
    picture = record.observation_picture(observation, n_agents=4, boundary=4, cell_px=1)
    assert tuple(picture[2, 2]) == (240, 140, 20) and tuple(picture[0, 0]) == (120, 120, 120)
