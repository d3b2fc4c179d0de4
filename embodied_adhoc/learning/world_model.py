"""ATLPO-MB's world model (thesis section 6.1.4, Fig. 6.3): an encoder ``q`` (the same small CNN as ATLPO-MF's,
:class:`~embodied_adhoc.learning.networks.Encoder`), a transition predictor ``T(z, a) -> z'``, a reward predictor
``R(z, a) -> r`` and a decoder ``D(z) -> o``, trained end to end on replayed experience; the actor and critic are
trained by PPO on the latent states ``z = q(o)``, which pass them no gradient (the thesis: "not trained end-to-end
alongside the Encoder"; :func:`train_mb_policy`).

Loss on a minibatch of replayed transitions ``(o, a, r, o')``::

    |D(q(o)) - o|^2 + |D(T(q(o), a)) - o'|^2 + |T(q(o), a) - q(o')|^2 + (R(q(o), a) - r)^2

(reconstruction, predicted-next-observation, latent-consistency and reward terms; mean squared errors over the
observation cells, the latent features and the batch). The thesis does not state how its replay was filled. Here
it holds transitions of a uniformly random ad hoc agent with the environment's scripted team
(:func:`collect_experience`), which cover states the trained policy later visits; optionally
(``WorldModelTraining.updates_per_rollout``) the policy's own transitions join it after every PPO update and the
world model trains on the mixture again, its encoder then replacing the policy's.

The actor and critic are MLPs with one hidden layer, as the thesis's (section 6.2.3), trained at its rate 0.001: on
a frozen encoder, linear heads at PPO's usual 2.5e-4 learned far less in 30,000 steps (LBF task 1 with tau1,
64 episodes: 59.2 steps; linear heads at 0.001: 20.0; MLP heads at 0.001: 9.7; ATLPO-MF: 10.0).
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
    experience: int = 8_192  # replayed transitions (env steps of a random agent) the model starts from
    iterations: int = 1_500  # minibatches on that random replay before PPO starts
    batch_size: int = 128
    learning_rate: float = 1e-3  # the thesis's Adam rate for encoder, decoder, transition and reward networks
    seed: int = 0
    policy_learning_rate: float = (
        1e-3  # PPO's rate for the actor and critic on the latents (the thesis: 0.001)
    )
    # world-model minibatches on the replay, refilled with the policy's transitions, after each PPO update; 0:
    # the encoder stays the one pre-trained on random replay (as good on LBF task 1, and cheaper to train)
    updates_per_rollout: int = 0
    head_hidden: int = (
        64  # the actor's and critic's hidden width on the latents (the thesis: MLPs); 0: linear
    )
    replay: int = 16_384  # replay capacity; the policy's own transitions replace the oldest

    def __post_init__(self) -> None:
        for name in ("experience", "iterations", "batch_size", "replay"):
            if getattr(self, name) < 1:
                raise ConfigError(f"WorldModelTraining.{name}={getattr(self, name)}: give a positive integer")
        for name in ("updates_per_rollout", "head_hidden"):
            if getattr(self, name) < 0:
                raise ConfigError(f"WorldModelTraining.{name}={getattr(self, name)}: give 0 or more")
        for name in ("learning_rate", "policy_learning_rate"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"WorldModelTraining.{name}={getattr(self, name)}: give a positive rate")


class WorldModel(nn.Module):
    """Fig. 6.3's encoder, transition and reward predictors and decoder."""

    def __init__(self, config: NetworkConfig) -> None:
        super().__init__()
        self.config = config
        features, actions = config.features, config.actions
        self.encoder = Encoder(config)
        self.transition = nn.Sequential(
            nn.Linear(features + actions, features), nn.ReLU(), nn.Linear(features, features), nn.ReLU()
        )
        self.reward = nn.Sequential(
            nn.Linear(features + actions, features), nn.ReLU(), nn.Linear(features, 1)
        )
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


def collect_experience(
    domain: str, env_kwargs: dict, steps: int, seed: int, num_envs: int = 16
) -> Experience:
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
    return Experience(
        parts[0].astype(np.float32),
        parts[1].astype(np.int64),
        parts[2].astype(np.float32),
        parts[3].astype(np.float32),
    )


class Replay:
    """A ring buffer of transitions (the oldest replaced first), as tensors on ``device``."""

    def __init__(self, data: Experience, capacity: int, device: torch.device) -> None:
        columns = (data.observations, data.actions, data.rewards, data.next_observations)
        self.tensors = [
            torch.zeros((capacity, *x.shape[1:]), dtype=torch.as_tensor(x[:1]).dtype, device=device)
            for x in columns
        ]
        self.size = self.cursor = 0
        self.add(*columns)

    def add(self, *columns: np.ndarray) -> None:
        capacity = len(self.tensors[0])
        rows = (self.cursor + np.arange(len(columns[0]))) % capacity
        index = torch.as_tensor(rows[-capacity:])
        for tensor, column in zip(self.tensors, columns, strict=True):
            tensor[index] = torch.as_tensor(
                np.asarray(column)[-capacity:], dtype=tensor.dtype, device=tensor.device
            )
        self.cursor = int((self.cursor + len(columns[0])) % capacity)
        self.size = min(capacity, self.size + len(columns[0]))


