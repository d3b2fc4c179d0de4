"""The library-free comparison scripts: library_free_bench.py scores every index domain the agents ship on and
renders the grid arenas' train/held-out tables from generalist_heldout.py's result files (one row per team, the
file's own numbers); those files name the command a user runs, never a machine's folders."""

import importlib.util
import json
from pathlib import Path

import pytest

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


def _check_of(bench, result: dict, part: str, shift: dict | None = None) -> dict:
    """A second kernel's check entry of ``part`` holding the published run's own IQMs and means, ``shift``
    (agent: amount) moving those agents' IQMs."""
    scope = bench._part(result, part)
    return {
        "kernel": "openblas:Sandybridge",
        "commit": "0" * 40,
        "command": "OPENBLAS_CORETYPE=Sandybridge .venv/bin/python scripts/library_free_bench.py --check "
        + part,
        "wall_s": 1.0,
        "cpu_s_all_checked_parts": 1.0,
        "episodes": result["episodes"],
        "seed": result["seed"],
        "version": scope["version"],
        "members": scope["members"],
        "aggregate": {
            agent: {"iqm": values["iqm"] + (shift or {}).get(agent, 0.0), "mean": values["mean"]}
            for agent, values in scope["aggregate"].items()
        },
    }


def test_a_check_is_compared_with_the_published_intervals_and_never_replaces_the_published_run():
    bench = _script("library_free_bench")
    from bench_heldout import kernel_check_lines

    published = {k: v for k, v in json.loads(bench.RESULT.read_text()).items() if k != "kernel_checks"}
    low, high = published["domains"]["ntu"]["agents"]["liam"]["iqm_ci"]
    checks = {
        "toxic-waste": _check_of(bench, published, "toxic-waste"),
        "ntu": _check_of(
            bench,
            published,
            "ntu",
            {"liam": high - published["domains"]["ntu"]["agents"]["liam"]["iqm"] + 0.01},
        ),
        "curve": _check_of(bench, published, "curve"),
    }
    merged = bench.merge(published, checks=checks)
    assert {k: v for k, v in merged.items() if k != "kernel_checks"} == published  # the published run is kept
    comparisons = {part: check["comparison"] for part, check in merged["kernel_checks"].items()}
    assert comparisons["toxic-waste"]["inside"] and comparisons["toxic-waste"]["identical_to_6_digits"]
    assert comparisons["toxic-waste"]["second_kernel"]
    # the lab's further training seed and the curve's runs are compared beside the shipped agents
    assert any("-seed-" in agent for agent in merged["kernel_checks"]["toxic-waste"]["aggregate"])
    assert set(merged["kernel_checks"]["curve"]["aggregate"]) == {
        f"ppo-generalist-{count}" for count in bench.CURVE_COUNTS
    }
    assert comparisons["curve"]["inside"]
    assert not comparisons["ntu"]["inside"]
    assert [line.split(" ")[:2] for line in comparisons["ntu"]["outside"]] == [["liam", "iqm"]]
    lines = kernel_check_lines(merged["kernel_checks"])
    ntu = next(line for line in lines if line.startswith("- ntu:"))
    assert "outside: liam iqm" in ntu and "openblas:Sandybridge" in ntu
    assert next(line for line in lines if line.startswith("- toxic-waste:")).endswith(
        "every agent inside (identical to 6 significant digits)."
    )

    # a later check of a part replaces that part's check, the others kept; another member list is not compared
    again = _check_of(bench, published, "ntu")
    again["members"] = again["members"][1:]
    later = bench.merge(merged, checks={"ntu": again})
    assert set(later["kernel_checks"]) == set(checks)
    assert later["kernel_checks"]["ntu"]["comparison"]["settings_differ"].keys() == {"members"}
    assert not later["kernel_checks"]["ntu"]["comparison"]["inside"]
    # a new published run keeps the checks, compared with it
    fresh = json.loads(json.dumps(published))
    fresh["domains"]["toxic-waste"]["agents"]["meliba"]["iqm_ci"] = [5.0, 6.0]
    rerun = bench.merge(later, fresh)
    assert rerun["domains"] == fresh["domains"]
    assert rerun["kernel_checks"]["toxic-waste"]["comparison"]["outside"][0].startswith("meliba iqm")


def test_a_check_of_an_unknown_part_is_refused_before_work_starts(monkeypatch, capsys):
    bench = _script("library_free_bench")
    monkeypatch.setattr("sys.argv", ["library_free_bench.py", "--check", "ntu,lab"])
    with pytest.raises(SystemExit) as stop:
        bench.parse()
    assert stop.value.code == 2
    assert "--check lab: no such part" in capsys.readouterr().err


def test_a_checks_command_names_the_kernels_it_ran_under(monkeypatch):
    bench = _script("library_free_bench")
    for name in bench.TORCH_KERNEL:
        monkeypatch.delenv(name, raising=False)
    assert bench.kernel_prefix("Sandybridge") == "OPENBLAS_CORETYPE=Sandybridge"
    monkeypatch.setenv("ATEN_CPU_CAPABILITY", "default")
    assert bench.kernel_prefix("Sandybridge") == "OPENBLAS_CORETYPE=Sandybridge ATEN_CPU_CAPABILITY=default"
