"""The trial runner on the test 'guess' domain: seeding, resume, storage, executors, interrupts."""

import json
import shutil

import pytest

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments import executors, runner
from embodied_adhoc.experiments.runner import SweepConfig, run_sweep
from embodied_adhoc.experiments.summary import summary_json
from embodied_adhoc.experiments.tables import comparison_table, summary_table

AGENTS = ("bayes", "known-task", "oracle", "random")


def config(**changes) -> SweepConfig:
    fields = {"domain": "guess", "backend": "abstract", "options": {"task": None}, "agents": AGENTS, "episodes": 12,
              "seed": 5}  # fmt: skip
    fields.update(changes)
    return SweepConfig(**fields)


def sorted_lines(path):
    header, *rows = path.read_text().splitlines()
    return header, sorted(rows)


def test_same_seed_gives_identical_csv(tmp_path):
    run_sweep(config(), out=tmp_path / "a")
    run_sweep(config(), out=tmp_path / "b")
    for name in ("trials.csv", "steps.csv"):
        assert (tmp_path / "a" / name).read_text() == (tmp_path / "b" / name).read_text()
    run_sweep(config(seed=6), out=tmp_path / "c")
    assert (tmp_path / "a" / "trials.csv").read_text() != (tmp_path / "c" / "trials.csv").read_text()


def test_all_agents_share_episode_specs(tmp_path):
    result = run_sweep(config())
    by_episode = {}
    for record in result.records:
        by_episode.setdefault(record.episode, set()).add(json.dumps(record.spec))
    assert len(by_episode) == 12 and all(len(specs) == 1 for specs in by_episode.values())
    assert {r.spec["task"] for r in result.records} == {0, 1}  # both tasks drawn


def test_results_do_not_depend_on_workers(tmp_path):
    run_sweep(config(), out=tmp_path / "serial", workers=1)
    run_sweep(config(), out=tmp_path / "pool", workers=2)
    for name in ("trials.csv", "steps.csv"):
        assert sorted_lines(tmp_path / "serial" / name) == sorted_lines(tmp_path / "pool" / name)


def test_resume_after_partial_runs_has_no_duplicates_and_same_table(tmp_path):
    fresh = run_sweep(config(), out=tmp_path / "fresh")
    partial = tmp_path / "partial"
    first = run_sweep(config(agents=("bayes", "random"), episodes=5), out=partial)
    assert first.new_trials == 10
    resumed = run_sweep(config(), out=partial)
    assert resumed.new_trials == len(AGENTS) * 12 - 10
    again = run_sweep(config(), out=partial)
    assert again.new_trials == 0
    header, rows = sorted_lines(partial / "trials.csv")
    keys = [tuple(row.split(",")[:2]) for row in rows]
    assert len(keys) == len(set(keys)) == len(AGENTS) * 12
    assert (header, rows) == sorted_lines(tmp_path / "fresh" / "trials.csv")
    assert sorted_lines(partial / "steps.csv") == sorted_lines(tmp_path / "fresh" / "steps.csv")
    assert summary_table(again.summary()) == summary_table(fresh.summary())
    assert comparison_table(again.summary()) == comparison_table(fresh.summary())
    assert again.entropy_curves == fresh.entropy_curves


