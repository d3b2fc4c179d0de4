"""The rollout pipeline: two halves of the sub-envs, one half's policy on a second thread while the other half's
env steps, with the single env's episodes and the same training run."""

import hashlib
import subprocess
import sys

import numpy as np
import pytest
import torch

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.recurrent_ppo import (
    RecurrentPpoConfig,
    _env_state,
    _restore_env,
    train_recurrent_ppo,
)
from embodied_adhoc.learning.rollout_pipeline import HalvedGridEnv, rollout_steps
from embodied_adhoc.learning.vector_grid import GridVectorEnv


def _same_outputs(single, halved) -> None:
    for one, other in zip(single[:4], halved[:4], strict=True):
        np.testing.assert_array_equal(one, other)
    assert single[4].keys() == halved[4].keys()
    for key in single[4]:
        np.testing.assert_array_equal(single[4][key], halved[4][key])


@pytest.mark.parametrize("domain", ["foraging", "pursuit"])
def test_the_halves_step_as_the_single_env(domain):
    kwargs = {"teammate_info": True}
    single, halved = GridVectorEnv(domain, 7, **kwargs), HalvedGridEnv(domain, 7, **kwargs)
    first, again = single.reset(seed=11), halved.reset(seed=11)
    np.testing.assert_array_equal(first[0], again[0])
    actions = np.random.default_rng(0).integers(0, 5, (120, 7))
    for row in actions:
        _same_outputs(single.step(row), halved.step(row))
    # the checkpointed state of the halves is the single env's, and restores into either
    state, halves_state = _env_state(single), _env_state(halved)
    assert state[1] == halves_state[1]
    for key, value in state[0].items():
        assert torch.equal(value, halves_state[0][key]), key
    other = HalvedGridEnv(domain, 7, **kwargs)
    other.reset(seed=99)
    _restore_env(other, *state)
    for row in actions[:40]:
        _same_outputs(single.step(row), other.step(row))


def _stand_in_policy(buffers: dict):
    """A policy that depends on each row's observation, previous action and state only (no torch kernels),
    recording what it saw as the training loop does."""

    def act(t: int, rows: slice, state: dict) -> torch.Tensor:
        observation = state["observation"].reshape(state["observation"].shape[0], -1)
        score = (observation * torch.arange(1, observation.shape[1] + 1)).sum(1).long()
        action = (score + 3 * state["previous"] + state["fresh"].long() + state["hidden"][:, 0].long()) % 5
        state["hidden"][...] = state["hidden"] + action[:, None]
        buffers["observations"][t, rows] = state["observation"]
        buffers["valid"][t, rows] = ~state["resetting"]
        buffers["actions"][t, rows] = action
        return action

    return act


def _run(env, steps: int) -> tuple[dict, dict, list]:
    observation, _ = env.reset(seed=3)
    n = observation.shape[0]
    carried = {
        "observation": torch.tensor(observation),
        "previous": torch.full((n,), 5, dtype=torch.long),
        "hidden": torch.zeros(n, 2),
        "fresh": torch.ones(n, dtype=torch.bool),
        "resetting": torch.zeros(n, dtype=torch.bool),
    }
    buffers = {
        "observations": torch.zeros((steps, *carried["observation"].shape)),
        "valid": torch.zeros((steps, n), dtype=torch.bool),
        "actions": torch.zeros((steps, n), dtype=torch.long),
    }
    yielded = [
        (t, reward.copy(), terminated.copy(), truncated.copy())
        for t, _, reward, terminated, truncated, _ in rollout_steps(
            env, _stand_in_policy(buffers), carried, steps
        )
    ]
    return carried, buffers, yielded


def test_the_pipelined_rollout_is_the_sequential_one():
    steps = 90
    single, halved = _run(GridVectorEnv("foraging", 9), steps), _run(HalvedGridEnv("foraging", 9), steps)
    for one, other in zip(single[:2], halved[:2], strict=True):
        for key in one:
            assert torch.equal(one[key], other[key]), key
    assert [t for t, *_ in halved[2]] == list(range(steps))
    for one, other in zip(single[2], halved[2], strict=True):
        for a, b in zip(one[1:], other[1:], strict=True):
            np.testing.assert_array_equal(a, b)
    assert single[1]["valid"].logical_not().any()  # episodes ended and reset within the rollout


def _weights_digest(model) -> str:
    digest = hashlib.sha256()
    for _, value in sorted(model.state_dict().items()):
        digest.update(value.numpy().tobytes())
    return digest.hexdigest()


@pytest.mark.slow  # four tiny training runs: ~15 s
def test_pipelined_training_gives_the_sequential_weights_and_resumes_across_modes(tmp_path):
    torch.set_num_threads(1)

    def config(pipeline: bool) -> RecurrentPpoConfig:
        return RecurrentPpoConfig(
            total_steps=16 * 16 * 3, num_envs=16, rollout_steps=16, seed=4, device="cpu", pipeline=pipeline
        )

    sequential = train_recurrent_ppo("foraging", {}, config(False))
    pipelined = train_recurrent_ppo("foraging", {}, config(True))
    # the network's kernels give every row the same result in a batch of 8 as in one of 16 on this host
    assert _weights_digest(pipelined.model) == _weights_digest(sequential.model)
    assert pipelined.history == [
        {**row, "seconds": pipelined.history[i]["seconds"]} for i, row in enumerate(sequential.history)
    ]
    train_recurrent_ppo("foraging", {}, config(True), folder=tmp_path, stop_after=1)
    resumed = train_recurrent_ppo("foraging", {}, config(False), folder=tmp_path)
    assert _weights_digest(resumed.model) == _weights_digest(sequential.model)


def test_the_pipeline_is_refused_where_it_cannot_run(tmp_path):
    with pytest.raises(ConfigError, match="at least 2 sub-envs"):
        HalvedGridEnv("foraging", 1)
    out = tmp_path / "run"
    result = subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", "train", "ppo-generalist", "--domain", "toxic-waste"]
        + ["--pipeline", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2 and "--pipeline" in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and not out.exists()
