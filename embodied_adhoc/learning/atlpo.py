"""ATLPO-MF (thesis sections 6.1-6.2): a library of PPO policies, one per environment (task x team), the recurrent
Bayesian classifier over them (Eq. 6.2) and the ad hoc agent that acts with the posterior-weighted library.

Environment sets (section 6.2, the chapter-6 table): ``task`` (K=4: tasks 1-4, team tau1 fixed), ``team`` (K=3:
teams tau0-tau2, task 1 fixed) and ``task+team`` (their union, K=6: the thesis reports K=7 without listing the
environments, and its two sets share one; which seventh it added is not recoverable from the text).

On disk a library is a folder: ``library.json`` (domain, env settings, the members in order, the classifier) and
one safetensors file per member and for the classifier (:mod:`embodied_adhoc.learning.weights`). Training is
resumable per member: a member whose weights exist is loaded, not retrained. A member's seed depends on its
environment, not on its set (:func:`member_seed`), so the ``task``, ``team`` and ``task+team`` libraries of one
seed share identical members. The package ships the ``task+team`` library of each domain
(:func:`shipped_library`; how it is made: docs/atlpo.md), so ``trials`` and ``run`` work without training.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch

from embodied_adhoc.atomic import atomic_write_text
from embodied_adhoc.decision.agents.base import AgentBase
from embodied_adhoc.decision.agents.selection import draw_action
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.classifier import ClassifierConfig, RecurrentBayesianClassifier, Trajectories
from embodied_adhoc.learning.networks import ActorCritic, NetworkConfig
from embodied_adhoc.learning.ppo import POLICY_KINDS, PpoConfig, train_ppo, training_metadata
from embodied_adhoc.learning.vector_grid import GridVectorEnv
from embodied_adhoc.learning.weights import WeightsError, load_into, load_weights, save_weights
from embodied_adhoc.paths import assets_dir

SETS = ("task", "team", "task+team")


@dataclass(frozen=True)
class LibraryEnvironment:
    task: int  # 1-based, as the envs' ``task`` option
    team: str

    @property
    def name(self) -> str:
        return f"task{self.task}-{self.team}"


def library_set(name: str) -> tuple[LibraryEnvironment, ...]:
    """The environments of one chapter-6 set (see the module docstring)."""
    tasks = tuple(LibraryEnvironment(k, "tau1") for k in range(1, 5))
    teams = tuple(LibraryEnvironment(1, team) for team in ("tau0", "tau1", "tau2"))
    if name == "task":
        return tasks
    if name == "team":
        return teams
    if name == "task+team":
        return tasks + tuple(e for e in teams if e not in tasks)
    raise ConfigError(f"set={name!r}: use one of {SETS}")


def member_seed(seed: int, environment: LibraryEnvironment) -> int:
    """The PPO seed of ``environment``'s member: ``seed`` plus its position in the ``task+team`` set, whichever
    set it is trained for (so one environment's member is the same in every set of a seed)."""
    return seed + library_set("task+team").index(environment)


SHIPPED_FOLDER = "atlpo"
SHIPPED_COMMAND = (
    "embodied-adhoc train atlpo --domain {domain} --set task+team --seed 0 --threads 1 "
    "--out assets/atlpo/{domain}"
)


def shipped_library(domain: str) -> Path:
    """The pre-trained ``task+team`` library of ``domain`` shipped in the package's data (``assets/atlpo/``),
    made by :data:`SHIPPED_COMMAND`."""
    folder = assets_dir() / SHIPPED_FOLDER / domain
    if not (folder / "library.json").is_file():
        raise ConfigError(
            f"no pre-trained ATLPO library for {domain!r} in {folder.parent}; train one with "
            f"`{SHIPPED_COMMAND.format(domain=domain)}` or pass --library DIR"
        )
    return folder


@dataclass
class PolicyLibrary:
    domain: str
    environments: tuple[LibraryEnvironment, ...]
    policies: list[ActorCritic]
    env_kwargs: dict
    model: str = (
        "mf"  # "mf": ATLPO-MF members (PPO end to end); "mb": ATLPO-MB (PPO on a world model's latents)
    )

    def env_for(self, k: int, **kwargs) -> dict:
        environment = self.environments[k]
        return {**self.env_kwargs, "tasks": (environment.task,), "teams": (environment.team,), **kwargs}


MODELS = ("mf", "mb")


def _member_path(folder: Path, domain: str, environment: LibraryEnvironment, model: str = "mf") -> Path:
    return folder / f"{domain}-{'mb-' if model == 'mb' else ''}{environment.name}.safetensors"


def _train_policy(
    domain: str, kwargs: dict, config: PpoConfig, model: str, path: Path, report, world_model=None
) -> ActorCritic:
    """One policy, saved to ``path``: PPO end to end (``mf``) or PPO on the latents of a world model trained on
    replayed experience first (``mb``, :func:`~embodied_adhoc.learning.world_model.train_mb_policy`)."""
    if model not in MODELS:
        raise ConfigError(f"model={model!r}: use one of {MODELS}")
    if model == "mf":
        result = train_ppo(domain, kwargs, config, report)
        save_weights(path, result.model, training_metadata(domain, kwargs, config, result))
        return result.model
    from embodied_adhoc.learning.world_model import (
        WorldModelTraining,
        mb_metadata,
        mb_policy_config,
        train_mb_policy,
    )

    settings = replace(world_model or WorldModelTraining(), seed=config.seed)
    result, _, history = train_mb_policy(domain, kwargs, config, settings, report)
    metadata = {
        **training_metadata(
            domain, kwargs, mb_policy_config(config, settings), result, kind="atlpo-mb-policy"
        ),
        **mb_metadata(settings, history),
    }
    save_weights(path, result.model, metadata)
    return result.model


def train_library(
    domain: str,
    set_name: str,
    config: PpoConfig,
    folder: str | Path,
    env_kwargs: dict | None = None,
    progress: Callable[[str, int, dict], None] | None = None,
    model: str = "mf",
    world_model=None,
) -> PolicyLibrary:
    """Train (or, where its weights exist, load) one policy per environment of ``set_name``; each member gets
    the seed :func:`member_seed` of ``config.seed``. ``model``: ``mf`` (ATLPO-MF) or ``mb`` (ATLPO-MB, with the
    world-model settings ``world_model``, a ``WorldModelTraining``)."""
    folder, env_kwargs = Path(folder), dict(env_kwargs or {})
    environments = library_set(set_name)
    policies = []
    for environment in environments:
        path = _member_path(folder, domain, environment, model)
        kwargs = {**env_kwargs, "tasks": (environment.task,), "teams": (environment.team,)}
        if path.exists():
            policies.append(load_policy(path))
            continue
        member_config = replace(config, seed=member_seed(config.seed, environment))
        report = (
            None
            if progress is None
            else (lambda steps, row, name=environment.name: progress(name, steps, row))
        )
        policies.append(_train_policy(domain, kwargs, member_config, model, path, report, world_model))
    library = PolicyLibrary(domain, environments, policies, env_kwargs, model)
    write_manifest(folder, library, classifier=None)
    return library


def generalist_path(folder: str | Path, domain: str, set_name: str, model: str = "mf") -> Path:
    return (
        Path(folder)
        / f"{domain}-{'mb-' if model == 'mb' else ''}all-{set_name.replace('+', '-')}.safetensors"
    )


def train_generalist(
    domain: str,
    set_name: str,
    config: PpoConfig,
    folder: str | Path,
    env_kwargs: dict | None = None,
    progress: Callable[[int, dict], None] | None = None,
    model: str = "mf",
    world_model=None,
) -> ActorCritic:
    """The model-free (``mf``) or model-based (``mb``) RL baseline trained on all environments of ``set_name``
    together (each episode draws one uniformly), with ``config.seed + 100``; loaded instead if its weights
    exist."""
    path = generalist_path(folder, domain, set_name, model)
    if path.exists():
        return load_policy(path)
    kwargs = {**(env_kwargs or {}), "environments": [(e.task, e.team) for e in library_set(set_name)]}
    return _train_policy(
        domain, kwargs, replace(config, seed=config.seed + 100), model, path, progress, world_model
    )


def load_policy(path: str | Path) -> ActorCritic:
    _, metadata = load_weights(path)
    if metadata.get("kind") not in POLICY_KINDS:
        raise WeightsError(f"{path}: not an ATLPO policy (kind={metadata.get('kind')!r})")
    model = ActorCritic(NetworkConfig(**metadata["network"]))
    load_into(model, path)
    return model.eval()


def write_manifest(
    folder: Path, library: PolicyLibrary, classifier: RecurrentBayesianClassifier | None
) -> None:
    manifest = {
        "domain": library.domain,
        "env_kwargs": library.env_kwargs,
        "model": library.model,
        "members": [
            {
                "task": e.task,
                "team": e.team,
                "weights": _member_path(folder, library.domain, e, library.model).name,
            }
            for e in library.environments
        ],
    }
    previous = folder / "library.json"
    if classifier is None and previous.exists():  # keep a classifier trained on the same members
        try:
            earlier = json.loads(previous.read_text())
        except ValueError:
            earlier = {}
        if earlier.get("members") == manifest["members"] and earlier.get("classifier"):
            manifest["classifier"] = earlier["classifier"]
    if classifier is not None:
        path = save_weights(
            folder / f"{library.domain}-classifier.safetensors",
            classifier,
            {"kind": "atlpo-classifier", "config": classifier.config.as_dict()},
        )
        manifest["classifier"] = path.name
    atomic_write_text(folder / "library.json", json.dumps(manifest, indent=1, sort_keys=True) + "\n")


def load_library(folder: str | Path) -> tuple[PolicyLibrary, RecurrentBayesianClassifier | None]:
    """A library folder written by :func:`train_library` / :func:`write_manifest`."""
    folder = Path(folder)
    try:
        manifest = json.loads((folder / "library.json").read_text())
        members = manifest["members"]
        environments = tuple(LibraryEnvironment(int(m["task"]), str(m["team"])) for m in members)
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ConfigError(
            f"{folder / 'library.json'}: not an ATLPO library manifest ({error!r}); "
            "train one with train_library"
        ) from None
    policies = [load_policy(folder / m["weights"]) for m in members]
    library = PolicyLibrary(
        manifest["domain"],
        environments,
        policies,
        dict(manifest.get("env_kwargs", {})),
        str(manifest.get("model", "mf")),
    )
    classifier = None
    if manifest.get("classifier"):
        _, metadata = load_weights(folder / manifest["classifier"])
        classifier = RecurrentBayesianClassifier(ClassifierConfig(**metadata["config"]))
        load_into(classifier, folder / manifest["classifier"])
        classifier.eval()
    return library, classifier


@torch.no_grad()
def collect_trajectories(
    library: PolicyLibrary, episodes: int, max_steps: int, seed: int, mixing: float = 0.0
) -> Trajectories:
    """``episodes`` episodes of each library environment ``k`` played by its own policy (sampled actions), cut at
    ``max_steps``: the classifier's training data, labelled ``k``. With ``mixing`` > 0, each step's action comes
    with that probability from a library member drawn uniformly instead, so that the data also covers the
    episodes of an agent still unsure which member to follow (ATLPO's own)."""
    if not 0.0 <= mixing <= 1.0:
        raise ConfigError(f"mixing={mixing}: a probability in [0, 1]")
    rng = np.random.default_rng(seed)
    observations, previous, labels, lengths = [], [], [], []
    for k, policy in enumerate(library.policies):
        env = GridVectorEnv(library.domain, episodes, **library.env_for(k, max_episode_steps=max_steps))
        torch.manual_seed(seed + k)
        observation, _ = env.reset(seed=seed + 1000 * k)
        none = env.single_action_space.n
        obs = np.zeros((episodes, max_steps, *observation.shape[1:]), np.float32)
        acts = np.full((episodes, max_steps), none, np.int64)
        length = np.zeros(episodes, np.int64)
        live = np.ones(episodes, bool)
        for t in range(max_steps):
            obs[live, t] = observation[live]
            length[live] += 1
            batch = torch.as_tensor(observation)
            action = torch.distributions.Categorical(logits=policy(batch)[0]).sample().numpy()
            if mixing > 0.0:
                member = rng.integers(len(library.policies), size=episodes)
                other = np.stack(
                    [
                        torch.distributions.Categorical(logits=p(batch)[0]).sample().numpy()
                        for p in library.policies
                    ]
                )
                action = np.where(rng.random(episodes) < mixing, other[member, np.arange(episodes)], action)
            if t + 1 < max_steps:
                acts[live, t + 1] = action[live]
            observation, _, terminated, truncated, _ = env.step(action)
            live &= ~(terminated | truncated)
            if not live.any():
                break
        env.close()
        observations.append(obs)
        previous.append(acts)
        labels.append(np.full(episodes, k))
        lengths.append(length)
    return Trajectories(
        np.concatenate(observations),
        np.concatenate(previous),
        np.concatenate(labels),
        np.concatenate(lengths),
    )


class AtlpoAgent(AgentBase):
    """The ATLPO ad hoc agent: posterior ``p_t`` over the library from the classifier (Eq. 6.2) and the action
    distribution ``pi_t(a | h_t) = sum_k p_t(m_k) pi_k(a | z_t)`` drawn (or its argmax with ``greedy``) by the
    decision layer's :func:`draw_action`, as ATPO does with its library (whose Perseus policies are
    deterministic; PPO's are stochastic, so their whole distributions are mixed).

    It follows the project's ``Agent`` protocol with ``observes_raw``: the episode loop
    (:func:`~embodied_adhoc.episodes.loop.run_episode_loop`) gives it the env's egocentric arrays instead of
    observation indices, the episode's first one through :meth:`start` (after :meth:`reset`), each following one
    through :meth:`observe`. With ``known=k`` the posterior stays on environment ``k``: the library member alone,
    the model-free RL baseline that knows task and team (section 6.2.4).

    :attr:`library_posterior` is ``p_t`` over the K library environments; :attr:`task_posterior` (what the trial
    runner's identification and entropy metrics read) is its marginal over the domain's ``tasks`` tasks, or None
    for a library whose environments all share one task (the team set: it identifies teams, not tasks).
    """

    observes_state = False
    observes_raw = True

    def __init__(
        self,
        library: PolicyLibrary,
        classifier: RecurrentBayesianClassifier,
        greedy: bool = False,
        name: str = "atlpo-mf",
        known: int | None = None,
        tasks: int = 4,
    ) -> None:
        if classifier.config.environments != len(library.policies):
            raise ConfigError(
                f"classifier over {classifier.config.environments} environments for a library of "
                f"{len(library.policies)}: train the classifier on this library"
            )
        if known is not None and not 0 <= known < len(library.policies):
            raise ConfigError(f"known={known}: the library has environments 0..{len(library.policies) - 1}")
        self.library, self.classifier, self.greedy, self.name, self.known = (
            library,
            classifier,
            greedy,
            name,
            known,
        )
        task_of = np.array([e.task - 1 for e in library.environments])
        if task_of.max() >= tasks:
            raise ConfigError(
                f"library environment of task {task_of.max() + 1} for a domain of {tasks} tasks"
            )
        # (K, tasks) 0/1 matrix: library posterior @ it = task marginal; None when the library has one task
        self._task_marginal = np.eye(tasks)[task_of] if len(set(task_of.tolist())) > 1 else None
        self.rng = np.random.default_rng(0)
        self._posterior = self._prior()
        self._history = None
        self._observation: np.ndarray | None = None

    def _prior(self) -> np.ndarray:
        size = len(self.library.policies)
        return np.full(size, 1.0 / size) if self.known is None else np.eye(size)[self.known]

    def _update(self, observation, action: int | None) -> None:
        self._observation = self._checked(observation)
        if self.known is None:
            self._posterior, self._history = self.classifier.posterior_step(
                self._observation, action, self._history
            )

    def reset(self, rng: np.random.Generator, state: int | None = None) -> None:
        self.rng, self._history, self._observation = rng, None, None
        self._posterior = self._prior()

    def start(self, observation: np.ndarray) -> None:
        """The episode's first observation ``z_0`` (Eq. 6.2 with no previous action)."""
        self._history = None
        self._update(observation, None)

    def _checked(self, observation) -> np.ndarray:
        config = self.library.policies[0].config
        expected = (config.channels, config.view, config.view)
        if np.shape(observation) != expected:
            raise ConfigError(
                f"ATLPO observation of shape {np.shape(observation)}: the library was trained on the "
                f"egocentric {expected} arrays of its grid env (not observation indices, nor another "
                "grid's agent or apple count)"
            )
        return np.asarray(observation, dtype=np.float32)

    @torch.no_grad()
    def action_distribution(self) -> np.ndarray:
        if self._observation is None:
            raise ConfigError("ATLPO: call start(observation) after reset() before acting")
        observation = torch.as_tensor(self._observation)[None]
        distribution = np.zeros(self.library.policies[0].config.actions)
        for k, policy in enumerate(self.library.policies):
            if self._posterior[k] > 0.0:
                distribution += (
                    self._posterior[k] * policy.action_distribution(observation)[0].double().numpy()
                )
        return distribution

    def act(self) -> int:
        return draw_action(self.action_distribution(), self.rng, self.greedy)

    def observe(self, action: int, observation, state: int | None = None) -> None:
        self._update(observation, action)

    @property
    def library_posterior(self) -> np.ndarray:
        return self._posterior.copy()

    @property
    def task_posterior(self) -> np.ndarray | None:
        return None if self._task_marginal is None else self._posterior @ self._task_marginal


_LOADED: dict[tuple[str, float], tuple[PolicyLibrary, RecurrentBayesianClassifier | None]] = {}
_GRID_FIELDS = ("rows", "cols", "n_agents", "n_targets", "toroidal", "max_agent_level")


def grid_differences(domain: str, env_kwargs: dict, grid, label: str) -> list[str]:
    """How the grid ``grid`` (a ``GridConfig``) differs from the one ``env_kwargs`` make for ``domain`` in size,
    agents, targets, walls and levels, each as ``"field value (label trained value)"``; empty when it fits."""
    import gymnasium

    import embodied_adhoc.envs  # noqa: F401  (registers the ids)
    from embodied_adhoc.learning.vector_grid import GRID_IDS

    probe = gymnasium.make(GRID_IDS[domain], **env_kwargs)
    trained = probe.unwrapped.core.rules.config
    probe.close()
    return [
        f"{field} {getattr(grid, field)} ({label} {getattr(trained, field)})"
        for field in _GRID_FIELDS
        if getattr(grid, field) != getattr(trained, field)
    ]


def library_agent(
    domain: str, folder: str | Path | None, grid, name: str = "atlpo-mf", known: int | None = None
) -> AtlpoAgent:
    """The ATLPO agent of the library in ``folder`` (None: the shipped one, :func:`shipped_library`) for an
    episode on the grid ``grid`` (a ``GridConfig``): the library must be of ``domain``, have its classifier and
    have been trained on the same grid (size, agents, targets, walls, levels), else one line saying which.
    Libraries are loaded once per process (the trial runner asks for one agent per trial)."""
    folder = shipped_library(domain) if folder is None else Path(folder)
    manifest = folder / "library.json"
    key = (str(folder.resolve()), manifest.stat().st_mtime if manifest.exists() else 0.0)
    if key not in _LOADED:
        _LOADED[key] = load_library(folder)
    library, classifier = _LOADED[key]
    if library.domain != domain:
        raise ConfigError(
            f"{manifest}: a {library.domain} library; {domain} needs one trained with --domain {domain}"
        )
    if classifier is None:
        raise ConfigError(
            f"{manifest}: the library has no classifier yet; rerun `embodied-adhoc train atlpo` on it"
        )
    differ = grid_differences(domain, library.env_kwargs, grid, "library")
    if differ:
        raise ConfigError(
            f"{manifest}: trained on another grid: {', '.join(differ)}; use the library's grid or "
            "train a library on this one (train_library's env_kwargs)"
        )
    return AtlpoAgent(library, classifier, name=name, known=known)
