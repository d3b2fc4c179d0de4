"""Plug-ins by name: the resolver's spec forms and errors, the Agent protocol check, and the tutorial of
docs/plugins.md run as a new user would (a file beside them, no PYTHONPATH; then the same code installed)."""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
import sys
import tomllib
import zlib
from pathlib import Path

import numpy as np
import pytest

from embodied_adhoc.decision.agents.base import Agent, AgentBase, protocol_gaps
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.plugins import installed, resolve

FIXTURES = Path(__file__).parent / "fixtures"
ROOT = Path(__file__).parent.parent


def _cli(*args, cwd, timeout=600):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}  # a new user sets no PYTHONPATH
    env.update(MUJOCO_GL="egl", PYOPENGL_PLATFORM="egl", XDG_CACHE_HOME=str(Path(cwd) / "xdg"))
    return subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.fixture
def user_folder(tmp_path, monkeypatch):
    """A user's working folder holding the tutorial agent, as the current directory."""
    shutil.copy(FIXTURES / "my_agent.py", tmp_path / "my_agent.py")
    (tmp_path / "helpers.py").write_text("def make(library, **options):\n    return object()\n")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _installed_fixture_package(root: Path) -> Path:
    """The fixture package as pip would install it: its code and a .dist-info holding its entry points (read
    from its pyproject.toml), in ``root`` (which the caller puts on sys.path)."""
    source = FIXTURES / "plugin_pkg"
    shutil.copytree(source / "my_adhoc_agent", root / "my_adhoc_agent")
    project = tomllib.loads((source / "pyproject.toml").read_text())["project"]
    info = root / f"{project['name'].replace('-', '_')}-{project['version']}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: {project['name']}\nVersion: {project['version']}\n"
    )
    lines = []
    for group, entries in project["entry-points"].items():
        lines.append(f"[{group}]")
        lines += [f"{name} = {value}" for name, value in entries.items()]
        lines.append("")
    (info / "entry_points.txt").write_text("\n".join(lines))
    return root


# ---------------------------------------------------------------------------------------------- the resolver
def test_builtin_names_win_and_carry_no_source():
    plugin = resolve("agent", "hotspot", builtin=("hotspot", "random"))
    assert plugin.builtin and plugin.factory is None and plugin.source is None


def test_module_and_file_specs_resolve_from_the_current_directory(user_folder):
    by_module = resolve("agent", "my_agent:make")
    by_file = resolve("agent", "./my_agent.py:make")
    assert by_module.source == by_file.source == (user_folder / "my_agent.py").resolve()
    assert callable(by_module.factory) and callable(by_file.factory)
    dotted = resolve("agent", "my_agent:QmdpAgent.reset")
    assert dotted.factory.__name__ == "reset"


def test_errors_name_the_spec_and_the_fix(user_folder):
    with pytest.raises(
        ConfigError, match=r"unknown agent 'nobody' \(--agents\); choose from hotspot, random"
    ):
        resolve("agent", "nobody", builtin=("hotspot", "random"), flag="--agents")
    with pytest.raises(ConfigError, match="no module 'nomodule' in the current directory"):
        resolve("agent", "nomodule:make")
    with pytest.raises(ConfigError, match="has no 'missing'; it defines .*make"):
        resolve("agent", "my_agent:missing")
    with pytest.raises(ConfigError, match="no file .*absent.py"):
        resolve("agent", "./absent.py:make")
    (user_folder / "needs.py").write_text("import not_a_real_package_xyz\n")
    with pytest.raises(ConfigError, match="needs the module 'not_a_real_package_xyz'.*pip install"):
        resolve("agent", "needs:make")
    (user_folder / "typo.py").write_text("def make(:\n")
    with pytest.raises(ConfigError, match=r"SyntaxError at .*typo.py:1"):
        resolve("agent", "./typo.py:make")


def test_the_current_directory_wins_over_a_module_imported_from_elsewhere(tmp_path, monkeypatch):
    for folder in ("first", "second"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "same_name_plugin.py").write_text(
            f"def make(library, **options):\n    return {folder!r}\n"
        )
    monkeypatch.chdir(tmp_path / "first")
    assert resolve("agent", "same_name_plugin:make").factory(None) == "first"
    monkeypatch.chdir(tmp_path / "second")
    plugin = resolve("agent", "same_name_plugin:make")
    assert plugin.factory(None) == "second" and plugin.source == (tmp_path / "second" / "same_name_plugin.py")
    monkeypatch.delitem(sys.modules, "same_name_plugin")


