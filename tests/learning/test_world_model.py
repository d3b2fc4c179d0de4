"""ATLPO-MB (Fig. 6.3): the world model learns on replayed experience, the MB member's PPO runs on its frozen
encoder's latents, and an MB library is an ordinary ATLPO library (loadable, usable by the agent)."""

import numpy as np
import torch

from embodied_adhoc.learning.atlpo import (
    generalist_path,
    load_library,
    load_policy,
    train_generalist,
    train_library,
)
from embodied_adhoc.learning.networks import NetworkConfig
from embodied_adhoc.learning.ppo import PpoConfig
from embodied_adhoc.learning.weights import load_weights
from embodied_adhoc.learning.world_model import (
    WorldModel,
    WorldModelTraining,
    collect_experience,
    train_mb_policy,
    train_world_model,
)

torch.set_num_threads(1)
ONE = {"tasks": (1,), "teams": ("tau1",)}


def test_replay_is_seeded():
    data = collect_experience("foraging", {**ONE, "max_episode_steps": 5}, steps=64, seed=3, num_envs=4)
    again = collect_experience("foraging", {**ONE, "max_episode_steps": 5}, steps=64, seed=3, num_envs=4)
    assert data.observations.shape == (64, 6, 5, 5) and data.actions.shape == (64,)
    assert np.array_equal(data.next_observations, again.next_observations)
    assert set(np.unique(data.actions)) <= set(range(5)) and len(np.unique(data.actions)) > 1


def test_world_model_training_lowers_every_loss_term():
    data = collect_experience("foraging", ONE, steps=1024, seed=0)
    model = WorldModel(NetworkConfig(channels=6))
    history = train_world_model(model, data, WorldModelTraining(iterations=200, batch_size=64))
    first, last = history[0], history[-1]
    for term in ("reconstruction", "next_observation", "latent", "loss"):
        assert last[term] < first[term], term


def test_mb_policy_learns_on_the_frozen_encoder(tmp_path):
    config = PpoConfig(
        total_steps=64, num_envs=2, rollout_steps=32, minibatches=2, epochs=1, seed=1, device="cpu"
    )
    settings = WorldModelTraining(experience=256, iterations=20, batch_size=32)
    result, world, _ = train_mb_policy("foraging", ONE, config, settings)
    for ours, theirs in zip(
        result.model.encoder.state_dict().values(), world.encoder.state_dict().values(), strict=True
    ):
        assert torch.equal(ours, theirs)  # PPO trained the heads only
    library = train_library("foraging", "team", config, tmp_path, model="mb", world_model=settings)
    assert sorted(p.name for p in tmp_path.glob("*-mb-*.safetensors")) == [
        "foraging-mb-task1-tau0.safetensors",
        "foraging-mb-task1-tau1.safetensors",
        "foraging-mb-task1-tau2.safetensors",
    ]
    assert load_weights(tmp_path / "foraging-mb-task1-tau0.safetensors")[1]["kind"] == "atlpo-mb-policy"
    loaded, _ = load_library(tmp_path)
    assert loaded.model == "mb" and len(loaded.policies) == len(library.policies) == 3
    baseline = train_generalist("foraging", "team", config, tmp_path, model="mb", world_model=settings)
    assert generalist_path(tmp_path, "foraging", "team", "mb").exists()
    assert torch.equal(
        next(iter(load_policy(generalist_path(tmp_path, "foraging", "team", "mb")).state_dict().values())),
        next(iter(baseline.state_dict().values())),
    )


def test_world_model_keeps_learning_on_the_policys_replay():
    """After every PPO update the rollout joins the replay and the world model trains on it (its encoder then
    replaces the policy's); with updates_per_rollout=0 the encoder stays the pre-trained one. Seeded."""
    config = PpoConfig(
        total_steps=128, num_envs=2, rollout_steps=32, minibatches=2, epochs=1, seed=1, device="cpu"
    )
    frozen = WorldModelTraining(experience=256, iterations=20, batch_size=32, updates_per_rollout=0)
    before, frozen_world, frozen_history = train_mb_policy("foraging", ONE, config, frozen)
    interleaved = WorldModelTraining(
        experience=256, iterations=20, batch_size=32, updates_per_rollout=5, replay=300
    )
    result, world, history = train_mb_policy("foraging", ONE, config, interleaved)
    assert frozen_history[-1]["iteration"] == 19 and history[-1]["iteration"] == 19 + 2 * 5  # two PPO updates
    changed = [
        not torch.equal(a, b)
        for a, b in zip(
            world.encoder.state_dict().values(), frozen_world.encoder.state_dict().values(), strict=True
        )
    ]
    assert any(changed)
    for ours, theirs in zip(
        result.model.encoder.state_dict().values(), world.encoder.state_dict().values(), strict=True
    ):
        assert torch.equal(ours, theirs)
    assert result.model.config.head_hidden == 64 and isinstance(result.model.actor, torch.nn.Sequential)
    again = train_mb_policy("foraging", ONE, config, interleaved)[0]
    for ours, theirs in zip(
        result.model.state_dict().values(), again.model.state_dict().values(), strict=True
    ):
        assert torch.equal(ours, theirs)


def test_replay_replaces_the_oldest_transitions():
    from embodied_adhoc.learning.world_model import Experience, Replay

    def rows(start, count):
        values = np.arange(start, start + count, dtype=np.float32)
        return Experience(
            np.broadcast_to(values[:, None, None, None], (count, 1, 2, 2)).copy(),
            np.arange(count, dtype=np.int64),
            values,
            values[:, None, None, None] + np.zeros((1, 2, 2)),
        )

    replay = Replay(rows(0, 3), capacity=4, device=torch.device("cpu"))
    assert replay.size == 3
    more = rows(10, 3)
    replay.add(more.observations, more.actions, more.rewards, more.next_observations)
    assert replay.size == 4 and sorted(replay.tensors[2].tolist()) == [2.0, 10.0, 11.0, 12.0]


def test_mb_member_metadata_records_the_ppo_settings_it_trained_with(tmp_path):
    config = PpoConfig(
        total_steps=64, num_envs=2, rollout_steps=32, minibatches=2, epochs=1, seed=1, device="cpu"
    )
    settings = WorldModelTraining(
        experience=128, iterations=5, batch_size=32, policy_learning_rate=5e-4, head_hidden=8
    )
    train_library("foraging", "team", config, tmp_path, model="mb", world_model=settings)
    metadata = load_weights(tmp_path / "foraging-mb-task1-tau1.safetensors")[1]
    assert metadata["ppo"]["learning_rate"] == 5e-4 and metadata["network"]["head_hidden"] == 8
    assert metadata["world_model"]["policy_learning_rate"] == 5e-4
