"""``evaluate`` on a tiny suite (a population file: two lab humans and a gridworld teammate): the same numbers twice
and after an interruption (the trial runner's store resumes it), no agent above the exact best response beyond its
interval, the summary's fields and plots, and one-line refusals of bad input."""

import json

import pytest
from scipy import stats as scipy_stats

import embodied_adhoc.experiments.executors as executors
from embodied_adhoc.bench.evaluate import evaluate, resolve_suite
from embodied_adhoc.cli import main

AGENTS = ("hotspot", "bopa", "random")
EPISODES = 4


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """The suite file, the cache folder and the first run's summary (shared by the tests: trials cost seconds)."""
    root = tmp_path_factory.mktemp("tiny")
    path = root / "tiny.json"
    members = [
        {"name": "wanderer", "domain": "toxic-waste", "type": "wanders", "params": {"wander": 0.3}},
        {
            "name": "late",
            "domain": "toxic-waste",
            "type": "order",
            "params": {"rule": "order", "order": [2, 1, 0]},
        },
        {"name": "lazy", "domain": "gridworld", "type": "lazy", "params": {"family": "lazy", "p": 0.5}},
    ]
    path.write_text(json.dumps({"name": "tiny", "version": "7", "members": members}))
    with pytest.MonkeyPatch.context() as patched:
        patched.setenv("XDG_CACHE_HOME", str(root / "cache"))
        summary = evaluate(AGENTS, resolve_suite(str(path)), root / "a", episodes=EPISODES, reps=200)
    return path, root, summary


@pytest.fixture(autouse=True)
def private_cache(tiny, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tiny[1] / "cache"))


def _counting(monkeypatch, stop_after: int | None = None) -> list:
    calls, original = [], executors.execute_job

    def counted(job):
        if stop_after is not None and len(calls) == stop_after:
            raise KeyboardInterrupt
        calls.append(job)
        return original(job)

    monkeypatch.setattr(executors, "execute_job", counted)
    return calls


def test_same_numbers_twice_and_after_an_interruption(tmp_path, tiny, monkeypatch):
    suite_file, root, first = tiny
    suite = resolve_suite(str(suite_file))
    assert (root / "a" / "overall-intervals.png").is_file()
    assert (root / "a" / "toxic-waste-profiles.png").is_file()
    assert json.loads((root / "a" / "summary.json").read_text())["version"] == "7"

    with monkeypatch.context() as patched:
        _counting(patched, stop_after=5)
        with pytest.raises(KeyboardInterrupt):
            evaluate(AGENTS, suite, tmp_path / "b", episodes=EPISODES, reps=200, plots=False)
    calls = _counting(monkeypatch)
    assert evaluate(AGENTS, suite, tmp_path / "b", episodes=EPISODES, reps=200, plots=False) == first
    total = 2 * len(AGENTS) * EPISODES + 2 * EPISODES  # gridworld runs bopa and random (hotspot is the lab's)
    assert len(calls) == total - 5  # the five trials before the interruption were kept
    calls.clear()
    assert evaluate(AGENTS, suite, root / "a", episodes=EPISODES, reps=200, plots=False) == first
    assert calls == []  # every trial resumed from the store


def test_summary_scores_between_the_bounds(tiny):
    summary = tiny[2]
    assert summary["domains"]["gridworld"]["agents"] == ["bopa", "random"]
    assert summary["overall"]["agents"] == ["bopa", "random"]
    assert set(summary["overall"]["probability_of_improvement"]) == {"bopa > random", "random > bopa"}
    for scope in summary["domains"].values():
        for row in scope["teammates"]:
            assert row["bounds"]["best"] > row["bounds"]["random"]
            for values in row["agents"].values():
                # from the same starts no agent beats the exact best response beyond a one-sided 99 % t bound
                margin = scipy_stats.t.ppf(0.99, EPISODES - 1) * values["normalised_sd"] / EPISODES**0.5
                assert values["normalised_mean"] - margin <= row["best_on_episodes"]
                assert values["normalised_ci"][0] <= values["normalised_mean"] <= values["normalised_ci"][1]
    late = next(row for row in summary["domains"]["toxic-waste"]["teammates"] if row["name"] == "late")
    assert 0.0 <= late["agents"]["hotspot"]["true_task_probability"] <= 1.0
    assert late["agents"]["random"]["true_task_probability"] is None  # no task posterior
    assert 0.0 <= late["agents"]["bopa"]["success"] <= 1.0
    lab = summary["domains"]["toxic-waste"]["aggregate"]
    assert lab["bopa"]["mean"] > lab["random"]["mean"]


def test_bad_input_is_one_line_before_any_work(tmp_path, tiny, capsys):
    suite_file = tiny[0]
    out = tmp_path / "never"
    assert main(["evaluate", "--agents", "nobody", "--suite", str(suite_file), "--out", str(out)]) == 2
    assert "--agents nobody: no selected domain knows it" in capsys.readouterr().err
    assert main(["evaluate", "--agents", "random", "--suite", "weekly", "--out", str(out)]) == 2
    assert "--suite 'weekly': choose from heldout, validation, train" in capsys.readouterr().err
    assert main(["evaluate", "--agents", "random", "--suite", str(suite_file), "--domains", "pursuit-task",
                 "--out", str(out)]) == 2  # fmt: skip
    assert "tiny.json has no member there" in capsys.readouterr().err
    assert main(["evaluate", "--agents", "random", "--suite", "heldout", "--domains", "overcooked",
                 "--backend", "mujoco", "--out", str(out)]) == 2  # fmt: skip
    assert "--backend mujoco: overcooked has abstract" in capsys.readouterr().err
    assert not out.exists()


def test_the_physics_lab_is_scored_between_the_abstract_labs_bounds(tmp_path):
    """``--backend mujoco``: the same member and episode specs on physics, normalised by the abstract lab's bounds,
    and compared with the abstract run per agent (two oracle episodes: the oracle needs no solve)."""
    from embodied_adhoc.bench.evaluate import backend_difference

    path = tmp_path / "lab.json"
    member = {"name": "wanderer", "domain": "toxic-waste", "type": "wanders", "params": {"wander": 0.3}}
    path.write_text(json.dumps({"name": "lab", "members": [member]}))
    suite, scores = resolve_suite(str(path)), {}
    runs = {}
    for backend in ("abstract", "mujoco"):
        scores[backend] = {}
        runs[backend] = evaluate(
            ("oracle",), suite, tmp_path / backend, episodes=2, backend=backend, reps=50, plots=False,
            scores=scores[backend],
        )  # fmt: skip
    abstract, physics = (runs[b]["domains"]["toxic-waste"]["teammates"][0] for b in ("abstract", "mujoco"))
    assert runs["mujoco"]["backend"] == "mujoco"
    assert (
        physics["bounds"] == abstract["bounds"]
        and physics["best_on_episodes"] == abstract["best_on_episodes"]
    )
    assert physics["agents"]["oracle"]["success"] == 1.0
    difference = backend_difference(
        scores["abstract"]["toxic-waste"], scores["mujoco"]["toxic-waste"], ["wanderer"]
    )
    assert difference["agents"]["oracle"]["n"] == [2, 2]
