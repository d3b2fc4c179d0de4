"""Rollouts that run the policy of one half of the sub-envs while the vector env steps the other half.

A rollout step is the policy's forward pass and draw (torch kernels, which release the GIL) followed by the vector
env's step (numpy kernels with Python between them, which holds it). One after the other, a two-core machine
runs one of them at a time. :class:`HalvedGridEnv` holds the sub-envs as two
:class:`~embodied_adhoc.learning.vector_grid.GridVectorEnv` halves, and :func:`rollout_steps` runs half A's
policy on a second thread while the main thread steps half B's env, then the reverse, so the two kinds of work
overlap.

Same results: sub-env ``i`` of a :class:`HalvedGridEnv` is seeded as sub-env ``i`` of the single env, and every
sub-env keeps its own Generator, so its episodes are the single env's for the same actions. The policy is called
for half A and then half B at every step, in that order, on one thread at a time, so the torch generator's draws
follow the same order as one call over all rows. Where the network's kernels give each row the same result
whatever the batch's size, the actions, and with them the whole run, are the single env's bit for bit
(``tests/learning/test_rollout_pipeline.py`` checks the rollout with a stand-in policy; the training test checks
the shipped network's kernels on the host it runs on).

A step's carried state (the observation the policy acts on, the previous action, the GRU state, "first
observation of an episode" and "the next step only resets the sub-env") lives in full-size tensors that both
threads update in place through their half's rows: the worker thread writes its half's GRU state, the main thread
the rest after the env's step, never the same rows at once.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import torch

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.vector_grid import GridVectorEnv, sub_env_seeds


class HalvedGridEnv:
    """``num_envs`` grid sub-envs as two :class:`GridVectorEnv` halves (rows ``rows[0]`` and ``rows[1]``), with
    the single vector env's ``reset`` and ``step`` over all of them (outputs concatenated) and ``step_half`` for
    one half."""

    def __init__(self, domain: str, num_envs: int, **env_kwargs) -> None:
        if not isinstance(num_envs, int) or num_envs < 2:
            raise ConfigError(f"num_envs={num_envs!r}: a rollout pipeline needs at least 2 sub-envs")
        first = num_envs // 2
        self.num_envs = num_envs
        self.rows = (slice(0, first), slice(first, num_envs))
        self.halves = (
            GridVectorEnv(domain, first, **env_kwargs),
            GridVectorEnv(domain, num_envs - first, **env_kwargs),
        )
        self.single_observation_space = self.halves[0].single_observation_space
        self.single_action_space = self.halves[0].single_action_space
        self.team_names = self.halves[0].team_names

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        """As :meth:`GridVectorEnv.reset` over all sub-envs (an int seed gives sub-env ``i`` ``seed + i``)."""
        seeds = sub_env_seeds(seed, self.num_envs)
        outputs = [
            half.reset(seed=seeds[rows], options=options)
            for half, rows in zip(self.halves, self.rows, strict=True)
        ]
        return np.concatenate([o[0] for o in outputs]), merge_infos([o[1] for o in outputs])

    def step_half(self, half: int, actions):
        """:meth:`GridVectorEnv.step` of half ``half`` (``actions`` for its rows)."""
        return self.halves[half].step(actions)

    def step(self, actions):
        actions = np.asarray(actions)
        if actions.shape != (self.num_envs,):
            raise ConfigError(f"actions: need {self.num_envs} integers in 0..4, got shape {actions.shape}")
        outputs = [self.step_half(h, actions[rows]) for h, rows in enumerate(self.rows)]
        return merge_outputs(outputs)

    def close(self) -> None:
        for half in self.halves:
            half.close()


def merge_infos(infos: list[dict]) -> dict:
    """The halves' ``infos`` as one env's: every entry has the sub-envs first, so entries are concatenated."""
    return {key: np.concatenate([info[key] for info in infos]) for key in infos[0]}


def merge_outputs(outputs: list[tuple]) -> tuple:
    """The halves' ``step`` results as one env's."""
    arrays = [np.concatenate([o[i] for o in outputs]) for i in range(4)]
    return (*arrays, merge_infos([o[4] for o in outputs]))


Act = Callable[[int, slice, dict], torch.Tensor]


def rollout_steps(env, act: Act, carried: dict[str, torch.Tensor], steps: int) -> Iterator[tuple]:
    """Run ``steps`` rollout steps; yield ``(t, observation, reward, terminated, truncated, infos)`` of all
    sub-envs once every sub-env has made step ``t``.

    ``act(t, rows, state)`` chooses step ``t``'s actions of the sub-envs ``rows`` from ``state``, the views of
    ``carried``'s tensors on those rows (``observation``, ``previous``, ``hidden``, ``fresh``, ``resetting``),
    records what it needs, writes the new GRU state into ``state["hidden"]`` and returns the actions. After each
    env step the rows' carried state advances (the action becomes ``previous``, ``fresh`` takes ``resetting``,
    ``resetting`` takes the step's end, the new observation replaces the old), NEXT_STEP autoreset's rule: the step
    after an episode's end only resets the sub-env, and the one after that sees its first observation.

    With a :class:`HalvedGridEnv` one half's ``act`` runs on a second thread while the other half's env steps
    (see the module docstring); with any other vector env, ``act`` and ``step`` alternate over all rows."""
    halved = isinstance(env, HalvedGridEnv)
    rows = env.rows if halved else (slice(None),)
    device = carried["observation"].device

    def views(half: int) -> dict:
        return {key: value[rows[half]] for key, value in carried.items()}

    def advance(half: int, action: torch.Tensor, observation, terminated, truncated) -> None:
        state = views(half)
        state["previous"][...] = action
        state["fresh"][...] = state["resetting"]
        state["resetting"][...] = torch.as_tensor(terminated | truncated, device=device)
        state["observation"][...] = torch.as_tensor(observation, device=device)

    if not halved:
        for t in range(steps):
            action = act(t, rows[0], views(0))
            output = env.step(action.cpu().numpy())
            advance(0, action, output[0], output[2], output[3])
            yield (t, *output)
        return
    with ThreadPoolExecutor(1, thread_name_prefix="rollout-policy") as worker:
        pending = worker.submit(act, 0, rows[0], views(0))
        for t in range(steps):
            outputs = []
            for half in (0, 1):
                action = pending.result()
                # the other half's step t, or half A's step t + 1: its inputs are final by now
                if half == 0:
                    pending = worker.submit(act, t, rows[1], views(1))
                elif t + 1 < steps:
                    pending = worker.submit(act, t + 1, rows[0], views(0))
                output = env.step_half(half, action.cpu().numpy())
                advance(half, action, output[0], output[2], output[3])
                outputs.append(output)
            yield (t, *merge_outputs(outputs))
