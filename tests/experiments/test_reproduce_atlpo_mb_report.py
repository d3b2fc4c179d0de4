"""scripts/reproduce_atlpo.py: the ATLPO-MB rows pool the evaluated seeds of a cell and name them."""

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "reproduce_atlpo.py"


def load_script():
    spec = importlib.util.spec_from_file_location("reproduce_atlpo", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclass resolves annotations through sys.modules
    spec.loader.exec_module(module)
    return module


def write_cell(module, out: Path, domain: str, seed: int, set_name: str, results: dict | None) -> None:
    folder = module.library_folder(out, domain, seed, set_name)
    folder = folder.with_name(folder.name + "-mb")
    folder.mkdir(parents=True)
    (folder / "training.json").write_text("{}\n")
    if results is not None:
        (folder / "evaluation-2x200.json").write_text(json.dumps(results) + "\n")


def test_mb_rows_pool_the_evaluated_seeds(tmp_path):
    module = load_script()
    seed0 = {
        "atlpo-mb": {"steps": [10, 20], "finished": [True, True]},
        "mb-all": {"steps": [200, 40], "finished": [False, True]},
    }
    seed2 = {"atlpo-mb": {"steps": [30, 40], "finished": [True, True]}}  # no baseline trained for this seed
    write_cell(module, tmp_path, "pursuit", 0, "team", seed0)
    write_cell(module, tmp_path, "pursuit", 1, "team", None)  # trained, not evaluated: not in the row
    write_cell(module, tmp_path, "pursuit", 2, "team", seed2)
    args = module.Args(out=tmp_path, seeds=(0, 1, 2), episodes=2, max_steps=200)
    lines, table = module.mb_report(args)
    rows = [line for line in lines if line.startswith("| team |")]
    assert len(rows) == 1
    cells = [cell.strip() for cell in rows[0].split(" | ")]
    assert cells[2] == "0,2"
    assert cells[3].startswith("25.00 [")  # mean of the four pooled episodes
    assert cells[3].endswith("(100 %) \\| 10.64")
    assert cells[4] == "not trained for every seed listed |"
    assert table["team/pursuit"]["seeds"] == [0, 2]
    assert table["team/pursuit"]["atlpo-mb"]["n"] == 4
    assert np.isclose(table["team/pursuit"]["atlpo-mb"]["mean"], 25.0)
    assert "mb-all" not in table["team/pursuit"]


def test_no_mb_rows_without_evaluations(tmp_path):
    module = load_script()
    write_cell(module, tmp_path, "foraging", 0, "task", None)
    assert module.mb_report(module.Args(out=tmp_path, seeds=(0,), episodes=2, max_steps=200)) == ([], {})
