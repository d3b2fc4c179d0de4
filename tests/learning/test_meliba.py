"""MeLIBA: seeded training, the ELBO's KL term, the belief of the shipped agent against a fixed team, the policy
cut off from the encoder's gradient, and the shipped agent (safetensors, no decoder, acting from obs alone)."""

import gymnasium
import numpy as np
import pytest
import torch

import embodied_adhoc.envs  # noqa: F401  (registers the ids)
from embodied_adhoc.decision.agents.base import protocol_gaps
from embodied_adhoc.domains.grid_rules import GridConfig
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.meliba import (
    ELBO_FIELDS,
    MelibaConfig,
    MelibaNetwork,
    gaussian_kl,
    load_meliba,
    meliba_agent,
    shipped_weights,
    train_meliba,
)
from embodied_adhoc.learning.networks import NetworkConfig
from embodied_adhoc.learning.vector_grid import GridVectorEnv
from embodied_adhoc.learning.weights import load_weights

torch.set_num_threads(1)
TEAMS = {"teams": ("tau0", "tau1", "tau2")}
TINY = MelibaConfig(
    total_steps=2 * 4 * 16, num_envs=4, rollout_steps=16, minibatches=2, epochs=2, seed=5, device="cpu"
)


def test_tiny_training_is_deterministic_given_the_seed():
    first, second = (train_meliba("foraging", TEAMS, TINY) for _ in range(2))
    assert first.updates == 2 and isinstance(first.model, MelibaNetwork)
    one, two = first.model.state_dict(), second.model.state_dict()
    assert one.keys() == two.keys() and all(torch.equal(one[k], two[k]) for k in one)
    assert any(k.startswith("decoder.") for k in one)
    strip = [{k: v for k, v in row.items() if k != "seconds"} for row in first.history]
    assert strip == [{k: v for k, v in row.items() if k != "seconds"} for row in second.history]
    assert all(np.isfinite(row[name]) for row in first.history for name in ELBO_FIELDS)
    assert all(row["kl"] >= 0.0 and row["posterior_variance"] > 0.0 for row in first.history)
    other = train_meliba("foraging", TEAMS, MelibaConfig(**{**TINY.__dict__, "seed": 6}), stop_after=1)
    assert not torch.equal(other.model.state_dict()["belief.weight"], one["belief.weight"])


def test_an_interrupted_run_resumes_to_the_uninterrupted_weights(tmp_path):
    whole = train_meliba("foraging", TEAMS, TINY)
    assert train_meliba("foraging", TEAMS, TINY, tmp_path, stop_after=1).updates == 1
    resumed = train_meliba("foraging", TEAMS, TINY, tmp_path)
    assert resumed.updates == 2
    one, two = whole.model.state_dict(), resumed.model.state_dict()
    assert all(torch.equal(one[k], two[k]) for k in one)


def test_the_kl_term_is_nonnegative_and_zero_only_between_equal_gaussians():
    generator = torch.Generator().manual_seed(0)
    mu_q, mu_p, logvar_q, logvar_p = (3 * torch.randn(512, 8, generator=generator) for _ in range(4))
    kl = gaussian_kl(mu_q, logvar_q, mu_p, logvar_p)
    assert kl.shape == (512,) and bool((kl > 0).all())
    assert torch.allclose(gaussian_kl(mu_q, logvar_q, mu_q, logvar_q), torch.zeros(512), atol=1e-5)
    # against N(0, I): the closed form 0.5 * sum(var + mu^2 - 1 - log var)
    zeros = torch.zeros_like(mu_q)
    closed = 0.5 * (logvar_q.exp() + mu_q**2 - 1 - logvar_q).sum(-1)
    assert torch.allclose(gaussian_kl(mu_q, logvar_q, zeros, zeros), closed, rtol=1e-5)