def test_entry_points_are_found_and_listed(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(_installed_fixture_package(tmp_path)))
    assert {"my-qmdp"} <= set(installed("agent"))
    plugin = resolve("agent", "my-qmdp", builtin=("hotspot",))
    assert plugin.source == (tmp_path / "my_adhoc_agent" / "__init__.py").resolve()
    with pytest.raises(ConfigError, match=r"installed \(embodied_adhoc.agents\): my-qmdp"):
        resolve("agent", "nobody", builtin=("hotspot",))


# ------------------------------------------------------------------------------------------ the Agent protocol
class _LazyPosterior(AgentBase):
    """Its posterior exists only after reset: reading it before raises AttributeError."""

    def reset(self, rng, state=None):
        self._posterior = np.array([0.5, 0.5])

    def act(self):
        return 0

    def observe(self, action, observation, state=None):
        pass

    @property
    def task_posterior(self):
        return self._posterior


def test_isinstance_does_not_depend_on_reset():
    agent = _LazyPosterior()
    with pytest.raises(AttributeError):
        agent.task_posterior  # noqa: B018  (the property really fails before reset)
    assert isinstance(agent, Agent) and protocol_gaps(agent) == []


def test_protocol_gaps_name_what_is_missing():
    class Partial:
        name = "partial"
        observes_state = "yes"

        def act(self):
            return 0

    gaps = protocol_gaps(Partial())
    assert "method reset()" in gaps and "method observe()" in gaps and "method start()" in gaps
    assert "flag observes_state = 'yes' (not a bool)" in gaps and "flag observes_raw (a bool)" in gaps
    assert not isinstance(Partial(), Agent)


def test_every_shipped_lab_agent_meets_the_protocol():
    from embodied_adhoc.decision.agents.factory import AGENT_NAMES, make_agent
    from embodied_adhoc.domains.lab import build_lab_library

    library = build_lab_library()
    for name in AGENT_NAMES:
        if name == "atpo":
            continue  # its Perseus solve is covered by the trial tests; the class is checked below
        agent = make_agent(name, library, true_task=0)
        assert protocol_gaps(agent) == [] and isinstance(agent, Agent), name
    from embodied_adhoc.decision.agents.atpo import AtpoAgent

    assert issubclass(AtpoAgent, AgentBase)


def test_a_plugin_that_breaks_the_protocol_is_refused_before_any_trial(user_folder):
    from embodied_adhoc.experiments.domains.toxic_waste import DOMAIN
    from embodied_adhoc.experiments.runner import SweepConfig, run_sweep

    config = SweepConfig("toxic-waste", "abstract", DOMAIN.options(), ("helpers:make",), episodes=1)
    with pytest.raises(
        ConfigError, match=r"object does not meet the Agent protocol: it lacks method reset\(\)"
    ):
        run_sweep(config, out=user_folder / "run")
    assert not (user_folder / "run" / "trials.csv").exists()


# ------------------------------------------------------------------------------------- the tutorial, end to end
def test_the_tutorial_shows_the_tested_agent_and_commands():
    page = (ROOT / "docs" / "plugins.md").read_text()
    assert (FIXTURES / "my_agent.py").read_text() in page  # the page's agent is the file these tests run
    assert "trials toxic-waste --agents hotspot,./my_agent.py:make" in page
    assert "run toxic-waste --agent my_agent:make" in page
    assert 'my-qmdp = "my_adhoc_agent:make_agent"' in (FIXTURES / "plugin_pkg" / "pyproject.toml").read_text()
    assert 'my-qmdp = "my_adhoc_agent:make_agent"' in page


def test_tutorial_agent_from_a_file_gives_the_files_a_shipped_agent_gives(user_folder):
    out = user_folder / "run"
    result = _cli(
        "trials",
        "toxic-waste",
        "--agents",
        "hotspot,./my_agent.py:make",
        "--episodes",
        "3",
        "--out",
        str(out),
        cwd=user_folder,
    )
    assert result.returncode == 0, result.stderr
    assert {"config.json", "trials.csv", "steps.csv", "summary.json", "steps.png", "entropy.png"} <= {
        p.name for p in out.iterdir()
    }
    rows = list(csv.DictReader((out / "trials.csv").open()))
    assert sorted({row["agent"] for row in rows}) == ["./my_agent.py:make", "hotspot"]
    summary = json.loads((out / "summary.json").read_text())
    mine = summary["agents"]["./my_agent.py:make"]
    assert mine["trials"] == 3 and mine["final_entropy_mean"] is not None  # it keeps a task posterior
    assert summary["config"]["agents"] == ["hotspot", "./my_agent.py:make"]
    assert "./my_agent.py:make" in result.stdout


