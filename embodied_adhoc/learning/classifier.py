"""The recurrent Bayesian classifier of ATLPO (thesis Eq. 6.2) and its calibration.

Eq. 6.2: ``p_{t+1}, h_{t+1} = (1 / rho) p_hat(phi(z_{t+1}), a_t, h_t; theta_p)``: a GRU keeps the latent history
``h_t`` and reads the features ``phi(z_{t+1})`` of each new observation (the CNN :class:`Encoder`) with the ad hoc
agent's own previous action ``a_t`` (one-hot; the first observation comes with a "no action" slot); a linear head
and a softmax (the normalisation ``rho``) give the posterior ``p_{t+1}`` over the K library environments (Eq. 6.1).
It never sees the teammates' actions, the reward or the state.

It is trained with the cross-entropy of the true environment at every step of trajectories collected in each
environment (:func:`train_classifier`); :func:`expected_calibration_error` measures whether its confidence
matches its accuracy, step by step (:func:`per_step_scores`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.networks import Encoder, NetworkConfig


@dataclass(frozen=True)
class ClassifierConfig:
    channels: int
    environments: int  # K
    view: int = 5
    actions: int = 5
    features: int = 64
    hidden: int = 64
    hidden_channels: int = 16

    def __post_init__(self) -> None:
        if self.environments < 2:
            raise ConfigError(f"ClassifierConfig.environments={self.environments}: a library needs K >= 2")

    def as_dict(self) -> dict:
        return asdict(self)


class RecurrentBayesianClassifier(nn.Module):
    """``p_hat`` of Eq. 6.2 (encoder ``phi``, GRU, head + softmax)."""

    def __init__(self, config: ClassifierConfig) -> None:
        super().__init__()
        self.config = config
        self.encoder = Encoder(
            NetworkConfig(
                channels=config.channels,
                view=config.view,
                actions=config.actions,
                hidden_channels=config.hidden_channels,
                features=config.features,
            )
        )
        self.gru = nn.GRU(config.features + config.actions + 1, config.hidden, batch_first=True)
        self.head = nn.Linear(config.hidden, config.environments)

    def _inputs(self, observations: torch.Tensor, previous_actions: torch.Tensor) -> torch.Tensor:
        """(B, T, features + A + 1): ``phi(z)`` beside the one-hot previous action (index A: none)."""
        batch, steps = previous_actions.shape
        features = self.encoder(observations.reshape(batch * steps, *observations.shape[2:]))
        one_hot = nn.functional.one_hot(previous_actions, self.config.actions + 1).float()
        return torch.cat([features.reshape(batch, steps, -1), one_hot], dim=-1)

    def forward(
        self, observations: torch.Tensor, previous_actions: torch.Tensor, history: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Log-posteriors (B, T, K) after each of T observations (B, T, C, f, f), each with the action that led
        to it (B, T; ``config.actions`` for none), and the final latent history (1, B, hidden)."""
        outputs, history = self.gru(self._inputs(observations, previous_actions), history)
        return torch.log_softmax(self.head(outputs), dim=-1), history

    @torch.no_grad()
    def posterior_step(
        self, observation: np.ndarray, previous_action: int | None, history: torch.Tensor | None
    ) -> tuple[np.ndarray, torch.Tensor]:
        """One online update of Eq. 6.2: ``(p_{t+1}, h_{t+1})`` from ``z_{t+1}`` and ``a_t`` (None at t=0)."""
        device = next(self.parameters()).device
        observation = torch.as_tensor(np.asarray(observation, dtype=np.float32), device=device)[None, None]
        action = self.config.actions if previous_action is None else int(previous_action)
        log_posterior, history = self(observation, torch.tensor([[action]], device=device), history)
        return log_posterior[0, 0].exp().cpu().numpy().astype(np.float64), history


