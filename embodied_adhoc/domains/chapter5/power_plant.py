"""The abandoned power plant (section 5.2.5): a robot (the ad hoc agent) and a human explore or clean a plant.

The plant is the lab's 5-node graph (:data:`~embodied_adhoc.domains.lab_graph.DEFAULT_GRAPH`: door, open space,
robot station, single and double workbench; moves "to the k-th lowest-index neighbour", falling back to the
lowest). Two tasks, each with its own state space (Table 5.2: 105 and 97 states):

* **explore** rooms 0, 1, 4: state ``(robot, human, e_0, e_1, e_4)``; a room is explored once either agent
  enters it, so a state with an agent in an unexplored room does not exist: 104 states + absorbing = 105;
* **clean** rooms 2, 4: state ``(robot, human, d_2, d_4)``; a room is cleaned when both agents are in it, so
  both in a dirty room does not exist: 96 states + absorbing = 97.

Robot actions: move to neighbour 1..3 (succeeds w.p. ``1 - eps``, else stays), stay, locate human, locate robot
(the two queries keep the robot in place). The human (the teammate) moves deterministically, following the task's
MMDP-optimal policy (``library.optimal_teammate_policy``; the original took the first optimal joint action).
A state with every room explored / cleaned is the goal: +100, then the absorbing state (``library.step_rewards``).

Observations (6): ``-1`` (nothing) or a room 0..4. After a move or stay the robot reads its own room w.p.
``1 - eps``, else nothing; after a query the human answers the asked room w.p. ``1 - eps``, else each of the five
other values w.p. ``eps / 5``. The absorbing state reads nothing. (The original's move observation spread ``eps``
over indices ``-1 .. degree - 1`` instead of over "nothing": we follow the thesis's text.)

The two tasks do not share states, so BOPA does not apply (Table 5.5: n/a). So that ATPO and the other agents run
unchanged, the library's models are padded to the larger state space with unreachable states (self-loops, zero
initial probability, reading nothing); ``native_pomdps`` keeps them at their own sizes (what ``pomdp export``
writes).
"""

from __future__ import annotations

import itertools

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.domains.chapter5.library import (
    DISCOUNT,
    ModelLibrary,
    joint_mdp,
    optimal_teammate_policy,
    reduce_joint,
    step_rewards,
)
from embodied_adhoc.domains.lab_graph import DEFAULT_GRAPH, LabGraph

__all__ = ["TASKS", "build_power_plant", "pad_pomdp"]

TASKS = {"explore": (0, 1, 4), "clean": (2, 4)}
ACTION_NAMES = ("move-1", "move-2", "move-3", "stay", "locate-human", "locate-robot")
N_MOVES = 3
STAY, LOCATE_HUMAN, LOCATE_ROBOT = 3, 4, 5
N_HUMAN_ACTIONS = 4


def _states(graph: LabGraph, rooms: tuple[int, ...], task: str) -> list[tuple]:
    states = []
    for robot, human in itertools.product(range(graph.n_nodes), repeat=2):
        for bits in itertools.product((0, 1), repeat=len(rooms)):
            status = dict(zip(rooms, bits, strict=True))
            if task == "explore":
                valid = all(status.get(node, 1) == 1 for node in (robot, human))
            else:
                valid = not (robot == human and status.get(robot, 1) == 0)
            if valid:
                states.append((robot, human, *bits))
    return states


def _update_rooms(task: str, rooms: tuple[int, ...], bits: tuple, robot: int, human: int) -> tuple:
    if task == "explore":
        return tuple(1 if bit or node in (robot, human) else 0 for node, bit in zip(rooms, bits, strict=True))
    return tuple(1 if bit or node == robot == human else 0 for node, bit in zip(rooms, bits, strict=True))


