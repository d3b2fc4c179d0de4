"""The library-free agents on the index domains (the toxic-waste lab and pursuit-task): the vector env draws only
train-split teammates and hides the ground truth unless asked, the forward pass is deterministic per seed, a
tiny training run lowers its loss and writes loadable safetensors, LIAM's and MeLIBA's training-only targets
never reach the acting network, and the agents run in ``trials`` through the plug-in specs."""

import csv
import json
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.generalist import GeneralistTraining, load_generalist, train_generalist_run
from embodied_adhoc.learning.index_domains import (
    INDEX_DOMAINS,
    TEAMMATE_CLASSES,
    IndexAgent,
    IndexNetworkConfig,
    IndexVectorEnv,
    index_agent,
    member_names,
)
from embodied_adhoc.learning.liam import LiamTraining, train_liam_run
from embodied_adhoc.learning.meliba import MelibaTraining, load_meliba, train_meliba_run
from embodied_adhoc.learning.recurrent_ppo import CHECKPOINT, RecurrentActorCritic
from embodied_adhoc.learning.weights import load_weights
from embodied_adhoc.teammates.populations import members

torch.set_num_threads(1)


def _rollout(env: IndexVectorEnv, steps: int, seed: int):
    rng = np.random.default_rng(seed)
    observation, infos = env.reset(seed=seed)
    out = [observation]
    for _ in range(steps):
        observation, reward, terminated, truncated, infos = env.step(rng.integers(0, 5, env.num_envs))
        out.append((observation, reward, terminated, truncated))
    return out, infos


@pytest.mark.parametrize("domain", INDEX_DOMAINS)
def test_the_vector_env_is_seeded_and_shows_the_targets_only_when_asked(domain):
    names = member_names(domain, 2)
    env = IndexVectorEnv(domain, 3, members=names, teammate_info=True)
    first, infos = _rollout(env, 40, 5)
    second, _ = _rollout(IndexVectorEnv(domain, 3, members=names, teammate_info=True), 40, 5)
    assert all(
        np.array_equal(a, b)
        for x, y in zip(first[1:], second[1:], strict=True)
        for a, b in zip(x, y, strict=True)
    )
    views, moves = TEAMMATE_CLASSES[domain]
    assert infos["teammate_observations"].shape == (3, 1) and infos["teammate_actions"].shape == (3, 1)
    assert (infos["teammate_observations"] < views).all() and (infos["teammate_actions"] < moves).all()
    assert set(np.concatenate([step[0] for step in first[1:]])) <= set(range(env.n_observations))
    plain = IndexVectorEnv(domain, 3, members=names)
    _, plain_infos = _rollout(plain, 3, 5)
    assert not any(key.startswith(("teammate_", "_teammate_")) for key in plain_infos)


@pytest.mark.parametrize("domain", INDEX_DOMAINS)
def test_training_sees_only_the_train_split(domain):
    for split in ("validation", "held-out"):
        with pytest.raises(ConfigError, match="train split"):
            IndexVectorEnv(domain, 2, members=[members(domain, split)[0].name])
    with pytest.raises(ConfigError, match="--teammates"):
        member_names(domain, len(members(domain, "train")) + 1)
    assert member_names(domain, 1) == [members(domain, "train")[0].name]


def test_the_forward_pass_is_deterministic_per_seed():
    def network(seed):
        torch.manual_seed(seed)
        return RecurrentActorCritic(IndexNetworkConfig(observations=73), recurrent=16)

    observations = torch.randint(0, 73, (7, 4))
    previous = torch.randint(0, 5, (7, 4))
    starts = torch.zeros(7, 4, dtype=torch.bool)
    starts[0] = True
    outputs = [network(s).unroll(observations, previous, torch.zeros(4, 16), starts) for s in (1, 1, 2)]
    assert all(torch.equal(a, b) for a, b in zip(outputs[0], outputs[1], strict=True))
    assert not torch.equal(outputs[0][0], outputs[2][0])


