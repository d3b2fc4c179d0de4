"""Grid rules of level-based foraging and predator-prey (thesis section 6.2.1), one implementation for both twins.

The grid twin applies a :class:`StepPlan` directly; the MuJoCo arena executes the same plan physically and
reads the resulting cells back from the robots' positions. Nothing here imports mujoco or gymnasium.

Conventions
-----------
* Cells are ``(row, col)``; row 0 is the north edge, so *Up* decreases the row.
* Actions (5): ``UP, DOWN, LEFT, RIGHT`` move one cell; ``INTERACT`` is *Forage* (LBF) or *Capture*
  (pursuit). With ``interact_required=False`` (the two-predator variant of Fig. 7.12) ``INTERACT`` is *Stay*
  and a target is captured as soon as the predators stand in the task's positions.
* A move succeeds only into a cell that is inside the grid (or wraps, if ``toroidal``), free in the current
  state (no agent, no target) and claimed by no other mover. Simultaneous claims all fail. Using the current
  occupancy (no chains, no swaps) keeps robots from driving through each other in the physical twin.
* Boundaries: the thesis's grids are toroidal. A physical arena cannot wrap, so both twins default to
  boundary walls (``toroidal=False``) to stay comparable; targets then live in the interior cells so that
  every task's positions exist around them. ``toroidal=True`` reproduces the thesis's wrap in the grid twin.
* A task is a tuple of offsets from the target, one per agent (agent ``i`` must stand at ``target +
  offsets[i]``), or, if ``interchangeable``, a set of offsets any agent may fill (Fig. 7.12's pairs).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from embodied_adhoc.errors import ConfigError

UP, DOWN, LEFT, RIGHT, INTERACT = range(5)
ACTION_NAMES = ("up", "down", "left", "right", "interact")
MOVES = np.array([[-1, 0], [1, 0], [0, -1], [0, 1], [0, 0]], dtype=np.int64)

OFFSETS = {
    "N": (-1, 0),
    "S": (1, 0),
    "W": (0, -1),
    "E": (0, 1),
    "NE": (-1, 1),
    "NW": (-1, -1),
    "SE": (1, 1),
    "SW": (1, -1),
}


@dataclass(frozen=True)
class Task:
    """Positions around a target that the team must occupy to forage/capture it."""

    name: str
    offsets: tuple[tuple[int, int], ...]
    interchangeable: bool = False


def rotation_tasks(n_agents: int = 4) -> tuple[Task, ...]:
    """The four tasks of section 6.2.2: task 1 puts agents 0..3 at N, S, W, E of the target; tasks 2-4 rotate
    that assignment by 90 degrees clockwise each (N->E->S->W). With fewer agents the first ``n_agents`` count."""
    if not 2 <= n_agents <= 4:
        raise ConfigError(f"n_agents={n_agents}: the N/S/W/E tasks need 2 to 4 agents")
    clockwise = ("N", "E", "S", "W")
    base = ("N", "S", "W", "E")
    tasks = []
    for turn in range(4):
        names = tuple(clockwise[(clockwise.index(d) + turn) % 4] for d in base[:n_agents])
        tasks.append(Task(f"task{turn + 1}:" + "".join(names), tuple(OFFSETS[d] for d in names)))
    return tuple(tasks)


def pair_tasks() -> tuple[Task, ...]:
    """Fig. 7.12 / section 5.2.5 two-predator tasks: N+S, W+E, SW+NE, NW+SE, positions interchangeable."""
    pairs = (("N", "S"), ("W", "E"), ("SW", "NE"), ("NW", "SE"))
    return tuple(
        Task(f"task{i + 1}:{a}+{b}", (OFFSETS[a], OFFSETS[b]), True) for i, (a, b) in enumerate(pairs)
    )


@dataclass(frozen=True)
class GridConfig:
    """Size and rules of one grid world (shared by both twins)."""

    domain: str = "foraging"  # "foraging" (apples with levels) or "pursuit" (moving prey)
    rows: int = 5
    cols: int = 5
    n_agents: int = 4
    n_targets: int = 1
    toroidal: bool = False
    interact_required: bool = True  # False: INTERACT means Stay and capture is automatic (Fig. 7.12)
    max_agent_level: int = 2  # LBF: agent levels drawn uniformly from 1..max_agent_level
    prey_stay_probability: float = 0.2  # pursuit: prey stays w.p. this, else tries one of 4 moves uniformly

    def __post_init__(self) -> None:
        if self.domain not in ("foraging", "pursuit"):
            raise ConfigError(f"GridConfig.domain={self.domain!r}: use 'foraging' or 'pursuit'")
        if not 2 <= self.n_agents <= 4:
            raise ConfigError(f"GridConfig.n_agents={self.n_agents}: use 2 to 4 agents")
        if self.n_targets < 1:
            raise ConfigError(f"GridConfig.n_targets={self.n_targets}: need at least one apple/prey")
        if self.rows < 3 or self.cols < 3:
            raise ConfigError(f"GridConfig {self.rows}x{self.cols}: use at least 3x3 cells")
        all_cells = np.stack(np.divmod(np.arange(self.rows * self.cols), self.cols), axis=-1)
        if GridRules(self).target_cells_valid(all_cells).sum() < self.n_targets:
            raise ConfigError(
                f"GridConfig {self.rows}x{self.cols}: too few cells where {self.n_targets} targets can "
                "be surrounded (walled grids keep targets off the border and interior corners); "
                "use at least 5x5 or toroidal=True"
            )
        if self.rows * self.cols < self.n_agents + self.n_targets:
            raise ConfigError(f"GridConfig {self.rows}x{self.cols}: too small for the agents and targets")
        if self.max_agent_level < 1:
            raise ConfigError(f"GridConfig.max_agent_level={self.max_agent_level}: must be >= 1")
        if not 0.0 <= self.prey_stay_probability <= 1.0:
            raise ConfigError(
                f"GridConfig.prey_stay_probability={self.prey_stay_probability}: must be in [0, 1]"
            )


@dataclass
class GridState:
    """Full state (thesis 6.2.1): agent cells and levels, target cells and levels, which targets remain."""

    agents: np.ndarray  # (N, 2) int64 cells
    agent_levels: np.ndarray  # (N,) int64 (all 1 in pursuit)
    targets: np.ndarray  # (M, 2) int64 cells
    target_levels: np.ndarray  # (M,) int64 (all 1 in pursuit)
    alive: np.ndarray = field(default=None)  # (M,) bool: not yet foraged/captured

    def __post_init__(self) -> None:
        if self.alive is None:
            self.alive = np.ones(len(self.targets), dtype=bool)

    def copy(self) -> GridState:
        return GridState(
            self.agents.copy(),
            self.agent_levels.copy(),
            self.targets.copy(),
            self.target_levels.copy(),
            self.alive.copy(),
        )

    def as_dict(self) -> dict:
        return {
            "agents": self.agents.tolist(),
            "agent_levels": self.agent_levels.tolist(),
            "targets": self.targets.tolist(),
            "target_levels": self.target_levels.tolist(),
            "alive": self.alive.tolist(),
        }


@dataclass
class GridBatch:
    """B states stacked on a leading axis (the vector env's state; a single env is B=1)."""

    agents: np.ndarray  # (B, N, 2)
    agent_levels: np.ndarray  # (B, N)
    targets: np.ndarray  # (B, M, 2)
    target_levels: np.ndarray  # (B, M)
    alive: np.ndarray  # (B, M) bool

    @classmethod
    def stack(cls, states: list[GridState]) -> GridBatch:
        return cls(
            *(
                np.stack([getattr(s, name) for s in states])
                for name in ("agents", "agent_levels", "targets", "target_levels", "alive")
            )
        )

    def state(self, index: int) -> GridState:
        return GridState(
            self.agents[index].copy(),
            self.agent_levels[index].copy(),
            self.targets[index].copy(),
            self.target_levels[index].copy(),
            self.alive[index].copy(),
        )

    def put(self, index: int, state: GridState) -> None:
        self.agents[index], self.agent_levels[index] = state.agents, state.agent_levels
        self.targets[index], self.target_levels[index], self.alive[index] = (
            state.targets,
            state.target_levels,
            state.alive,
        )

    def put_rows(self, rows: np.ndarray, states: list[GridState]) -> None:
        """``states[k]`` into row ``rows[k]`` for every ``k``, one assignment per field."""
        self.put_batch(rows, GridBatch.stack(states))

    def put_batch(self, rows: np.ndarray, batch: GridBatch) -> None:
        """Row ``k`` of ``batch`` into row ``rows[k]`` for every ``k``, one assignment per field."""
        for name in (f.name for f in fields(self)):
            getattr(self, name)[rows] = getattr(batch, name)


@dataclass(frozen=True)
class StepPlan:
    """The outcome of one grid step decided by the rules, before it is applied (or executed physically)."""

    agents: np.ndarray  # (N, 2) cells after the move ((B, N, 2) from plan_batch)
    targets: np.ndarray  # (M, 2) cells after the prey's move
    completed: np.ndarray  # (M,) bool: foraged/captured this step


class GridRules:
    """The rules of one :class:`GridConfig`: spawning, moves, foraging/capture, distances."""

    def __init__(self, config: GridConfig) -> None:
        self.config = config
        self.shape = np.array([config.rows, config.cols], dtype=np.int64)
        cells = np.stack(np.divmod(np.arange(config.rows * config.cols), config.cols), axis=-1)
        wanted, inside = self.normalise(cells[:, None, :] + MOVES[None, :4, :])
        # neighbours[flat cell, action] = flat index of the cell that move leads to, or -1 (a wall)
        self.neighbours = np.where(inside, wanted[..., 0] * config.cols + wanted[..., 1], -1)
        self.all_cells, self.flat_cells = cells, np.arange(len(cells))
        # step_to[flat cell, action]: the cell an action leads to (-1 into a wall; itself for INTERACT)
        self.step_to = np.concatenate([self.neighbours, self.flat_cells[:, None]], axis=1)
        self.target_cell_ok = self.target_cells_valid(cells)  # per flat cell
        self.valid_target_cells = np.flatnonzero(self.target_cell_ok)  # flat, ascending

    # -- geometry ---------------------------------------------------------------------------------------------
    def normalise(self, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Wrap cells on a torus, or flag those outside the walls: returns (cells, inside mask)."""
        cells = np.asarray(cells, dtype=np.int64)
        if self.config.toroidal:
            return cells % self.shape, np.ones(cells.shape[:-1], dtype=bool)
        inside = np.all((cells >= 0) & (cells < self.shape), axis=-1)
        return cells, inside

    def delta(self, frm: np.ndarray, to: np.ndarray) -> np.ndarray:
        """Shortest signed displacement ``to - frm`` (through the wrap on a torus)."""
        d = np.asarray(to, dtype=np.int64) - np.asarray(frm, dtype=np.int64)
        if self.config.toroidal:
            d = (d + self.shape // 2) % self.shape - self.shape // 2
        return d

    def distance(self, frm: np.ndarray, to: np.ndarray) -> np.ndarray:
        """Manhattan distance (toroidal if the grid wraps)."""
        return np.abs(self.delta(frm, to)).sum(axis=-1)

    def target_cells_valid(self, cells: np.ndarray) -> np.ndarray:
        """Cells where a target may stand: anywhere on a torus, else the interior (all task positions exist)."""
        cells = np.asarray(cells)
        if self.config.toroidal:
            return np.ones(cells.shape[:-1], dtype=bool)
        interior = np.all((cells >= 1) & (cells <= self.shape - 2), axis=-1)
        # An apple on an interior corner would, with agents on two of its slots, seal the grid's corner cell
        # (its only exits are those slots): such cells are excluded so that no spawn can deadlock a team.
        corner = np.all((cells == 1) | (cells == self.shape - 2), axis=-1)
        return interior & ~corner

    # -- spawning ---------------------------------------------------------------------------------------------
    def sample_state(self, rng: np.random.Generator) -> GridState:
        """A random initial state: targets on valid cells, agents on the remaining free cells."""
        return self.sample_states([rng])[0].state(0)

    def sample_states(self, rngs: list[np.random.Generator], first=None) -> tuple[GridBatch, list]:
        """One initial state per Generator, stacked (row ``k`` from ``rngs[k]``). Each Generator draws the
        numbers :meth:`sample_state` always drew, in the same order (target cells, then agents among the
        remaining cells, then levels): only the integers are drawn per Generator, and turning them into cells
        is done for the whole batch. ``first(rng)``, if given, runs on each Generator before its state draws
        (the episode's task and team draws); the batch comes with the list of its results (empty without it)."""
        cfg, cells = self.config, self.config.rows * self.config.cols
        n_valid, n_free = len(self.valid_target_cells), cells - cfg.n_targets
        b = len(rngs)
        target_pick = np.empty((b, cfg.n_targets), np.int64)
        agent_pick = np.empty((b, cfg.n_agents), np.int64)
        agent_levels = np.ones((b, cfg.n_agents), np.int64)
        target_levels = np.ones((b, cfg.n_targets), np.int64)
        foraging, extras = cfg.domain == "foraging", []
        for k, rng in enumerate(rngs):
            if first is not None:
                extras.append(first(rng))
            # choice over a count draws the same indices as choice over an array of that length
            target_pick[k] = rng.choice(n_valid, size=cfg.n_targets, replace=False)
            agent_pick[k] = rng.choice(n_free, size=cfg.n_agents, replace=False)
            if foraging:
                agent_levels[k] = rng.integers(1, cfg.max_agent_level + 1, size=cfg.n_agents)
                target_levels[k] = rng.integers(1, int(agent_levels[k].sum()) + 1, size=cfg.n_targets)
        targets = self.valid_target_cells[target_pick]
        taken = np.zeros((b, cells), bool)
        taken[np.arange(b)[:, None], targets] = True
        # the cells without a target in ascending order (a stable sort puts the False entries first)
        free = np.argsort(taken, axis=1, kind="stable")[:, :n_free]
        agents = np.take_along_axis(free, agent_pick, axis=1)
        batch = GridBatch(
            self.all_cells[agents],
            agent_levels,
            self.all_cells[targets],
            target_levels,
            np.ones((b, cfg.n_targets), bool),
        )
        return batch, extras

    # -- one step (batched: one implementation for the single envs, B=1, and the vector env) ---------------
    def flat(self, cells: np.ndarray) -> np.ndarray:
        """Flat index ``row * cols + col`` of (inside) cells."""
        return cells[..., 0] * self.config.cols + cells[..., 1]

    def occupied(self, batch: GridBatch) -> np.ndarray:
        """(B, R*C) bool: cells holding an agent or a live target."""
        b, cells = len(batch.agents), self.config.rows * self.config.cols
        grid = np.zeros((b, cells), dtype=bool)
        grid[np.arange(b)[:, None], self.flat(batch.agents)] = True
        rows, slots = np.nonzero(batch.alive)
        grid[rows, self.flat(batch.targets[rows, slots])] = True
        return grid

    def completed_targets(
        self, batch: GridBatch, offsets: np.ndarray, interchangeable: bool, actions: np.ndarray
    ) -> np.ndarray:
        """(B, M) targets foraged/captured by ``actions`` (B, N) (section 6.2.1): every agent stands at its
        task position ``offsets`` (B, N, 2) around the target, all execute Forage/Capture (unless
        ``interact_required`` is off) and, for LBF, their levels sum to at least the target's level."""
        rel = self.delta(batch.targets[:, :, None, :], batch.agents[:, None, :, :])  # (B, M, N, 2)
        offsets = offsets[:, None, :, :]
        if interchangeable:  # the same multiset of offsets, in any agent order
            rows, cols = int(self.shape[0]), int(self.shape[1])
            code = lambda d: (d[..., 0] + rows) * (2 * cols + 1) + d[..., 1] + cols  # noqa: E731
            placed = np.all(np.sort(code(rel), axis=-1) == np.sort(code(offsets), axis=-1), axis=-1)
        else:
            placed = np.all(rel == offsets, axis=(-1, -2))
        strong = batch.agent_levels.sum(axis=1)[:, None] >= batch.target_levels
        done = placed & strong & batch.alive
        if self.config.interact_required:
            done &= np.all(actions == INTERACT, axis=1)[:, None]
        return done

    def resolve_moves(self, movers: np.ndarray, actions: np.ndarray, blocked: np.ndarray) -> np.ndarray:
        """New flat cells of ``movers`` (B, K, flat cells) taking ``actions`` (B, K; INTERACT stays): a move fails
        if it leaves the walls, enters a ``blocked`` (B, R*C) cell, or claims a cell another mover of the same
        env also claims."""
        wanted = self.step_to[movers, actions]
        moving = (actions != INTERACT) & (wanted >= 0)
        flat = np.maximum(wanted, 0)
        env = np.arange(len(movers))[:, None]
        moving &= ~blocked[env, flat]
        key = env * blocked.shape[1] + flat
        claims = np.bincount(key[moving], minlength=blocked.size)
        moving &= claims[key] == 1
        return np.where(moving, wanted, movers)

    def plan_batch(
        self,
        batch: GridBatch,
        offsets: np.ndarray,
        interchangeable: bool,
        actions: np.ndarray,
        prey_uniforms: np.ndarray | None = None,
    ) -> StepPlan:
        """Decide one step of B envs: completions (checked first, on the current state), agent moves, then prey
        moves into cells free both before and after the agents move. Pursuit needs ``prey_uniforms`` (B, M, 2)
        in [0, 1): the first decides whether a prey stays, the second which of the 4 moves it tries."""
        completed = self.completed_targets(batch, offsets, interchangeable, actions)
        blocked = self.occupied(batch)
        agents = self.resolve_moves(self.flat(batch.agents), actions, blocked)
        if self.config.domain != "pursuit":
            return StepPlan(self.all_cells[agents], batch.targets.copy(), completed)
        alive = batch.alive & ~completed
        stay = prey_uniforms[..., 0] < self.config.prey_stay_probability
        direction = np.minimum((prey_uniforms[..., 1] * 4).astype(np.int64), 3)
        prey = self.flat(batch.targets)
        moves = np.where(stay | ~alive, INTERACT, direction)
        wanted = self.step_to[prey, moves]
        moves = np.where(
            (wanted >= 0) & self.target_cell_ok[np.maximum(wanted, 0)], moves, INTERACT
        )  # valid cells
        blocked = blocked.copy()
        blocked[np.arange(len(agents))[:, None], agents] = True
        return StepPlan(
            self.all_cells[agents], self.all_cells[self.resolve_moves(prey, moves, blocked)], completed
        )

    def prey_draws(self) -> int:
        """Uniforms one step of :meth:`plan` consumes (2 per prey in pursuit, none in LBF)."""
        return 2 * self.config.n_targets if self.config.domain == "pursuit" else 0

    def plan(self, state: GridState, task: Task, actions: np.ndarray, rng: np.random.Generator) -> StepPlan:
        """Decide one step of one env (:meth:`plan_batch` with B=1). Only pursuit consumes ``rng``: a fixed
        ``rng.random((M, 2))`` per step, so that the vector env reproduces the single env draw for draw."""
        actions = np.asarray(actions, dtype=np.int64)
        if actions.shape != (self.config.n_agents,) or np.any((actions < 0) | (actions > 4)):
            raise ConfigError(f"actions {actions.tolist()}: need {self.config.n_agents} integers in 0..4")
        n = self.config.n_agents
        if len(task.offsets) != n:
            raise ConfigError(f"task {task.name} has {len(task.offsets)} positions for {n} agents")
        uniforms = rng.random((1, self.config.n_targets, 2)) if self.prey_draws() else None
        offsets = np.array(task.offsets, dtype=np.int64)[None]
        plan = self.plan_batch(
            GridBatch.stack([state]), offsets, task.interchangeable, actions[None], uniforms
        )
        return StepPlan(plan.agents[0], plan.targets[0], plan.completed[0])

    def apply(self, state: GridState, plan: StepPlan) -> GridState:
        """The state after ``plan`` (the grid twin's transition)."""
        return GridState(
            plan.agents.copy(),
            state.agent_levels.copy(),
            plan.targets.copy(),
            state.target_levels.copy(),
            state.alive & ~plan.completed,
        )
