"""LIAM: the vector env's training-only teammate targets, seeded training, the reconstruction loss learning on a
fixed batch, and the shipped agent (safetensors, no decoder, acting from its own observations)."""

import gymnasium
import numpy as np
import pytest
import torch

import embodied_adhoc.envs  # noqa: F401  (registers the ids)
from embodied_adhoc.decision.agents.base import protocol_gaps
from embodied_adhoc.domains.grid_rules_obs import egocentric_batch
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.liam import (
    RECONSTRUCTION_FIELDS,
    LiamConfig,
    LiamNetwork,
    liam_agent,
    reconstruction_loss,
    shipped_weights,
    train_liam,
)
from embodied_adhoc.learning.networks import NetworkConfig
from embodied_adhoc.learning.recurrent_ppo import RecurrentActorCritic
from embodied_adhoc.learning.vector_grid import GridVectorEnv
from embodied_adhoc.learning.weights import load_into, load_weights

torch.set_num_threads(1)
TEAMS = {"teams": ("tau0", "tau1", "tau2")}
TINY = LiamConfig(
    total_steps=2 * 4 * 16, num_envs=4, rollout_steps=16, minibatches=2, epochs=2, seed=3, device="cpu"
)


def _rollout(env: GridVectorEnv, steps: int, seed: int):
    """Random actions for ``steps`` steps: (observations, step outputs) with the infos of each step."""
    rng = np.random.default_rng(seed)
    observation, _ = env.reset(seed=seed)
    observations, outputs = [observation], []
    for _ in range(steps):
        outputs.append(env.step(rng.integers(0, 5, env.num_envs)))
        observations.append(outputs[-1][0])
    return observations, outputs


def test_the_teammate_targets_appear_only_when_asked_and_change_nothing_else():
    plain = GridVectorEnv("foraging", 3, max_episode_steps=6, **TEAMS)
    told = GridVectorEnv("foraging", 3, max_episode_steps=6, teammate_info=True, **TEAMS)
    plain_obs, plain_out = _rollout(plain, 14, seed=5)
    told_obs, told_out = _rollout(told, 14, seed=5)
    for a, b in zip(plain_obs, told_obs, strict=True):
        np.testing.assert_array_equal(a, b)
    resets = 0
    for (_, reward, terminated, truncated, info), (_, reward2, terminated2, truncated2, info2) in zip(
        plain_out, told_out, strict=True
    ):
        assert not any(k.startswith(("teammate", "_teammate")) for k in info)
        np.testing.assert_array_equal(reward, reward2)
        np.testing.assert_array_equal(terminated | truncated, terminated2 | truncated2)
        assert info2["teammate_observations"].shape == (3, 3, *plain.single_observation_space.shape)
        assert info2["teammate_actions"].shape == (3, 3)
        assert ((info2["teammate_actions"] >= 0) & (info2["teammate_actions"] <= 4)).all()
        resets += int((~info2["_teammate_actions"]).sum())
    assert resets > 0  # the 6-step cap made reset steps, where no teammate acts (masked)


def test_a_teammate_window_is_what_that_teammate_sees():
    env = GridVectorEnv("foraging", 2, teammate_info=True, **TEAMS)
    observation, _ = env.reset(seed=1)
    expected = egocentric_batch(env.rules, env.batch, np.array([[1, 2, 3]] * 2), env.view)
    info = env.step(np.zeros(2, np.int64))[4]
    np.testing.assert_array_equal(info["teammate_observations"], expected)
    assert observation.shape[1:] == expected.shape[2:]


def test_tiny_training_is_deterministic_given_the_seed():
    first = train_liam("foraging", TEAMS, TINY)
    second = train_liam("foraging", TEAMS, TINY)
    assert first.updates == 2 and isinstance(first.model, LiamNetwork)
    one, two = first.model.state_dict(), second.model.state_dict()
    assert one.keys() == two.keys() and all(torch.equal(one[k], two[k]) for k in one)
    assert any(k.startswith("decoder.") for k in one)
    strip = [{k: v for k, v in row.items() if k != "seconds"} for row in first.history]
    assert strip == [{k: v for k, v in row.items() if k != "seconds"} for row in second.history]
    assert all(np.isfinite(row[name]) for row in first.history for name in RECONSTRUCTION_FIELDS)
    other = train_liam("foraging", TEAMS, LiamConfig(**{**TINY.__dict__, "seed": 4}))
    assert not torch.equal(other.model.state_dict()["decoder.2.weight"], one["decoder.2.weight"])


