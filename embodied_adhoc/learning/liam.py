"""``liam``: local-information agent modelling (Papoudakis, Christianos and Albrecht 2021, "Agent Modelling under
Partial Observability for Deep Reinforcement Learning"), the second library-free ad hoc agent.

The ego's trajectory encoder is the recurrent generalist's trunk (:class:`~embodied_adhoc.learning.recurrent_ppo.
RecurrentActorCritic`: a CNN over its egocentric window, a GRU over that encoding and its previous action); the
GRU state is the embedding ``z_t`` of its own observations and actions so far, and the actor and critic read it.
During training only, a decoder (:class:`LiamNetwork`) reconstructs from ``z_t`` what the ego never sees: each
teammate's egocentric window of the state at ``t`` (mean squared error) and the action it takes there (cross
entropy). Their sum, weighted by ``reconstruction_coef``, is added to PPO's loss, so the embedding is shaped to
carry what identifies the teammates. The vector env hands the targets over through its training-only
``teammate_info`` (:class:`~embodied_adhoc.learning.vector_grid.GridVectorEnv`); nothing else reads them.

At execution the decoder is gone: the weights file holds the policy network alone (the generalist's layout, kind
``liam``), so the agent (:func:`liam_agent`, a :class:`~embodied_adhoc.learning.generalist.GeneralistAgent`)
acts from its own observations through the Agent protocol, exactly as ``ppo-generalist`` does.

One deviation from the paper: encoder and policy share one GRU, and PPO's gradient reaches the encoder too (the
paper's encoder is a separate network trained by the reconstruction alone; one trunk halves the recurrent cost
on this 2-core machine).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.generalist import (
    GeneralistAgent,
    GeneralistTraining,
    generalist_agent,
    train_generalist_run,
)
from embodied_adhoc.learning.generalist import shipped_weights as generalist_shipped_weights
from embodied_adhoc.learning.generalist import weights_name as generalist_weights_name
from embodied_adhoc.learning.networks import NetworkConfig
from embodied_adhoc.learning.recurrent_ppo import (
    RecurrentActorCritic,
    RecurrentPpoConfig,
    train_recurrent_ppo,
)

KIND = "liam"
SHIPPED_FOLDER = "liam"
SHIPPED_COMMAND = (
    "embodied-adhoc train liam --domain {domain} --steps 120000 --seed 0 --threads 1 "
    "--out assets/liam/{domain}"
)
RECONSTRUCTION_FIELDS = ("reconstruction_loss", "observation_mse", "action_cross_entropy", "action_accuracy")


@dataclass(frozen=True)
class LiamConfig(RecurrentPpoConfig):
    """Recurrent PPO settings plus the decoder's: its hidden width and the reconstruction loss's weight."""

    reconstruction_coef: float = 0.1
    decoder_hidden: int = 128

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.reconstruction_coef >= 0.0:
            raise ConfigError(
                f"LiamConfig.reconstruction_coef={self.reconstruction_coef}: give a number >= 0"
            )
        if self.decoder_hidden < 1:
            raise ConfigError(f"LiamConfig.decoder_hidden={self.decoder_hidden}: give a positive integer")


class LiamNetwork(RecurrentActorCritic):
    """The generalist's network plus the training-only decoder from the GRU state to the ``teammates``' windows
    and action logits. :meth:`unroll` keeps its GRU states (:attr:`embeddings`) for the reconstruction loss."""

    def __init__(
        self, network: NetworkConfig, recurrent: int, teammates: int, decoder_hidden: int, views: int = 0
    ) -> None:
        super().__init__(network, recurrent)
        self.teammates, self.views = teammates, views
        # a grid teammate's view is its window (regressed); an index domain's is one of ``views`` classes
        self.window = (views,) if views else (network.channels, network.view, network.view)
        outputs = teammates * (int(np.prod(self.window)) + network.actions)
        self.decoder = nn.Sequential(
            nn.Linear(recurrent, decoder_hidden), nn.ReLU(), nn.Linear(decoder_hidden, outputs)
        )
        self.embeddings: torch.Tensor | None = None

    def unroll(self, observations, previous, hidden, starts):
        self.embeddings = self.unroll_states(observations, previous, hidden, starts)
        return self.actor(self.embeddings), self.critic(self.embeddings).squeeze(-1)

    def reconstruct(self, embeddings: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(teammates' windows (..., K, C, V, V), their action logits (..., K, A)) decoded from embeddings."""
        decoded = self.decoder(embeddings)
        split = self.teammates * int(np.prod(self.window))
        windows = decoded[..., :split].reshape(*embeddings.shape[:-1], self.teammates, *self.window)
        logits = decoded[..., split:].reshape(*embeddings.shape[:-1], self.teammates, self.config.actions)
        return windows, logits

    def policy(self) -> RecurrentActorCritic:
        """The execution network alone (the decoder left out), as the generalist's class."""
        policy = RecurrentActorCritic(self.config, self.recurrent)
        policy.load_state_dict(
            {k: v for k, v in self.state_dict().items() if not k.startswith("decoder.")}, strict=True
        )
        return policy.eval()


