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
