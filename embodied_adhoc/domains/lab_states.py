"""The lab's state space: ONE indexing shared by every task of a library.

A world state is ``(n_robot, n_human, w_1..w_K)`` with ``w_i`` in {ground, held, disposed}. It is valid for a task
when the human holds at most one ball and only while standing at that ball's node (260 states per task for the
default lab). A model state adds one bit, ``rfid_event``: "a ball entered the container in the transition that
led here". The RFID observation depends on that event, which is not a function of the world state alone; carrying
it in the state keeps the POMDPs standard (``O(z | x', a)``) and exact. It can be 1 only right after a hand-over:
robot and human at the same node, a ball of this task at that node disposed, no ball held (12 extra states per
default task, so each task's POMDP has 272 valid states).

The index space is the union over the library of the tasks' valid model states in lexicographic order of
``(n_robot, n_human, w_1..w_K, rfid_event)``: index ``s`` means the same concrete state in every task (the
original implementation enumerated each task separately and then added beliefs index by index, a bug).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from embodied_adhoc.domains.lab_graph import DISPOSED, GROUND, HELD, LabGraph
from embodied_adhoc.errors import ConfigError

__all__ = ["LabStateSpace"]


@dataclass(frozen=True, eq=False)
class LabStateSpace:
    """Arrays describing every model state (length ``n_states``) and per-task validity masks."""

    n_nodes: int
    n_balls: int
    robot_node: np.ndarray  # (S,)
    human_node: np.ndarray  # (S,)
    ball_status: np.ndarray  # (S, K)
    rfid_event: np.ndarray  # (S,) bool
    valid: np.ndarray  # (M, S) bool: valid model state of task m
    _index_of_code: np.ndarray  # code -> index (-1: not in the union)

    @classmethod
    def build(cls, graph: LabGraph, tasks: Sequence[tuple[int, ...]]) -> LabStateSpace:
        n, k = graph.n_nodes, len(tasks[0])
        grid = np.array(
            list(itertools.product(range(n), range(n), *([range(3)] * k), range(2))), dtype=np.int64
        )
        robot, human, status, event = grid[:, 0], grid[:, 1], grid[:, 2 : 2 + k], grid[:, 2 + k].astype(bool)
        held = status == HELD
        valid = []
        for balls in tasks:
            at_ball = human[:, None] == np.asarray(balls)[None, :]
            world_ok = (held.sum(axis=1) <= 1) & np.all(~held | at_ball, axis=1)
            just_disposed = (
                (robot == human) & ~held.any(axis=1) & np.any((status == DISPOSED) & at_ball, axis=1)
            )
            valid.append(world_ok & (~event | just_disposed))
        valid = np.array(valid)
        keep = valid.any(axis=0)
        index_of_code = np.full(len(grid), -1, dtype=np.int64)
        index_of_code[np.flatnonzero(keep)] = np.arange(int(keep.sum()))
        arrays = [robot[keep], human[keep], status[keep], event[keep], valid[:, keep], index_of_code]
        for array in arrays:
            array.setflags(write=False)
        return cls(n, k, *arrays)

    @property
    def n_states(self) -> int:
        return len(self.robot_node)

    def world_valid(self, task: int) -> np.ndarray:
        """Mask of the task's valid *world* states (rfid_event = 0): 260 per default task."""
        return self.valid[task] & ~self.rfid_event

    def index(
        self, robot_node: int, human_node: int, ball_status: Sequence[int], rfid_event: bool = False
    ) -> int:
        """The shared index of a state; ConfigError if no task of the library allows it."""
        status = tuple(int(s) for s in ball_status)
        if len(status) != self.n_balls or any(s not in (GROUND, HELD, DISPOSED) for s in status):
            raise ConfigError(f"ball_status {status} must have {self.n_balls} entries in {{0, 1, 2}}")
        if not (0 <= robot_node < self.n_nodes and 0 <= human_node < self.n_nodes):
            raise ConfigError(f"nodes ({robot_node}, {human_node}) outside 0..{self.n_nodes - 1}")
        index = self.fast_index(robot_node, human_node, status, rfid_event)
        if index < 0:
            raise ConfigError(
                f"state (robot {robot_node}, human {human_node}, balls {status}, rfid {bool(rfid_event)}) "
                "is valid in no task of the library"
            )
        return index

    def fast_index(
        self, robot_node: int, human_node: int, ball_status: tuple[int, ...], rfid_event: bool
    ) -> int:
        """:meth:`index` without validation (-1 for a state outside the union), for inner loops."""
        code = robot_node * self.n_nodes + human_node
        for s in ball_status:
            code = code * 3 + s
        return int(self._index_of_code[code * 2 + (1 if rfid_event else 0)])

    def describe(self, index: int) -> tuple[int, int, tuple[int, ...], bool]:
        """``(robot_node, human_node, ball_status, rfid_event)`` of a state index."""
        return (
            int(self.robot_node[index]),
            int(self.human_node[index]),
            tuple(int(s) for s in self.ball_status[index]),
            bool(self.rfid_event[index]),
        )

    def names(self) -> tuple[str, ...]:
        labels = {GROUND: "g", HELD: "h", DISPOSED: "d"}
        return tuple(
            f"r{r}h{h}{''.join(labels[int(s)] for s in w)}{'+' if e else ''}"
            for r, h, w, e in zip(
                self.robot_node, self.human_node, self.ball_status, self.rfid_event, strict=True
            )
        )
