"""``ppo-generalist``: the library-free ad hoc agent, one recurrent (GRU) policy trained with PPO against teammates
drawn per episode from a train population (:mod:`embodied_adhoc.learning.recurrent_ppo`).

Unlike ATLPO it holds no library of (task, team) models and no classifier: whatever it infers about its
teammates and the task lives in its GRU state, updated from its own observations and actions. It follows the
project's Agent protocol with ``observes_raw`` (the egocentric arrays of the grid env, the episode's first one
through :meth:`GeneralistAgent.start`) and keeps no task posterior.

The train population of the grid domains is the thesis's teams tau0-tau2 on the four tasks (:data:`TRAIN_TEAMS`):
the held-out teams of :mod:`embodied_adhoc.learning.atlpo_heldout` (noisy and mixed teams) are never seen in
training. ``train_generalist_run`` is the ``embodied-adhoc train ppo-generalist`` pipeline; the package ships one
agent per trained domain in ``assets/generalist/<domain>/`` (:func:`shipped_weights`, made by
:data:`SHIPPED_COMMAND`), so ``trials`` and ``run`` use it without training.
"""

from __future__ import annotations

import csv
import io
import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from embodied_adhoc.atomic import atomic_write_text
from embodied_adhoc.decision.agents.base import AgentBase
from embodied_adhoc.decision.agents.selection import draw_action
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning import LEARNED_CHAPTER5_DOMAINS
from embodied_adhoc.learning.recurrent_ppo import (
    CHECKPOINT,
    RecurrentActorCritic,
    RecurrentPpoConfig,
    generalist_metadata,
    network_config,
    train_recurrent_ppo,
)
from embodied_adhoc.learning.weights import WeightsError, load_into, load_weights, save_weights
from embodied_adhoc.paths import assets_dir

TRAIN_TEAMS = ("tau0", "tau1", "tau2")
GRID_DOMAINS = ("foraging", "pursuit")
DOMAINS = (*GRID_DOMAINS, "toxic-waste", *LEARNED_CHAPTER5_DOMAINS)
"""The grid arenas (teams tau0-tau2) and the benchmark's index domains (:mod:`~embodied_adhoc.learning.
index_domains`, teammates from the benchmark's train split)."""
SHIPPED_FOLDER = "generalist"
SHIPPED_COMMAND = (
    "embodied-adhoc train ppo-generalist --domain {domain} --steps 300000 --seed 0 --threads 1 "
    "--out assets/generalist/{domain}"
)
CURVE_FIELDS = (
    "update",
    "env_steps",
    "seconds",
    "episodes",
    "mean_episode_length",
    "solved",
    "loss_before",
    "loss_after",
    "policy_loss",
    "value_loss",
    "entropy",
)


def weights_name(domain: str, kind: str = "ppo-generalist") -> str:
    return f"{domain}-{kind}.safetensors"


def shipped_weights(
    domain: str, kind: str = "ppo-generalist", folder: str | None = None, command: str | None = None
) -> Path:
    """The pre-trained ``kind`` agent of ``domain`` shipped in the package's data (in ``folder``, made by
    ``command``; by default the generalist's :data:`SHIPPED_FOLDER` and :data:`SHIPPED_COMMAND`)."""
    path = assets_dir() / (folder or SHIPPED_FOLDER) / domain / weights_name(domain, kind)
    if not path.is_file():
        raise ConfigError(
            f"no pre-trained {kind} for {domain!r} in {path.parent}; train one with "
            f"`{(command or SHIPPED_COMMAND).format(domain=domain)}`"
        )
    return path


def load_generalist(path: str | Path, kind: str = "ppo-generalist") -> tuple[RecurrentActorCritic, dict]:
    """(network in eval mode, metadata) of a weights file written by :func:`train_generalist_run` (safetensors:
    tensors only, nothing executable is read); ``kind`` the agent the file must hold (``liam`` ships the same
    network)."""
    _, metadata = load_weights(path)
    if metadata.get("kind") != kind:
        raise WeightsError(f"{path}: not a {kind} (kind={metadata.get('kind')!r})")
    model = RecurrentActorCritic(network_config(metadata["network"]), int(metadata["recurrent"]))
    load_into(model, path)
    return model.eval(), metadata