TINY = {"steps": 4 * 4 * 16, "envs": 4, "rollout": 16, "seed": 1, "teammates": 2}


@pytest.mark.parametrize(
    ("domain", "settings", "run", "kind", "loader"),
    [
        ("toxic-waste", GeneralistTraining, train_generalist_run, "ppo-generalist", load_generalist),
        ("pursuit-task", LiamTraining, train_liam_run, "liam", load_generalist),
        ("pursuit-task", MelibaTraining, train_meliba_run, "meliba", load_meliba),
    ],
)
def test_a_tiny_run_lowers_its_loss_and_writes_loadable_weights(
    tmp_path, domain, settings, run, kind, loader
):
    report = run(settings(domain, str(tmp_path), **TINY))
    assert report["finished"] and report["env_steps"] == 256
    assert json.loads((tmp_path / "training.json").read_text())["env_steps"] == 256
    curve = (tmp_path / "curve.csv").read_text().splitlines()
    assert len(curve) == 1 + 4
    rows = [dict(zip(curve[0].split(","), line.split(","), strict=True)) for line in curve[1:]]
    drops = [float(r["loss_before"]) - float(r["loss_after"]) for r in rows]
    assert sum(d > 0 for d in drops) >= 3 and sum(drops) > 0, drops  # the updates lower the PPO loss
    weights = tmp_path / f"{domain}-{kind}.safetensors"
    tensors, metadata = load_weights(weights)  # safetensors: tensors and a JSON header, nothing executable
    assert metadata["kind"] == kind and metadata["domain"] == domain
    assert metadata["env_kwargs"] == {"members": member_names(domain, 2)}
    assert not any(name.startswith("decoder.") for name in tensors)  # the training-only decoder left out
    model, _ = loader(weights, kind)
    assert isinstance(model.config, IndexNetworkConfig)
    assert not (tmp_path / CHECKPOINT).exists()


def test_an_interrupted_run_resumes_to_its_full_budget(tmp_path):
    settings = GeneralistTraining("pursuit-task", str(tmp_path), **TINY)
    part = train_generalist_run(settings, stop_after=2)
    assert not part["finished"] and (tmp_path / CHECKPOINT).exists()
    resumed = train_generalist_run(settings)
    assert resumed["finished"] and resumed["env_steps"] == 256 and resumed["updates"] == 4


def test_liams_reconstruction_target_never_reaches_the_acting_agent():
    from embodied_adhoc.learning.liam import LiamConfig, train_liam

    config = LiamConfig(total_steps=2 * 4 * 16, num_envs=4, rollout_steps=16, minibatches=1, epochs=2, seed=1)
    trained = train_liam("pursuit-task", {"members": member_names("pursuit-task", 2)}, config).model
    acting = trained.policy()  # what the weights file holds and the agent acts with
    assert not any(name.startswith("decoder.") for name in acting.state_dict())
    torch.manual_seed(0)
    observations = torch.randint(0, 82, (9, 3))
    previous = torch.randint(0, 5, (9, 3))
    starts = torch.zeros(9, 3, dtype=torch.bool)
    starts[0] = True
    hidden = torch.zeros(3, config.recurrent)
    with torch.no_grad():
        before = trained.unroll(observations, previous, hidden, starts)[0]
        for parameter in trained.decoder.parameters():  # another reconstruction of the teammate entirely
            parameter.add_(torch.randn_like(parameter))
        after = trained.unroll(observations, previous, hidden, starts)[0]
        executed = acting.unroll(observations, previous, hidden, starts)[0]
    assert torch.equal(before, after) and torch.equal(before, executed)