def test_the_policy_gradient_never_reaches_the_belief_encoder():
    network = MelibaNetwork(NetworkConfig(channels=5), 16, 4, teammates=3)
    starts = torch.zeros(6, 2, dtype=torch.bool)
    starts[0] = True
    generator = torch.Generator().manual_seed(1)
    observations = torch.rand(6, 2, 5, 5, 5, generator=generator)
    previous = torch.zeros(6, 2, dtype=torch.long)
    logits, values = network.unroll(observations, previous, network.initial_state(2), starts)
    (logits.sum() + values.sum()).backward()
    for name, parameter in network.named_parameters():
        reached = parameter.grad is not None and bool(parameter.grad.abs().sum() > 0)
        encoder = name.startswith(("encoder.", "gru.", "belief.", "decoder."))
        assert reached != encoder, name  # the policy's own layers learn from PPO, the belief's do not


def test_the_shipped_belief_narrows_over_an_episode_against_a_fixed_team():
    model, _ = load_meliba(shipped_weights("foraging"))
    env = GridVectorEnv("foraging", 32, teams=("tau0",))
    observation, _ = env.reset(seed=11)
    torch.manual_seed(0)
    hidden = model.initial_state(32)
    previous = torch.full((32,), model.no_action, dtype=torch.long)
    starts, alive, variances = torch.ones(32, dtype=torch.bool), torch.ones(32, dtype=torch.bool), []
    with torch.no_grad():
        for _ in range(12):
            logits, _, hidden = model.step(torch.as_tensor(observation), previous, hidden, starts)
            variances.append(model.posterior(hidden)[1].exp().mean(-1))
            previous = torch.distributions.Categorical(logits=logits).sample()
            observation, _, terminated, truncated, _ = env.step(previous.numpy())
            alive &= ~torch.as_tensor(terminated | truncated)
            starts = torch.zeros(32, dtype=torch.bool)
    env.close()
    assert int(alive.sum()) >= 16  # most episodes are still in their first 12 steps
    first, last = variances[0][alive].mean(), variances[-1][alive].mean()
    assert last < 0.8 * first, (first, last)


def test_the_shipped_agent_loads_without_its_decoder_and_acts_from_observations_alone():
    from safetensors.torch import load_file

    path = shipped_weights("foraging")
    assert path.stat().st_size < 2_000_000
    tensors, metadata = load_weights(path)  # safetensors: tensors and a JSON header, no pickle
    assert tensors.keys() == load_file(path).keys()
    assert metadata["kind"] == "meliba" and metadata["env_kwargs"]["teams"] == ["tau0", "tau1", "tau2"]
    assert not any(k.startswith("decoder.") for k in tensors)  # the decoder is training-only
    agent = meliba_agent("foraging", None, GridConfig())
    assert agent.name == "meliba" and protocol_gaps(agent) == []
    assert agent.observes_raw and not agent.observes_state

    def episode(seed: int) -> list[int]:
        env = gymnasium.make("EmbodiedAdhoc/ForagingGrid-v0")
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

    first = episode(2)
    assert first and all(0 <= a <= 4 for a in first) and episode(2) == first
    with pytest.raises(ConfigError, match="pursuit"):
        meliba_agent("pursuit", path, GridConfig())


def test_trials_run_the_shipped_meliba_agent():
    from embodied_adhoc.experiments.runner import SweepConfig, run_sweep

    options = {"domain": "foraging", "teams": ["tau0", "tau1", "tau2"], "task": None, "rows": 5, "cols": 5}
    options.update({"agents": 4, "toroidal": False, "pairs": False})
    config = SweepConfig(
        "foraging", "abstract", options, agents=("meliba",), episodes=2, seed=1, max_steps=30
    )
    steps = [r.steps for r in run_sweep(config).records]
    assert len(steps) == 2 and all(1 <= s <= 30 for s in steps)


def test_bad_settings_are_refused_before_work(tmp_path):
    import subprocess
    import sys

    out = tmp_path / "run"
    result = subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", "train", "meliba", "--domain", "foraging"]
        + ["--kl", "-1", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2 and "--kl -1.0: give a weight >= 0" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and not out.exists()
    with pytest.raises(ConfigError, match="horizon"):
        MelibaConfig(rollout_steps=4, horizon=8)