class GeneralistAgent(AgentBase):
    """The recurrent policy as an ad hoc agent: its GRU state starts at zero with each episode and takes in each
    observation with the action that led to it; ``act`` draws from the policy (its argmax with ``greedy``)
    with the episode's ``rng``."""

    observes_raw = True

    def __init__(
        self, model: RecurrentActorCritic, name: str = "ppo-generalist", greedy: bool = False
    ) -> None:
        self.model, self.name, self.greedy = model.eval(), name, greedy
        self.rng = np.random.default_rng(0)
        self._hidden: torch.Tensor | None = None
        self._probabilities: np.ndarray | None = None

    def reset(self, rng: np.random.Generator, state: int | None = None) -> None:
        self.rng, self._hidden, self._probabilities = rng, None, None

    @torch.no_grad()
    def _advance(self, observation, previous: int, first: bool) -> None:
        observation = self._checked(observation)
        if self._hidden is None:
            self._hidden = self.model.initial_state(1)
        logits, _, self._hidden = self.model.step(
            torch.as_tensor(observation)[None],
            torch.tensor([previous]),
            self._hidden,
            torch.tensor([first]),
        )
        self._probabilities = torch.softmax(logits[0], -1).double().numpy()

    def start(self, observation) -> None:
        """The episode's first observation (the GRU state is zeroed)."""
        self._advance(observation, self.model.no_action, True)

    def _checked(self, observation) -> np.ndarray:
        config = self.model.config
        expected = (config.channels, config.view, config.view)
        if np.shape(observation) != expected:
            raise ConfigError(
                f"ppo-generalist observation of shape {np.shape(observation)}: it was trained on the "
                f"egocentric {expected} arrays of its grid env (not observation indices, nor another grid's)"
            )
        return np.asarray(observation, dtype=np.float32)

    def action_distribution(self) -> np.ndarray:
        if self._probabilities is None:
            raise ConfigError("ppo-generalist: call start(observation) after reset() before acting")
        return self._probabilities.copy()

    def act(self) -> int:
        return draw_action(self.action_distribution(), self.rng, self.greedy)

    def observe(self, action: int, observation, state: int | None = None, **outcome) -> None:
        self._advance(observation, int(action), False)


_LOADED: dict[tuple[str, float], tuple[RecurrentActorCritic, dict]] = {}


def generalist_agent(
    domain: str,
    path: str | Path | None,
    grid,
    name: str = "ppo-generalist",
    kind: str = "ppo-generalist",
    loader: Callable[[Path, str], tuple] | None = None,
) -> GeneralistAgent:
    """The agent of the weights at ``path`` (None: the shipped ones, :func:`shipped_weights`) for an episode on
    ``grid`` (a ``GridConfig``): the weights must be of ``domain`` and trained on the same grid, else one line
    saying which. Weights are read once per process; each call gets its own agent (its own GRU state).
    ``loader(path, kind)`` -> (network, metadata) reads another network with the same step interface (meliba's;
    default :func:`load_generalist`)."""
    from embodied_adhoc.learning.atlpo import grid_differences

    path = shipped_weights(domain) if path is None else Path(path)
    key = (str(path.resolve()), path.stat().st_mtime if path.exists() else 0.0)
    if key not in _LOADED:
        _LOADED[key] = (loader or load_generalist)(path, kind)
    model, metadata = _LOADED[key]
    if metadata["domain"] != domain:
        raise ConfigError(
            f"{path}: a {metadata['domain']} agent; {domain} needs one trained with --domain {domain}"
        )
    differ = grid_differences(domain, metadata["env_kwargs"], grid, "trained")
    if differ:
        raise ConfigError(
            f"{path}: trained on another grid: {', '.join(differ)}; use its grid or train one on this grid"
        )
    return GeneralistAgent(model, name=name)


def train_teams(domain: str) -> tuple:
    """The train population as teams of the held-out protocol (``atlpo_heldout.HeldOutTeam``): each thesis team
    of :data:`TRAIN_TEAMS` in every teammate seat, without noise, for scoring on the teams it was trained with."""
    import gymnasium

    import embodied_adhoc.envs  # noqa: F401  (registers the ids)
    from embodied_adhoc.learning.atlpo_heldout import HeldOutTeam, thesis_team
    from embodied_adhoc.learning.vector_grid import GRID_IDS

    probe = gymnasium.make(GRID_IDS[domain])
    specs = probe.unwrapped.core.teams
    probe.close()
    return tuple(HeldOutTeam(tau, thesis_team(specs, (tau,))) for tau in TRAIN_TEAMS)


def plugin(library, rng_seed: int = 0) -> GeneralistAgent:
    """The shipped agent as an agent plug-in (``--agents embodied_adhoc.learning.generalist:plugin``), for any
    command that takes plug-ins: built for the grid of the arena's ``library`` (its ``rules.config``), or for the
    library of an index domain, the lab, pursuit-task or ntu
    (:func:`~embodied_adhoc.learning.index_domains.index_agent`)."""
    from embodied_adhoc.learning.index_domains import index_agent, index_domain

    if index_domain(library) is not None:
        return index_agent(library, "ppo-generalist")
    grid = library.rules.config
    return generalist_agent(grid.domain, None, grid)


