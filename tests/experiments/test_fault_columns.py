"""Per-trial extra columns (the physics lab's fault counts and cap reasons) from the session to the CSV, the summary
and ``--json``; the agents' RFID miss model follows ``--rfid-miss`` unless ``--model-rfid-miss`` says otherwise."""

from __future__ import annotations

import csv
import json

import pytest
from fake_trial_domain import GuessDomain, Session

from embodied_adhoc.cli import main
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.domains.toxic_waste import DOMAIN as TOXIC
from embodied_adhoc.experiments.domains.toxic_waste import ToxicWasteSession
from embodied_adhoc.experiments.registry import register_trial_domain
from embodied_adhoc.experiments.runner import SweepConfig, run_sweep
from embodied_adhoc.experiments.summary import extras_table, summary_json

COLUMNS = ("fault_wrong_actions", "fault_wander_m", "cap_reason")


class CountingSession(Session):
    """The guess domain's session with extra columns computed from the trace (wrong actions and a float)."""

    trial_columns = COLUMNS

    def trial_extras(self, trace, info):
        wrong = sum(action != trace.actions[-1] for action in trace.actions)
        return {
            "fault_wrong_actions": wrong,
            "fault_wander_m": 0.25 * wrong,
            "cap_reason": "wrong_action" if trace.truncated else "",
        }


class CountingDomain(GuessDomain):
    name = "guess-counted"

    def open_session(self, backend, options):
        return CountingSession()


@pytest.fixture(scope="module", autouse=True)
def counted_domain():
    register_trial_domain("guess-counted", CountingDomain())


def _config(name: str, episodes: int = 6, max_steps: int = 5) -> SweepConfig:
    return SweepConfig(name, "abstract", {"task": None}, ("bayes", "random"), episodes, 3, max_steps)


def _header(path) -> list[str]:
    with open(path, encoding="utf-8", newline="") as stream:
        return next(csv.reader(stream))


def test_extra_columns_are_written_read_back_and_resumed(tmp_path):
    memory = run_sweep(_config("guess-counted"))
    stored = run_sweep(_config("guess-counted"), out=tmp_path / "run")
    header = _header(tmp_path / "run" / "trials.csv")
    assert [name for name in header if name in COLUMNS] == list(COLUMNS)
    assert [r.extras for r in stored.records] == [r.extras for r in memory.records]
    resumed = run_sweep(_config("guess-counted"), out=tmp_path / "run")
    assert resumed.new_trials == 0
    assert [r.extras for r in resumed.records] == [r.extras for r in memory.records]
    values = [r.extras for r in memory.records]
    assert all(
        isinstance(v["fault_wrong_actions"], int) and isinstance(v["fault_wander_m"], float) for v in values
    )
    capped = [r for r in memory.records if not r.success]
    assert capped and all(r.extras["cap_reason"] == "wrong_action" for r in capped)
    assert all(r.extras["cap_reason"] == "" for r in memory.records if r.success)


def test_a_session_without_extra_columns_keeps_the_csv_as_it_was(tmp_path):
    run_sweep(_config("guess"), out=tmp_path / "plain")
    header = _header(tmp_path / "plain" / "trials.csv")
    assert not [name for name in header if name.startswith(("fault_", "event_", "cap_"))]
    assert all(r.extras == {} for r in run_sweep(_config("guess")).records)


def test_the_summary_reports_extra_columns_per_agent():
    result = run_sweep(_config("guess-counted", episodes=8, max_steps=4))
    summary = result.summary()
    for agent, s in summary.agents.items():
        rows = [r for r in result.records if r.agent == agent]
        expected = sum(r.extras["fault_wrong_actions"] for r in rows) / len(rows)
        assert s.extras_mean["fault_wrong_actions"] == pytest.approx(expected)
        assert sum(s.extras_counts["cap_reason"].values()) == sum(not r.success for r in rows)
    document = summary_json(summary, result.config.describe())
    assert set(document["agents"]["random"]["per_episode_mean"]) == {"fault_wrong_actions", "fault_wander_m"}
    json.dumps(document, allow_nan=False)
    table = extras_table(summary)
    assert "fault_wrong_actions" in table and "bayes" in table and "random" in table
    assert extras_table(run_sweep(_config("guess")).summary()) == ""