def test_the_reconstruction_loss_decreases_on_a_fixed_batch():
    env = GridVectorEnv("foraging", 8, teammate_info=True, **TEAMS)
    observations, outputs = _rollout(env, 12, seed=2)
    obs = torch.as_tensor(np.stack(observations[:-1]))  # (T, B, C, V, V): what each step acted on
    windows = torch.as_tensor(np.stack([out[4]["teammate_observations"] for out in outputs]))
    actions = torch.as_tensor(np.stack([out[4]["teammate_actions"] for out in outputs]))
    valid = torch.as_tensor(np.stack([out[4]["_teammate_actions"] for out in outputs]))
    steps, batch = valid.shape
    previous = torch.full((steps, batch), 5, dtype=torch.long)
    starts = torch.zeros((steps, batch), dtype=torch.bool)
    starts[0] = True
    torch.manual_seed(0)
    model = LiamNetwork(NetworkConfig(channels=obs.shape[2], view=obs.shape[3]), 32, 3, 64)
    optimiser = torch.optim.Adam(model.parameters(), lr=3e-3)

    def loss():
        model.unroll(obs, previous, model.initial_state(batch), starts)
        return reconstruction_loss(model, model.embeddings[valid], windows[valid], actions[valid])[0]

    with torch.no_grad():
        before = loss().item()
    for _ in range(25):
        optimiser.zero_grad()
        value = loss()
        value.backward()
        optimiser.step()
    with torch.no_grad():
        after = loss().item()
    assert after < 0.8 * before, (before, after)


@pytest.mark.parametrize(
    ("domain", "env_id"),
    [("foraging", "EmbodiedAdhoc/ForagingGrid-v0"), ("pursuit", "EmbodiedAdhoc/PursuitGrid-v0")],
)
def test_the_shipped_agent_loads_without_its_decoder_and_acts_from_observations_alone(domain, env_id):
    path = shipped_weights(domain)
    tensors, metadata = load_weights(path)  # safetensors: tensors and a JSON header, no pickle
    assert metadata["kind"] == "liam" and metadata["env_kwargs"]["teams"] == ["tau0", "tau1", "tau2"]
    assert path.stat().st_size < 2_000_000
    assert not any(k.startswith("decoder.") for k in tensors)  # the reconstruction is training-only
    network = RecurrentActorCritic(NetworkConfig(**metadata["network"]), int(metadata["recurrent"]))
    load_into(network, path)  # exactly the execution network's parameters
    env = gymnasium.make(env_id)
    agent = liam_agent(domain, None, env.unwrapped.core.rules.config)
    env.close()
    assert agent.name == "liam" and protocol_gaps(agent) == []
    assert agent.observes_raw and not agent.observes_state and agent.task_posterior is None

    def episode(seed: int) -> list[int]:
        env = gymnasium.make(env_id)
        observation, _ = env.reset(seed=seed)
        agent.reset(np.random.default_rng(seed))
        agent.start(observation)
        actions = []
        for _ in range(10):
            actions.append(agent.act())
            observation, _, terminated, truncated, _ = env.step(actions[-1])
            if terminated or truncated:
                break
            agent.observe(actions[-1], observation)  # obs only: info never reaches the agent
        env.close()
        return actions

    first = episode(4)
    assert first and all(0 <= a <= 4 for a in first) and episode(4) == first


def test_trials_run_the_shipped_liam_agent():
    from embodied_adhoc.experiments.runner import SweepConfig, run_sweep

    options = {
        "domain": "foraging",
        "teams": ["tau0", "tau1", "tau2"],
        "task": None,
        "rows": 5,
        "cols": 5,
        "agents": 4,
        "toroidal": False,
        "pairs": False,
    }
    config = SweepConfig("foraging", "abstract", options, agents=("liam",), episodes=2, seed=1, max_steps=30)
    steps = [r.steps for r in run_sweep(config).records]
    assert len(steps) == 2 and all(1 <= s <= 30 for s in steps)


def test_the_train_command_refuses_a_negative_weight_before_work(tmp_path):
    import subprocess
    import sys

    out = tmp_path / "run"
    result = subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", "train", "liam", "--domain", "foraging"]
        + ["--reconstruction", "-1", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2 and "--reconstruction -1.0: give a weight >= 0" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and not out.exists()
    with pytest.raises(ConfigError, match="reconstruction_coef"):
        LiamConfig(reconstruction_coef=-0.5)
