"""Torch building blocks of ATLPO (thesis chapter 6): the encoder ``q`` over egocentric grid observations and
the actor-critic of each ATLPO-MF library policy (Fig. 6.2).

The observation is the ``C x f x f`` egocentric window of section 6.2.1 (teammate, target, boundary and level
channels; :mod:`embodied_adhoc.domains.grid_rules_obs`). The encoder is a small CNN (two 3x3 convolutions with
padding keep the ``f x f`` map, then a linear layer to ``features``), shared end to end by the actor
``pi(a | z)`` and the critic ``V(z)`` and trained with PPO (:mod:`embodied_adhoc.learning.ppo`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

from embodied_adhoc.errors import ConfigError


@dataclass(frozen=True)
class NetworkConfig:
    """Sizes of one library member's networks (stored beside its weights)."""

    channels: int  # C, observation channels
    view: int = 5  # f, the field of view
    actions: int = 5
    hidden_channels: int = 16
    features: int = 64
    head_hidden: int = 0  # 0: linear actor and critic heads; else one hidden layer of this width (MLP heads)

    def __post_init__(self) -> None:
        for name in ("channels", "view", "actions", "hidden_channels", "features"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ConfigError(f"NetworkConfig.{name}={value!r}: give a positive integer")
        if not isinstance(self.head_hidden, int) or self.head_hidden < 0:
            raise ConfigError(
                f"NetworkConfig.head_hidden={self.head_hidden!r}: give 0 (linear heads) or a width"
            )

    def as_dict(self) -> dict:
        return asdict(self)


def _layer(layer: nn.Module, gain: float) -> nn.Module:
    """Orthogonal weights and zero biases (the usual PPO initialisation)."""
    nn.init.orthogonal_(layer.weight, gain)
    nn.init.zeros_(layer.bias)
    return layer


class Encoder(nn.Module):
    """``q``: (B, C, f, f) observations -> (B, features) latent vectors."""

    def __init__(self, config: NetworkConfig) -> None:
        super().__init__()
        hidden, gain = config.hidden_channels, 2**0.5
        self.net = nn.Sequential(
            _layer(nn.Conv2d(config.channels, hidden, 3, padding=1), gain),
            nn.ReLU(),
            _layer(nn.Conv2d(hidden, hidden, 3, padding=1), gain),
            nn.ReLU(),
            nn.Flatten(),
            _layer(nn.Linear(hidden * config.view * config.view, config.features), gain),
            nn.ReLU(),
        )

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        return self.net(observations)


def _head(config: NetworkConfig, outputs: int, gain: float) -> nn.Module:
    """A linear head on the latent state, or an MLP with one tanh hidden layer of ``config.head_hidden``."""
    if not config.head_hidden:
        return _layer(nn.Linear(config.features, outputs), gain)
    return nn.Sequential(
        _layer(nn.Linear(config.features, config.head_hidden), 2**0.5),
        nn.Tanh(),
        _layer(nn.Linear(config.head_hidden, outputs), gain),
    )


class ActorCritic(nn.Module):
    """Fig. 6.2: encoder ``q``, actor ``pi`` (action logits) and critic ``V``, trained end to end (ATLPO-MF), or
    on a world model's latent states (ATLPO-MB, Fig. 6.3, where the thesis's actor and critic are MLPs)."""

    def __init__(self, config: NetworkConfig) -> None:
        super().__init__()
        self.config = config
        self.encoder = Encoder(config)
        self.actor = _head(config, config.actions, 0.01)
        self.critic = _head(config, 1, 1.0)

    def forward(self, observations: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(action logits (B, A), values (B,))."""
        latent = self.encoder(observations)
        return self.actor(latent), self.critic(latent).squeeze(-1)

    def action_distribution(self, observations: torch.Tensor) -> torch.Tensor:
        """``pi(. | z)`` as probabilities (B, A)."""
        logits, _ = self(observations)
        return torch.softmax(logits, dim=-1)
