"""PPO (Schulman et al. 2017) for one ATLPO-MF library member (thesis section 6.1.4, Fig. 6.2), CleanRL style:
one readable loop, every random source seeded (``torch.manual_seed`` for the action samples, a numpy
``Generator`` for the minibatch order, the env's seeds).

It trains on :class:`~embodied_adhoc.learning.vector_grid.GridVectorEnv`, whose autoreset is gymnasium's
NEXT_STEP: the step after an episode ends only resets its sub-env (the action is ignored, reward 0). Such *reset
steps* are masked out of the loss and GAE never flows across an episode end; a truncated episode bootstraps from
the value of its last observation (which NEXT_STEP returns on the ending step), a terminated one from 0.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from torch import nn

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.networks import ActorCritic, NetworkConfig
from embodied_adhoc.learning.vector_grid import GridVectorEnv


@dataclass(frozen=True)
class PpoConfig:
    """Training settings of one library member (defaults: small CleanRL-like values for 5x5 grids)."""

    total_steps: int = 30_000  # env steps over all sub-envs (the thesis pre-trained 30,000 per policy)
    num_envs: int = 16
    rollout_steps: int = 32  # steps per sub-env between updates
    learning_rate: float = 2.5e-4
    anneal_lr: bool = True
    gamma: float = 0.95
    gae_lambda: float = 0.95
    minibatches: int = 4
    epochs: int = 4
    clip: float = 0.2
    entropy_coef: float = 0.01
    value_coef: float = 0.5
    max_grad_norm: float = 0.5
    seed: int = 0
    device: str = "auto"  # "auto": cuda when available, else cpu
    hidden_channels: int = 16
    features: int = 64
    head_hidden: int = 0  # 0: linear actor/critic heads; else MLP heads with one hidden layer of this width

    def __post_init__(self) -> None:
        for name in ("total_steps", "num_envs", "rollout_steps", "minibatches", "epochs"):
            if getattr(self, name) < 1:
                raise ConfigError(f"PpoConfig.{name}={getattr(self, name)}: give a positive integer")
        if (self.num_envs * self.rollout_steps) % self.minibatches:
            raise ConfigError(
                f"PpoConfig.minibatches={self.minibatches}: must divide num_envs * rollout_steps "
                f"= {self.num_envs * self.rollout_steps}"
            )
        for name in ("gamma", "gae_lambda"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ConfigError(f"PpoConfig.{name}={getattr(self, name)}: must be in [0, 1]")
        if self.device not in ("auto", "cpu", "cuda"):
            raise ConfigError(f"PpoConfig.device={self.device!r}: use auto, cpu or cuda")


def pick_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise ConfigError("device='cuda': no CUDA device is visible to torch; use auto or cpu")
    return torch.device(name)


def ppo_loss(model: ActorCritic, observations, actions, old_logprobs, advantages, returns, config: PpoConfig):
    """The clipped PPO objective to minimise and its parts (policy, value, entropy)."""
    logits, values = model(observations)
    return clipped_objective(logits, values, actions, old_logprobs, advantages, returns, config)


def clipped_objective(logits, values, actions, old_logprobs, advantages, returns, config: PpoConfig):
    """The clipped PPO objective of given action logits and values (any network's) and its parts."""
    distribution = torch.distributions.Categorical(logits=logits)
    ratio = torch.exp(distribution.log_prob(actions) - old_logprobs)
    policy = torch.max(
        -advantages * ratio, -advantages * torch.clamp(ratio, 1 - config.clip, 1 + config.clip)
    ).mean()
    value = 0.5 * ((values - returns) ** 2).mean()
    entropy = distribution.entropy().mean()
    return policy - config.entropy_coef * entropy + config.value_coef * value, policy, value, entropy


def advantages_and_returns(rewards, values, next_value, ended, terminal, config: PpoConfig):
    """GAE over a (steps, envs) rollout: ``values[t]`` is V of the observation step ``t`` acted on, ``next_value``
    V of the observation the last step returned; it never flows across an episode end (``ended``), and a
    terminated step bootstraps from 0, a truncated one from the value of its last observation."""
    steps = rewards.shape[0]
    advantages = torch.zeros_like(rewards)
    running = torch.zeros_like(next_value)
    for t in reversed(range(steps)):
        following = values[t + 1] if t + 1 < steps else next_value  # V of the obs step t returned
        delta = rewards[t] + config.gamma * following * (~terminal[t]) - values[t]
        running = delta + config.gamma * config.gae_lambda * (~ended[t]) * running
        advantages[t] = running
    return advantages, advantages + values


def start_training(domain: str, env_kwargs: dict, config: PpoConfig, vector_env=GridVectorEnv):
    """What every PPO run begins with, in this order (the seeds' use depends on it): torch seeded, the minibatch
    Generator, the device, the vector env (``vector_env(domain, num_envs, **env_kwargs)``) reset with the seed,
    and the network sizes its observations give."""
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    device = pick_device(config.device)
    env = vector_env(domain, config.num_envs, **env_kwargs)
    observation, _ = env.reset(seed=config.seed)
    network = NetworkConfig(
        channels=observation.shape[1],
        view=observation.shape[2],
        hidden_channels=config.hidden_channels,
        features=config.features,
        head_hidden=config.head_hidden,
    )
    return rng, device, env, observation, network


@dataclass
class PpoResult:
    model: ActorCritic
    history: list[dict] = field(default_factory=list)  # one row per update
    seconds: float = 0.0
    env_steps: int = 0

    @property
    def steps_per_second(self) -> float:
        return self.env_steps / self.seconds if self.seconds > 0 else 0.0


def train_ppo(
    domain: str,
    env_kwargs: dict,
    config: PpoConfig,
    progress: Callable[[int, dict], None] | None = None,
    encoder: nn.Module | None = None,
    after_update: Callable[[ActorCritic, tuple], None] | None = None,
) -> PpoResult:
    """Train an actor-critic on ``GridVectorEnv(domain, config.num_envs, **env_kwargs)`` for
    ``config.total_steps`` env steps. ``progress(steps_done, row)`` is called after every update. With
    ``encoder`` (ATLPO-MB: a world model's trained encoder) the actor and critic learn on its latent states: its
    weights are copied in and frozen, only the actor and critic heads are trained (Fig. 6.3).
    ``after_update(model, transitions)``, if given, is called after every update with the rollout's transitions
    ``(observations, actions, rewards, next_observations)`` as numpy arrays (reset steps left out); ATLPO-MB
    trains its world model on them there and copies the new encoder into ``model``."""
    rng, device, env, observation, network = start_training(domain, env_kwargs, config)
    model = ActorCritic(network)
    if encoder is not None:
        model.encoder.load_state_dict(encoder.state_dict())
        model.encoder.requires_grad_(False)
    model.to(device)
    optimiser = torch.optim.Adam(
        [p for p in model.parameters() if p.requires_grad], lr=config.learning_rate, eps=1e-5
    )
    steps, envs = config.rollout_steps, config.num_envs
    batch = steps * envs
    updates = max(1, config.total_steps // batch)
    obs_buf = torch.zeros((steps, envs, *observation.shape[1:]), device=device)
    action_buf = torch.zeros((steps, envs), dtype=torch.long, device=device)
    logprob_buf, value_buf, reward_buf = (torch.zeros((steps, envs), device=device) for _ in range(3))
    ended_buf, terminal_buf, valid_buf = (
        torch.zeros((steps, envs), dtype=torch.bool, device=device) for _ in range(3)
    )
    next_obs = torch.as_tensor(observation, device=device)
    resetting = torch.zeros(envs, dtype=torch.bool, device=device)  # this step only resets the sub-env
    lengths = np.zeros(envs, dtype=np.int64)
    result = PpoResult(model)
    start = time.perf_counter()
    for update in range(updates):
        if config.anneal_lr:
            optimiser.param_groups[0]["lr"] = config.learning_rate * (1.0 - update / updates)
        finished: list[int] = []
        for t in range(steps):
            obs_buf[t], valid_buf[t] = next_obs, ~resetting
            with torch.no_grad():
                logits, value = model(next_obs)
                distribution = torch.distributions.Categorical(logits=logits)
                action = distribution.sample()
            action_buf[t], logprob_buf[t], value_buf[t] = action, distribution.log_prob(action), value
            observation, reward, terminated, truncated, _ = env.step(action.cpu().numpy())
            result.env_steps += envs
            ended = terminated | truncated
            lengths += ~resetting.cpu().numpy()
            finished.extend(lengths[ended].tolist())
            lengths[ended] = 0
            reward_buf[t] = torch.as_tensor(reward, dtype=torch.float32, device=device)
            ended_buf[t] = torch.as_tensor(ended, device=device)
            terminal_buf[t] = torch.as_tensor(terminated, device=device)
            next_obs = torch.as_tensor(observation, device=device)
            resetting = ended_buf[t].clone()
        with torch.no_grad():
            _, next_value = model(next_obs)
            advantages, returns = advantages_and_returns(
                reward_buf, value_buf, next_value, ended_buf, terminal_buf, config
            )
        valid = valid_buf.reshape(-1)
        flat = [
            b.reshape(-1, *b.shape[2:])[valid]
            for b in (obs_buf, action_buf, logprob_buf, advantages, returns)
        ]
        b_obs, b_actions, b_logprobs, b_advantages, b_returns = flat
        if len(b_obs) > 1:
            b_advantages = (b_advantages - b_advantages.mean()) / (b_advantages.std() + 1e-8)
        with torch.no_grad():
            loss_before = ppo_loss(model, b_obs, b_actions, b_logprobs, b_advantages, b_returns, config)[
                0
            ].item()
        size = len(b_obs)
        for _ in range(config.epochs):
            order = rng.permutation(size)
            for chunk in np.array_split(order, config.minibatches):
                if chunk.size == 0:
                    continue
                index = torch.as_tensor(chunk, device=device)
                loss, policy, value, entropy = ppo_loss(
                    model,
                    b_obs[index],
                    b_actions[index],
                    b_logprobs[index],
                    b_advantages[index],
                    b_returns[index],
                    config,
                )
                optimiser.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(model.parameters(), config.max_grad_norm)
                optimiser.step()
        with torch.no_grad():
            after = ppo_loss(model, b_obs, b_actions, b_logprobs, b_advantages, b_returns, config)
        if after_update is not None:
            following = torch.cat([obs_buf[1:], next_obs[None]]).reshape(-1, *obs_buf.shape[2:])[valid]
            after_update(
                model,
                tuple(x.cpu().numpy() for x in (b_obs, b_actions, reward_buf.reshape(-1)[valid], following)),
            )
        row = {
            "update": update + 1,
            "env_steps": result.env_steps,
            "loss_before": loss_before,
            "loss_after": after[0].item(),
            "policy_loss": after[1].item(),
            "value_loss": after[2].item(),
            "entropy": after[3].item(),
            "episodes": len(finished),
            "mean_episode_length": float(np.mean(finished)) if finished else None,
        }
        result.history.append(row)
        if progress is not None:
            progress(result.env_steps, row)
    result.seconds = time.perf_counter() - start
    env.close()
    return result


POLICY_KINDS = ("atlpo-mf-policy", "atlpo-mb-policy")


def training_metadata(
    domain: str, env_kwargs: dict, config: PpoConfig, result: PpoResult, kind: str = "atlpo-mf-policy"
) -> dict:
    """What to store beside the weights: network sizes, env, settings and the training cost."""
    return {
        "kind": kind,
        "domain": domain,
        "env_kwargs": env_kwargs,
        "network": result.model.config.as_dict(),
        "ppo": asdict(config),
        "env_steps": result.env_steps,
        "seconds": round(result.seconds, 3),
        "final": result.history[-1] if result.history else None,
    }
