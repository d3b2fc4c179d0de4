"""Fig. 7.12's two-predator pursuit with the pursuit POMDP's own dynamics and observations, on the grid twin
(``EmbodiedAdhoc/PursuitPairPomdpGrid-v0``) and in the MuJoCo arena (``EmbodiedAdhoc/PursuitPairPomdp-v0``).

The world *is* the ``pursuit-task`` library of :mod:`embodied_adhoc.domains.chapter5.pursuit` (626 states, 81
observations): every step samples the next state from the true task's POMDP transition row (which already holds
the greedy teammate's policy and the prey's uniformly random move) and the observation from its observation row.
The grid twin applies the sampled move to the robots' cells; the MuJoCo arena drives the three robots there
through the shared waypoint controller and reads the cells back from physics, and the observation is then drawn
from the state *physics shows*. So a POMDP agent (HOTSPOT, ATPO, BOPA, ...) acts in both unchanged, and the two
backends differ only where physics fails to execute a move.
"""

from __future__ import annotations

import functools

import gymnasium
import numpy as np

from embodied_adhoc import checks
from embodied_adhoc.envs import contract
from embodied_adhoc.errors import ConfigError

__all__ = ["PursuitPomdpEnv", "pursuit_pair_library"]

SIZE = 5  # the library's torus (626 = 25 x 25 + 1 states)
MOVES = np.array([(-1, 0), (1, 0), (0, -1), (0, 1), (0, 0)])  # the library's action deltas (row, column)
ACTION_MEANING = "0 up, 1 down, 2 left, 3 right, 4 stay"
RESET_OPTIONS = ("task", "start", "agent_cell")
NOTHING_SEEN = 40  # z = 9 * 4 + 4: neither the teammate nor the prey seen (what reset returns)


@functools.lru_cache(maxsize=4)
def pursuit_pair_library(noise: float | None = None):
    """The ``pursuit-task`` library (Table 5.2: eps = 0.2), built once per process and noise."""
    from embodied_adhoc.domains.chapter5.pursuit import build_pursuit

    return build_pursuit("pursuit-task", size=SIZE, noise=noise)


def _wrap(cells: np.ndarray) -> np.ndarray:
    return np.mod(cells, SIZE)


def offset_index(offsets: np.ndarray) -> np.ndarray:
    """The library's index of wrapped (row, column) offsets: ``(dr + 2) * 5 + (dc + 2)``."""
    half = SIZE // 2
    wrapped = (np.asarray(offsets) + half) % SIZE
    return wrapped[..., 0] * SIZE + wrapped[..., 1]


def state_index(cells: np.ndarray) -> int:
    """The library state of (agent, teammate, prey) cells: the teammate's and the prey's offsets from the agent."""
    cells = np.asarray(cells)
    mate, prey = offset_index(cells[1] - cells[0]), offset_index(cells[2] - cells[0])
    return int(mate * SIZE * SIZE + prey)


def cells_of_state(state: int, agent_cell: np.ndarray) -> np.ndarray:
    """(agent, teammate, prey) cells of a live library state with the agent at ``agent_cell``."""
    half = SIZE // 2
    mate, prey = divmod(int(state), SIZE * SIZE)
    offsets = np.array([divmod(mate, SIZE), divmod(prey, SIZE)]) - half
    agent = np.asarray(agent_cell, dtype=np.int64)
    return np.vstack([agent, _wrap(agent + offsets)]).astype(np.int64)


def _sample_row(matrix, row: int, rng: np.random.Generator) -> int:
    start, end = matrix.indptr[row], matrix.indptr[row + 1]
    return int(rng.choice(matrix.indices[start:end], p=matrix.data[start:end] / matrix.data[start:end].sum()))


