"""The recurrent PPO generalist: seeded training, exact resumption from a checkpoint, the GRU state's episode
boundaries, and the shipped agent (safetensors weights, the Agent protocol, its grid check)."""

import gymnasium
import numpy as np
import pytest
import torch

import embodied_adhoc.envs  # noqa: F401  (registers the ids)
from embodied_adhoc.decision.agents.base import protocol_gaps
from embodied_adhoc.domains.grid_rules import GridConfig
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.generalist import (
    GeneralistAgent,
    GeneralistTraining,
    generalist_agent,
    load_generalist,
    shipped_weights,
    train_generalist_run,
)
from embodied_adhoc.learning.networks import NetworkConfig
from embodied_adhoc.learning.recurrent_ppo import (
    CHECKPOINT,
    RecurrentActorCritic,
    RecurrentPpoConfig,
    rollout_step,
    train_recurrent_ppo,
)
from embodied_adhoc.learning.weights import load_weights

torch.set_num_threads(1)
TINY = RecurrentPpoConfig(
    total_steps=4 * 4 * 16, num_envs=4, rollout_steps=16, minibatches=2, epochs=2, seed=3, device="cpu"
)
TEAMS = {"teams": ("tau0", "tau1", "tau2")}


def _same_weights(a, b) -> bool:
    first, second = a.state_dict(), b.state_dict()
    return first.keys() == second.keys() and all(torch.equal(first[k], second[k]) for k in first)


def _without_time(history):
    return [{k: v for k, v in row.items() if k != "seconds"} for row in history]


def test_tiny_training_is_deterministic_given_the_seed():
    first = train_recurrent_ppo("foraging", TEAMS, TINY)
    second = train_recurrent_ppo("foraging", TEAMS, TINY)
    assert first.updates == first.total_updates == 4 and first.env_steps == 256
    assert _same_weights(first.model, second.model)
    assert _without_time(first.history) == _without_time(second.history)
    other = train_recurrent_ppo("foraging", TEAMS, RecurrentPpoConfig(**{**TINY.__dict__, "seed": 4}))
    assert not _same_weights(first.model, other.model)


def test_a_checkpoint_resumes_to_the_uninterrupted_result(tmp_path):
    config = RecurrentPpoConfig(**{**TINY.__dict__, "checkpoint_every": 1})
    whole = train_recurrent_ppo("foraging", TEAMS, config)
    part = train_recurrent_ppo("foraging", TEAMS, config, folder=tmp_path, stop_after=2)
    assert part.updates == 2 and not part.finished and (tmp_path / CHECKPOINT).exists()
    resumed = train_recurrent_ppo("foraging", TEAMS, config, folder=tmp_path)
    assert resumed.finished and resumed.env_steps == whole.env_steps
    assert _same_weights(whole.model, resumed.model)
    assert _without_time(whole.history) == _without_time(resumed.history)
    with pytest.raises(
        ConfigError, match="learning_rate"
    ):  # another run's checkpoint is refused, not mixed in
        train_recurrent_ppo(
            "foraging",
            TEAMS,
            RecurrentPpoConfig(**{**config.__dict__, "learning_rate": 1e-3}),
            folder=tmp_path,
        )


def test_the_rollout_step_draws_what_the_checked_distribution_draws():
    model = RecurrentActorCritic(NetworkConfig(channels=4), 8)
    observations = torch.rand(64, 4, 5, 5)
    previous, hidden = torch.randint(0, 6, (64,)), torch.rand(64, 8)
    starts = torch.rand(64) < 0.3
    torch.manual_seed(11)
    action, logprob, value, state = rollout_step(model, observations, previous, hidden, starts)
    torch.manual_seed(11)
    with torch.no_grad():
        logits, expected_value, expected_state = model.step(observations, previous, hidden, starts)
        checked = torch.distributions.Categorical(logits=logits, validate_args=True)
        expected = checked.sample()
    assert len(set(expected.tolist())) > 1  # the draws are not all one action
    assert torch.equal(action, expected) and torch.equal(logprob, checked.log_prob(expected))
    assert torch.equal(value, expected_value) and torch.equal(state, expected_state)


def test_the_gru_state_starts_afresh_at_every_episode_start():
    torch.manual_seed(0)
    model = RecurrentActorCritic(NetworkConfig(channels=6), recurrent=8)
    steps, batch = 6, 3
    observations = torch.rand(steps, batch, 6, 5, 5)
    previous = torch.randint(0, 5, (steps, batch))
    starts = torch.zeros(steps, batch, dtype=torch.bool)
    starts[0], starts[3, 1] = True, True
    with torch.no_grad():
        logits, values = model.unroll(observations, previous, torch.rand(batch, 8), starts)
        # sequence 1 from its episode start at step 3 is what a fresh sequence starting there computes
        fresh_logits, fresh_values = model.unroll(
            observations[3:, 1:2], previous[3:, 1:2], torch.zeros(1, 8), starts[3:, 1:2]
        )
        hidden = model.initial_state(batch)
        for t in range(steps):  # step by step (the rollout's and the agent's path) = the unrolled pass
            step_logits, step_values, hidden = model.step(observations[t], previous[t], hidden, starts[t])
            assert torch.allclose(step_logits, logits[t], atol=1e-5)
            assert torch.allclose(step_values, values[t], atol=1e-5)
    assert torch.allclose(fresh_logits[:, 0], logits[3:, 1], atol=1e-5)
    assert torch.allclose(fresh_values[:, 0], values[3:, 1], atol=1e-5)