def reconstruction_loss(model: LiamNetwork, embeddings, windows, actions) -> tuple[torch.Tensor, dict]:
    """The decoder's loss on (N, H) embeddings against the teammates' (N, K, C, V, V) windows and (N, K)
    actions: window MSE plus action cross entropy, with the action accuracy as a diagnostic. In an index domain
    the (N, K) views are classes and their term is a cross entropy too (reported as ``observation_mse``)."""
    predicted, logits = model.reconstruct(embeddings)
    if model.views:
        observation_mse = nn.functional.cross_entropy(predicted.reshape(-1, model.views), windows.reshape(-1))
    else:
        observation_mse = nn.functional.mse_loss(predicted, windows)
    cross_entropy = nn.functional.cross_entropy(logits.reshape(-1, logits.shape[-1]), actions.reshape(-1))
    loss = observation_mse + cross_entropy
    with torch.no_grad():
        accuracy = (logits.argmax(-1) == actions).float().mean()
    stats = {
        "reconstruction_loss": loss.item(),
        "observation_mse": observation_mse.item(),
        "action_cross_entropy": cross_entropy.item(),
        "action_accuracy": accuracy.item(),
    }
    return loss, stats


class Reconstruction:
    """The training-only auxiliary of :func:`~embodied_adhoc.learning.recurrent_ppo.train_recurrent_ppo`: it
    asks the vector env for the teammates' windows and actions, keeps one rollout segment of them and adds the
    weighted reconstruction loss of the sub-envs of each minibatch."""

    vector_kwargs = {"teammate_info": True}
    curve_fields = RECONSTRUCTION_FIELDS

    def __init__(self, config: LiamConfig, teammates: int, views: int = 0) -> None:
        self.config, self.teammates, self.views = config, teammates, views
        self.windows = self.actions = self.valid = None

    def network(self, network: NetworkConfig, recurrent: int) -> LiamNetwork:
        return LiamNetwork(network, recurrent, self.teammates, self.config.decoder_hidden, self.views)

    @property
    def metadata(self) -> dict:
        return {"teammates": self.teammates, "decoder_hidden": self.config.decoder_hidden}

    def exported(self, model: LiamNetwork) -> RecurrentActorCritic:
        """What the weights file holds: the execution network, the decoder left out."""
        return model.policy()

    def record(self, t: int, infos: dict) -> None:
        windows = torch.as_tensor(infos["teammate_observations"])
        if self.windows is None:
            steps = self.config.rollout_steps
            self.windows = torch.zeros((steps, *windows.shape), dtype=windows.dtype)
            self.actions = torch.zeros((steps, *windows.shape[:2]), dtype=torch.long)
            self.valid = torch.zeros((steps, windows.shape[0]), dtype=torch.bool)
        self.windows[t] = windows
        self.actions[t] = torch.as_tensor(infos["teammate_actions"])
        self.valid[t] = torch.as_tensor(infos["_teammate_actions"])

    def loss(self, model: LiamNetwork, index: torch.Tensor) -> tuple[torch.Tensor, dict]:
        embeddings = model.embeddings  # the states of the PPO objective just computed for ``index``
        cpu = index.cpu()
        mask = self.valid[:, cpu]
        device = embeddings.device
        loss, stats = reconstruction_loss(
            model,
            embeddings[mask.to(device)],
            self.windows[:, cpu][mask].to(device),
            self.actions[:, cpu][mask].to(device),
        )
        return self.config.reconstruction_coef * loss, stats


