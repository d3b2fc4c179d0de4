"""Recurrent PPO: a GRU actor-critic trained with PPO over rollout segments (truncated backpropagation through
time), the library-free ``ppo-generalist`` ego agent's learner (:mod:`embodied_adhoc.learning.generalist`).

The network is the ATLPO encoder (:class:`~embodied_adhoc.learning.networks.Encoder`, a small CNN over the
egocentric window) followed by a GRU cell whose input is the encoding and the ego's previous action (one-hot,
"none" at an episode's first step), and linear actor and critic heads on the GRU state. The GRU state is the
agent's memory of the episode: what it has seen of its teammates' moves, from which it can infer who they are and
which task they pursue, without a library of either.

Training follows :mod:`embodied_adhoc.learning.ppo` (CleanRL style) on the same
:class:`~embodied_adhoc.learning.vector_grid.GridVectorEnv`: NEXT_STEP autoreset, reset steps masked out of the
loss, GAE that never crosses an episode end (:func:`~embodied_adhoc.learning.ppo.advantages_and_returns`), the
clipped objective (:func:`~embodied_adhoc.learning.ppo.clipped_objective`). Recurrence adds: the GRU state is
zeroed at every episode's first observation; each update re-runs the GRU over the whole rollout segment from the
state it had when the segment began (minibatches are sets of whole sub-env sequences); the state carries across
segments without gradient. Each episode draws its task and its team from the train population given in
``env_kwargs`` (``teams``, ``tasks``), as the vector env does.

Every random source is seeded (torch for the action samples, a numpy Generator for the minibatch order, the
env's seeds), so one seed gives the same weights. Training is resumable: every ``checkpoint_every`` updates (and
when a call stops) ``checkpoint.safetensors`` holds the network, Adam's moments, the torch RNG, the rollout's
carried state and the vector env's per-sub-env state, with a JSON header of counters, Generator states and the
curve so far; a resumed run continues exactly where the uninterrupted one would be.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import torch
from torch import nn

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.networks import Encoder, NetworkConfig, _layer
from embodied_adhoc.learning.ppo import (
    PpoConfig,
    PpoResult,
    advantages_and_returns,
    clipped_objective,
    pick_device,
    start_training,
)
from embodied_adhoc.learning.rollout_pipeline import rollout_steps
from embodied_adhoc.learning.vector_grid import GridVectorEnv
from embodied_adhoc.learning.weights import WeightsError, load_weights, save_weights

CHECKPOINT = "checkpoint.safetensors"


@dataclass(frozen=True)
class RecurrentPpoConfig(PpoConfig):
    """PPO settings plus the GRU's size; minibatches split the sub-envs (whole sequences), so they divide
    ``num_envs``; ``rollout_steps`` is the truncated-BPTT length."""

    total_steps: int = 300_000
    num_envs: int = 32
    rollout_steps: int = 64
    learning_rate: float = 5e-4
    recurrent: int = 64  # GRU state size
    checkpoint_every: int = 25  # updates between checkpoints
    # grid domains: step the policy of one half of the sub-envs while the env steps the other (a second thread,
    # rollout_pipeline); the same run where the network's kernels treat rows alike, so, like ``device``, not
    # part of a checkpoint's identity
    pipeline: bool = False

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.num_envs % self.minibatches:
            raise ConfigError(
                f"RecurrentPpoConfig.minibatches={self.minibatches}: must divide num_envs={self.num_envs} "
                "(a minibatch is a set of whole sub-env sequences)"
            )
        for name in ("recurrent", "checkpoint_every"):
            if getattr(self, name) < 1:
                raise ConfigError(f"RecurrentPpoConfig.{name}={getattr(self, name)}: give a positive integer")


def make_encoder(network) -> nn.Module:
    """The observation encoder of ``network``: the CNN of a grid's :class:`NetworkConfig`, or the encoder an
    index domain's config makes (:class:`~embodied_adhoc.learning.index_domains.IndexNetworkConfig`)."""
    return network.make_encoder() if hasattr(network, "make_encoder") else Encoder(network)


def observation_shape(network) -> tuple[int, ...]:
    """The shape of one observation the network reads (the grid's window; () for an index)."""
    if hasattr(network, "observation_shape"):
        return network.observation_shape
    return (network.channels, network.view, network.view)