def _episode(agent, seed: int, steps: int = 12, env_id: str = "EmbodiedAdhoc/ForagingGrid-v0") -> list[int]:
    env = gymnasium.make(env_id)
    observation, _ = env.reset(seed=seed)
    agent.reset(np.random.default_rng(seed))
    agent.start(observation)
    actions = []
    for _ in range(steps):
        action = agent.act()
        actions.append(action)
        observation, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
        agent.observe(action, observation)
    env.close()
    return actions


def test_the_shipped_agent_loads_from_safetensors_and_plays_by_the_protocol():
    path = shipped_weights("foraging")
    _, metadata = load_weights(path)  # safetensors: tensors and a JSON header, no pickle
    assert metadata["kind"] == "ppo-generalist" and metadata["env_kwargs"]["teams"] == [
        "tau0",
        "tau1",
        "tau2",
    ]
    assert path.stat().st_size < 2_000_000
    agent = generalist_agent("foraging", None, GridConfig())
    assert protocol_gaps(agent) == [] and agent.observes_raw and not agent.observes_state
    assert agent.task_posterior is None
    first = _episode(agent, seed=7)
    assert first and all(0 <= a <= 4 for a in first)
    assert _episode(agent, seed=7) == first  # reset and start clear the GRU state: the same episode again
    distribution = agent.action_distribution()
    assert distribution.shape == (5,) and distribution.sum() == pytest.approx(1.0)
    from types import SimpleNamespace

    from embodied_adhoc.learning.generalist import plugin

    arena = SimpleNamespace(rules=SimpleNamespace(config=GridConfig()))  # what a plug-in factory receives
    assert _episode(plugin(arena, rng_seed=3), seed=7) == first


def test_the_shipped_pursuit_agent_plays_the_pursuit_grid():
    agent = generalist_agent("pursuit", None, GridConfig(domain="pursuit"))
    first = _episode(agent, seed=5, env_id="EmbodiedAdhoc/PursuitGrid-v0")
    assert first and all(0 <= a <= 4 for a in first)
    assert _episode(agent, seed=5, env_id="EmbodiedAdhoc/PursuitGrid-v0") == first
    with pytest.raises(ConfigError, match="a pursuit agent"):
        generalist_agent("foraging", shipped_weights("pursuit"), GridConfig())


def test_the_agent_refuses_another_grid_and_observation_indices():
    with pytest.raises(ConfigError, match="n_agents 3 \\(trained 4\\)"):
        generalist_agent("foraging", None, GridConfig(n_agents=3))
    with pytest.raises(ConfigError, match="a foraging agent"):
        generalist_agent("pursuit", shipped_weights("foraging"), GridConfig(domain="pursuit"))
    model, _ = load_generalist(shipped_weights("foraging"))
    agent = GeneralistAgent(model)
    agent.reset(np.random.default_rng(0))
    with pytest.raises(ConfigError, match="before acting"):
        agent.act()
    with pytest.raises(ConfigError, match="egocentric"):
        agent.start(17)


def test_the_training_run_writes_weights_and_curve_and_removes_its_checkpoint(tmp_path):
    settings = GeneralistTraining("foraging", str(tmp_path), steps=128, envs=4, rollout=16, seed=1)
    partial = train_generalist_run(settings, stop_after=1)
    assert not partial["finished"] and (tmp_path / CHECKPOINT).exists()
    report = train_generalist_run(settings)
    assert report["finished"] and report["env_steps"] == 128 and not (tmp_path / CHECKPOINT).exists()
    lines = (tmp_path / "curve.csv").read_text().splitlines()
    assert lines[0].startswith("update,env_steps") and len(lines) == 1 + 2
    model, metadata = load_generalist(tmp_path / "foraging-ppo-generalist.safetensors")
    assert metadata["env_steps"] == 128 and model.recurrent == settings.config().recurrent
    assert train_generalist_run(settings) == report  # finished: read back, not retrained


def test_settings_that_do_not_fit_are_refused():
    with pytest.raises(ConfigError, match="must divide num_envs"):
        RecurrentPpoConfig(num_envs=6, minibatches=4, rollout_steps=8)
    with pytest.raises(ConfigError, match="--domain"):
        GeneralistTraining("lab", "out")


def test_the_train_command_refuses_bad_input_before_work(tmp_path):
    import subprocess
    import sys

    for flags, message in (
        (("--steps", "0"), "--steps 0: give a positive integer"),
        (("--device", "cuda"), "cuda"),
    ):
        if flags[0] == "--device" and torch.cuda.is_available():
            continue  # the refusal is for hosts without CUDA
        out = tmp_path / flags[0].strip("-")
        result = subprocess.run(
            [sys.executable, "-m", "embodied_adhoc.cli", "train", "ppo-generalist", "--domain", "foraging"]
            + [*flags, "--out", str(out)],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert result.returncode == 2 and message in result.stderr, result.stderr
        assert len(result.stderr.strip().splitlines()) == 1 and not out.exists()


def test_trials_run_the_shipped_generalist_seeded():
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
    config = SweepConfig(
        "foraging", "abstract", options, agents=("ppo-generalist",), episodes=3, seed=2, max_steps=40
    )
    first, again = run_sweep(config), run_sweep(config)
    steps = [r.steps for r in first.records]
    assert len(steps) == 3 and all(1 <= s <= 40 for s in steps)
    assert steps == [r.steps for r in again.records]  # the episode's rng drives its samples
    assert first.curves_by_agent().get("ppo-generalist") is None  # it keeps no task posterior