def test_rfid_miss_sets_the_agents_model_unless_told_otherwise():
    assert TOXIC.options(faults={"rfid_miss": 0.5})["model_rfid_miss"] == 0.5
    assert TOXIC.options(faults={"rfid_miss": 0.5}, model_rfid_miss=0.0)["model_rfid_miss"] == 0.0
    assert "model_rfid_miss" not in TOXIC.options(faults={"wheel_slip": 0.02})
    with pytest.raises(ConfigError, match="--model-rfid-miss"):
        TOXIC.options(model_rfid_miss=1.5)
    told = ToxicWasteSession("mujoco", TOXIC.options(faults={"rfid_miss": 0.5}))
    assert told.library.config.rfid_miss == 0.5
    assert told.env_kwargs["rfid_miss"] == 0.5 and told.env_kwargs["reader_miss"] == 0.5
    apart = ToxicWasteSession("mujoco", TOXIC.options(faults={"rfid_miss": 0.5}, model_rfid_miss=0.1))
    assert apart.library.config.rfid_miss == 0.1 and apart.env_kwargs["reader_miss"] == 0.5
    model_only = ToxicWasteSession("mujoco", TOXIC.options(model_rfid_miss=0.3))
    assert model_only.env_kwargs["rfid_miss"] == 0.3 and model_only.env_kwargs["reader_miss"] == 0.0
    plain = ToxicWasteSession("mujoco", TOXIC.options())
    assert plain.library.config.rfid_miss == 0.0 and "reader_miss" not in plain.env_kwargs
    assert plain.trial_columns[-2:] == ("cap_reason", "cap_detail")
    assert ToxicWasteSession("abstract", TOXIC.options()).trial_columns == ()


def test_cli_refuses_a_bad_model_rfid_miss_before_any_work(capsys):
    assert (
        main(["trials", "toxic-waste", "--backend", "mujoco", "--model-rfid-miss", "1.5", "--episodes", "1"])
        == 2
    )
    err = capsys.readouterr().err
    assert "--model-rfid-miss 1.5: must be in [0, 1]" in err and len(err.strip().splitlines()) == 1
    code = main(
        ["trials", "toxic-waste", "--backend", "abstract", "--model-rfid-miss", "0.2", "--episodes", "1"]
    )
    assert code == 2
    assert "use --backend mujoco" in capsys.readouterr().err


def _physics_trial(tmp_path, name: str, *faults: str) -> tuple[dict, list[dict]]:
    out = tmp_path / name
    args = ["trials", "toxic-waste", "--backend", "mujoco", "--agents", "hotspot", "--episodes", "1"]
    assert main([*args, "--max-steps", "3", "--seed", "100", "--json", "--out", str(out), *faults]) == 0
    with open(out / "trials.csv", encoding="utf-8", newline="") as stream:
        rows = list(csv.DictReader(stream))
    return json.loads((out / "summary.json").read_text()), rows


def test_physics_sweep_counts_faults_in_the_csv_and_the_json(tmp_path, capsys):
    clean, clean_rows = _physics_trial(tmp_path, "clean")
    lost, lost_rows = _physics_trial(tmp_path, "lost", "--speech-failure", "1")
    capsys.readouterr()
    means = lost["agents"]["hotspot"]["per_episode_mean"]
    (row,) = lost_rows
    assert int(row["steps"]) == 3 and row["success"] == "0"
    assert means["fault_replies_lost"] == int(row["fault_replies_lost"]) == int(row["event_replies"])
    assert int(row["event_robot_node_readings"]) == 4
    assert clean["agents"]["hotspot"]["per_episode_mean"]["fault_replies_lost"] == 0
    assert row["cap_reason"] and row["cap_detail"].startswith("cap reached: ")
    assert lost["agents"]["hotspot"]["counts"]["cap_reason"] == {row["cap_reason"]: 1}
    assert int(row["event_replies"]) > 0  # HOTSPOT asks where the human is in its first steps
    assert row["cap_reason"] == "reply_lost" and clean_rows[0]["fault_replies_lost"] == "0"
    assert clean_rows != lost_rows  # a sweep with faults no longer reads as the fault-free one


def test_run_metrics_hold_the_fault_counts_and_the_cap_reason():
    from embodied_adhoc.experiments.recorded import EpisodeConfig, run_episode

    metrics = run_episode(EpisodeConfig(seed=100, max_steps=2, faults={"rfid_miss": 1.0})).metrics
    assert metrics["outcome"] == "truncated"
    assert set(metrics["faults"]) >= {"rfid_misses", "replies_lost", "lidar_dropped_beams", "blocked_moves"}
    assert metrics["faults"]["robot_node_readings"] == 3
    assert metrics["cap_reason"]["code"] and metrics["cap_reason"]["detail"].startswith("cap reached: ")
    assert metrics["config"]["options"]["model_rfid_miss"] == 1.0
