"""The training loop's collection path: the shipped agent's actions through ``rollout_step`` on the vector env
are those of the network's step and the checked distribution, and the speed script refuses a bad baseline."""

import subprocess
import sys
from pathlib import Path

import torch

from embodied_adhoc.learning.generalist import TRAIN_TEAMS, load_generalist, shipped_weights
from embodied_adhoc.learning.recurrent_ppo import rollout_step
from embodied_adhoc.learning.vector_grid import GridVectorEnv

ROOT = Path(__file__).resolve().parents[2]


def _collect(model, act, envs=24, steps=40):
    """Actions of ``act`` over a seeded vector-env rollout, and how many sub-env resets it went through."""
    env = GridVectorEnv("foraging", envs, teams=list(TRAIN_TEAMS))
    observation = env.reset(seed=4)[0]
    torch.manual_seed(9)
    hidden, previous = model.initial_state(envs), torch.full((envs,), model.no_action)
    fresh = torch.ones(envs, dtype=torch.bool)
    actions, resets = [], 0
    for _ in range(steps):
        action, hidden = act(torch.as_tensor(observation), previous, hidden, fresh)
        observation, _, terminated, truncated, _ = env.step(action.numpy())
        actions.append(action)
        previous, fresh = action, torch.as_tensor(terminated | truncated)
        resets += int(fresh.sum())
    env.close()
    return torch.stack(actions), resets


def test_the_shipped_agent_collects_the_same_actions_through_the_rollout_step():
    torch.set_num_threads(1)
    model = load_generalist(shipped_weights("foraging"))[0]

    def fast(observation, previous, hidden, fresh):
        action, _, _, hidden = rollout_step(model, observation, previous, hidden, fresh)
        return action, hidden

    def checked(observation, previous, hidden, fresh):
        with torch.no_grad():
            logits, _, hidden = model.step(observation, previous, hidden, fresh)
            return torch.distributions.Categorical(logits=logits, validate_args=True).sample(), hidden

    actions, resets = _collect(model, fast)
    expected, _ = _collect(model, checked)
    assert resets > 0 and len(set(actions.flatten().tolist())) > 1  # episodes end and restart mid-rollout
    assert torch.equal(actions, expected)


def test_the_speed_script_refuses_a_baseline_that_is_not_a_commit():
    done = subprocess.run(
        [sys.executable, "scripts/library_free_speed.py", "--baseline", "no-such-commit"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2 and "--baseline no-such-commit: not a commit" in done.stderr