class PursuitPomdpEnv(gymnasium.Env):
    """Two-predator pursuit of thesis section 5.2.5 / Fig. 7.12, with the pursuit POMDP as its rules.

    ## Description
    A 5 x 5 torus; the ad hoc predator (agent 0), a greedy teammate (agent 1) and a prey. The task (unknown to
    the ad hoc agent) is the pair of capture cells around the prey: N+S, W+E, SW+NE or NW+SE (positions
    interchangeable). Each step the next state is drawn from the true task's row of the ``pursuit-task`` POMDP
    (:func:`pursuit_pair_library`): the agent moves by its action, the teammate by its greedy policy for the
    task (columns first, toroidal), the prey uniformly over the 5 moves, with no collisions (predators may share
    a cell). The episode ends when the two predators stand on the task's capture cells.

    ``backend="mujoco"``: the three are robots in the grid arena (``sim.grid_arena_world``), each move a
    waypoint for the shared controller; a move across an edge of the torus is executed as a teleport to the
    opposite edge (a physical floor cannot wrap) and contacts between the robots are disabled (the model has no
    collisions). After each step the cells are read back from the robots' physical poses and the observation
    is drawn from *that* state's observation row: the same observation function and noise as the POMDP.

    ## Action space
    ``Discrete(5)``: 0 up (row - 1), 1 down, 2 left, 3 right, 4 stay (the library's actions).

    ## Observation space
    ``Discrete(81)``: the POMDP's observation ``z = 9 t + p``, the teammate's (t) and the prey's (p) cell in the
    agent's 3x3 neighbourhood (``3 (dr + 1) + (dc + 1)``), each seen with probability ``1 - noise``; a miss, or
    one outside the neighbourhood, reads 4 (the agent's own cell). The same flat index is
    ``info["observation_index"]``, so any agent of :mod:`embodied_adhoc.decision.agents` can drive the env.

    ## Rewards
    1.0 on the step that reaches the capture configuration, else 0.0 (the library's -1 / +100 are its own).

    ## Starting state
    ``reset`` returns observation 40 (nothing seen; the POMDP observes only after an action). ``start`` drawn
    from the true task's initial belief (uniform over live non-capture states), the agent's
    cell uniform over the 25 cells.

    ## Episode end
    Terminated on capture; truncated by the registered ``TimeLimit`` (150 steps, Fig. 7.12's cap).

    ## Arguments
    ``gymnasium.make("EmbodiedAdhoc/PursuitPairPomdpGrid-v0", tasks=None, noise=None, backend="abstract",
    render_mode=None, physics=None)``; ``tasks``: library indices 0..3 drawn from (default all); ``noise``: the
    observation noise (default the library's 0.2); ``physics``: an ``ArenaPhysics`` (mujoco only).
    ``reset(options={"task": k, "start": x, "agent_cell": [r, c]})`` imposes any of them.

    ## Info
    ``observation_index`` (flat z), ``state`` (library state index, ground truth: evaluation and
    state-observing agents only), ``task`` (library index), ``task_name``, ``cells`` ((agent, teammate, prey)
    cells), ``steps``; on ``backend="mujoco"`` also ``sim_time`` (s) and ``poses`` (the three robots' x, y, yaw);
    after a step ``intended_state`` (the state the POMDP drew; differs from ``state`` when
    physics did not execute the move), ``teammate_action`` and ``prey_action`` (the moves drawn).

    ## Version history
    v0: initial release.
    """

    metadata = {"render_modes": list(contract.RENDER_MODES), "render_fps": 4}

    @contract.keywords()
    def __init__(
        self,
        tasks=None,
        noise: float | None = None,
        backend: str = "abstract",
        render_mode: str | None = None,
        physics=None,
    ) -> None:
        self.noise = None if noise is None else checks.number("noise", noise, 0.0, 1.0)
        self.library = pursuit_pair_library(self.noise)
        n_tasks = self.library.n_models
        chosen = range(n_tasks) if tasks is None else (tasks if isinstance(tasks, (list, tuple)) else [tasks])
        self.task_set = tuple(checks.integer("tasks", k, 0, n_tasks - 1) for k in chosen)
        if not self.task_set:
            raise ConfigError(f"tasks=[]: choose library indices from 0..{n_tasks - 1}")
        self.backend_name = checks.choice("backend", backend, ("abstract", "mujoco"))
        self.render_mode = contract.render_mode(render_mode)
        self.action_space = gymnasium.spaces.Discrete(5)
        self.observation_space = gymnasium.spaces.Discrete(self.library.pomdps[0].n_observations)
        absorbing = self.library.absorbing_state
        self.capture_states = [
            np.flatnonzero(np.asarray(p.transitions[0][:, absorbing].todense()).ravel() >= 1.0 - 1e-12)
            for p in self.library.pomdps
        ]
        self.capture_states = [s[s != absorbing] for s in self.capture_states]
        self.arena = None
        if self.backend_name == "mujoco":
            from embodied_adhoc.sim.pursuit_pomdp_arena import PursuitPomdpArena

            self.arena = PursuitPomdpArena(physics)
        elif physics is not None:
            raise ConfigError("physics: an option of the MuJoCo arena only (backend='mujoco')")
        self._episode = contract.EpisodeGate(type(self).__name__)
        self.task, self.state, self.steps = 0, 0, 0
        self.cells = np.zeros((3, 2), dtype=np.int64)

    def privileged_state(self) -> int:
        """The true state, as ``info["state"]`` holds it: the one channel through which the episode loop gives it to
        privileged agents (``observes_state``); agents never read ``info``."""
        return int(self.state)

    def _info(self) -> dict:
        info = {
            "observation_index": self.observation,
            "state": self.state,
            "task": self.task,
            "task_name": self.library.task_names[self.task],
            "cells": self.cells.tolist(),
            "steps": self.steps,
        }
        if self.arena is not None:
            info["sim_time"] = self.arena.sim_time
            info["poses"] = self.arena.poses().tolist()
        return info

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        checks.refuse_unknown("reset options", options, RESET_OPTIONS, what="option")
        rng = self.np_random
        task = self.task_set[int(rng.integers(len(self.task_set)))]
        if "task" in options:
            task = checks.integer("reset option task", options["task"], 0, self.library.n_models - 1)
        pomdp = self.library.pomdps[task]
        start = int(rng.choice(pomdp.n_states, p=pomdp.initial_belief))
        agent_cell = rng.integers(SIZE, size=2)
        if "start" in options:
            start = checks.integer("reset option start", options["start"], 0, pomdp.n_states - 1)
            if pomdp.initial_belief[start] <= 0.0:
                raise ConfigError(
                    f"reset option start={start}: not a start state of task {task} (capture or absorbing)"
                )
        if "agent_cell" in options:
            agent_cell = np.array(
                [checks.integer("reset option agent_cell", v, 0, SIZE - 1) for v in options["agent_cell"]]
            )
        self.task, self.steps = int(task), 0
        self.cells = cells_of_state(start, agent_cell)
        if self.arena is not None:
            self.cells = self.arena.reset(self.cells)
        self.state = state_index(self.cells)
        self.observation = NOTHING_SEEN  # the POMDP has no observation before the first action
        self._episode.open()
        return self.observation, self._info()

    def step(self, action):
        self._episode.check()
        action = contract.action(action, 5, ACTION_MEANING)
        pomdp = self.library.pomdps[self.task]
        rng = self.np_random
        intended = _sample_row(pomdp.transitions[action], self.state, rng)
        agent = _wrap(self.cells[0] + MOVES[action])
        target = cells_of_state(intended, agent)
        moves = [_move_of(self.cells[i], target[i]) for i in (1, 2)]
        self.cells = target if self.arena is None else self.arena.execute(self.cells, target)
        self.state = state_index(self.cells)
        self.observation = _sample_row(pomdp.observations[action], self.state, rng)
        self.steps += 1
        terminated = bool(np.isin(self.state, self.capture_states[self.task]))
        self._episode.close_if(terminated)
        info = self._info()
        info.update(intended_state=int(intended), teammate_action=moves[0], prey_action=moves[1])
        return self.observation, 1.0 if terminated else 0.0, terminated, False, info

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self.arena is not None:
            return self.arena.render_top()
        return draw_cells(self.cells)

    def close(self) -> None:
        if self.arena is not None:
            self.arena.close()


def _move_of(before: np.ndarray, after: np.ndarray) -> int:
    """The action (0..4) that takes ``before`` to ``after`` on the torus."""
    delta = offset_index(after - before)
    return int(next(k for k, move in enumerate(MOVES) if offset_index(move) == delta))


def draw_cells(
    cells: np.ndarray, cell_px: int = 32, colours=((240, 140, 20), (40, 90, 220), (220, 40, 40))
) -> np.ndarray:
    """Top-down RGB picture of the torus: agent orange, teammate blue, prey red (shared cells split); one colour
    per row of ``cells`` (chapter 4's pursuit passes five)."""
    image = np.full((SIZE * cell_px, SIZE * cell_px, 3), 235, dtype=np.uint8)
    image[::cell_px, :] = 180
    image[:, ::cell_px] = 180
    for k, (cell, colour) in enumerate(zip(cells, colours, strict=True)):
        r, c = int(cell[0]) * cell_px, int(cell[1]) * cell_px
        margin = cell_px // 5 + 3 * k * (sum((cells == cell).all(axis=1)) > 1)
        image[r + margin : r + cell_px - margin, c + margin : c + cell_px - margin] = colour
    return image


__all__ += ["cells_of_state", "draw_cells", "offset_index", "state_index"]
