"""scripts/bench_heldout.py's result file: a run of some domains replaces their entries and keeps the others (with
the provenance they were made with), what no table reads is left out, and the compact JSON reads back the same."""

import importlib
import json
from pathlib import Path

import pytest

SCRIPTS = Path(__file__).resolve().parents[2] / "scripts"


@pytest.fixture
def script(monkeypatch):
    monkeypatch.syspath_prepend(str(SCRIPTS))
    return importlib.import_module("bench_heldout")


def _scope(agents, mean: float, **extra) -> dict:
    row = {
        "name": "m",
        "domain": "d",
        "split": "held-out",
        "version": "2",
        "type": "t",
        "best_on_episodes": 1.0,
        "agents": {a: {"normalised_mean": mean, "normalised_sd": 0.1} for a in agents},
    }
    return {
        "agents": list(agents),
        "teammates": [row],
        "aggregate": {a: {"iqm": mean} for a in agents},
        "probability_of_improvement": {f"{a} > {b}": {"p": 0.5} for a in agents for b in agents if a != b},
        "profiles": {a: {"tau": [0.0, 1.0], "fraction": [1.0, 0.5]} for a in agents},
        "episodes": 8,
        **extra,
    }


def test_a_run_replaces_its_domains_and_keeps_the_others_with_their_provenance(script):
    previous = {
        "commit": "old",
        "kernel": "openblas:SkylakeX",
        "suites": {"heldout": {"lab": _scope(("x", "y"), 0.5), "grid": _scope(("x", "y"), 0.2)}},
    }
    fresh = {
        "commit": "new",
        "kernel": "openblas:Haswell",
        "suites": {"heldout": {"grid": _scope(("x", "y"), 0.9, commit="new", kernel="openblas:Haswell")}},
    }
    merged = script.merge(previous, fresh)
    held = merged["suites"]["heldout"]
    assert list(held) == ["lab", "grid"]
    assert held["grid"]["aggregate"]["x"]["iqm"] == 0.9  # replaced
    assert (held["lab"]["commit"], held["lab"]["kernel"]) == ("old", "openblas:SkylakeX")  # kept, as made
    assert (held["grid"]["commit"], merged["commit"]) == ("new", "new")
    assert merged["best_response_check"]["checked"] == 4 and merged["best_response_check"]["above"] == []
    for scope in held.values():
        assert "profiles" not in scope
        assert list(scope["probability_of_improvement"]) == ["x > y"]  # y > x is 1 - P(x > y)
        assert not {"domain", "split", "version"} & set(scope["teammates"][0])
    again = script.merge(json.loads(script.dumps(merged)), {})
    assert json.loads(script.dumps(again)) == json.loads(
        script.dumps(merged)
    )  # merging again changes nothing


def test_compact_json_reads_back_and_puts_plain_objects_on_one_line(script):
    value = {"a": [1, 2.0, "x"], "b": {"c": 0.123456789, "d": None}, "e": [{"f": [True]}], "g": {}}
    text = script.dumps(value)
    assert json.loads(text) == {**value, "b": {"c": 0.123457, "d": None}}
    assert '"b": {"c": 0.123457, "d": null}' in text
    assert '"a": [1, 2.0, "x"]' in text


def _published(mean: float, low: float, high: float, **extra) -> dict:
    cell = {"iqm": mean, "iqm_ci": [low, high], "mean": mean, "mean_ci": [low, high]}
    return {
        "aggregate": {"x": cell},
        "episodes": 32,
        "seed": 0,
        "version": "2",
        "kernel": "openblas:Haswell",
        **extra,
    }


def _check(mean: float, **extra) -> dict:
    return {"aggregate": {"x": {"iqm": mean, "mean": mean}}, "episodes": 32, "seed": 0, "version": "2"} | {
        "kernel": "openblas:Sandybridge",
        **extra,
    }