def flat_observations(network, observations: torch.Tensor) -> torch.Tensor:
    """Observations (..., *observation_shape) as (..., features) rows for a decoder: the window flattened, or
    an index one-hot."""
    if hasattr(network, "flat_observations"):
        return network.flat_observations(observations)
    return observations.reshape(*observations.shape[:-3], -1)


def network_config(stored: dict):
    """The network sizes stored beside weights: an index domain's (it has ``observations``) or a grid's."""
    if "observations" in stored:
        from embodied_adhoc.learning.index_domains import IndexNetworkConfig

        return IndexNetworkConfig(**stored)
    return NetworkConfig(**stored)


class RecurrentActorCritic(nn.Module):
    """Encoder ``q``, a GRU cell over (encoding, previous action) and linear actor and critic heads."""

    def __init__(self, network: NetworkConfig, recurrent: int) -> None:
        super().__init__()
        self.config, self.recurrent = network, recurrent
        self.encoder = make_encoder(network)
        self.gru = nn.GRUCell(network.features + network.actions + 1, recurrent)
        self.actor = _layer(nn.Linear(recurrent, network.actions), 0.01)
        self.critic = _layer(nn.Linear(recurrent, 1), 1.0)

    @property
    def no_action(self) -> int:
        """The previous-action index of an episode's first step."""
        return self.config.actions

    def initial_state(self, batch: int, device=None) -> torch.Tensor:
        return torch.zeros(batch, self.recurrent, device=device)

    def _inputs(self, latent, previous, starts):
        """The GRU's inputs (encoding, one-hot previous action, "none" at ``starts``) and the masks (1 where the
        state carries over, 0 at ``starts``) for steps of any leading shape."""
        previous = torch.where(starts, torch.full_like(previous, self.no_action), previous)
        inputs = torch.cat([latent, nn.functional.one_hot(previous, self.no_action + 1).to(latent.dtype)], -1)
        return inputs, (~starts).unsqueeze(-1).to(latent.dtype)

    def _cell(self, latent, previous, hidden, starts):
        inputs, keep = self._inputs(latent, previous, starts)
        return self.gru(inputs, hidden * keep)

    def step(self, observations, previous, hidden, starts):
        """One step of B sequences: (logits (B, A), values (B,), new state (B, H)); ``starts`` (B,) bool marks an
        episode's first observation (the state is zeroed and the previous action is "none" there)."""
        hidden = self._cell(self.encoder(observations), previous, hidden, starts)
        return self.actor(hidden), self.critic(hidden).squeeze(-1), hidden

    def unroll(self, observations, previous, hidden, starts):
        """T steps of B sequences from state ``hidden``: (logits (T, B, A), values (T, B))."""
        states = self.unroll_states(observations, previous, hidden, starts)
        return self.actor(states), self.critic(states).squeeze(-1)

    def unroll_states(self, observations, previous, hidden, starts):
        """T steps of B sequences from state ``hidden``: the GRU states (T, B, H)."""
        steps, batch = starts.shape
        latent = self.encoder(observations.reshape(steps * batch, *observations.shape[2:]))
        # everything but the recurrence is prepared for the whole segment at once (the same values per step)
        inputs, keep = self._inputs(latent.reshape(steps, batch, -1), previous, starts)
        states = []
        for t in range(steps):
            hidden = self.gru(inputs[t], hidden * keep[t])
            states.append(hidden)
        return torch.stack(states)


@dataclass
class RecurrentPpoResult(PpoResult):
    """:class:`~embodied_adhoc.learning.ppo.PpoResult` of a run that may stop before its last update."""

    updates: int = 0  # done so far
    total_updates: int = 0

    @property
    def finished(self) -> bool:
        return self.updates >= self.total_updates


_BATCH_FIELDS = ("agents", "agent_levels", "targets", "target_levels", "alive")
_ENV_ARRAYS = ("task_index", "team_index", "steps", "needs_reset", "uniforms", "used")


