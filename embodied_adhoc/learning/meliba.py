"""``meliba``: a variational belief over a latent teammate/task embedding, the policy conditioned on it (Zintgraf
et al. 2020, VariBAD, and 2021, "Deep Interactive Bayesian Reinforcement Learning via Meta-Learning"), the third
library-free ad hoc agent and the thesis's section 8.1.2 direction.

The belief encoder is the recurrent generalist's trunk (:class:`~embodied_adhoc.learning.recurrent_ppo.
RecurrentActorCritic`'s CNN and GRU over the ego's egocentric window and previous action); a linear layer maps
its state to a diagonal Gaussian posterior ``q(m | tau_t) = N(mu_t, diag(sigma_t^2))`` over a latent ``m``. During
training only, a decoder reads a sample of ``m`` (reparametrised) with the window and the ego's action of each of
the next ``horizon`` steps of the same episode and predicts the reward there (Bernoulli: the grid's only reward is
1 at the step that ends the episode) and the teammates' actions (categorical, from the vector env's training-only
``teammate_info``). The ELBO's negative, reconstruction plus ``kl_coef`` times ``KL(q_t || q_{t-1})`` (``N(0, I)``
before an episode's first step), trains encoder and decoder.

The policy is VariBAD's: a second CNN over the current window, concatenated with the posterior's mean and log
variance, then a tanh layer and the generalist's actor and critic heads, trained by PPO
(:func:`~embodied_adhoc.learning.recurrent_ppo.train_recurrent_ppo` with this module's auxiliary loss). The
belief enters the policy detached, so PPO's gradient never reaches the encoder: the belief is shaped by the ELBO
alone. Its only memory of the episode is therefore the belief.

At execution the decoder is gone (the weights file, kind ``meliba``, holds encoder, belief and policy); the
agent is a :class:`~embodied_adhoc.learning.generalist.GeneralistAgent` over this network, acting from its own
observations through the Agent protocol.

Deviations from the papers: the encoder does not take in the reward, since every reward before an episode's end
is 0 and the episode stops at the first non-zero one (it carries nothing; the held-out protocol also gives the
agent no reward); the decoder reconstructs a window of ``horizon`` future steps of each step's segment instead of
the whole trajectory, and the encoder is trained by truncated backpropagation over PPO's rollout segments.
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
from embodied_adhoc.learning.liam import teammate_count
from embodied_adhoc.learning.networks import NetworkConfig
from embodied_adhoc.learning.recurrent_ppo import (
    RecurrentActorCritic,
    RecurrentPpoConfig,
    flat_observations,
    make_encoder,
    network_config,
    observation_shape,
    train_recurrent_ppo,
)
from embodied_adhoc.learning.weights import WeightsError, load_into, load_weights

KIND = "meliba"
SHIPPED_FOLDER = "meliba"
SHIPPED_COMMAND = (
    "embodied-adhoc train meliba --domain {domain} --steps 120000 --seed 0 --threads 1 "
    "--out assets/meliba/{domain}"
)
ELBO_FIELDS = (
    "elbo_loss",
    "kl",
    "reward_bce",
    "teammate_cross_entropy",
    "teammate_accuracy",
    "posterior_variance",
)


@dataclass(frozen=True)
class MelibaConfig(RecurrentPpoConfig):
    """Recurrent PPO settings plus the belief's: latent size, decoder width, future steps decoded per step, the
    KL term's weight in the ELBO and the ELBO's weight beside PPO's loss."""

    latent: int = 8
    decoder_hidden: int = 64
    horizon: int = 4
    kl_coef: float = 0.1
    elbo_coef: float = 1.0
    reward_likelihood: str = "bernoulli"  # the grid's 0/1 reward; "gaussian" (squared error) elsewhere

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.reward_likelihood not in ("bernoulli", "gaussian"):
            raise ConfigError(
                f"MelibaConfig.reward_likelihood={self.reward_likelihood!r}: use bernoulli or gaussian"
            )
        for name in ("latent", "decoder_hidden", "horizon"):
            if getattr(self, name) < 1:
                raise ConfigError(f"MelibaConfig.{name}={getattr(self, name)}: give a positive integer")
        for name in ("kl_coef", "elbo_coef"):
            if not getattr(self, name) >= 0.0:
                raise ConfigError(f"MelibaConfig.{name}={getattr(self, name)}: give a number >= 0")
        if self.horizon > self.rollout_steps:
            raise ConfigError(
                f"MelibaConfig.horizon={self.horizon}: at most rollout_steps={self.rollout_steps} "
                "(the decoder reads future steps of the same rollout segment)"
            )