def test_a_second_kernel_check_passes_inside_the_published_interval_and_names_what_falls_outside(script):
    inside = script.compare_check(_check(0.5000001), _published(0.5, 0.4, 0.6))
    assert inside["inside"] and inside["second_kernel"] and inside["identical_to_6_digits"]
    assert inside["outside"] == [] and inside["published_kernel"] == "openblas:Haswell"
    shifted = script.compare_check(_check(0.55), _published(0.5, 0.4, 0.6))
    assert shifted["inside"] and not shifted["identical_to_6_digits"]
    outside = script.compare_check(_check(0.65), _published(0.5, 0.4, 0.6))
    assert (
        not outside["inside"]
        and len(outside["outside"]) == 2
        and outside["outside"][0].startswith("x iqm 0.65")
    )
    other_episodes = script.compare_check(_check(0.5, episodes=8), _published(0.5, 0.4, 0.6))
    assert not other_episodes["inside"] and other_episodes["settings_differ"] == {"episodes": [8, 32]}
    published = _published(0.5, 0.4, 0.6, teammates=[{"name": "m", "params": {"p": 0.5}}], version="1")
    same_members = script.compare_check(_check(0.5, members=[["m", {"p": 0.5}]]), published)
    assert same_members["inside"] and same_members["versions"] == ["2", "1"]
    other_members = script.compare_check(_check(0.5, members=[["m", {"p": 0.6}]]), published)
    assert not other_members["inside"] and list(other_members["settings_differ"]) == ["members"]


def test_the_file_command_reruns_the_whole_suite_and_a_partial_run_command_moves_to_its_own_entries(script):
    partial = ".venv/bin/python scripts/bench_heldout.py --domains ntu --suites heldout --out /tmp/x"
    previous = {
        "commit": "c",
        "kernel": "openblas:Haswell",
        "command": partial,
        "suites": {
            "heldout": {"ntu": _scope(("x",), 0.5, seed=0, version="2"), "grid": _scope(("x", "y"), 0.2)},
            "validation": {"ntu": _scope(("x", "y"), 0.5)},
        },
        "kernel_checks": {"ntu": _check(0.5, episodes=8, commit="c", command="k", wall_s=1.0)},
    }
    previous["suites"]["heldout"]["ntu"]["aggregate"] = _published(0.5, 0.4, 0.6)["aggregate"]
    merged = script.merge(previous, {})
    assert merged["command"] == script.SUITE_COMMAND
    assert merged["suites"]["heldout"]["ntu"]["command"] == partial
    assert "command" not in merged["suites"]["heldout"]["grid"]  # another run's: not known
    assert "command" not in merged["suites"]["validation"]["ntu"]  # the partial run did not run validation
    assert merged["kernel_checks"]["ntu"]["comparison"]["inside"]
    assert "ntu: openblas:Sandybridge, suite v2 (published openblas:Haswell" in "\n".join(
        script.kernel_check_lines(merged["kernel_checks"])
    )


def test_simulated_bounds_skip_the_best_response_check_and_are_stated(script):
    grid = _scope(
        ("x", "y"), 1.4, commit="new", kernel="openblas:Haswell", version="3", seed=0, wall_s=1.0, members=1
    )
    grid["teammates"][0] |= {
        "best_on_episodes": None,  # no exact best response: a mean above 1 is no error
        "bounds": {"random": -90.0, "best": -12.0, "horizon": 100, "upper": "original team", "episodes": 32},
        "params": {},
    }
    for cell in grid["aggregate"].values():
        cell |= {"iqm_ci": [1.3, 1.5], "mean": 1.4, "mean_ci": [1.3, 1.5]}
    merged = script.merge(
        {}, {"commit": "new", "kernel": "openblas:Haswell", "suites": {"heldout": {"foraging": grid}}}
    )
    assert merged["best_response_check"]["checked"] == 0 and merged["best_response_check"]["above"] == []
    text = script.table(merged)
    assert "foraging: a return is minus the steps to finish (the cap, 100, when unfinished)" in text
    assert "upper bound is the original team, not a best response" in text
    assert "| m | t | - | 1.40 | 1.40 |" in text
