"""PPO for ATLPO-MF library members (thesis Fig. 6.2) and the weights files (safetensors, never pickles)."""

import pickle

import pytest
import torch

from embodied_adhoc.learning.networks import ActorCritic, NetworkConfig
from embodied_adhoc.learning.ppo import PpoConfig, train_ppo, training_metadata
from embodied_adhoc.learning.weights import WeightsError, load_into, load_weights, save_weights

torch.set_num_threads(1)
TINY = PpoConfig(total_steps=384, num_envs=4, rollout_steps=32, epochs=4, minibatches=4, seed=3, device="cpu")
ENV = {"tasks": (2,), "teams": ("tau1",)}


def test_tiny_training_lowers_the_ppo_loss_and_writes_loadable_weights(tmp_path):
    result = train_ppo("pursuit", ENV, TINY)
    assert len(result.history) == 3 and result.env_steps == 384
    for row in result.history:  # each update lowers the PPO objective on the batch it was computed from
        assert row["loss_after"] < row["loss_before"], row
    path = save_weights(
        tmp_path / "member.safetensors", result.model, training_metadata("pursuit", ENV, TINY, result)
    )
    tensors, metadata = load_weights(path)
    assert metadata["domain"] == "pursuit" and metadata["ppo"]["seed"] == 3
    fresh = ActorCritic(NetworkConfig(**metadata["network"]))
    load_into(fresh, path)
    observations = torch.rand(6, *fresh_shape(metadata))
    assert torch.equal(fresh(observations)[0], result.model(observations)[0])


def fresh_shape(metadata):
    network = metadata["network"]
    return network["channels"], network["view"], network["view"]


def test_training_is_deterministic_given_the_seed():
    config = PpoConfig(
        total_steps=128, num_envs=2, rollout_steps=32, minibatches=2, epochs=2, seed=5, device="cpu"
    )
    first, second = train_ppo("foraging", ENV, config), train_ppo("foraging", ENV, config)
    for a, b in zip(first.model.state_dict().values(), second.model.state_dict().values(), strict=True):
        assert torch.equal(a, b)
    assert first.history == second.history


class Payload:
    """Anything a pickle could smuggle in."""


def test_a_pickled_object_in_a_weights_file_is_refused(tmp_path):
    for name, write in (
        ("torch", lambda p: torch.save({"weight": torch.zeros(2), "payload": Payload()}, p)),
        ("pickle", lambda p: p.write_bytes(pickle.dumps(Payload()))),
    ):
        path = tmp_path / f"{name}.safetensors"
        write(path)
        with pytest.raises(WeightsError, match=str(path)):
            load_weights(path)
    with pytest.raises(WeightsError, match="no such"):
        load_weights(tmp_path / "missing.safetensors")
    with pytest.raises(WeightsError, match="suffix"):
        save_weights(tmp_path / "member.pt", ActorCritic(NetworkConfig(channels=5)), {})


def test_weights_must_fit_the_network(tmp_path):
    path = save_weights(
        tmp_path / "small.safetensors", ActorCritic(NetworkConfig(channels=5)), {"kind": "test"}
    )
    with pytest.raises(WeightsError, match="do not fit"):
        load_into(ActorCritic(NetworkConfig(channels=6)), path)