def gaussian_kl(mu_q, logvar_q, mu_p, logvar_p) -> torch.Tensor:
    """KL(N(mu_q, e^logvar_q) || N(mu_p, e^logvar_p)) of diagonal Gaussians, summed over the last axis."""
    ratio = torch.exp(logvar_q - logvar_p)
    return 0.5 * (ratio + (mu_q - mu_p) ** 2 * torch.exp(-logvar_p) - 1.0 - (logvar_q - logvar_p)).sum(-1)


class MelibaNetwork(RecurrentActorCritic):
    """Belief encoder (the parent's CNN and GRU, then ``belief`` to (mu, log variance)), the policy (its own CNN,
    ``trunk`` over the window's features and the detached belief, the parent's actor and critic) and, with
    ``teammates`` > 0, the training-only decoder. The recurrent state passed between steps is the GRU's."""

    def __init__(
        self,
        network: NetworkConfig,
        recurrent: int,
        latent: int,
        teammates: int = 0,
        decoder_hidden: int = 64,
    ) -> None:
        super().__init__(network, recurrent)
        self.latent, self.teammates = latent, teammates
        self.belief = nn.Linear(recurrent, 2 * latent)
        self.policy_encoder = make_encoder(network)
        self.trunk = nn.Sequential(nn.Linear(network.features + 2 * latent, recurrent), nn.Tanh())
        self.window = int(flat_observations(network, torch.zeros((1, *observation_shape(network)))).shape[-1])
        if teammates:
            self.decoder = nn.Sequential(
                nn.Linear(latent + self.window + network.actions, decoder_hidden),
                nn.ReLU(),
                nn.Linear(decoder_hidden, 1 + teammates * network.actions),
            )
        self.trace: dict | None = None

    def posterior(self, hidden: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(mean, log variance) of q(m | tau) from GRU states (..., H)."""
        mu, logvar = self.belief(hidden).chunk(2, -1)
        return mu, logvar.clamp(-10.0, 5.0)

    def _heads(self, observations, mu, logvar):
        shape = observation_shape(self.config)
        features = self.policy_encoder(observations.reshape(-1, *shape))
        features = features.reshape(*mu.shape[:-1], -1)
        hidden = self.trunk(torch.cat([features, mu.detach(), logvar.detach()], -1))
        return self.actor(hidden), self.critic(hidden).squeeze(-1)

    def step(self, observations, previous, hidden, starts):
        hidden = self._cell(self.encoder(observations), previous, hidden, starts)
        logits, values = self._heads(observations, *self.posterior(hidden))
        return logits, values, hidden

    def unroll(self, observations, previous, hidden, starts):
        """As the parent's; keeps what the ELBO needs (:attr:`trace`): the windows, starts, the belief before
        the segment and the posteriors of every step."""
        states = self.unroll_states(observations, previous, hidden, starts)
        mu, logvar = self.posterior(states)
        self.trace = {
            "observations": observations,
            "starts": starts,
            "before": self.posterior(hidden),
            "mu": mu,
            "logvar": logvar,
        }
        return self._heads(observations, mu, logvar)

    def decode(self, latent, observations, actions) -> tuple[torch.Tensor, torch.Tensor]:
        """(reward logits (...), teammates' action logits (..., K, A)) from latents (..., L), windows
        (..., C, V, V) and the ego's actions (...)."""
        inputs = torch.cat(
            [
                latent,
                flat_observations(self.config, observations).reshape(*latent.shape[:-1], self.window),
                nn.functional.one_hot(actions, self.config.actions).to(latent.dtype),
            ],
            -1,
        )
        out = self.decoder(inputs)
        return out[..., 0], out[..., 1:].reshape(*latent.shape[:-1], self.teammates, self.config.actions)

    def execution(self) -> MelibaNetwork:
        """The network the agent acts with: the decoder left out."""
        policy = MelibaNetwork(self.config, self.recurrent, self.latent)
        policy.load_state_dict(
            {k: v for k, v in self.state_dict().items() if not k.startswith("decoder.")}, strict=True
        )
        return policy.eval()


def elbo_loss(
    model: MelibaNetwork,
    actions,
    rewards,
    teammate_actions,
    valid,
    horizon: int,
    kl_coef: float,
    reward_likelihood: str = "bernoulli",
):
    """The negative ELBO of the segment the model last unrolled (:attr:`MelibaNetwork.trace`, T steps of B
    sequences) with the ego's (T, B) actions, (T, B) rewards, the teammates' (T, B, K) actions and the (T, B)
    mask of steps that are not reset steps: reconstruction (reward BCE, or squared error with a ``gaussian``
    likelihood, + teammates' cross entropy, over each step's next ``horizon`` steps of the same episode) plus
    ``kl_coef`` times KL to the previous posterior."""
    trace = model.trace
    mu, logvar, starts = trace["mu"], trace["logvar"], trace["starts"]
    steps = starts.shape[0]
    before_mu, before_logvar = trace["before"]
    prior_mu = torch.cat([before_mu[None], mu[:-1]], 0)
    prior_logvar = torch.cat([before_logvar[None], logvar[:-1]], 0)
    fresh = starts.unsqueeze(-1)
    prior_mu = torch.where(fresh, torch.zeros_like(prior_mu), prior_mu)
    prior_logvar = torch.where(fresh, torch.zeros_like(prior_logvar), prior_logvar)
    kl = gaussian_kl(mu, logvar, prior_mu, prior_logvar)[valid]
    sample = mu + torch.exp(0.5 * logvar) * torch.randn_like(mu)
    episode = torch.cumsum(starts.long(), 0)  # the same number for the steps of one episode
    reward_terms, teammate_terms, correct = [], [], []
    for k in range(min(horizon, steps)):
        mask = valid[: steps - k] & valid[k:] & (episode[: steps - k] == episode[k:])
        reward_logits, teammate_logits = model.decode(
            sample[: steps - k][mask], trace["observations"][k:][mask], actions[k:][mask]
        )
        if reward_likelihood == "gaussian":
            reward_terms.append((reward_logits - rewards[k:][mask]) ** 2)
        else:
            reward_terms.append(
                nn.functional.binary_cross_entropy_with_logits(
                    reward_logits, rewards[k:][mask], reduction="none"
                )
            )
        targets = teammate_actions[k:][mask]
        teammate_terms.append(
            nn.functional.cross_entropy(
                teammate_logits.reshape(-1, teammate_logits.shape[-1]), targets.reshape(-1), reduction="none"
            )
        )
        with torch.no_grad():
            correct.append((teammate_logits.argmax(-1) == targets).float().reshape(-1))
    reward_bce = torch.cat(reward_terms).mean()
    teammate_ce = torch.cat(teammate_terms).mean()
    kl_mean = kl.mean()
    loss = reward_bce + teammate_ce + kl_coef * kl_mean
    stats = {
        "elbo_loss": loss.item(),
        "kl": kl_mean.item(),
        "reward_bce": reward_bce.item(),
        "teammate_cross_entropy": teammate_ce.item(),
        "teammate_accuracy": torch.cat(correct).mean().item(),
        "posterior_variance": torch.exp(logvar[valid]).mean().item(),
    }
    return loss, stats


class Belief:
    """The training-only auxiliary of :func:`~embodied_adhoc.learning.recurrent_ppo.train_recurrent_ppo`: it
    keeps one rollout segment of the ego's actions and rewards and the teammates' actions, and adds the
    weighted negative ELBO of each minibatch's sub-envs."""

    vector_kwargs = {"teammate_info": True}
    curve_fields = ELBO_FIELDS
    records_steps = True

    def __init__(self, config: MelibaConfig, teammates: int) -> None:
        self.config, self.teammates = config, teammates
        self.actions = self.rewards = self.teammate_actions = self.valid = None

    def network(self, network: NetworkConfig, recurrent: int) -> MelibaNetwork:
        return MelibaNetwork(
            network, recurrent, self.config.latent, self.teammates, self.config.decoder_hidden
        )

    @property
    def metadata(self) -> dict:
        return {"latent": self.config.latent, "teammates": self.teammates}

    def exported(self, model: MelibaNetwork) -> MelibaNetwork:
        return model.execution()

    def record(self, t: int, infos: dict) -> None:
        actions = torch.as_tensor(infos["teammate_actions"])
        if self.teammate_actions is None:
            steps, envs = self.config.rollout_steps, actions.shape[0]
            self.teammate_actions = torch.zeros((steps, *actions.shape), dtype=torch.long)
            self.valid = torch.zeros((steps, envs), dtype=torch.bool)
            self.actions = torch.zeros((steps, envs), dtype=torch.long)
            self.rewards = torch.zeros((steps, envs))
        self.teammate_actions[t] = actions
        self.valid[t] = torch.as_tensor(infos["_teammate_actions"])

    def record_step(self, t: int, action: torch.Tensor, reward: np.ndarray, terminated: np.ndarray) -> None:
        self.actions[t] = action.cpu()
        self.rewards[t] = torch.as_tensor(reward, dtype=torch.float32)

    def loss(self, model: MelibaNetwork, index: torch.Tensor) -> tuple[torch.Tensor, dict]:
        device, cpu = model.trace["mu"].device, index.cpu()
        loss, stats = elbo_loss(
            model,
            self.actions[:, cpu].to(device),
            self.rewards[:, cpu].to(device),
            self.teammate_actions[:, cpu].to(device),
            self.valid[:, cpu].to(device),
            self.config.horizon,
            self.config.kl_coef,
            self.config.reward_likelihood,
        )
        return self.config.elbo_coef * loss, stats


def train_meliba(
    domain: str,
    env_kwargs: dict,
    config: MelibaConfig,
    folder: str | Path | None = None,
    progress: Callable[[int, dict], None] | None = None,
    stop_after: int | None = None,
):
    """Recurrent PPO with the belief's ELBO; the result's ``model`` is the :class:`MelibaNetwork` (decoder
    included)."""
    auxiliary = Belief(config, teammate_count(domain, dict(env_kwargs)))
    return train_recurrent_ppo(domain, env_kwargs, config, folder, progress, stop_after, auxiliary=auxiliary)


def weights_name(domain: str) -> str:
    return generalist_weights_name(domain, KIND)


def load_meliba(path: str | Path, kind: str = KIND) -> tuple[MelibaNetwork, dict]:
    """(execution network in eval mode, metadata) of a weights file written by :func:`train_meliba_run`
    (safetensors: tensors only)."""
    _, metadata = load_weights(path)
    if metadata.get("kind") != kind:
        raise WeightsError(f"{path}: not a {kind} (kind={metadata.get('kind')!r})")
    model = MelibaNetwork(
        network_config(metadata["network"]), int(metadata["recurrent"]), int(metadata["latent"])
    )
    load_into(model, path)
    return model.eval(), metadata


def shipped_weights(domain: str) -> Path:
    """The pre-trained MeLIBA agent of ``domain`` shipped in the package's data, made by :data:`SHIPPED_COMMAND`."""
    return generalist_shipped_weights(domain, KIND, SHIPPED_FOLDER, SHIPPED_COMMAND)


def meliba_agent(domain: str, path: str | Path | None, grid, name: str = KIND) -> GeneralistAgent:
    """The agent of the MeLIBA weights at ``path`` (None: the shipped ones) for an episode on ``grid``; the
    checks of :func:`~embodied_adhoc.learning.generalist.generalist_agent` (domain, grid) apply."""
    path = shipped_weights(domain) if path is None else path
    return generalist_agent(domain, path, grid, name=name, kind=KIND, loader=load_meliba)


def plugin(library, rng_seed: int = 0) -> GeneralistAgent:
    """The shipped agent as an agent plug-in (``--agents embodied_adhoc.learning.meliba:plugin``), on a grid
    arena, the lab, pursuit-task or ntu."""
    from embodied_adhoc.learning.index_domains import index_agent, index_domain

    if index_domain(library) is not None:
        return index_agent(library, KIND)
    grid = library.rules.config
    return meliba_agent(grid.domain, None, grid)


@dataclass(frozen=True)
class MelibaTraining(GeneralistTraining):
    """The ``train meliba`` settings: ``train ppo-generalist``'s plus the belief's."""

    steps: int = 120_000
    latent: int = 8
    kl_coef: float = 0.1

    def config(self) -> MelibaConfig:
        from embodied_adhoc.learning.index_domains import INDEX_DOMAINS

        likelihood = "gaussian" if self.domain in INDEX_DOMAINS else "bernoulli"
        return MelibaConfig(
            **asdict(super().config()),
            latent=self.latent,
            kl_coef=self.kl_coef,
            reward_likelihood=likelihood,
        )


def train_meliba_run(
    settings: MelibaTraining,
    progress: Callable[[int, dict], None] | None = None,
    stop_after: int | None = None,
) -> dict:
    """``train ppo-generalist``'s pipeline (:func:`~embodied_adhoc.learning.generalist.train_generalist_run`)
    with the belief's ELBO: the checkpoint resumes, the weights file (:func:`weights_name`) holds the execution
    network without the decoder, ``curve.csv`` has the ELBO's columns."""
    auxiliary = Belief(settings.config(), teammate_count(settings.domain, settings.env_kwargs()))
    return train_generalist_run(settings, progress, stop_after, auxiliary=auxiliary, kind=KIND)
