"""The memory cap of infinite-horizon Perseus (PerseusConfig.max_memory): estimate, stop with a reason, keep the
bounds; and the readings it is built on (decision/memory.py)."""

from __future__ import annotations

import math
import subprocess
import sys
import time

import numpy as np
import pytest

from embodied_adhoc import paths
from embodied_adhoc.decision import memory
from embodied_adhoc.decision.perseus import PerseusConfig, perseus
from embodied_adhoc.decision.pomdp_io import read_pomdp
from embodied_adhoc.errors import SolverError


@pytest.fixture(scope="module")
def tiger():
    return read_pomdp(paths.asset("data/tiger.95.POMDP"))


def test_resident_memory_is_read_and_positive():
    assert memory.resident_mb() > 1.0
    available = memory.available_mb()
    assert available is None or available > 0.0


def test_a_peak_belongs_to_the_process_not_to_the_one_that_started_it():
    """VmHWM of a small child started by this (larger) process is the child's own: getrusage's ru_maxrss would
    report at least this process's peak, carried over the fork and exec."""
    own = memory.peak_mb()
    assert own is not None and own >= memory.resident_mb() - 1.0
    child = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"], stdin=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 30.0
        peak = None
        while peak is None and time.monotonic() < deadline:  # until the child's memory map is there
            peak = memory.peak_mb(child.pid)
        assert peak is not None and 0.0 < peak < own
    finally:
        child.communicate(b"")
    assert memory.peak_mb(child.pid) is None  # reaped: no process, no reading


def test_default_cap_is_the_resident_memory_plus_a_share_of_the_available(monkeypatch):
    monkeypatch.setattr(memory, "resident_mb", lambda: 100.0)
    monkeypatch.setattr(memory, "available_mb", lambda: 1000.0)
    assert memory.default_cap_mb() == pytest.approx(100.0 + memory.DEFAULT_SHARE * 1000.0)
    monkeypatch.setattr(memory, "available_mb", lambda: None)
    assert memory.default_cap_mb() is None


@pytest.mark.parametrize("value", [0.0, -5.0, math.nan])
def test_a_cap_that_is_not_positive_is_refused(value):
    with pytest.raises(SolverError, match="max_memory must be positive MiB"):
        PerseusConfig(max_memory=value)


def test_a_cap_below_the_first_stage_stops_with_the_blind_bound(tiger, capsys):
    settings = dict(n_beliefs=100, expand=True, max_iterations=20)
    policy = perseus(tiger, PerseusConfig(max_memory=1.0, **settings))  # below what the process already holds
    note = capsys.readouterr().err
    assert "perseus stopped before iteration 1" in note and "memory cap of 1 MB" in note
    assert note.count("\n") == 1  # one line
    full = perseus(tiger, PerseusConfig(max_memory=math.inf, **settings))
    assert capsys.readouterr().err == ""
    # anytime: the bounds of the first instant, kept and achievable (the blind policies)
    assert policy.stats.iterations == 0
    assert policy.stats.lower == full.stats.trace[0][1] and policy.stats.lower < full.stats.lower
    assert policy.stats.upper >= full.stats.upper
    assert policy.value(tiger.initial_belief) == pytest.approx(policy.stats.lower)


def test_an_expansion_over_the_cap_keeps_the_belief_set(tiger, monkeypatch, capsys):
    """With the expansion's estimate made huge, B stays as collected, the stages still run, and the note says so."""
    import embodied_adhoc.decision.perseus as perseus_module

    monkeypatch.setattr(perseus_module, "_expansion_need", lambda state, count: 1e15)
    settings = dict(n_beliefs=5, expand=True, max_iterations=20, max_memory=1e6)
    policy = perseus(tiger, PerseusConfig(**settings))
    note = capsys.readouterr().err
    assert "perseus stopped expanding its belief set" in note and note.count("\n") == 1
    assert policy.stats.n_beliefs <= 5 and policy.stats.iterations > 1
    assert policy.stats.lower > policy.stats.trace[0][1]  # the stages on the kept B raised the bound


def test_a_cap_that_is_never_reached_changes_nothing(tiger):
    settings = dict(n_beliefs=100, expand=True, max_iterations=15)
    capped = perseus(tiger, PerseusConfig(max_memory=1e6, **settings))
    free = perseus(tiger, PerseusConfig(max_memory=math.inf, **settings))
    assert np.array_equal(capped.alphas, free.alphas)
    assert [value for _, value in capped.stats.trace] == [value for _, value in free.stats.trace]


def test_the_stage_estimate_covers_the_graph_growth(tiger, monkeypatch):
    """The estimate includes the grown graph buffer whenever the next stage's vectors would not fit in it."""
    from embodied_adhoc.decision.plan_graph import PlanGraph

    graph = PlanGraph.of_blind_policies(np.zeros((3, tiger.n_states)), tiger.n_observations)
    assert graph.growth_bytes(0) == 0
    row = 8 * tiger.n_states + 8 * (1 + tiger.n_observations)
    assert graph.growth_bytes(10) == (3 + 10) * row
    graph.add(
        np.zeros((10, tiger.n_states)),
        np.zeros(10, dtype=np.int64),
        np.zeros((10, tiger.n_observations), dtype=np.int64),
    )
    assert graph.growth_bytes(len(graph) // 4) == (13 + 13 // 2) * row  # grows by half


def test_the_values_on_b_kept_between_stages_are_a_cache(monkeypatch):
    """Without V_n's values on B kept between Gauss-Seidel stages (over _OLD_ROWS_MAX_ENTRIES), the same bits."""
    import embodied_adhoc.decision.perseus as perseus_module

    pomdp = read_pomdp(paths.asset("data/tiger.95.POMDP"))
    settings = dict(n_beliefs=200, expand=True, max_iterations=25, seed=1)
    kept = perseus(pomdp, PerseusConfig(**settings))
    monkeypatch.setattr(perseus_module, "_OLD_ROWS_MAX_ENTRIES", 0)
    recomputed = perseus(pomdp, PerseusConfig(**settings))
    assert np.array_equal(kept.alphas, recomputed.alphas)
    assert [value for _, value in kept.stats.trace] == [value for _, value in recomputed.stats.trace]


def test_the_cli_flag_caps_the_solve_and_refuses_a_cap_that_is_not_positive():
    import json
    import subprocess
    import sys

    def solve(*flags: str) -> subprocess.CompletedProcess:
        command = [sys.executable, "-m", "embodied_adhoc.cli", "pomdp", "solve", "tiger.95.POMDP", *flags]
        return subprocess.run(command, capture_output=True, text=True, timeout=120)

    capped = solve("--max-memory", "1", "--json", "--quiet", "--time-limit", "5")
    assert capped.returncode == 0, capped.stderr
    assert capped.stderr.startswith("embodied-adhoc: note: perseus stopped before iteration 1: ")
    assert json.loads(capped.stdout)["iterations"] == 0
    refused = solve("--max-memory", "0")
    assert refused.returncode == 2 and "argument --max-memory: 0 is not a finite number > 0" in refused.stderr