def _env_state(env) -> tuple[dict[str, torch.Tensor], dict]:
    """Everything a :class:`GridVectorEnv` carries from one step to the next: its state arrays (tensors) and its
    Generators' states (JSON); a :class:`~embodied_adhoc.learning.rollout_pipeline.HalvedGridEnv`'s halves
    concatenated, which is the single env's state (a checkpoint resumes with or without the pipeline). The
    episode's offsets and team table follow from the task and team indices. An index domain's env (its episodes
    live in registered envs and plug-in humans) is restarted instead."""
    halves = getattr(env, "halves", (env,))
    if not all(isinstance(half, GridVectorEnv) for half in halves):
        return {}, {"restart": True}

    def joined(read) -> torch.Tensor:
        return torch.from_numpy(np.concatenate([read(half) for half in halves]))

    tensors = {f"env.batch.{n}": joined(lambda h, n=n: getattr(h.batch, n)) for n in _BATCH_FIELDS}
    tensors.update({f"env.{n}": joined(lambda h, n=n: getattr(h, n)) for n in _ENV_ARRAYS})
    header = {
        "rngs": [rng.bit_generator.state for half in halves for rng in half.rngs],
        "block_states": [state for half in halves for state in half.block_states],
    }
    return tensors, header


def _restore_env(env, tensors: dict, header: dict) -> None:
    if header.get("restart"):
        return
    halves, rows = getattr(env, "halves", (env,)), getattr(env, "rows", (slice(None),))
    for half, part in zip(halves, rows, strict=True):
        for name in _BATCH_FIELDS:
            getattr(half.batch, name)[...] = tensors[f"env.batch.{name}"].numpy()[part]
        for name in _ENV_ARRAYS:
            getattr(half, name)[...] = tensors[f"env.{name}"].numpy()[part]
        half.rngs = []
        for state in header["rngs"][part]:
            rng = np.random.Generator(np.random.PCG64())
            rng.bit_generator.state = state
            half.rngs.append(rng)
        half.block_states = list(header["block_states"][part])
        half.episode_offsets = half.offsets[half.task_index]
        half.episode_teams = half.team_table.take(half.team_index)


def _save_checkpoint(
    path: Path, model, optimiser, carried: dict, env, rng, result, config, env_kwargs
) -> None:
    tensors = {f"model.{k}": v for k, v in model.state_dict().items()}
    optimiser_state = optimiser.state_dict()
    for index, slots in optimiser_state["state"].items():
        tensors.update({f"optimiser.{index}.{k}": v for k, v in slots.items()})
    tensors.update({f"carried.{k}": v for k, v in carried.items()})
    tensors["torch_rng"] = torch.get_rng_state()
    device = next(model.parameters()).device
    if device.type == "cuda":  # the action samples are drawn on the device
        tensors["cuda_rng"] = torch.cuda.get_rng_state(device)
    env_tensors, env_header = _env_state(env)
    tensors.update(env_tensors)
    header = {
        "kind": "ppo-generalist-checkpoint",
        "config": asdict(config),
        "env_kwargs": env_kwargs,
        "param_groups": _json_ready(optimiser_state["param_groups"]),
        "optimiser_slots": sorted(optimiser_state["state"]),
        "rng": rng.bit_generator.state,
        "env": env_header,
        "history": result.history,
        "seconds": result.seconds,
        "env_steps": result.env_steps,
        "updates": result.updates,
    }
    tensors = {k: v.detach().cpu().contiguous() for k, v in tensors.items()}
    save_weights(path, SimpleNamespace(state_dict=lambda: tensors), header)


def _load_checkpoint(path: Path, config: RecurrentPpoConfig, env_kwargs: dict):
    tensors, header = load_weights(path)
    if header.get("kind") != "ppo-generalist-checkpoint":
        raise WeightsError(f"{path}: not a ppo-generalist checkpoint (kind={header.get('kind')!r})")
    wanted = asdict(config)
    stored = header["config"]
    defaults = asdict(RecurrentPpoConfig())  # a setting added later reads as its default in older checkpoints
    differ = [
        k for k in wanted if k not in ("device", "pipeline") and stored.get(k, defaults.get(k)) != wanted[k]
    ]
    if differ or header["env_kwargs"] != json.loads(json.dumps(env_kwargs)):
        names = ", ".join(f"{k} {stored.get(k)!r} (now {wanted[k]!r})" for k in differ) or "env settings"
        raise ConfigError(
            f"{path}: a checkpoint of another run ({names}); resume with its settings or use another --out"
        )
    return tensors, header