def test_tutorial_agent_by_module_in_physics(user_folder):
    result = _cli(
        "run",
        "toxic-waste",
        "--agent",
        "my_agent:make",
        "--max-steps",
        "2",
        "--no-progress",
        "--json",
        cwd=user_folder,
    )
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    # the agent's task posterior was recorded (a shipped agent's is, as final_entropy)
    assert summary["steps"] == 2 and summary["final_entropy"] is not None
    bad = _cli("run", "toxic-waste", "--agent", "my_agent:nothing", cwd=user_folder)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "has no 'nothing'" in bad.stderr


def test_installed_plugins_through_entry_points(tmp_path, monkeypatch, capsys):
    from embodied_adhoc.cli import main

    monkeypatch.syspath_prepend(str(_installed_fixture_package(tmp_path / "site")))
    monkeypatch.chdir(tmp_path)
    status = main(["trials", "toxic-waste", "--agents", "random,my-qmdp", "--episodes", "2", "--max-steps", "5",
                   "--human", "my-idle-human", "--json"])  # fmt: skip
    assert status in (0, None)
    document = json.loads(capsys.readouterr().out)
    assert list(document["agents"]) == ["random", "my-qmdp"]
    assert document["config"]["options"]["human"] == "my-idle-human"
    status = main(["trials", "foraging", "--agents", "original", "--team", "my-still-team", "--episodes", "2",
                   "--max-steps", "5", "--json"])  # fmt: skip
    assert status in (0, None)
    assert json.loads(capsys.readouterr().out)["config"]["options"]["teams"] == ["my-still-team"]


# ---------------------------------------------------------------------------------- teammates and humans
def test_user_teammates_and_human_by_module_without_pythonpath(tmp_path):
    shutil.copytree(FIXTURES / "plugin_pkg" / "my_adhoc_agent", tmp_path / "my_adhoc_agent")
    foraging = _cli(
        "trials", "foraging", "--agents", "original", "--team", "my_adhoc_agent:still_team", "--episodes", "2",
        "--max-steps", "10", "--json", cwd=tmp_path,
    )  # fmt: skip
    assert foraging.returncode == 0, foraging.stderr
    original = json.loads(foraging.stdout)["agents"]["original"]
    # a team that never moves, with its policy in the ad hoc seat too, never forages
    assert original["steps_mean"] == 10.0 and original["success_rate"] == 0.0
    ntu = _cli("trials", "ntu", "--agents", "value-iteration", "--episodes", "2",
               "--teammate", "my_adhoc_agent:still_policy", "--json", cwd=tmp_path)  # fmt: skip
    assert ntu.returncode == 0, ntu.stderr
    assert json.loads(ntu.stdout)["config"]["options"]["teammate"] == "my_adhoc_agent:still_policy"
    lab = _cli("trials", "toxic-waste", "--agents", "known-task", "--episodes", "2", "--max-steps", "25",
               "--human", "my_adhoc_agent:idle_human", "--json", cwd=tmp_path)  # fmt: skip
    assert lab.returncode == 0, lab.stderr
    known = json.loads(lab.stdout)["agents"]["known-task"]
    assert known["success_rate"] == 0.0  # the robot cannot pick balls up: an idle human finishes nothing
    physics = _cli("run", "toxic-waste", "--agent", "random", "--human", "my_adhoc_agent:idle_human", "--max-steps",
                   "2", "--record", str(tmp_path / "rec"), "--no-progress", "--json", cwd=tmp_path)  # fmt: skip
    assert physics.returncode == 0, physics.stderr
    recorded = json.loads((tmp_path / "rec" / "metrics.json").read_text())["config"]
    assert recorded["human"] == "my_adhoc_agent:idle_human"
    bad = _cli("trials", "toxic-waste", "--human", "my_adhoc_agent:nobody", "--episodes", "1", cwd=tmp_path)
    assert bad.returncode == 2 and "has no 'nobody'" in bad.stderr and "Traceback" not in bad.stderr


