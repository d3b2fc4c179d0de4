"""The HOTSPOT toxic-waste lab as a library of task models, built from rules (thesis section 7.1).

``build_lab_library()`` returns, per task (ball placement), the MMDP with joint robot-human actions, the
single-agent MDP with the human averaged out over its optimal actions (the transitions P̄_m of Eq. 7.1) and the
POMDP over the robot's observations. All tasks share states, actions and observations (see ``lab_states``).

Robot actions: ``0..D-1`` move to the (k+1)-th lowest-index neighbour (D = the graph's max degree, 3 for the lab;
a k beyond a node's degree falls back to the lowest), ``D`` stay, ``D + 1`` locate human (with communication).
Robot moves are deterministic. A held ball goes into the container when the robot is at the human's node at the
start of the step and stays or asks. Reward (``LabReward``): -1 per ball on the ground, -2 per held ball, 0 per
disposed ball, as a function of the state before the step; gamma = 0.95. Libraries are cached per configuration.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np
import scipy.sparse as sp

from embodied_adhoc import checks
from embodied_adhoc.decision.models import MDP, POMDP
from embodied_adhoc.domains.confusion import DEFAULT_CONFUSION
from embodied_adhoc.domains.lab_graph import (
    DEFAULT_GRAPH,
    DEFAULT_TASKS,
    DISPOSED,
    GROUND,
    HELD,
    LabGraph,
    validate_tasks,
)
from embodied_adhoc.domains.lab_human import HumanOutcome, LabHuman
from embodied_adhoc.domains.lab_observations import (
    LabObservation,
    ObservationConfig,
    ObservationModel,
    observation_names,
)
from embodied_adhoc.domains.lab_states import LabStateSpace
from embodied_adhoc.errors import ConfigError

__all__ = [
    "DEFAULT_GRAPH",
    "DEFAULT_TASKS",
    "LAB_PARAMETERS",
    "RESET_OPTIONS",
    "LabConfig",
    "LabGraph",
    "LabLibrary",
    "LabObservation",
    "LabReward",
    "ObservationConfig",
    "apply_step",
    "average_over_teammate",
    "build_lab_library",
]


@dataclass(frozen=True)
class LabReward:
    """Per-ball reward by status (thesis: -1 ground, -2 held, 0 disposed)."""

    ground: float = -1.0
    held: float = -2.0
    disposed: float = 0.0

    def of(self, ball_status: np.ndarray) -> np.ndarray:
        table = np.array([self.ground, self.held, self.disposed])
        return table[np.asarray(ball_status)].sum(axis=-1)


@dataclass(frozen=True)
class LabConfig:
    """The lab's parameters with their defaults, defined once (thesis section 7.1).

    :func:`build_lab_library` takes them (same order), the abstract and the physics toxic-waste env take them as
    their kwargs (:meth:`from_kwargs`) and the ``trials toxic-waste`` options map onto them. Values are checked
    here, so every entry point refuses the same bad input with the same message (``communication="no"``,
    ``human_epsilon=2``, a ball outside the graph). Hashable: libraries are cached per configuration.

    ``confusion``: "measured" (default), "thesis" or a JSON path (``domains.confusion``); ``robot_node_accuracy``:
    probability that the robot-node reading is reported (else unknown): the model's robot-node factor and the
    physics robot's area sensor (``sim.area_sensor``) read this one number; ``rfid_miss``: probability that the
    container's reader misses a ball going in; ``localisation_model``: None (the ``robot_node_accuracy`` factor),
    "measured" or a JSON path: the robot-node factor is the localiser's measured confusion
    (``domains.lab_observations.load_localisation_model``), and the physics robot's area sensor drops nothing.
    """

    graph: LabGraph = DEFAULT_GRAPH
    tasks: tuple[tuple[int, ...], ...] = DEFAULT_TASKS
    human_epsilon: float = 0.05
    communication: bool = True
    confusion: str = DEFAULT_CONFUSION
    robot_node_accuracy: float = 0.99
    rfid_miss: float = 0.0
    localisation_model: str | None = None
    reward: LabReward = LabReward()
    discount: float = 0.95

    def __post_init__(self) -> None:
        if not isinstance(self.graph, LabGraph):
            raise ConfigError(f"graph={self.graph!r}: must be a domains.lab_graph.LabGraph")
        if not isinstance(self.reward, LabReward):
            raise ConfigError(f"reward={self.reward!r}: must be a domains.lab.LabReward")
        if not isinstance(self.confusion, (str, os.PathLike)):
            raise ConfigError(f"confusion={self.confusion!r}: use 'measured', 'thesis' or a JSON path")
        if self.localisation_model is not None and not isinstance(
            self.localisation_model, (str, os.PathLike)
        ):
            raise ConfigError(
                f"localisation_model={self.localisation_model!r}: use None, 'measured' or a JSON path"
            )
        discount = checks.number("discount", self.discount, 0.0, 1.0)
        if discount >= 1.0:
            raise ConfigError(f"discount must lie in [0, 1), got {self.discount}")
        normalised = {
            "tasks": validate_tasks(self.graph, self.tasks),
            "human_epsilon": checks.number("human_epsilon", self.human_epsilon, 0.0, 1.0),
            "communication": checks.flag("communication", self.communication),
            "confusion": os.fspath(self.confusion),
            "robot_node_accuracy": checks.number("robot_node_accuracy", self.robot_node_accuracy, 0.0, 1.0),
            "rfid_miss": checks.number("rfid_miss", self.rfid_miss, 0.0, 1.0),
            "localisation_model": None
            if self.localisation_model is None
            else os.fspath(self.localisation_model),
            "discount": discount,
        }
        for name, value in normalised.items():
            object.__setattr__(self, name, value)

    @classmethod
    def from_kwargs(cls, where: str, kwargs: dict) -> LabConfig:
        """The configuration of keyword arguments given to ``where`` (unknown names refused)."""
        checks.refuse_unknown(where, kwargs, LAB_PARAMETERS)
        return cls(**kwargs)

    @property
    def observation(self) -> ObservationConfig:
        return ObservationConfig(
            self.communication,
            self.robot_node_accuracy,
            self.rfid_miss,
            self.confusion,
            self.localisation_model,
        )


LAB_PARAMETERS = tuple(f.name for f in fields(LabConfig))
"""The names of the lab's parameters (the toxic-waste envs' lab kwargs)."""


def apply_step(
    graph: LabGraph,
    robot_node: int,
    human_node: int,
    ball_status: tuple[int, ...],
    robot_action: int,
    human: HumanOutcome,
) -> tuple[int, int, tuple[int, ...], bool]:
    """The joint transition rule given the human's sampled step: ``(robot', human', status', disposed)``.

    Used by the model builder (for every outcome) and by the simulators (for the sampled one).
    """
    stay = graph.max_degree
    next_robot = graph.move_target(robot_node, robot_action) if robot_action < stay else robot_node
    status = list(ball_status)
    disposed = False
    if HELD in status:
        if robot_node == human_node and robot_action >= stay:  # stay or locate human: the hand-over
            status[status.index(HELD)] = DISPOSED
            disposed = True
        elif human.dropped:  # a human that lets the ball fall: on the ground again, where it was picked up
            status[status.index(HELD)] = GROUND
        return next_robot, human_node, tuple(status), disposed
    if human.picked_ball >= 0:
        status[human.picked_ball] = HELD
    return next_robot, human.next_node, tuple(status), disposed


def average_over_teammate(joint: Sequence[sp.csr_matrix], policy: np.ndarray) -> sp.csr_matrix:
    """Eq. 7.1's averaged transitions ``P̄(y | x, a) = sum_h pi(h | x) P(y | x, a, h)`` for one robot action.

    ``joint[h]`` is ``P(. | ., a, h)``; ``policy`` (S x H) is the teammate's distribution over its actions, here
    uniform over its optimal actions A*(x).
    """
    return sum(sp.diags(policy[:, h]) @ joint[h] for h in range(len(joint))).tocsr()


RESET_OPTIONS = ("task", "robot_node", "human_node")
"""The ``reset(options=...)`` keys of the toxic-waste envs (abstract and physics)."""


@dataclass(frozen=True, eq=False)
class LabLibrary:
    """The task library: per-task MMDPs, averaged MDPs and POMDPs over one shared state/action/observation space."""

    config: LabConfig
    states: LabStateSpace
    humans: tuple[LabHuman, ...]
    observation_model: ObservationModel
    mmdps: tuple[MDP, ...]
    mdps: tuple[MDP, ...]
    pomdps: tuple[POMDP, ...]
    action_names: tuple[str, ...]

    graph = property(lambda self: self.config.graph)
    tasks = property(lambda self: self.config.tasks)
    n_tasks = property(lambda self: len(self.config.tasks))
    n_states = property(lambda self: self.states.n_states)
    n_actions = property(lambda self: len(self.action_names))
    n_observations = property(lambda self: self.pomdps[0].n_observations)
    stay_action = property(lambda self: self.config.graph.max_degree)

    @property
    def locate_action(self) -> int | None:
        return self.stay_action + 1 if self.config.observation.communication else None

    def encode_observation(self, observation: LabObservation) -> int:
        return observation.encode()

    def decode_observation(self, index: int) -> LabObservation:
        return LabObservation.decode(index, self.graph.n_nodes)

    def state_index(
        self, robot_node: int, human_node: int, ball_status: Sequence[int], rfid_event: bool = False
    ) -> int:
        return self.states.index(robot_node, human_node, ball_status, rfid_event)

    def episode_start(
        self, options: dict | None, fixed_task: int | None, rng: np.random.Generator
    ) -> tuple[int, int, int]:
        """``(task, robot_node, human_node)`` of a new episode, from Gymnasium ``reset`` options.

        Options ``task``, ``robot_node``, ``human_node`` fix them; what is not fixed (nor by ``fixed_task``) is
        drawn uniformly from ``rng`` in that order (the model's initial belief). Shared by the abstract and the
        physics env, so the same seed and options start both in the same place.
        """
        options = dict(options or {})
        checks.refuse_unknown("reset options", options, RESET_OPTIONS, what="option")
        n = self.graph.n_nodes
        task = options.get("task", fixed_task)
        task = int(rng.integers(self.n_tasks)) if task is None else task
        # Both nodes are drawn even when imposed, so the env's later draws do not depend on which were imposed.
        drawn_robot, drawn_human = int(rng.integers(n)), int(rng.integers(n))
        robot = options.get("robot_node", drawn_robot)
        human = options.get("human_node", drawn_human)
        task = checks.integer("reset option task", task, 0, self.n_tasks - 1)
        robot = checks.integer("reset option robot_node", robot, 0, n - 1)
        human = checks.integer("reset option human_node", human, 0, n - 1)
        return task, robot, human


def build_lab_library(graph: LabGraph = DEFAULT_GRAPH, /, **parameters) -> LabLibrary:
    """Build (or fetch from the per-process cache) the lab's task library; see the module docstring.

    ``parameters`` are the fields of :class:`LabConfig` (tasks, human_epsilon, communication, confusion,
    robot_node_accuracy, rfid_miss, reward, discount), with its defaults.
    """
    return library_from_config(LabConfig.from_kwargs("build_lab_library", {"graph": graph, **parameters}))


@functools.lru_cache(maxsize=32)
def library_from_config(config: LabConfig) -> LabLibrary:
    """The library of one :class:`LabConfig` (cached: building is deterministic)."""
    graph, tasks = config.graph, config.tasks
    states = LabStateSpace.build(graph, tasks)
    stay = graph.max_degree
    n_robot_actions = stay + (2 if config.observation.communication else 1)
    humans = tuple(LabHuman(graph, balls, config.human_epsilon) for balls in tasks)
    n_human_actions = humans[0].n_actions
    names = tuple(f"move to neighbour {k + 1}" for k in range(stay)) + ("stay",)
    names += ("locate human",) if config.observation.communication else ()
    observation_model = ObservationModel(
        config.observation, graph.n_nodes, stay + 1 if config.observation.communication else None
    )
    observations = _observation_matrices(states, observation_model, n_robot_actions)
    rewards = np.repeat(config.reward.of(states.ball_status)[:, None], n_robot_actions, axis=1)
    initial = (states.ball_status == GROUND).all(axis=1) & ~states.rfid_event
    initial_belief = initial / initial.sum()
    state_names, z_names = states.names(), observation_names(graph.n_nodes)
    mmdps, mdps, pomdps = [], [], []
    for task, human in enumerate(humans):
        joint, policy = _task_transitions(states, task, human, n_robot_actions)
        joint_names = tuple(f"{a} & human {h}" for a in names for h in human.action_names)
        mmdps.append(
            MDP(joint, np.repeat(rewards, n_human_actions, axis=1), config.discount, state_names, joint_names)
        )
        averaged = [
            average_over_teammate(joint[a * n_human_actions : (a + 1) * n_human_actions], policy)
            for a in range(n_robot_actions)
        ]
        mdps.append(MDP(averaged, rewards, config.discount, state_names, names))
        pomdps.append(
            POMDP(
                averaged, rewards, config.discount, state_names, names, observations, initial_belief, z_names
            )
        )
    return LabLibrary(
        config, states, humans, observation_model, tuple(mmdps), tuple(mdps), tuple(pomdps), names
    )


def _task_transitions(
    states: LabStateSpace, task: int, human: LabHuman, n_robot_actions: int
) -> tuple[list[sp.csr_matrix], np.ndarray]:
    """Joint transition matrices (index ``a * H + h``) and the human policy (S x H) of one task."""
    graph, n_states, n_human = human.graph, states.n_states, human.n_actions
    rows = [[] for _ in range(n_robot_actions * n_human)]
    cols = [[] for _ in range(n_robot_actions * n_human)]
    probs = [[] for _ in range(n_robot_actions * n_human)]
    policy = np.zeros((n_states, n_human))
    policy[:, human.stay_action] = 1.0
    for s in range(n_states):
        robot, human_node, status, _ = states.describe(s)
        if not states.valid[task, s]:  # unreachable under this task: a self-loop keeps rows stochastic
            for j in range(len(rows)):
                rows[j].append(s), cols[j].append(s), probs[j].append(1.0)
            continue
        optimal = human.optimal_actions(human_node, status)
        policy[s] = 0.0
        policy[s, list(optimal)] = 1.0 / len(optimal)
        for h in range(n_human):
            outcomes = human.outcomes(human_node, status, h)
            for a in range(n_robot_actions):
                j = a * n_human + h
                for outcome in outcomes:
                    nr, nh, ns, disposed = apply_step(graph, robot, human_node, status, a, outcome)
                    (
                        rows[j].append(s),
                        cols[j].append(states.fast_index(nr, nh, ns, disposed)),
                        probs[j].append(outcome.probability),
                    )
    joint = [
        sp.csr_matrix((probs[j], (rows[j], cols[j])), shape=(n_states, n_states)) for j in range(len(rows))
    ]  # duplicate (row, col) entries are summed
    return joint, policy


def _observation_matrices(
    states: LabStateSpace, model: ObservationModel, n_actions: int
) -> list[sp.csr_matrix]:
    """``O[a][x', z]`` from the observation factors, one row per distinct (robot, human, event) of x'."""
    features = np.stack([states.robot_node, states.human_node, states.rfid_event.astype(np.int64)], axis=1)
    unique, inverse = np.unique(features, axis=0, return_inverse=True)
    matrices = []
    for a in range(n_actions):
        rows = np.stack([model.distribution(int(r), int(h), bool(e), a) for r, h, e in unique])
        matrices.append(sp.csr_matrix(rows[inverse.ravel()]))
    return matrices