@dataclass(frozen=True)
class GeneralistTraining:
    """The ``train ppo-generalist`` settings (CLI flags map one to one)."""

    domain: str
    out: str
    steps: int = 300_000
    seed: int = 0
    envs: int = 32
    rollout: int = 64
    device: str = "cpu"
    threads: int = 1
    teammates: int = 0  # the first N teams or train members; 0: all of them
    pipeline: bool = False  # RecurrentPpoConfig.pipeline (grid domains)

    def __post_init__(self) -> None:
        if self.domain not in DOMAINS:
            raise ConfigError(f"--domain {self.domain}: use one of {', '.join(DOMAINS)}")
        if self.pipeline and self.domain not in GRID_DOMAINS:
            raise ConfigError(
                f"--pipeline: the rollout pipeline steps the grid domains ({', '.join(GRID_DOMAINS)}) only; "
                f"drop it for {self.domain}"
            )
        if self.domain in GRID_DOMAINS and not 0 <= self.teammates <= len(TRAIN_TEAMS):
            raise ConfigError(f"--teammates {self.teammates}: give 1..{len(TRAIN_TEAMS)} or 0 for all")

    def config(self) -> RecurrentPpoConfig:
        # The index domains' networks are small, so an update's cost is the per-step overhead of each unroll:
        # one minibatch of every sub-env there, four on the grids.
        minibatches = 4 if self.envs % 4 == 0 and self.domain in GRID_DOMAINS else 1
        return RecurrentPpoConfig(
            total_steps=self.steps,
            num_envs=self.envs,
            rollout_steps=self.rollout,
            minibatches=minibatches,
            seed=self.seed,
            device=self.device,
            pipeline=self.pipeline,
        )

    def env_kwargs(self) -> dict:
        if self.domain in GRID_DOMAINS:
            return {"teams": list(TRAIN_TEAMS[: self.teammates or len(TRAIN_TEAMS)])}
        from embodied_adhoc.learning.index_domains import member_names

        return {"members": member_names(self.domain, self.teammates)}


def curve_csv(history: list[dict], fields: tuple[str, ...] = CURVE_FIELDS) -> str:
    """The training curve, one row per update (:data:`CURVE_FIELDS`, or ``fields``)."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=fields, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for row in history:
        writer.writerow({k: "" if row.get(k) is None else row[k] for k in fields})
    return buffer.getvalue()


def train_generalist_run(
    settings: GeneralistTraining,
    progress: Callable[[int, dict], None] | None = None,
    stop_after: int | None = None,
    auxiliary=None,
    kind: str = "ppo-generalist",
) -> dict:
    """Train (resuming a checkpoint in ``settings.out`` of the same settings) and write the weights
    (:func:`weights_name`), ``curve.csv`` and ``training.json``; the checkpoint is removed once the weights are
    written. A folder whose weights exist already is not retrained: its report is returned. With ``stop_after``
    the run stops after that many updates in all, checkpointed.

    ``auxiliary`` (a training-only loss, see :func:`train_recurrent_ppo`) and ``kind`` make another agent of the
    same network (``liam``): the auxiliary's ``curve_fields`` join the curve, ``exported(model)`` is the network
    the weights file holds and ``metadata`` joins its header, whose kind is ``kind``."""
    if settings.threads:
        torch.set_num_threads(settings.threads)
    out = Path(settings.out)
    weights, report_path = out / weights_name(settings.domain, kind), out / "training.json"
    if weights.exists() and report_path.exists() and not (out / CHECKPOINT).exists():
        return json.loads(report_path.read_text())
    config, env_kwargs = settings.config(), settings.env_kwargs()
    started = time.perf_counter()
    result = train_recurrent_ppo(settings.domain, env_kwargs, config, out, progress, stop_after, auxiliary)
    fields = CURVE_FIELDS + tuple(getattr(auxiliary, "curve_fields", ()))
    atomic_write_text(out / "curve.csv", curve_csv(result.history, fields))
    report = {
        "settings": asdict(settings),
        "finished": result.finished,
        "updates": result.updates,
        "total_updates": result.total_updates,
        "env_steps": result.env_steps,
        "train_seconds": round(result.seconds, 1),
        "steps_per_second": round(result.steps_per_second, 1),
        "call_seconds": round(time.perf_counter() - started, 1),
        "final": result.history[-1] if result.history else None,
    }
    if result.finished:
        metadata = generalist_metadata(settings.domain, env_kwargs, config, result)
        model = result.model
        if auxiliary is not None:
            model = auxiliary.exported(model)
            metadata.update(auxiliary.metadata)
        save_weights(weights, model, {**metadata, "kind": kind})
        atomic_write_text(report_path, json.dumps(report, indent=1) + "\n")
        (out / CHECKPOINT).unlink(missing_ok=True)
    return report
