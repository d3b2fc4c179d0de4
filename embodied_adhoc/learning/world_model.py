"""ATLPO-MB's world model (thesis section 6.1.4, Fig. 6.3): an encoder ``q`` (the same small CNN as ATLPO-MF's,
:class:`~embodied_adhoc.learning.networks.Encoder`), a transition predictor ``T(z, a) -> z'``, a reward predictor
``R(z, a) -> r`` and a decoder ``D(z) -> o``, trained end to end on replayed experience; the actor and critic are
then trained by PPO on the latent states ``z = q(o)`` with the encoder frozen (:func:`train_mb_policy`).

Loss on a minibatch of replayed transitions ``(o, a, r, o')``::

    |D(q(o)) - o|^2 + |D(T(q(o), a)) - o'|^2 + |T(q(o), a) - q(o')|^2 + (R(q(o), a) - r)^2

(reconstruction, predicted-next-observation, latent-consistency and reward terms; mean squared errors over the
observation cells, the latent features and the batch). The replay buffer holds ``steps`` transitions of a uniformly
random ad hoc agent with the environment's scripted team (:func:`collect_experience`); the thesis does not state
how its replay was filled, and a random behaviour policy covers states the trained policy later visits.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.networks import Encoder, NetworkConfig
from embodied_adhoc.learning.vector_grid import GridVectorEnv


@dataclass(frozen=True)
class WorldModelTraining:
    experience: int = 8_192  # replayed transitions (env steps of a random agent)
    iterations: int = 1_500
    batch_size: int = 128
    learning_rate: float = 1e-3
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("experience", "iterations", "batch_size"):
            if getattr(self, name) < 1:
                raise ConfigError(f"WorldModelTraining.{name}={getattr(self, name)}: give a positive integer")


class WorldModel(nn.Module):
    """Fig. 6.3's encoder, transition and reward predictors and decoder."""

    def __init__(self, config: NetworkConfig) -> None:
        super().__init__()
        self.config = config
        features, actions = config.features, config.actions
        self.encoder = Encoder(config)
        self.transition = nn.Sequential(nn.Linear(features + actions, features), nn.ReLU(),
                                        nn.Linear(features, features), nn.ReLU())
        self.reward = nn.Sequential(nn.Linear(features + actions, features), nn.ReLU(), nn.Linear(features, 1))
        self.decoder = nn.Linear(features, config.channels * config.view * config.view)

    def _with_action(self, latent: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        return torch.cat([latent, nn.functional.one_hot(actions, self.config.actions).float()], dim=-1)

    def decode(self, latent: torch.Tensor) -> torch.Tensor:
        c, f = self.config.channels, self.config.view
        return self.decoder(latent).reshape(-1, c, f, f)

    def losses(self, observations, actions, rewards, next_observations) -> dict[str, torch.Tensor]:
        latent = self.encoder(observations)
        joined = self._with_action(latent, actions)
        predicted = self.transition(joined)
        return {
            "reconstruction": ((self.decode(latent) - observations) ** 2).mean(),
            "next_observation": ((self.decode(predicted) - next_observations) ** 2).mean(),
            "latent": ((predicted - self.encoder(next_observations)) ** 2).mean(),
            "reward": ((self.reward(joined).squeeze(-1) - rewards) ** 2).mean(),
        }


@dataclass
class Experience:
    observations: np.ndarray  # (n, C, f, f)
    actions: np.ndarray  # (n,)
    rewards: np.ndarray  # (n,)
    next_observations: np.ndarray  # (n, C, f, f)


def collect_experience(domain: str, env_kwargs: dict, steps: int, seed: int, num_envs: int = 16) -> Experience:
    """``steps`` transitions of a uniformly random agent on ``GridVectorEnv`` (NEXT_STEP autoreset: the reset
    steps, which are no transitions, are left out)."""
    rng = np.random.default_rng(seed)
    env = GridVectorEnv(domain, num_envs, **env_kwargs)
    observation, _ = env.reset(seed=seed)
    resetting = np.zeros(num_envs, bool)
    rows: list[tuple] = []
    kept = 0
    while kept < steps:
        action = rng.integers(env.single_action_space.n, size=num_envs)
        following, reward, terminated, truncated, _ = env.step(action)
        valid = ~resetting
        rows.append((observation[valid], action[valid], reward[valid], following[valid]))
        kept += int(valid.sum())
        observation, resetting = following, terminated | truncated
    env.close()
    parts = [np.concatenate(column)[:steps] for column in zip(*rows, strict=True)]
    return Experience(parts[0].astype(np.float32), parts[1].astype(np.int64), parts[2].astype(np.float32),
                      parts[3].astype(np.float32))


def train_world_model(model: WorldModel, data: Experience, settings: WorldModelTraining,
                      device: torch.device | None = None) -> list[dict]:
    """Minibatches drawn (seeded) from the replay; returns the loss terms every 50 iterations (and the last)."""
    device = device or torch.device("cpu")
    torch.manual_seed(settings.seed)
    rng = np.random.default_rng(settings.seed)
    model.to(device).train()
    tensors = [torch.as_tensor(x, device=device) for x in (data.observations, data.actions, data.rewards,
                                                           data.next_observations)]
    optimiser = torch.optim.Adam(model.parameters(), lr=settings.learning_rate)
    history = []
    for iteration in range(settings.iterations):
        index = torch.as_tensor(rng.integers(len(data.actions), size=settings.batch_size), device=device)
        terms = model.losses(*(t[index] for t in tensors))
        loss = sum(terms.values())
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        if iteration % 50 == 0 or iteration == settings.iterations - 1:
            history.append({"iteration": iteration, "loss": loss.item(), **{k: v.item() for k, v in terms.items()}})
    model.cpu().eval()
    return history


def train_mb_policy(domain: str, env_kwargs: dict, config, settings: WorldModelTraining, progress=None):
    """ATLPO-MB's member for one environment (or, with ``env_kwargs['environments']``, the model-based baseline
    over several): the world model on replayed experience, then PPO (:func:`~embodied_adhoc.learning.ppo.train_ppo`)
    on its frozen encoder's latent states. Returns (PPO result, world model, world-model loss history)."""
    from embodied_adhoc.learning.ppo import train_ppo

    data = collect_experience(domain, env_kwargs, settings.experience, settings.seed, config.num_envs)
    network = NetworkConfig(channels=data.observations.shape[1], view=data.observations.shape[2],
                            hidden_channels=config.hidden_channels, features=config.features)
    torch.manual_seed(settings.seed)
    model = WorldModel(network)
    history = train_world_model(model, data, settings)
    result = train_ppo(domain, env_kwargs, config, progress, encoder=model.encoder)
    return result, model, history


def mb_metadata(settings: WorldModelTraining, history: list[dict]) -> dict:
    return {"world_model": asdict(settings), "world_model_loss": {"first": history[0], "last": history[-1]}}