def test_interrupt_keeps_finished_trials_and_resume_completes(tmp_path, monkeypatch):
    out = tmp_path / "run"
    original = executors.execute

    def interrupted(jobs, workers=1, executor="local"):
        for index, result in enumerate(original(jobs, workers, executor)):
            if index == 7:
                raise KeyboardInterrupt
            yield result

    monkeypatch.setattr(runner, "execute", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(config(), out=out)
    assert len((out / "trials.csv").read_text().splitlines()) == 1 + 7
    monkeypatch.setattr(runner, "execute", original)
    resumed = run_sweep(config(), out=out)
    assert resumed.new_trials == len(AGENTS) * 12 - 7
    fresh = run_sweep(config(), out=tmp_path / "fresh")
    assert sorted_lines(out / "trials.csv") == sorted_lines(tmp_path / "fresh" / "trials.csv")
    assert summary_table(resumed.summary()) == summary_table(fresh.summary())


def test_torn_last_line_and_uncommitted_steps_are_dropped(tmp_path):
    out = tmp_path / "run"
    run_sweep(config(agents=("bayes",), episodes=4), out=out)
    trials = out / "trials.csv"
    text = trials.read_text()
    trials.write_text(
        text[: text.rstrip("\n").rfind("\n") + 1] + "bayes,3,1,1"
    )  # kill mid-write of episode 3
    result = run_sweep(config(agents=("bayes",), episodes=4), out=out)
    assert result.new_trials == 1
    fresh = tmp_path / "fresh"
    run_sweep(config(agents=("bayes",), episodes=4), out=fresh)
    assert sorted_lines(trials) == sorted_lines(fresh / "trials.csv")
    assert sorted_lines(out / "steps.csv") == sorted_lines(fresh / "steps.csv")


def test_different_config_in_same_folder_is_refused(tmp_path):
    run_sweep(config(episodes=2), out=tmp_path)
    with pytest.raises(ConfigError, match="seed: stored 5, now 6"):
        run_sweep(config(episodes=2, seed=6), out=tmp_path)
    with pytest.raises(ConfigError, match="max_steps"):
        run_sweep(config(episodes=2, max_steps=50), out=tmp_path)


def test_state_goes_only_to_agents_that_observe_it():
    # The fake agents assert on what they receive: BayesAgent rejects any state, OracleAgent requires one.
    result = run_sweep(config(agents=("bayes", "oracle"), episodes=3))
    assert all(r.success for r in result.records)
    assert all(r.steps == 3 for r in result.records if r.agent == "oracle")


def test_step_cap_and_fixed_task():
    result = run_sweep(config(agents=("random",), episodes=6, max_steps=2, options={"task": 1}))
    assert all(r.steps == 2 and not r.success for r in result.records)
    assert {r.spec["task"] for r in result.records} == {1}


def test_bad_requests_are_clear_errors():
    with pytest.raises(ConfigError, match="unknown agent"):
        run_sweep(config(agents=("bayes", "nobody")))
    with pytest.raises(ConfigError, match="no backend 'mujoco'"):
        run_sweep(config(backend="mujoco"))
    with pytest.raises(ConfigError, match="unknown trial domain"):
        run_sweep(config(domain="chess"))
    with pytest.raises(ConfigError, match="episodes"):
        run_sweep(config(episodes=0))


def test_ray_executor_without_ray_names_the_extra(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ModuleNotFoundError
    with pytest.raises(ConfigError, match=r"pip install 'embodied-adhoc\[ray\]'"):
        run_sweep(config(episodes=1), executor="ray")


def test_json_summary_schema():
    result = run_sweep(config())
    document = json.loads(
        json.dumps(summary_json(result.summary(), result.config.describe()), allow_nan=False)
    )
    assert set(document) == {"agents", "comparisons", "statistics", "config"}
    assert document["statistics"]["ci"].startswith("percentile bootstrap")
    assert list(document["agents"]) == list(AGENTS)
    for name, agent in document["agents"].items():
        for key in (
            "steps_mean",
            "steps_ci95",
            "steps_iqm",
            "steps_iqm_ci95",
            "success_rate",
            "identify_steps_mean",
            "final_entropy_mean",
        ):
            assert key in agent, (name, key)
        low, high = agent["steps_ci95"]
        assert low <= agent["steps_mean"] <= high
    assert document["agents"]["known-task"]["identify_steps_mean"] == 0.0
    assert document["agents"]["oracle"]["identify_steps_mean"] is None
    assert len(document["comparisons"]) == 6
    first = document["comparisons"][0]
    assert {"a", "b", "metric", "t", "p", "significant", "p_improvement", "p_improvement_ci95"} <= set(first)
    assert 0.0 <= first["p_improvement"] <= 1.0
    assert document["config"]["episodes"] == 12 and document["config"]["agents"] == list(AGENTS)


def test_plots_are_written(tmp_path):
    from embodied_adhoc.experiments.plots import plot_entropy, plot_settings, plot_steps

    result = run_sweep(config(episodes=4))
    summary = result.summary()
    paths = [
        plot_steps(summary, tmp_path / "steps.png"),
        plot_entropy(result.curves_by_agent(), tmp_path / "entropy.png"),
        plot_settings({"setting A": summary, "setting B": summary}, tmp_path / "settings.png"),
    ]
    for path in paths:
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["entropy.png", "settings.png", "steps.png"]
    shutil.rmtree(tmp_path)