def teammate_count(domain: str, env_kwargs: dict) -> int:
    """How many scripted teammates an episode of ``domain`` with ``env_kwargs`` has (one in an index domain)."""
    import gymnasium

    import embodied_adhoc.envs  # noqa: F401  (registers the ids)
    from embodied_adhoc.learning.index_domains import INDEX_DOMAINS
    from embodied_adhoc.learning.vector_grid import GRID_IDS

    if domain in INDEX_DOMAINS:
        return 1

    probe = gymnasium.make(GRID_IDS[domain], **env_kwargs)
    count = probe.unwrapped.core.rules.config.n_agents - 1
    probe.close()
    return count


def teammate_views(domain: str) -> int:
    """How many classes a teammate's view has in an index domain (0 in a grid domain: a window)."""
    from embodied_adhoc.learning.index_domains import TEAMMATE_CLASSES

    return TEAMMATE_CLASSES.get(domain, (0, 0))[0]


def train_liam(
    domain: str,
    env_kwargs: dict,
    config: LiamConfig,
    folder: str | Path | None = None,
    progress: Callable[[int, dict], None] | None = None,
    stop_after: int | None = None,
):
    """Recurrent PPO with the reconstruction loss; the result's ``model`` is the :class:`LiamNetwork`."""
    auxiliary = Reconstruction(config, teammate_count(domain, dict(env_kwargs)), teammate_views(domain))
    return train_recurrent_ppo(domain, env_kwargs, config, folder, progress, stop_after, auxiliary=auxiliary)


def weights_name(domain: str) -> str:
    return generalist_weights_name(domain, KIND)


def shipped_weights(domain: str) -> Path:
    """The pre-trained LIAM agent of ``domain`` shipped in the package's data, made by :data:`SHIPPED_COMMAND`."""
    return generalist_shipped_weights(domain, KIND, SHIPPED_FOLDER, SHIPPED_COMMAND)


def liam_agent(domain: str, path: str | Path | None, grid, name: str = KIND) -> GeneralistAgent:
    """The agent of the LIAM weights at ``path`` (None: the shipped ones) for an episode on ``grid``; the checks
    of :func:`~embodied_adhoc.learning.generalist.generalist_agent` (domain, grid) apply."""
    path = shipped_weights(domain) if path is None else path
    return generalist_agent(domain, path, grid, name=name, kind=KIND)


def plugin(library, rng_seed: int = 0) -> GeneralistAgent:
    """The shipped agent as an agent plug-in (``--agents embodied_adhoc.learning.liam:plugin``), on a grid arena,
    the lab, pursuit-task or ntu."""
    from embodied_adhoc.learning.index_domains import index_agent, index_domain

    if index_domain(library) is not None:
        return index_agent(library, KIND)
    grid = library.rules.config
    return liam_agent(grid.domain, None, grid)


@dataclass(frozen=True)
class LiamTraining(GeneralistTraining):
    """The ``train liam`` settings: ``train ppo-generalist``'s plus the reconstruction loss's weight."""

    reconstruction_coef: float = 0.1

    def config(self) -> LiamConfig:
        return LiamConfig(**asdict(super().config()), reconstruction_coef=self.reconstruction_coef)


def train_liam_run(
    settings: LiamTraining,
    progress: Callable[[int, dict], None] | None = None,
    stop_after: int | None = None,
) -> dict:
    """``train ppo-generalist``'s pipeline (:func:`~embodied_adhoc.learning.generalist.train_generalist_run`)
    with the reconstruction loss: the checkpoint resumes, the weights file (:func:`weights_name`) holds the
    execution network without the decoder, ``curve.csv`` has the reconstruction columns."""
    config = settings.config()
    auxiliary = Reconstruction(
        config, teammate_count(settings.domain, settings.env_kwargs()), teammate_views(settings.domain)
    )
    return train_generalist_run(settings, progress, stop_after, auxiliary=auxiliary, kind=KIND)
