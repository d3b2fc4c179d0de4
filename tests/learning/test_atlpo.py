"""ATLPO-MF end to end on a tiny library: per-environment PPO members, trajectories, the classifier and the
agent acting in the single env (thesis chapter 6)."""

import gymnasium
import numpy as np
import pytest
import torch

from embodied_adhoc.decision.agents.base import Agent
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.atlpo import (
    AtlpoAgent,
    collect_trajectories,
    generalist_path,
    library_set,
    load_library,
    member_seed,
    train_generalist,
    train_library,
    write_manifest,
)
from embodied_adhoc.learning.atlpo_eval import evaluate
from embodied_adhoc.learning.classifier import (
    ClassifierConfig,
    ClassifierTraining,
    RecurrentBayesianClassifier,
    train_classifier,
)
from embodied_adhoc.learning.ppo import PpoConfig

torch.set_num_threads(1)


def test_library_sets():
    assert [e.name for e in library_set("team")] == ["task1-tau0", "task1-tau1", "task1-tau2"]
    assert len(library_set("task")) == 4 and len(library_set("task+team")) == 6
    with pytest.raises(ConfigError, match="set="):
        library_set("teams")


def test_member_seeds_depend_on_the_environment_not_the_set():
    team, task = library_set("team"), library_set("task")
    assert member_seed(3, team[1]) == member_seed(3, task[0]) == 3  # task1-tau1 in both sets
    assert sorted(member_seed(0, e) for e in library_set("task+team")) == list(range(6))


def test_tiny_library_classifier_and_agent(tmp_path):
    config = PpoConfig(
        total_steps=64, num_envs=2, rollout_steps=32, minibatches=2, epochs=1, seed=1, device="cpu"
    )
    library = train_library("foraging", "team", config, tmp_path)
    assert len(library.policies) == 3 and len(list(tmp_path.glob("*.safetensors"))) == 3
    data = collect_trajectories(library, episodes=4, max_steps=12, seed=0)
    assert data.observations.shape[:2] == (12, 12) and set(data.labels.tolist()) == {0, 1, 2}
    assert np.all(data.previous_actions[:, 0] == 5)
    mixed = collect_trajectories(library, episodes=4, max_steps=12, seed=0, mixing=1.0)
    assert not np.array_equal(mixed.previous_actions, data.previous_actions)  # other members' actions
    with pytest.raises(ConfigError, match="mixing"):
        collect_trajectories(library, episodes=4, max_steps=12, seed=0, mixing=1.5)
    classifier = RecurrentBayesianClassifier(
        ClassifierConfig(
            channels=data.observations.shape[2], environments=3, features=16, hidden=16, hidden_channels=4
        )
    )
    train_classifier(classifier, data, ClassifierTraining(iterations=5, batch_size=8))
    write_manifest(tmp_path, library, classifier)
    library, classifier = load_library(tmp_path)  # the agent runs on what was written
    agent = AtlpoAgent(library, classifier)
    assert isinstance(agent, Agent)
    env = gymnasium.make("EmbodiedAdhoc/ForagingGrid-v0", tasks=(1,), teams=("tau2",))
    observation, _ = env.reset(seed=3)
    agent.reset(np.random.default_rng(0))
    agent.start(observation)
    for _ in range(10):
        action = agent.act()
        assert 0 <= action < 5
        observation, _, terminated, truncated, _ = env.step(action)
        agent.observe(action, observation)
        assert np.isclose(agent.library_posterior.sum(), 1.0) and agent.library_posterior.min() >= 0
        assert agent.task_posterior is None  # the team set's environments share task 1: no task marginal
        if terminated or truncated:
            break
    with pytest.raises(ConfigError, match="egocentric"):
        agent.observe(0, 17)
    known = AtlpoAgent(library, classifier, known=2)
    known.reset(np.random.default_rng(0))
    known.start(observation)
    known.observe(known.act(), observation)
    assert known.library_posterior.tolist() == [0.0, 0.0, 1.0]
    generalist = train_generalist("foraging", "team", config, tmp_path)
    assert generalist_path(tmp_path, "foraging", "team").exists()
    results = evaluate(library, classifier, episodes=1, seed=0, max_steps=8, generalist=generalist)
    assert results == evaluate(
        library, classifier, episodes=1, seed=0, max_steps=8, generalist=generalist
    )  # seeded
    for name in ("original", "known", "mf-all", "atlpo-mf", "random"):
        assert len(results[name]["steps"]) == 3 and all(1 <= s <= 8 for s in results[name]["steps"])
    assert 1 <= len(results["true_posterior_per_step"]) <= 8
    again = train_library("foraging", "team", config, tmp_path)  # resumes: members are loaded, not retrained
    assert load_library(tmp_path)[1] is not None  # and the classifier stays in the manifest
    for a, b in zip(again.policies, library.policies, strict=True):
        assert all(
            torch.equal(x, y) for x, y in zip(a.state_dict().values(), b.state_dict().values(), strict=True)
        )
