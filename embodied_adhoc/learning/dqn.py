"""DQN (Mnih et al. 2015) as PLASTIC-Policy uses it (thesis section 4.1.2, Table 4.3, pursuit row): an MLP
``q(x, .)`` over the ad hoc agent's state features, 2 x 64 ReLU, Adam 0.01, replay of 15,000, minibatches of
32, discount 0.95, epsilon-greedy decaying linearly from 0.50 to 0.05 over the interaction, no initial random
steps, the target network copied after every update (target update frequency 1), the standard squared TD loss

    L = 1/T sum_t (r_t + gamma max_a q'(y_t, a) (1 - terminal_t) - q(x_t, a_t))^2.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.blocks import ReplayBuffer, adam_step, mlp, seeded_module
from embodied_adhoc.learning.weights import load_into, save_weights


@dataclass(frozen=True)
class DqnConfig:
    """Table 4.3 (pursuit row) and the DQN loss's discount."""

    hidden: int = 64
    layers: int = 2
    lr: float = 0.01
    epsilon_start: float = 0.50
    epsilon_end: float = 0.05
    random_steps: int = 0
    target_every: int = 1
    gamma: float = 0.95
    capacity: int = 15_000
    batch: int = 32

    def __post_init__(self) -> None:
        if not (0 <= self.epsilon_end <= self.epsilon_start <= 1 and 0 < self.gamma <= 1):
            raise ConfigError(
                f"DqnConfig: need 0 <= epsilon_end <= epsilon_start <= 1 and 0 < gamma <= 1 "
                f"(got {self.epsilon_end}, {self.epsilon_start}, {self.gamma})"
            )


class Dqn:
    """One Q-network ``q_k`` trained while playing with one team."""

    def __init__(
        self,
        inputs: int,
        actions: int,
        rng: np.random.Generator,
        config: DqnConfig | None = None,
        decay_steps: int = 1,
    ) -> None:
        self.config = config or DqnConfig()
        self.inputs, self.actions, self.rng, self.decay_steps = inputs, actions, rng, max(1, decay_steps)
        cfg = self.config
        self.q = seeded_module(lambda: mlp(inputs, cfg.hidden, cfg.layers, actions), rng)
        self.target = copy.deepcopy(self.q)
        self.optimiser = torch.optim.Adam(self.q.parameters(), lr=cfg.lr)
        self.buffer = ReplayBuffer(
            cfg.capacity,
            {
                "x": ((inputs,), np.float32),
                "a": ((), np.int64),
                "r": ((), np.float32),
                "y": ((inputs,), np.float32),
                "done": ((), np.float32),
            },
        )
        self.steps = 0

    @property
    def epsilon(self) -> float:
        cfg = self.config
        fraction = min(1.0, self.steps / self.decay_steps)
        return cfg.epsilon_start + fraction * (cfg.epsilon_end - cfg.epsilon_start)

    def greedy(self, features: np.ndarray) -> int:
        with torch.no_grad():
            values = self.q(torch.from_numpy(features[None].astype(np.float32)))[0].numpy()
        best = np.flatnonzero(values == values.max())
        return int(best[0])

    def act(self, features: np.ndarray, explore: bool) -> int:
        if explore and (self.steps < self.config.random_steps or self.rng.random() < self.epsilon):
            return int(self.rng.integers(self.actions))
        return self.greedy(features)

    def update(self, x: np.ndarray, a: int, r: float, y: np.ndarray, done: bool) -> float:
        cfg = self.config
        self.buffer.add(x=x, a=a, r=r, y=y, done=float(done))
        self.steps += 1
        batch = {k: torch.from_numpy(v) for k, v in self.buffer.sample(cfg.batch, self.rng).items()}
        with torch.no_grad():
            target = batch["r"] + cfg.gamma * self.target(batch["y"]).max(-1).values * (1 - batch["done"])
        value = self.q(batch["x"]).gather(1, batch["a"][:, None])[:, 0]
        loss = adam_step(self.optimiser, ((target - value) ** 2).mean())
        if self.steps % cfg.target_every == 0:
            self.target.load_state_dict(self.q.state_dict())
        return loss

    def save(self, path: str | Path) -> Path:
        return save_weights(
            path,
            self.q,
            {
                "kind": "dqn",
                "inputs": self.inputs,
                "actions": self.actions,
                "hidden": self.config.hidden,
                "steps": self.steps,
            },
        )

    def load(self, path: str | Path) -> dict:
        meta = load_into(self.q, path)
        self.target.load_state_dict(self.q.state_dict())
        return meta
