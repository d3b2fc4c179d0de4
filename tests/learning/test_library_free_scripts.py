"""The library-free comparison scripts: library_free_bench.py scores every index domain the agents ship on and
renders the grid arenas' train/held-out tables from generalist_heldout.py's result files (one row per team, the
file's own numbers); those files name the command a user runs, never a machine's folders."""

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _script(name: str):
    spec = importlib.util.spec_from_file_location(f"script_{name}", ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_bench_scores_every_index_domain_the_benchmark_has():
    from embodied_adhoc.learning.index_domains import INDEX_DOMAINS

    bench = _script("library_free_bench")
    assert bench.DOMAINS == INDEX_DOMAINS
    library = json.loads((ROOT / "results" / "benchmark-heldout.json").read_text())["suites"]["heldout"]
    assert set(bench.DOMAINS) <= set(library)  # the library-based rows come from the same suite


def test_the_grid_tables_are_the_result_files_own_numbers():
    bench = _script("library_free_bench")
    for grid, path in bench.GRID_HELDOUT.items():
        record = json.loads(path.read_text())
        lines = bench.grid_table(grid, record)
        header = next(line for line in lines if line.startswith("| split |"))
        agents = [cell.strip() for cell in header.strip("|").split("|")][2:]
        assert agents == [*record["training"], "atlpo-mf", "known-task"]
        rows = [line for line in lines if line.startswith(("| train |", "| held-out |"))]
        expected = [(split, team) for split, teams in record["scores"].items() for team in teams]
        assert [tuple(c.strip() for c in row.strip("|").split("|")[:2]) for row in rows] == expected
        split, team = expected[-1]
        last = record["scores"][split][team][agents[0]]
        assert rows[-1].split("|")[3].strip().startswith(f"{last['iqm']:.2f} [{last['ci'][0]:.2f}, ")
        for agent, cost in record["training"].items():
            assert f"{agent} {cost['env_steps']:,} env steps" in lines[0]


def test_the_result_files_name_the_users_command_not_a_machines_folders(monkeypatch):
    heldout = _script("generalist_heldout")
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    assert heldout.command(["--domain", "pursuit", "--out", "/tmp/x", "--episodes", "8"]) == (
        ".venv/bin/python scripts/generalist_heldout.py --domain pursuit --out DIR --episodes 8"
    )
    assert heldout.command(["--out=/tmp/x"]).endswith(" --out=DIR")
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    assert heldout.command([]).startswith("OPENBLAS_NUM_THREADS=1 .venv/bin/python ")
    assert heldout.shown(ROOT / "assets" / "x.safetensors") == "assets/x.safetensors"
    for path in (ROOT / "results" / "library_free").rglob("*"):
        if path.suffix in (".json", ".md", ".txt", ".csv"):
            text = path.read_text()
            assert "/tmp/" not in text and str(ROOT) not in text, path