def test_the_agents_run_in_trials_as_plugins(tmp_path, monkeypatch):
    import embodied_adhoc.learning.index_domains as index_domains

    train_generalist_run(GeneralistTraining("pursuit-task", str(tmp_path), **TINY))
    weights = tmp_path / "pursuit-task-ppo-generalist.safetensors"
    real = index_domains.shipped_weights
    monkeypatch.setattr(index_domains, "shipped_weights", lambda domain, kind, *rest: weights)
    from embodied_adhoc.cli import main

    out = tmp_path / "trials"
    code = main(
        [
            "trials",
            "pursuit-task",
            "--agents",
            "embodied_adhoc.learning.generalist:plugin,random",
            "--episodes",
            "2",
            "--workers",
            "1",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    rows = (out / "trials.csv").read_text().splitlines()
    assert sum("embodied_adhoc.learning.generalist:plugin" in row for row in rows) == 2
    monkeypatch.setattr(index_domains, "shipped_weights", real)


# what the trials hand a plug-in on pursuit-task, as far as the agent reads it (its domain and observation count)
_LIBRARY = SimpleNamespace(domain="pursuit-task", pomdps=(SimpleNamespace(n_observations=81),))


def test_the_agent_reads_indices_and_refuses_another_domains(tmp_path):
    train_generalist_run(GeneralistTraining("pursuit-task", str(tmp_path), **TINY))
    agent = index_agent(_LIBRARY, "ppo-generalist", tmp_path / "pursuit-task-ppo-generalist.safetensors")
    assert isinstance(agent, IndexAgent) and not agent.observes_raw and not agent.observes_state
    agent.reset(np.random.default_rng(0))
    agent.start(-1)  # chapter 5's "no observation yet"
    first = agent.action_distribution()
    assert first.shape == (5,) and abs(first.sum() - 1.0) < 1e-9
    agent.observe(agent.act(), 80)
    with pytest.raises(ConfigError, match="outside the 81 indices"):
        agent.observe(0, 81)
    with pytest.raises(ConfigError, match="no index domain"):
        index_agent(object(), "ppo-generalist", tmp_path / "pursuit-task-ppo-generalist.safetensors")


def test_the_cli_offers_the_domains_the_agents_train_on():
    from embodied_adhoc.commands.train import RECURRENT_DOMAINS
    from embodied_adhoc.learning.generalist import DOMAINS

    assert RECURRENT_DOMAINS == DOMAINS


def test_a_teammate_count_the_split_lacks_is_refused_before_training(tmp_path):
    import subprocess
    import sys

    out = tmp_path / "run"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "embodied_adhoc.cli",
            "train",
            "liam",
            "--domain",
            "toxic-waste",
            "--teammates",
            "9",
        ]
        + ["--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2 and "--teammates 9" in done.stderr
    assert "step/s" not in done.stderr and not out.exists()  # no progress bar, nothing written


@pytest.mark.parametrize(
    ("domain", "agents"), [("toxic-waste", "ppo-generalist,liam,meliba"), ("pursuit-task", "liam,random")]
)
def test_trials_name_the_shipped_agents_where_their_weights_ship(tmp_path, domain, agents):
    from embodied_adhoc.cli import main
    from embodied_adhoc.experiments.registry import get_trial_domain

    assert set(agents.split(",")) <= set(get_trial_domain(domain).agent_names)
    out = tmp_path / "trials"
    code = main(
        ["trials", domain, "--agents", agents, "--episodes", "2", "--workers", "1", "--out", str(out)]
    )
    assert code == 0
    rows = list(csv.DictReader((out / "trials.csv").open()))
    assert sorted({row["agent"] for row in rows}) == sorted(agents.split(","))
    assert len(rows) == 2 * len(agents.split(","))


def test_the_learned_agents_are_not_among_chapter5_defaults():
    from embodied_adhoc.experiments.registry import get_trial_domain

    domain = get_trial_domain("pursuit-task")
    assert "liam" in domain.agent_names and "liam" not in domain.default_agents
    assert "liam" not in get_trial_domain("gridworld").agent_names