def _json_ready(state: list[dict]) -> list[dict]:
    """Adam's param groups as JSON (tuples become lists, which it accepts back)."""
    return [{k: list(v) if isinstance(v, tuple) else v for k, v in group.items()} for group in state]


def _fresh_carried(model: RecurrentActorCritic, observation, envs: int) -> dict:
    """The rollout's carried state at the start of every sub-env's first episode."""
    return {
        "observation": torch.tensor(observation),  # a copy: the rollout updates it in place
        "hidden": model.initial_state(envs),
        "previous": torch.full((envs,), model.no_action, dtype=torch.long),
        "fresh": torch.ones(envs, dtype=torch.bool),  # the observation is an episode's first
        "resetting": torch.zeros(envs, dtype=torch.bool),  # the next step only resets the sub-env
        "lengths": torch.zeros(envs, dtype=torch.long),
    }


def _start(domain: str, vector_kwargs: dict, config: RecurrentPpoConfig):
    """:func:`~embodied_adhoc.learning.ppo.start_training` for the grid domains; for an index domain the same
    steps in the same order over :class:`~embodied_adhoc.learning.index_domains.IndexVectorEnv`."""
    from embodied_adhoc.learning.index_domains import INDEX_DOMAINS, IndexNetworkConfig, IndexVectorEnv

    if domain not in INDEX_DOMAINS:
        if config.pipeline:
            from embodied_adhoc.learning.rollout_pipeline import HalvedGridEnv

            return start_training(domain, vector_kwargs, config, vector_env=HalvedGridEnv)
        return start_training(domain, vector_kwargs, config)
    if config.pipeline:
        raise ConfigError(f"pipeline: the rollout pipeline steps the grid domains only, not {domain}")
    env = IndexVectorEnv(domain, config.num_envs, **vector_kwargs)  # it draws nothing until its reset
    torch.manual_seed(config.seed)
    rng, device = np.random.default_rng(config.seed), pick_device(config.device)
    observation = env.reset(seed=config.seed)[0]
    sizes = {"features": config.features, "head_hidden": config.head_hidden}
    return rng, device, env, observation, IndexNetworkConfig(env.n_observations, env.n_actions, **sizes)


@torch.inference_mode()
def rollout_step(model: RecurrentActorCritic, observation, previous, hidden, starts):
    """One rollout step of every sub-env: (sampled actions, their log-probabilities, values, new GRU state),
    without autograd. The draw is ``Categorical(logits=logits).sample()``'s own computation (normalised logits,
    their softmax, one multinomial draw per row) without building the distribution each step, so the actions
    are the distribution's for the same torch seed."""
    logits, value, hidden = model.step(observation, previous, hidden, starts)
    logits = logits - logits.logsumexp(-1, keepdim=True)
    action = torch.multinomial(torch.softmax(logits, -1), 1, True)
    return action.squeeze(-1), logits.gather(-1, action).squeeze(-1), value, hidden


def segment_loss(model: RecurrentActorCritic, segment: dict, index: torch.Tensor, config: RecurrentPpoConfig):
    """The clipped PPO objective of the sub-envs ``index`` of a rollout segment: the GRU re-run over their whole
    sequences from the state it had when the segment began, the reset steps left out."""
    logits, values = model.unroll(
        segment["observations"][:, index],
        segment["previous"][:, index],
        segment["hidden"][index],
        segment["starts"][:, index],
    )
    mask = segment["valid"][:, index]
    return clipped_objective(
        logits[mask],
        values[mask],
        *(segment[name][:, index][mask] for name in ("actions", "logprobs", "advantages", "returns")),
        config,
    )