class WorldModelTrainer:
    """Adam on Fig. 6.3's summed losses over seeded minibatches of a :class:`Replay`; :meth:`train` may be
    called again as the replay fills with the policy's own experience."""

    def __init__(self, model: WorldModel, replay: Replay, settings: WorldModelTraining) -> None:
        self.model, self.replay, self.settings = model, replay, settings
        self.rng = np.random.default_rng(settings.seed)
        self.optimiser = torch.optim.Adam(model.parameters(), lr=settings.learning_rate)
        self.iterations = 0

    def train(self, iterations: int) -> list[dict]:
        """``iterations`` minibatches; returns the loss terms every 50 iterations overall (and the last)."""
        self.model.train()
        history = []
        device = self.replay.tensors[0].device
        for step in range(iterations):
            index = torch.as_tensor(
                self.rng.integers(self.replay.size, size=self.settings.batch_size), device=device
            )
            terms = self.model.losses(*(t[index] for t in self.replay.tensors))
            loss = sum(terms.values())
            self.optimiser.zero_grad()
            loss.backward()
            self.optimiser.step()
            if self.iterations % 50 == 0 or step == iterations - 1:
                history.append(
                    {
                        "iteration": self.iterations,
                        "loss": loss.item(),
                        **{k: v.item() for k, v in terms.items()},
                    }
                )
            self.iterations += 1
        self.model.eval()
        return history


def train_world_model(
    model: WorldModel, data: Experience, settings: WorldModelTraining, device: torch.device | None = None
) -> list[dict]:
    """``settings.iterations`` minibatches drawn (seeded) from the replay ``data``; returns the loss terms every
    50 iterations (and the last)."""
    device = device or torch.device("cpu")
    torch.manual_seed(settings.seed)
    model.to(device)
    history = WorldModelTrainer(model, Replay(data, len(data.actions), device), settings).train(
        settings.iterations
    )
    model.cpu()
    return history


def mb_policy_config(config, settings: WorldModelTraining):
    """The PPO settings of an ATLPO-MB member: ``config`` with the world-model settings' rate and head width."""
    from dataclasses import replace

    return replace(config, learning_rate=settings.policy_learning_rate, head_hidden=settings.head_hidden)


def train_mb_policy(domain: str, env_kwargs: dict, config, settings: WorldModelTraining, progress=None):
    """ATLPO-MB's member for one environment (or, with ``env_kwargs['environments']``, the model-based baseline
    over several), Fig. 6.3: the world model first learns on a random agent's replay; then PPO
    (:func:`~embodied_adhoc.learning.ppo.train_ppo`, at ``settings.policy_learning_rate``, MLP heads of
    ``settings.head_hidden``) trains the actor and critic on the encoder's latent states (the encoder gets no
    gradient from them). With ``settings.updates_per_rollout`` > 0, after every PPO update the rollout's
    transitions join the replay and the world model trains that many minibatches on it end to end, after which
    its encoder is copied into the policy. Returns (PPO result, world model, world-model loss history)."""
    from embodied_adhoc.learning.ppo import train_ppo

    data = collect_experience(domain, env_kwargs, settings.experience, settings.seed, config.num_envs)
    network = NetworkConfig(
        channels=data.observations.shape[1],
        view=data.observations.shape[2],
        hidden_channels=config.hidden_channels,
        features=config.features,
    )
    torch.manual_seed(settings.seed)
    model = WorldModel(network)
    trainer = WorldModelTrainer(
        model, Replay(data, max(settings.replay, settings.experience), torch.device("cpu")), settings
    )
    history = trainer.train(settings.iterations)

    def after_update(policy, transitions) -> None:
        trainer.replay.add(*transitions)
        history.extend(trainer.train(settings.updates_per_rollout))
        policy.encoder.load_state_dict(model.encoder.state_dict())

    hook = after_update if settings.updates_per_rollout else None
    result = train_ppo(
        domain,
        env_kwargs,
        mb_policy_config(config, settings),
        progress,
        encoder=model.encoder,
        after_update=hook,
    )
    return result, model, history


def mb_metadata(settings: WorldModelTraining, history: list[dict]) -> dict:
    return {"world_model": asdict(settings), "world_model_loss": {"first": history[0], "last": history[-1]}}
