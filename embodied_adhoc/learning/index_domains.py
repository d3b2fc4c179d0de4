"""The library-free agents on the benchmark's domains with observation indices: the toxic-waste lab (the abstract
env, ``EmbodiedAdhoc/ToxicWasteAbstract-v0``) and chapter 5's pursuit-task and ntu map (the true model as a
generative POMDP).

Both observe one flat index per step (the lab's ``[robot node, human node, rfid]`` encoded as the trials encode
it; the chapter-5 model's observation, none at reset), so the recurrent agents read an embedding of the index
(:class:`IndexNetworkConfig`) where the grid agents read a CNN over the egocentric window; the GRU, heads, PPO
and the auxiliaries are the grid agents' own (:mod:`~embodied_adhoc.learning.recurrent_ppo`). Input index 0
means "no observation yet" and ``z + 1`` the domain's index ``z``.

:class:`IndexVectorEnv` steps ``num_envs`` episodes at once with gymnasium's NEXT_STEP autoreset (as
:class:`~embodied_adhoc.learning.vector_grid.GridVectorEnv`). Each episode draws its teammate from the
benchmark's *train* split (:func:`embodied_adhoc.teammates.populations.members`), the first ``teammates`` members of
it in the population's order (all of them by default); validation and held-out members are refused. The lab's
episodes are the registered env's own, one env per (sub-env, member) with the member as its ``human``; the
chapter-5 episodes sample the joint model: the teammate's action ``b ~ pi(b | x)``, then
``y ~ P(. | x, a, b)`` and ``z ~ O(. | y, a)``, which is Fig. 5.2's reduced world (the trials' ``LibraryEnv``
with the member as ``--teammate``) with the teammate's action drawn explicitly. Training rewards are the env's
divided by :data:`REWARD_SCALE` (returns of order one for PPO's value loss); ``infos`` hold the ground truth
only with ``teammate_info=True``: ``teammate_observations`` (num_envs, 1), the teammate's own view as one class
(the lab's human: its node and every ball's status; chapter 5's teammate: the state it acts on) and
``teammate_actions`` (num_envs, 1) (the lab's human: the node it moves to; chapter 5: ``b``), for the LIAM and
MeLIBA decoders in training, never an agent's input.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning import LEARNED_CHAPTER5_DOMAINS
from embodied_adhoc.learning.generalist import _LOADED, GeneralistAgent, load_generalist, shipped_weights

LAB = "toxic-waste"
PURSUIT_TASK, NTU = LEARNED_CHAPTER5_DOMAINS
INDEX_DOMAINS = (LAB, *LEARNED_CHAPTER5_DOMAINS)
REWARD_SCALE = {LAB: 6.0, PURSUIT_TASK: 100.0, NTU: 100.0}
"""The largest reward magnitude of each domain: the lab's -2 per held ball for its three balls, chapter 5's +100
(the capture, the goal)."""
TEAMMATE_CLASSES = {LAB: (5 * 3**3, 5), PURSUIT_TASK: (626, 5), NTU: (241, 5)}
"""(classes of the teammate's view, of its action) in ``teammate_info``: the lab's human on 5 nodes with 3 balls of
3 statuses, moving to one of the 5 nodes; pursuit-task's 626 states, ntu's 241 (16 open cells, the two agents
on distinct cells, and the absorbing state) and 5 teammate moves."""
EPISODE_CAP = {LAB: 100, PURSUIT_TASK: 75, NTU: 75}
"""The step caps of the trials (the lab's registered 100; pursuit-task's and ntu's Table 5.2 horizon)."""


@dataclass(frozen=True)
class IndexNetworkConfig:
    """Sizes of an agent over observation indices: ``observations`` input indices (the domain's count plus the
    "none yet" 0), an embedding of ``features``, ``actions`` outputs."""

    observations: int
    actions: int = 5
    features: int = 64
    head_hidden: int = 0

    def __post_init__(self) -> None:
        for name in ("observations", "actions", "features"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ConfigError(f"IndexNetworkConfig.{name}={value!r}: give a positive integer")

    @property
    def observation_shape(self) -> tuple[int, ...]:
        return ()

    def make_encoder(self) -> nn.Module:
        return IndexEncoder(self)

    def flat_observations(self, observations: torch.Tensor) -> torch.Tensor:
        """(..., observations) one-hot rows of (...) indices: what a decoder reads of an observation."""
        return nn.functional.one_hot(observations.long(), self.observations).float()

    def as_dict(self) -> dict:
        return asdict(self)


class IndexEncoder(nn.Module):
    """An embedding of the observation index, then a ReLU: the index domains' counterpart of the grid's CNN."""

    def __init__(self, config: IndexNetworkConfig) -> None:
        super().__init__()
        self.embedding = nn.Embedding(config.observations, config.features)

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        return torch.relu(self.embedding(observations.long()))


def train_members(domain: str, teammates: int = 0) -> tuple:
    """The first ``teammates`` members (0: all) of ``domain``'s benchmark train split."""
    from embodied_adhoc.teammates.populations import members

    train = members(domain, "train")
    if not isinstance(teammates, int) or not 0 <= teammates <= len(train):
        raise ConfigError(
            f"--teammates {teammates}: give 1..{len(train)} (the train split of {domain} has {len(train)} "
            "members) or 0 for all"
        )
    return train[: teammates or len(train)]


def member_names(domain: str, teammates: int = 0) -> list[str]:
    return [spec.name for spec in train_members(domain, teammates)]


class IndexVectorEnv:
    """``num_envs`` episodes of an index domain against train members (see the module docstring); the training
    loop's vector env for :data:`INDEX_DOMAINS`. ``members`` names train members of ``domain``."""

    def __init__(
        self,
        domain: str,
        num_envs: int,
        members: list[str] | None = None,
        teammate_info: bool = False,
        max_episode_steps: int | None = None,
    ) -> None:
        from embodied_adhoc.teammates.populations import members as split_members

        if domain not in INDEX_DOMAINS:
            raise ConfigError(f"domain={domain!r}: use one of {', '.join(INDEX_DOMAINS)}")
        if not isinstance(num_envs, int) or num_envs < 1:
            raise ConfigError(f"num_envs={num_envs!r}: give a positive integer")
        train = {spec.name: spec for spec in split_members(domain, "train")}
        names = list(train) if members is None else list(members)
        unknown = [name for name in names if name not in train]
        if unknown or not names:
            raise ConfigError(
                f"teammates {unknown or names}: training sees only the train split of {domain} "
                f"({', '.join(train)})"
            )
        self.domain, self.num_envs, self.teammate_info = domain, num_envs, bool(teammate_info)
        self.specs = [train[name] for name in names]
        self.max_episode_steps = int(max_episode_steps or EPISODE_CAP[domain])
        self.scale = REWARD_SCALE[domain]
        if domain == LAB:
            self.world = _LabWorld(self.specs, num_envs, self.max_episode_steps)
        else:
            self.world = _Chapter5World(domain, self.specs, num_envs)
        if self.world.teammate_classes != TEAMMATE_CLASSES[domain]:
            raise ConfigError(
                f"{domain}: the teammate's view and action have {self.world.teammate_classes} classes, the "
                f"decoders {TEAMMATE_CLASSES[domain]}: the domain's defaults changed; update TEAMMATE_CLASSES"
            )
        self.n_observations = self.world.n_observations + 1  # 0: none yet
        self.n_actions = self.world.n_actions
        self.member = np.zeros(num_envs, np.int64)
        self.steps = np.zeros(num_envs, np.int64)
        self.needs_reset = np.zeros(num_envs, bool)
        self.observation = np.zeros(num_envs, np.int64)
        self.rngs: list[np.random.Generator] = []

    def _reset_one(self, index: int) -> None:
        self.member[index] = int(self.rngs[index].integers(len(self.specs)))
        self.observation[index] = self.world.reset(index, int(self.member[index]), self.rngs[index]) + 1
        self.steps[index] = 0
        self.needs_reset[index] = False

    def reset(self, *, seed: int | None = None):
        """Every sub-env reset; sub-env ``i``'s draws come from a Generator seeded ``(seed, i)``."""
        self.rngs = [np.random.default_rng([0 if seed is None else seed, i]) for i in range(self.num_envs)]
        self.world.seed(seed)
        for index in range(self.num_envs):
            self._reset_one(index)
        return self.observation.copy(), self._infos()

    def _infos(self) -> dict:
        return {"teammate": self.member.copy()}

    def step(self, actions):
        actions = np.asarray(actions)
        if actions.shape != (self.num_envs,) or np.any((actions < 0) | (actions >= self.n_actions)):
            raise ConfigError(f"actions {actions.tolist()!r}: need {self.num_envs} integers in 0..4")
        reward = np.zeros(self.num_envs)
        terminated, truncated = np.zeros(self.num_envs, bool), np.zeros(self.num_envs, bool)
        seen = np.zeros((self.num_envs, 1), np.int64)
        acted = np.zeros((self.num_envs, 1), np.int64)
        stepping = ~self.needs_reset
        for index in range(self.num_envs):
            if not stepping[index]:
                self._reset_one(index)
                continue
            z, r, done, view, move = self.world.step(index, int(actions[index]), self.rngs[index])
            self.observation[index], reward[index] = z + 1, r / self.scale
            seen[index, 0], acted[index, 0] = view, move
            self.steps[index] += 1
            terminated[index] = done
            truncated[index] = not done and self.steps[index] >= self.max_episode_steps
        self.needs_reset = terminated | truncated
        infos = self._infos()
        if self.teammate_info:
            infos.update(
                {
                    "teammate_observations": seen,
                    "teammate_actions": acted,
                    "_teammate_observations": stepping,
                    "_teammate_actions": stepping.copy(),
                }
            )
        return self.observation.copy(), reward, terminated, truncated, infos

    @property
    def teammate_classes(self) -> tuple[int, int]:
        """(classes of the teammate's observation, classes of its action) of ``teammate_info``."""
        return self.world.teammate_classes

    def close(self) -> None:
        self.world.close()


class _LabWorld:
    """The lab's episodes: one registered abstract env per (sub-env, member), the member as its human, made when
    first drawn; each env's own Generator is seeded once from (seed, sub-env, member) and then runs on."""

    def __init__(self, specs, num_envs: int, cap: int) -> None:
        import gymnasium

        import embodied_adhoc.envs  # noqa: F401  (registers the ids)

        self.specs, self.gymnasium, self.cap = specs, gymnasium, cap
        self.envs: dict[tuple[int, int], object] = {}
        self.current: list = [None] * num_envs
        probe = gymnasium.make("EmbodiedAdhoc/ToxicWasteAbstract-v0")
        library = probe.unwrapped.library
        self.n_nodes, self.balls = library.graph.n_nodes, len(library.tasks[0])
        self.n_observations = 2 * (self.n_nodes + 1) ** 2
        self.n_actions = library.n_actions
        self.teammate_classes = (self.n_nodes * 3**self.balls, self.n_nodes)
        probe.close()
        self.infos: list[dict | None] = [None] * num_envs  # each sub-env's last info (the human's view)

    def seed(self, seed: int | None) -> None:
        for env in self.envs.values():
            env.close()
        self.envs = {}

    def _index(self, vector) -> int:
        from embodied_adhoc.domains.lab_observations import LabObservation

        return LabObservation.from_vector(vector, self.n_nodes).encode()

    def reset(self, index: int, member: int, rng: np.random.Generator) -> int:
        key = (index, member)
        first = key not in self.envs
        if first:
            self.envs[key] = self.gymnasium.make(  # its TimeLimit at the vector env's cap, which ends first
                "EmbodiedAdhoc/ToxicWasteAbstract-v0",
                human=self.specs[member].plugin,
                max_episode_steps=self.cap,
            )
        env = self.envs[key]
        self.current[index] = env
        observation, self.infos[index] = env.reset(seed=int(rng.integers(2**31)) if first else None)
        return self._index(observation)

    def _teammate_view(self, info: dict) -> int:
        status = 0
        for position, ball in enumerate(info["ball_status"]):
            status += int(ball) * 3**position
        return int(info["human_node"]) * 3**self.balls + status

    def step(self, index: int, action: int, rng) -> tuple[int, float, bool, int, int]:
        before = self._teammate_view(self.infos[index])
        observation, reward, terminated, _, info = self.current[index].step(action)
        self.infos[index] = info
        return self._index(observation), float(reward), bool(terminated), before, int(info["human_node"])

    def close(self) -> None:
        for env in self.envs.values():
            env.close()


class _Chapter5World:
    """A chapter-5 domain's joint model (pursuit-task, ntu: the trials' default library) with each member's
    teammate policy (see the module docstring)."""

    def __init__(self, domain: str, specs, num_envs: int) -> None:
        from embodied_adhoc.domains.chapter5 import build_library

        self.library = library = build_library(domain)
        self.pomdps, self.mmdps = library.pomdps, library.mmdps
        self.n_models = len(self.pomdps)
        first = self.pomdps[0]
        self.n_observations, self.n_actions = first.n_observations, first.n_actions
        self.n_teammate = self.mmdps[0].n_actions // self.n_actions
        self.teammate_classes = (first.n_states, self.n_teammate)
        # each member's pi(b | x) per model, as cumulative rows for one draw each
        self.policies = [
            [
                np.cumsum(np.asarray(spec.factory()(library, m), dtype=np.float64), axis=1)
                for m in range(self.n_models)
            ]
            for spec in specs
        ]
        self.model = np.zeros(num_envs, np.int64)
        self.state = np.zeros(num_envs, np.int64)
        self.member = np.zeros(num_envs, np.int64)

    def seed(self, seed: int | None) -> None:
        return None

    def reset(self, index: int, member: int, rng: np.random.Generator) -> int:
        self.member[index] = member
        self.model[index] = int(rng.integers(self.n_models))
        self.state[index] = int(self.pomdps[self.model[index]].sample_initial_state(rng))
        return -1

    def step(self, index: int, action: int, rng) -> tuple[int, float, bool, int, int]:
        from embodied_adhoc.decision.models import _sample_row

        m, x = int(self.model[index]), int(self.state[index])
        row = self.policies[self.member[index]][m][x]
        b = min(int(np.searchsorted(row, rng.random() * row[-1], side="right")), self.n_teammate - 1)
        pomdp = self.pomdps[m]
        y = _sample_row(self.mmdps[m].transitions[action * self.n_teammate + b], x, rng)
        z = _sample_row(pomdp.observations[action], y, rng)
        self.state[index] = y
        return z, float(pomdp.rewards[x, action]), y == self.library.absorbing(m), x, b

    def close(self) -> None:
        return None


def index_domain(library) -> str | None:
    """The index domain whose trials hand an agent plug-in ``library`` (the lab's ``LabLibrary``, a chapter-5
    ``ModelLibrary`` of pursuit-task or ntu), or None."""
    if type(library).__name__ == "LabLibrary":
        return LAB
    domain = getattr(library, "domain", None)
    return domain if domain in LEARNED_CHAPTER5_DOMAINS else None


def first_index(observation, nodes: int = 5) -> int:
    """The input index of an episode's first observation as the episode loop hands it to ``start``: the lab's
    MultiDiscrete vector on ``nodes`` areas (encoded as the trials encode it), chapter 5's -1 (none yet)."""
    if np.ndim(observation) == 0:
        return int(observation) + 1
    from embodied_adhoc.domains.lab_observations import LabObservation

    return LabObservation.from_vector(observation, nodes).encode() + 1


def input_indices(library) -> int:
    """How many input indices an agent for ``library``'s domain reads: its observations plus "none yet"."""
    if index_domain(library) == LAB:
        return 2 * (library.graph.n_nodes + 1) ** 2 + 1
    return library.pomdps[0].n_observations + 1


class IndexAgent(GeneralistAgent):
    """A recurrent agent over observation indices: the loop hands it the domain's index ``z`` (it reads ``z + 1``,
    0 being "none yet") and the first raw observation through ``start``."""

    observes_raw = False
    nodes = 5  # the lab's areas, for its first observation's vector

    def start(self, observation) -> None:
        self._advance(first_index(observation, self.nodes), self.model.no_action, True)

    def observe(self, action: int, observation, state: int | None = None, **outcome) -> None:
        self._advance(int(observation) + 1, int(action), False)

    def _checked(self, observation) -> np.ndarray:
        size = self.model.config.observations
        if not 0 <= int(observation) < size:
            raise ConfigError(
                f"{self.name}: observation index {int(observation) - 1} outside the {size - 1} indices it "
                "was trained on (another domain's agent?)"
            )
        return np.asarray(int(observation), dtype=np.int64)


SHIPPED_COMMAND = (
    "embodied-adhoc train {kind} --domain {domain} --steps 98304 --envs 16 --seed 0 --threads 1 "
    "--out assets/{folder}/{domain}"
)
"""How each shipped agent of an index domain was made: the same env steps for the three agents on a domain."""

_KINDS = {
    "ppo-generalist": ("generalist", "embodied_adhoc.learning.generalist"),
    "liam": ("liam", "embodied_adhoc.learning.liam"),
    "meliba": ("meliba", "embodied_adhoc.learning.meliba"),
}


def index_agent(library, kind: str, path=None, name: str | None = None):
    """The ``kind`` agent (ppo-generalist, liam, meliba) of the weights at ``path`` (None: the shipped ones) for
    the index domain of ``library``; weights are read once per process."""
    import importlib
    from pathlib import Path

    domain = index_domain(library)
    if domain is None:
        raise ConfigError(
            f"{kind}: no index domain for a {type(library).__name__}; use {', '.join(INDEX_DOMAINS)}"
        )
    folder, module_name = _KINDS[kind]
    module = importlib.import_module(module_name)
    if path is None:
        command = SHIPPED_COMMAND.format(kind=kind, folder=folder, domain="{domain}")
        path = shipped_weights(domain, kind, folder, command)
    path = Path(path)
    key = (str(path.resolve()), path.stat().st_mtime if path.exists() else 0.0)
    if key not in _LOADED:
        _LOADED[key] = getattr(module, "load_meliba", load_generalist)(path, kind)
    model, metadata = _LOADED[key]
    if metadata["domain"] != domain:
        raise ConfigError(
            f"{path}: a {metadata['domain']} agent; {domain} needs one trained with --domain {domain}"
        )
    if model.config.observations != input_indices(library):
        raise ConfigError(
            f"{path}: trained on {model.config.observations - 1} observations; this {domain} has "
            f"{input_indices(library) - 1} (another lab graph or model?): train one on it"
        )
    agent = IndexAgent(model, name=name or kind)
    if domain == LAB:
        agent.nodes = library.graph.n_nodes
    return agent
