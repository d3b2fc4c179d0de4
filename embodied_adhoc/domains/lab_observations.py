"""What the lab robot observes, defined once for the model, the abstract simulator and the embodied env.

An observation is ``z = (robot node, human node, rfid)`` (thesis section 7.1, "the observations"):

* robot node: the true node with probability ``robot_node_accuracy`` (0.99), else unknown (the thesis's model);
  or, with ``localisation_model`` ("measured" or a JSON path), the row of a measured confusion matrix of the
  robot's localiser (true area x reported area + unknown; :func:`load_localisation_model`);
* human node: with communication, only after "locate human": a column drawn from the speech confusion-matrix
  row of the human's true node ("failed" reads as none); without communication the human is seen only when
  co-located with the robot (then the human node is the robot's true node); otherwise none;
* rfid: 1 iff a ball entered the container in this transition (missed with probability ``rfid_miss``).

The flat index is ``(robot * (N + 1) + human) * 2 + rfid`` with ``N`` standing for unknown/none; the vector form
is ``MultiDiscrete([N + 1, N + 1, 2])``.
"""

from __future__ import annotations

import bisect
import itertools
from dataclasses import dataclass

import numpy as np

from embodied_adhoc.domains.confusion import ConfusionMatrix, load_confusion
from embodied_adhoc.errors import ConfigError

__all__ = [
    "MEASURED_LOCALISATION",
    "LabObservation",
    "ObservationConfig",
    "ObservationModel",
    "load_localisation_model",
    "observation_names",
]

MEASURED_LOCALISATION = "data/localisation_confusion_measured.json"
"""The robot-node confusion of the physics lab's localiser, measured by ``scripts/bench_faults.py --confusion-out``
(schema of ``domains.confusion``; the last column is "unknown")."""


def load_localisation_model(source: str) -> ConfusionMatrix:
    """The robot-node confusion matrix: ``"measured"`` = :data:`MEASURED_LOCALISATION`, else a JSON path."""
    from embodied_adhoc import paths

    if source == "measured":
        try:
            return load_confusion(paths.asset(MEASURED_LOCALISATION))
        except FileNotFoundError:
            raise ConfigError(
                f"localisation_model='measured': {MEASURED_LOCALISATION} is missing; run "
                "scripts/bench_faults.py --confusion-out assets/data/localisation_confusion_measured.json or "
                "pass a JSON path"
            ) from None
    from pathlib import Path

    if not Path(source).exists():  # a device or a pipe goes on to the loader, which reads it up to its cap
        raise ConfigError(
            f"localisation_model={source!r}: no such file; use 'measured' or the path of a robot-node confusion JSON "
            "(scripts/bench_faults.py --confusion-out writes one)"
        )
    return load_confusion(source)


@dataclass(frozen=True)
class LabObservation:
    """One observation; ``None`` means unknown (robot) / none (human)."""

    robot_node: int | None
    human_node: int | None
    rfid: bool
    n_nodes: int = 5

    def __post_init__(self) -> None:
        for name in ("robot_node", "human_node"):
            value = getattr(self, name)
            if value is not None and not 0 <= value < self.n_nodes:
                raise ConfigError(f"LabObservation.{name} = {value} outside 0..{self.n_nodes - 1} (or None)")

    def to_vector(self) -> np.ndarray:
        """``[robot, human, rfid]`` with ``n_nodes`` for unknown/none (the Gymnasium MultiDiscrete form)."""
        robot = self.n_nodes if self.robot_node is None else self.robot_node
        human = self.n_nodes if self.human_node is None else self.human_node
        return np.array([robot, human, int(self.rfid)], dtype=np.int64)

    def encode(self) -> int:
        """The flat observation index the agents consume."""
        robot, human, rfid = (int(v) for v in self.to_vector())
        return (robot * (self.n_nodes + 1) + human) * 2 + rfid

    @classmethod
    def from_vector(cls, vector, n_nodes: int = 5) -> LabObservation:
        robot, human, rfid = (int(v) for v in vector)
        if not (0 <= robot <= n_nodes and 0 <= human <= n_nodes and rfid in (0, 1)):
            raise ConfigError(
                f"observation vector {list(vector)} outside MultiDiscrete([{n_nodes + 1}, {n_nodes + 1}, 2])"
            )
        return cls(
            None if robot == n_nodes else robot, None if human == n_nodes else human, bool(rfid), n_nodes
        )

    @classmethod
    def decode(cls, index: int, n_nodes: int = 5) -> LabObservation:
        """Inverse of :meth:`encode`."""
        count = 2 * (n_nodes + 1) ** 2
        if not 0 <= int(index) < count:
            raise ConfigError(f"observation index {index} outside 0..{count - 1}")
        rest, rfid = divmod(int(index), 2)
        robot, human = divmod(rest, n_nodes + 1)
        return cls.from_vector((robot, human, rfid), n_nodes)