def train_recurrent_ppo(
    domain: str,
    env_kwargs: dict,
    config: RecurrentPpoConfig,
    folder: str | Path | None = None,
    progress: Callable[[int, dict], None] | None = None,
    stop_after: int | None = None,
    auxiliary=None,
) -> RecurrentPpoResult:
    """Train on ``GridVectorEnv(domain, config.num_envs, **env_kwargs)`` for ``config.total_steps`` env steps.

    With ``folder`` the run checkpoints there (:data:`CHECKPOINT`) and, if a checkpoint of the same settings is
    there, resumes from it; ``stop_after`` ends this call after that many updates in all (checkpointed), so a
    later call continues. ``progress(env_steps, row)`` is called after every update.

    ``auxiliary`` adds a training-only loss term (LIAM's reconstruction, :mod:`embodied_adhoc.learning.liam`):
    ``auxiliary.vector_kwargs`` (extra GridVectorEnv arguments, not part of the run's identity),
    ``auxiliary.network(network, recurrent)`` builds the model, ``auxiliary.record(t, infos)`` sees every
    rollout step's infos (with ``records_steps`` also ``auxiliary.record_step(t, action, reward, terminated)``:
    the ego's action and the env's reward and ends) and ``auxiliary.loss(model, index)`` -> (loss, stats), called
    right after the PPO objective of the sub-envs ``index``, is added to it (stats of the last evaluation go in
    the curve's rows)."""
    env_kwargs = dict(env_kwargs)
    vector_kwargs = env_kwargs if auxiliary is None else {**env_kwargs, **auxiliary.vector_kwargs}
    rng, device, env, observation, network = _start(domain, vector_kwargs, config)
    if auxiliary is None:
        model = RecurrentActorCritic(network, config.recurrent).to(device)
    else:
        model = auxiliary.network(network, config.recurrent).to(device)
    optimiser = torch.optim.Adam(model.parameters(), lr=config.learning_rate, eps=1e-5)
    steps, envs = config.rollout_steps, config.num_envs
    result = RecurrentPpoResult(model, total_updates=max(1, config.total_steps // (steps * envs)))
    carried = _fresh_carried(model, observation, envs)
    checkpoint = None if folder is None else Path(folder) / CHECKPOINT
    if checkpoint is not None and checkpoint.exists():
        tensors, header = _load_checkpoint(checkpoint, config, env_kwargs)
        model.load_state_dict({k[6:]: v for k, v in tensors.items() if k.startswith("model.")})
        optimiser.load_state_dict(  # it puts each slot on its parameter's device (Adam's step stays on the CPU)
            {
                "state": {
                    i: {k.split(".", 2)[2]: v for k, v in tensors.items() if k.startswith(f"optimiser.{i}.")}
                    for i in header["optimiser_slots"]
                },
                "param_groups": header["param_groups"],
            }
        )
        carried = {k[8:]: v for k, v in tensors.items() if k.startswith("carried.")}
        torch.set_rng_state(tensors["torch_rng"])
        if "cuda_rng" in tensors and device.type == "cuda":
            torch.cuda.set_rng_state(tensors["cuda_rng"], device)
        rng.bit_generator.state = header["rng"]
        _restore_env(env, tensors, header["env"])
        result.history, result.seconds = header["history"], header["seconds"]
        result.env_steps, result.updates = header["env_steps"], header["updates"]
        if header["env"].get("restart"):  # new episodes, seeded by the run's seed and the updates done
            observation, _ = env.reset(seed=config.seed + 7919 * result.updates)
            carried = _fresh_carried(model, observation, envs)
    carried = {k: v.to(device) for k, v in carried.items()}
    last = result.total_updates if stop_after is None else min(result.total_updates, stop_after)
    obs_buf = torch.zeros(
        (steps, envs, *observation.shape[1:]), dtype=torch.as_tensor(observation).dtype, device=device
    )
    action_buf, previous_buf = (torch.zeros((steps, envs), dtype=torch.long, device=device) for _ in range(2))
    logprob_buf, value_buf, reward_buf = (torch.zeros((steps, envs), device=device) for _ in range(3))
    start_buf, ended_buf, terminal_buf, valid_buf = (
        torch.zeros((steps, envs), dtype=torch.bool, device=device) for _ in range(4)
    )
    while result.updates < last:
        began = time.perf_counter()
        update = result.updates
        if config.anneal_lr:
            optimiser.param_groups[0]["lr"] = config.learning_rate * (1.0 - update / result.total_updates)
        first_hidden = carried["hidden"].clone()
        lengths = carried["lengths"]
        finished, solved = [], []

        def act(t: int, rows: slice, state: dict) -> torch.Tensor:
            obs_buf[t, rows], previous_buf[t, rows] = state["observation"], state["previous"]
            start_buf[t, rows], valid_buf[t, rows] = state["fresh"], ~state["resetting"]
            action, logprob, value, hidden = rollout_step(
                model, state["observation"], state["previous"], state["hidden"], state["fresh"]
            )
            action_buf[t, rows], logprob_buf[t, rows], value_buf[t, rows] = action, logprob, value
            state["hidden"][...] = hidden
            return action

        for t, _, reward, terminated, truncated, infos in rollout_steps(env, act, carried, steps):
            if auxiliary is not None:
                auxiliary.record(t, infos)
                if getattr(auxiliary, "records_steps", False):  # targets built from the ego's own steps
                    auxiliary.record_step(t, action_buf[t], reward, terminated)
            result.env_steps += envs
            ended = torch.as_tensor(terminated | truncated, device=device)
            lengths = lengths + valid_buf[t].long()
            finished.extend(lengths[ended].tolist())
            solved.extend(terminated[(terminated | truncated)].tolist())
            lengths = torch.where(ended, torch.zeros_like(lengths), lengths)
            reward_buf[t] = torch.as_tensor(reward, dtype=torch.float32, device=device)
            ended_buf[t], terminal_buf[t] = ended, torch.as_tensor(terminated, device=device)
        carried["lengths"] = lengths
        next_obs, previous, hidden, fresh = (
            carried[k] for k in ("observation", "previous", "hidden", "fresh")
        )
        with torch.no_grad():
            _, next_value, _ = model.step(next_obs, previous, hidden, fresh)
            advantages, returns = advantages_and_returns(
                reward_buf, value_buf, next_value, ended_buf, terminal_buf, config
            )
            valid_advantages = advantages[valid_buf]
            if valid_advantages.numel() > 1:
                advantages = (advantages - valid_advantages.mean()) / (valid_advantages.std() + 1e-8)

        segment = {
            "observations": obs_buf,
            "previous": previous_buf,
            "hidden": first_hidden,
            "starts": start_buf,
            "valid": valid_buf,
            "actions": action_buf,
            "logprobs": logprob_buf,
            "advantages": advantages,
            "returns": returns,
        }
        every = torch.arange(envs, device=device)
        with torch.no_grad():
            loss_before = segment_loss(model, segment, every, config)[0].item()
        for _ in range(config.epochs):
            order = rng.permutation(envs)
            for chunk in np.array_split(order, config.minibatches):
                index = torch.as_tensor(chunk, device=device)
                loss = segment_loss(model, segment, index, config)[0]
                if auxiliary is not None:
                    loss = loss + auxiliary.loss(model, index)[0]
                optimiser.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(model.parameters(), config.max_grad_norm)
                optimiser.step()
        with torch.no_grad():
            after = segment_loss(model, segment, every, config)
            extra = {} if auxiliary is None else auxiliary.loss(model, every)[1]
        result.updates += 1
        result.seconds += time.perf_counter() - began
        row = {
            "update": result.updates,
            "env_steps": result.env_steps,
            "seconds": round(result.seconds, 3),
            "episodes": len(finished),
            "mean_episode_length": float(np.mean(finished)) if finished else None,
            "solved": float(np.mean(solved)) if solved else None,
            "loss_before": loss_before,
            "loss_after": after[0].item(),
            "policy_loss": after[1].item(),
            "value_loss": after[2].item(),
            "entropy": after[3].item(),
            **extra,
        }
        result.history.append(row)
        if checkpoint is not None and (
            result.updates % config.checkpoint_every == 0 or result.updates == last
        ):
            _save_checkpoint(checkpoint, model, optimiser, carried, env, rng, result, config, env_kwargs)
        if progress is not None:
            progress(result.env_steps, row)
    env.close()
    model.eval()
    return result


def generalist_metadata(domain: str, env_kwargs: dict, config: RecurrentPpoConfig, result) -> dict:
    """What to store beside the trained weights: network sizes, env, settings and the training cost."""
    return {
        "kind": "ppo-generalist",
        "domain": domain,
        "env_kwargs": env_kwargs,
        "network": result.model.config.as_dict(),
        "recurrent": result.model.recurrent,
        "ppo": asdict(config),
        "env_steps": result.env_steps,
        "updates": result.updates,
        "seconds": round(result.seconds, 3),
        "final": result.history[-1] if result.history else None,
    }