def test_lab_envs_take_a_human():
    import gymnasium

    import embodied_adhoc.envs  # noqa: F401
    from embodied_adhoc.domains.lab_human import HumanOutcome

    class Idle:
        def step(self, rng, human_node, ball_status):
            return HumanOutcome(1.0, int(human_node))

    env = gymnasium.make("EmbodiedAdhoc/ToxicWasteAbstract-v0", human=lambda library, task: Idle())
    _, info = env.reset(seed=3)
    start = info["human_node"]
    for _ in range(15):
        _, _, terminated, _, info = env.step(int(env.action_space.sample()))
        assert info["human_node"] == start and not terminated
    with pytest.raises(ConfigError, match="no step"):
        gymnasium.make("EmbodiedAdhoc/ToxicWasteAbstract-v0", human=lambda library, task: object())


# ------------------------------------------------------------------------------------------------------ maps
def test_a_map_with_one_task_warns_once_and_skips_the_entropy_plot(tmp_path):
    (tmp_path / "two_goals.txt").write_text("######\n#G..G#\n#S..S#\n######\n")
    out = tmp_path / "run"
    result = _cli("trials", "map", "--map", "two_goals.txt", "--agents", "value-iteration,random", "--episodes",
                  "2", "--out", str(out), cwd=tmp_path)  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert (
        result.stderr.count("has a single task (r1c1+r1c4)") == 1
        and "pairs of its 'G' cells" in result.stderr
    )
    assert "No artists with labels" not in result.stderr
    files = {p.name for p in out.iterdir()}
    assert "steps.png" in files and "entropy.png" not in files


def test_entropy_plot_without_curves_draws_no_empty_legend(tmp_path):
    import warnings

    from embodied_adhoc.experiments.plots import plot_entropy

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # matplotlib's "No artists with labels found" would raise here
        path = plot_entropy({"known-task": [[0.0, 0.0, 0.0]]}, tmp_path / "entropy.png")
    assert path.is_file()


def test_teamster_takes_a_chapter_4_plugin(tmp_path):
    shutil.copytree(FIXTURES / "plugin_pkg" / "my_adhoc_agent", tmp_path / "my_adhoc_agent")
    spec = "my_adhoc_agent:chapter4_agent"
    ok = _cli("teamster", "pursuit", "--agents", spec, "--steps", "10", "--points", "1", "--trials", "1",
              "--json", cwd=tmp_path)  # fmt: skip
    assert ok.returncode == 0, ok.stderr
    assert spec in json.loads(ok.stdout)["agents"]
    bad = _cli("teamster", "pursuit", "--agents", "my_adhoc_agent:make_agent", "--steps", "10", "--points", "1",
               cwd=tmp_path)  # fmt: skip
    assert bad.returncode == 2 and "does not meet the chapter-4 TeamworkAgent protocol" in bad.stderr


def test_a_file_plugin_draws_the_same_trials_from_any_folder(user_folder):
    from embodied_adhoc.experiments import seeding
    from embodied_adhoc.experiments.domains.toxic_waste import DOMAIN
    from embodied_adhoc.experiments.runner import SweepConfig, run_sweep

    # a registered name keeps its key; a file plug-in is keyed by file name and callable, not by its folder
    assert seeding.agent_key("hotspot") == zlib.crc32(b"hotspot")
    assert seeding.agent_key("/a/b/my_agent.py:make") == seeding.agent_key("my_agent.py:make")
    assert seeding.agent_key("my_agent.py:make") != seeding.agent_key("other.py:make")
    assert seeding.agent_key("my_agent.py:make") != seeding.agent_key("my_agent.py:build")
    assert seeding.env_seed(3, 1, "./x/my_agent.py:make") == seeding.env_seed(3, 1, "../y/my_agent.py:make")

    rows = []
    for folder in ("first", "second/deeper"):
        (user_folder / folder).mkdir(parents=True)
        shutil.copy(user_folder / "my_agent.py", user_folder / folder / "my_agent.py")
        spec = f"./{folder}/my_agent.py:make"
        config = SweepConfig("toxic-waste", "abstract", DOMAIN.options(), (spec,), episodes=3, seed=5)
        run_sweep(config, out=user_folder / f"run-{folder.replace('/', '-')}")
        with open(user_folder / f"run-{folder.replace('/', '-')}" / "trials.csv", newline="") as handle:
            rows.append(
                [
                    {k: v for k, v in row.items() if k not in ("agent", "check")}
                    for row in csv.DictReader(handle)
                ]
            )
    assert len(rows[0]) == 3 and rows[0] == rows[1]