def observation_names(n_nodes: int) -> tuple[str, ...]:
    names = []
    for index in range(2 * (n_nodes + 1) ** 2):
        obs = LabObservation.decode(index, n_nodes)
        robot = "?" if obs.robot_node is None else obs.robot_node
        human = "-" if obs.human_node is None else obs.human_node
        names.append(f"r{robot}h{human}{'+rfid' if obs.rfid else ''}")
    return tuple(names)


@dataclass(frozen=True)
class ObservationConfig:
    """The sensor fields of ``domains.lab.LabConfig`` (which defines and checks them, with their defaults)."""

    communication: bool
    robot_node_accuracy: float
    rfid_miss: float
    confusion: str
    localisation_model: str | None = None


class ObservationModel:
    """The three independent factors of ``O(z | x', a)``, as small probability vectors per end-state feature.

    The lab model multiplies them into its observation matrices; the simulators sample them. ``locate_action``
    is the index of "locate human" (None without communication).
    """

    def __init__(self, config: ObservationConfig, n_nodes: int, locate_action: int | None) -> None:
        self.config = config
        self.n_nodes = n_nodes
        self.locate_action = locate_action
        self.confusion: ConfusionMatrix | None = None
        if config.communication:
            self.confusion = load_confusion(config.confusion)
            if self.confusion.n_nodes != n_nodes:
                raise ConfigError(
                    f"confusion matrix '{config.confusion}' has {self.confusion.n_nodes} nodes, "
                    f"the graph has {n_nodes}; "
                    "give a matrix with one row per graph node"
                )
        self.localisation: ConfusionMatrix | None = None
        if config.localisation_model is not None:
            self.localisation = load_localisation_model(config.localisation_model)
            if self.localisation.n_nodes != n_nodes:
                raise ConfigError(
                    f"localisation model '{config.localisation_model}' has {self.localisation.n_nodes} nodes, the "
                    f"graph has {n_nodes}; give a matrix with one row per graph node"
                )
            self._robot = self.localisation.matrix.copy()
        else:
            accuracy = config.robot_node_accuracy
            self._robot = np.zeros((n_nodes, n_nodes + 1))
            self._robot[np.arange(n_nodes), np.arange(n_nodes)] = accuracy
            self._robot[:, n_nodes] += 1.0 - accuracy
        self._rfid = np.array([[1.0, 0.0], [config.rfid_miss, 1.0 - config.rfid_miss]])
        none = np.zeros(n_nodes + 1)
        none[n_nodes] = 1.0
        self._none = none
        self._cumulative: dict[tuple[int, int, bool, int], list[float]] = {}
        self._vectors = tuple(
            LabObservation.decode(z, n_nodes).to_vector() for z in range(2 * (n_nodes + 1) ** 2)
        )

    def robot(self, robot_node: int) -> np.ndarray:
        """P(robot reading | true robot node), length N + 1 (last: unknown)."""
        return self._robot[robot_node]

    def human(self, robot_node: int, human_node: int, action: int) -> np.ndarray:
        """P(human reading | true nodes, action), length N + 1 (last: none)."""
        if self.config.communication:
            return self.confusion.matrix[human_node] if action == self.locate_action else self._none
        if robot_node == human_node:
            seen = np.zeros(self.n_nodes + 1)
            seen[robot_node] = 1.0
            return seen
        return self._none

    def rfid(self, disposed: bool) -> np.ndarray:
        """P(rfid flag | a ball entered the container in this transition), length 2."""
        return self._rfid[int(disposed)]

    def distribution(self, robot_node: int, human_node: int, disposed: bool, action: int) -> np.ndarray:
        """The full ``O(. | x', a)`` over flat indices (length ``2 (N + 1)^2``)."""
        joint = np.multiply.outer(
            np.multiply.outer(self.robot(robot_node), self.human(robot_node, human_node, action)),
            self.rfid(disposed),
        )
        return joint.ravel()

    def sample_index(
        self, rng: np.random.Generator, robot_node: int, human_node: int, disposed: bool, action: int
    ) -> int:
        """Draw one flat observation index (one uniform draw from ``rng``; cumulative tables cached per case)."""
        key = (robot_node, human_node, bool(disposed), action)
        cumulative = self._cumulative.get(key)
        if cumulative is None:
            cumulative = list(itertools.accumulate(self.distribution(*key).tolist()))
            self._cumulative[key] = cumulative
        index = bisect.bisect_right(cumulative, rng.random() * cumulative[-1])
        return min(index, len(cumulative) - 1)

    def vector(self, index: int) -> np.ndarray:
        """The MultiDiscrete vector of a flat index (a fresh array)."""
        return self._vectors[index].copy()

    def sample(
        self, rng: np.random.Generator, robot_node: int, human_node: int, disposed: bool, action: int
    ) -> LabObservation:
        """Draw one observation as a :class:`LabObservation`."""
        return LabObservation.decode(
            self.sample_index(rng, robot_node, human_node, disposed, action), self.n_nodes
        )