@dataclass
class Trajectories:
    """Padded episodes: observations (E, T, C, f, f), previous actions (E, T) (``actions`` = none at t=0 and on
    padding), labels (E,) the environment index, lengths (E,) the real steps of each."""

    observations: np.ndarray
    previous_actions: np.ndarray
    labels: np.ndarray
    lengths: np.ndarray

    def mask(self) -> np.ndarray:
        return np.arange(self.observations.shape[1])[None, :] < self.lengths[:, None]


@dataclass(frozen=True)
class ClassifierTraining:
    iterations: int = 300
    batch_size: int = 32
    learning_rate: float = 1e-3
    seed: int = 0


def train_classifier(
    model: RecurrentBayesianClassifier,
    data: Trajectories,
    settings: ClassifierTraining,
    device: torch.device | None = None,
) -> list[float]:
    """Minimise the per-step cross-entropy of the true environment over random minibatches of episodes;
    returns the loss of every iteration. Seeded: ``torch.manual_seed`` and a numpy Generator."""
    torch.manual_seed(settings.seed)
    rng = np.random.default_rng(settings.seed)
    device = device or torch.device("cpu")
    model.to(device)
    observations = torch.as_tensor(data.observations, dtype=torch.float32, device=device)
    actions = torch.as_tensor(data.previous_actions, dtype=torch.long, device=device)
    labels = torch.as_tensor(data.labels, dtype=torch.long, device=device)
    mask = torch.as_tensor(data.mask(), device=device)
    optimiser = torch.optim.Adam(model.parameters(), lr=settings.learning_rate)
    losses = []
    for _ in range(settings.iterations):
        pick = torch.as_tensor(
            rng.choice(len(labels), size=min(settings.batch_size, len(labels)), replace=False), device=device
        )
        log_posterior, _ = model(observations[pick], actions[pick])
        chosen = log_posterior.gather(-1, labels[pick][:, None, None].expand(-1, log_posterior.shape[1], 1))[
            ..., 0
        ]
        loss = -(chosen * mask[pick]).sum() / mask[pick].sum()
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        losses.append(loss.item())
    return losses


def expected_calibration_error(probabilities: np.ndarray, labels: np.ndarray, bins: int = 10) -> float:
    """ECE (Guo et al. 2017): the confidence (top probability) of ``probabilities`` (N, K) binned into ``bins``
    equal-width bins; the mean over bins, weighted by their share of samples, of |accuracy - confidence|."""
    probabilities, labels = np.asarray(probabilities), np.asarray(labels)
    if len(probabilities) == 0:
        raise ConfigError("expected_calibration_error: no samples")
    confidence = probabilities.max(axis=1)
    correct = probabilities.argmax(axis=1) == labels
    which = np.minimum((confidence * bins).astype(np.int64), bins - 1)
    total = 0.0
    for b in np.unique(which):
        members = which == b
        total += members.mean() * abs(correct[members].mean() - confidence[members].mean())
    return float(total)


@torch.no_grad()
def per_step_scores(model: RecurrentBayesianClassifier, data: Trajectories, bins: int = 10) -> list[dict]:
    """For every step t: how many episodes reach it, the accuracy of the posterior's argmax, the mean posterior
    of the true environment and the expected calibration error over those episodes."""
    model.eval()
    device = next(model.parameters()).device
    log_posterior, _ = model(
        torch.as_tensor(data.observations, dtype=torch.float32, device=device),
        torch.as_tensor(data.previous_actions, dtype=torch.long, device=device),
    )
    posterior = log_posterior.exp().cpu().numpy()
    mask = data.mask()
    rows = []
    for t in range(posterior.shape[1]):
        live = mask[:, t]
        if not live.any():
            break
        p, labels = posterior[live, t], data.labels[live]
        rows.append(
            {
                "step": t,
                "episodes": int(live.sum()),
                "accuracy": float((p.argmax(1) == labels).mean()),
                "true_posterior": float(p[np.arange(len(labels)), labels].mean()),
                "ece": expected_calibration_error(p, labels, bins),
            }
        )
    return rows
