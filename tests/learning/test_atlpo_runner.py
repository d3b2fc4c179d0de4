"""ATLPO through the project's one episode loop: ``trials foraging|pursuit --agents atlpo-mf`` (raw egocentric
observations, ``observes_raw``), the task marginal the runner's metrics read, the library/grid checks, the shipped
libraries, and ``run foraging`` recorded in the MuJoCo arena."""

import json
import subprocess
import sys

import numpy as np
import pytest
import torch

from embodied_adhoc.domains.grid_rules import GridConfig
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.runner import SweepConfig, run_sweep
from embodied_adhoc.learning.atlpo import library_agent, shipped_library, train_library, write_manifest
from embodied_adhoc.learning.classifier import ClassifierConfig, RecurrentBayesianClassifier
from embodied_adhoc.learning.ppo import PpoConfig

torch.set_num_threads(1)


def _tiny_library(folder, domain="foraging", set_name="task"):
    """Untrained-enough members (64 PPO steps) and an untrained classifier: enough to drive the loop."""
    config = PpoConfig(
        total_steps=64, num_envs=2, rollout_steps=32, minibatches=2, epochs=1, seed=1, device="cpu"
    )
    library = train_library(domain, set_name, config, folder)
    torch.manual_seed(0)
    classifier = RecurrentBayesianClassifier(
        ClassifierConfig(
            channels=library.policies[0].config.channels,
            environments=len(library.policies),
            features=8,
            hidden=8,
            hidden_channels=4,
        )
    )
    write_manifest(folder, library, classifier.eval())
    return folder


def _options(domain, library, **changes):
    options = {
        "domain": domain,
        "teams": ["tau0", "tau1", "tau2"],
        "task": None,
        "rows": 5,
        "cols": 5,
        "agents": 4,
        "toroidal": False,
        "pairs": False,
        "library": str(library),
    }
    return {**options, **changes}


@pytest.mark.parametrize("domain", ["foraging", "pursuit"])
def test_trials_run_atlpo_with_raw_observations_and_a_task_posterior(tmp_path, domain):
    library = _tiny_library(tmp_path / "lib", domain)
    config = SweepConfig(
        domain,
        "abstract",
        _options(domain, library),
        agents=("atlpo-mf", "random"),
        episodes=3,
        seed=2,
        max_steps=12,
    )
    result = run_sweep(config)
    again = run_sweep(config)
    atlpo = [r for r in result.records if r.agent == "atlpo-mf"]
    assert len(atlpo) == 3 and all(1 <= r.steps <= 12 for r in atlpo)
    assert [r.steps for r in atlpo] == [r.steps for r in again.records if r.agent == "atlpo-mf"]  # seeded
    curves = result.curves_by_agent()
    assert len(curves["atlpo-mf"]) == 3 and "random" not in curves  # a task posterior per step for ATLPO only
    assert all(len(c) == r.steps + 1 for c, r in zip(curves["atlpo-mf"], atlpo, strict=True))


def test_the_episode_loop_hands_atlpo_the_arrays_and_the_first_observation(tmp_path):
    import gymnasium

    import embodied_adhoc.envs  # noqa: F401
    from embodied_adhoc.episodes.loop import run_episode_loop

    agent = library_agent("foraging", _tiny_library(tmp_path), GridConfig())
    seen = []
    original_start, original_observe = agent.start, agent.observe
    agent.start = lambda observation: (
        seen.append(("start", np.shape(observation))),
        original_start(observation),
    )
    agent.observe = lambda action, observation, state=None: (
        seen.append(("observe", np.shape(observation))),
        original_observe(action, observation, state),
    )
    env = gymnasium.make("EmbodiedAdhoc/ForagingGrid-v0")
    trace = run_episode_loop(
        env,
        agent,
        env_seed=0,
        agent_rng=np.random.default_rng(0),
        reset_options=None,
        max_steps=4,
        observation_index=lambda observation: 7,
    )
    assert seen[0] == ("start", (6, 5, 5)) and all(s == ("observe", (6, 5, 5)) for s in seen[1:])
    assert (
        len(seen) == trace.steps + 1 and trace.observations == [7] * trace.steps
    )  # the trace keeps the index
    history = trace.posterior_history()
    assert history.shape == (trace.steps + 1, 4) and np.allclose(history.sum(axis=1), 1.0)


def test_library_agent_refuses_another_domain_grid_or_a_missing_classifier(tmp_path):
    folder = _tiny_library(tmp_path / "lib")
    with pytest.raises(ConfigError, match="a foraging library; pursuit needs"):
        library_agent("pursuit", folder, GridConfig(domain="pursuit"))
    with pytest.raises(ConfigError, match="n_agents 3 \\(library 4\\)"):
        library_agent("foraging", folder, GridConfig(n_agents=3))
    manifest = json.loads((folder / "library.json").read_text())
    del manifest["classifier"]
    (folder / "library.json").write_text(json.dumps(manifest))
    with pytest.raises(ConfigError, match="no classifier"):
        library_agent("foraging", folder, GridConfig())


def test_trials_cli_refuses_a_folder_without_a_library(tmp_path):
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "embodied_adhoc.cli",
            "trials",
            "foraging",
            "--agents",
            "atlpo-mf",
            "--library",
            str(tmp_path),
            "--episodes",
            "1",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2
    assert done.stderr.strip().count("\n") == 0 and "train atlpo --domain foraging" in done.stderr


@pytest.mark.parametrize("domain", ["foraging", "pursuit"])
def test_the_shipped_libraries_load_and_fit_the_default_grid(domain):
    folder = shipped_library(domain)
    agent = library_agent(domain, None, GridConfig(domain=domain))
    assert [e.name for e in agent.library.environments] == [
        "task1-tau1",
        "task2-tau1",
        "task3-tau1",
        "task4-tau1",
        "task1-tau0",
        "task1-tau2",
    ]
    size = sum(path.stat().st_size for path in folder.iterdir())
    assert size < 3 * 2**20  # a few MB at most for both domains
    training = json.loads((folder / "training.json").read_text())
    assert training["set"] == "task+team" and training["steps"] == 30_000 and training["seed"] == 0


@pytest.mark.slow
def test_run_foraging_records_atlpo_in_the_arena(tmp_path):
    from embodied_adhoc.gl import choose_gl_platform

    choose_gl_platform()
    from embodied_adhoc.experiments.recorded import ForagingEpisodeConfig, run_foraging_episode

    config = ForagingEpisodeConfig(
        seed=1, library=_tiny_library(tmp_path / "lib"), max_steps=3, record_dir=tmp_path / "rec", size=64
    )
    outcome = run_foraging_episode(config)
    assert set(outcome.files) == {"video", "rerun", "metrics"} and outcome.video_frames > 0
    metrics = json.loads((tmp_path / "rec" / "metrics.json").read_text())
    assert metrics["config"]["agent"] == "atlpo-mf" and 1 <= metrics["steps"] <= 3
    assert all(np.isclose(sum(s["library_posterior"]), 1.0) for s in metrics["per_step"])
    assert metrics["config"]["spec"]["team"] == outcome.metrics["true_team"]


@pytest.mark.parametrize(
    ("args", "named"),
    [(("--team", "tau9"), "--team tau9"), (("--task", "7"), "--task 7"), (("--size", "15"), "--size: 15")],
)
def test_run_foraging_bad_input_is_one_line_and_exit_2(args, named):
    done = subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", "run", "foraging", *args, "--no-progress"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2 and named in done.stderr and done.stderr.strip().count("\n") == 0, done.stderr