def _task_pomdp(graph: LabGraph, task: str, noise: float) -> tuple[POMDP, object]:
    rooms = TASKS[task]
    states = _states(graph, rooms, task)
    index = {state: k for k, state in enumerate(states)}
    absorbing = len(states)
    n_states = absorbing + 1
    goal = np.array([all(s[2:]) for s in states] + [False])
    rewards = step_rewards(goal, absorbing, len(ACTION_NAMES))
    joint = []
    for a in range(len(ACTION_NAMES)):
        per_action = []
        for b in range(N_HUMAN_ACTIONS):
            rows, cols, probs = [], [], []
            for x, (robot, human, *bits) in enumerate(states):
                if goal[x]:
                    rows.append(x), cols.append(absorbing), probs.append(1.0)
                    continue
                next_human = graph.move_target(human, b) if b < N_MOVES else human
                robot_outcomes = [(robot, 1.0)]
                if a < N_MOVES:
                    robot_outcomes = [(graph.move_target(robot, a), 1.0 - noise), (robot, noise)]
                for next_robot, p in robot_outcomes:
                    nxt = (
                        next_robot,
                        next_human,
                        *_update_rooms(task, rooms, tuple(bits), next_robot, next_human),
                    )
                    rows.append(x), cols.append(index[nxt]), probs.append(p)
            rows.append(absorbing), cols.append(absorbing), probs.append(1.0)
            per_action.append(sp.csr_matrix((probs, (rows, cols)), shape=(n_states, n_states)))
        joint.append(per_action)
    mmdp = joint_mdp(joint, rewards)
    policy = optimal_teammate_policy(mmdp, len(ACTION_NAMES))
    transitions = reduce_joint(joint, policy)
    observations = [_observations(states, a, noise) for a in range(len(ACTION_NAMES))]
    initial = np.zeros(n_states)
    start = (0, 0, *_update_rooms(task, rooms, (0,) * len(rooms), 0, 0))
    initial[index[start]] = 1.0
    names = tuple(f"r{s[0]}h{s[1]}-" + "".join(map(str, s[2:])) for s in states) + ("absorbing",)
    z_names = ("nothing",) + tuple(f"room{n}" for n in range(graph.n_nodes))
    pomdp = POMDP(transitions, rewards, DISCOUNT, names, ACTION_NAMES, observations, initial, z_names)
    return pomdp, mmdp


def _observations(states: list[tuple], action: int, noise: float) -> sp.csr_matrix:
    """``O(z | y, a)``; z = 0 is "nothing", z = 1 + room."""
    n_states = len(states) + 1
    matrix = np.zeros((n_states, 6))
    matrix[-1, 0] = 1.0
    for y, (robot, human, *_bits) in enumerate(states):
        if action in (LOCATE_HUMAN, LOCATE_ROBOT):
            answer = human if action == LOCATE_HUMAN else robot
            matrix[y] = noise / 5
            matrix[y, 1 + answer] = 1.0 - noise
        else:
            matrix[y, 1 + robot] = 1.0 - noise
            matrix[y, 0] += noise
    return sp.csr_matrix(matrix)


def pad_pomdp(pomdp: POMDP, n_states: int) -> POMDP:
    """``pomdp`` with unreachable states appended up to ``n_states`` (self-loops, reward 0, reading z = 0)."""
    extra = n_states - pomdp.n_states
    if extra == 0:
        return pomdp
    loops = sp.identity(extra, format="csr")
    transitions = [sp.block_diag([t, loops], format="csr") for t in pomdp.transitions]
    padding = sp.csr_matrix(
        (np.ones(extra), (np.arange(extra), np.zeros(extra, dtype=int))), shape=(extra, pomdp.n_observations)
    )
    observations = [sp.vstack([o, padding], format="csr") for o in pomdp.observations]
    rewards = np.vstack([pomdp.rewards, np.zeros((extra, pomdp.n_actions))])
    names = pomdp.state_names + tuple(f"unused{k}" for k in range(extra))
    initial = np.append(pomdp.initial_belief, np.zeros(extra))
    return POMDP(
        transitions,
        rewards,
        pomdp.discount,
        names,
        pomdp.action_names,
        observations,
        initial,
        pomdp.observation_names,
    )


def build_power_plant(noise: float = 0.20, horizon: int = 50, n_beliefs: int = 2500) -> ModelLibrary:
    """The two-task library of Table 5.2 (eps 0.2, h 50, 2,500 beliefs); see the module docstring."""
    built = [_task_pomdp(DEFAULT_GRAPH, task, noise) for task in TASKS]
    native = tuple(pomdp for pomdp, _ in built)
    size = max(p.n_states for p in native)
    padded = tuple(pad_pomdp(p, size) for p in native)
    return ModelLibrary(
        "power-plant",
        tuple(TASKS),
        padded,
        tuple(m for _, m in built),
        horizon,
        noise,
        n_beliefs,
        native[0].n_states - 1,
        "abandoned power plant: a robot helps a human explore (105 states) or clean (97 states) the lab graph",
        {"noise": noise, "native_states": [p.n_states for p in native]},
        native,
        tuple(p.n_states - 1 for p in native),
    )
