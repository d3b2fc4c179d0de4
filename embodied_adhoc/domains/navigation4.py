"""Chapter-4 navigation (thesis section 4.1.1, Fig. 4.5): N agents leave a facility (ntu, isr, pentagon) by its
exits, fully observable, the teammates' actions visible. Batched over B states; numpy only, no gymnasium.

Maps: the chapter-5 map parser (:func:`embodied_adhoc.domains.chapter5.grid_maps.load_map`, same file format)
reads ``assets/maps/chapter4/{ntu,isr,pentagon}.txt``. Their open cells are those of the chapter-5 maps; the
marks differ: 'S' are the spawn cells and 'G' the exits of the chapter-4 implementation (Ribeiro's TEAMSTER
code), and there are as many agents as exits: N = 4 on ntu, 3 on isr and pentagon (section 4.1.1).

Rules (the grid moves of :class:`~embodied_adhoc.domains.chapter5.grid_maps.GridMap`: up, down, left, right,
stay; a move into a wall or the border stays):

* state ``(s_0, ..., s_{N-1})`` cell indices, column 0 the ad hoc agent; an episode starts with the N agents on N
  distinct spawn cells drawn uniformly;
* an agent on an exit has left: it stays there whatever it does (and still holds the cell);
* agents move one at a time in seat order 0, 1, ..., N-1, each into its target cell unless another agent holds
  that cell at its turn (agents that moved earlier at their new cells): a collision leaves it in place. The
  dynamics are deterministic (the changed environment adds ``slip``: each move fails w.p. ``slip``; or
  ``mirror``: the ad hoc agent's moves are mirrored, up <-> down, left <-> right);
* the episode ends when every agent stands on an exit ("all agents have exited"). Reward -1 per step, plus 100
  on the step that completes it, so an episode's accumulated reward is ``100 - steps`` (ntu's 98 in Table 4.5:
  two moves). The thesis's original counts the +100 on one extra step taken from the finished state; the total
  is the same.

Teams (section 4.1.1), each the exact per-agent action distribution ``pi^n(a | x)`` (Eq. 4.2's factors):
``d_m(g)`` is agent m's breadth-first path length to exit g through open cells, treating every other agent as an
obstacle and never passing through another exit (entering an exit ends the walk); infinite when walled off, and
for an agent that has left, 0 to its own exit and infinite to the others. An agent moves towards its target exit
uniformly among the first moves of its shortest paths (stays on it; uniform over the five actions when it
cannot reach it, as the original's random fallback).

* ``altruistic`` (tau1): the assignments of the N agents to the N exits (permutations) of least total
  ``sum_m d_m(sigma(m))``; uniform among tied assignments; each agent heads to its exit in the chosen one;
* ``selfish`` (tau2): each agent heads to its nearest exit not held by another agent (ties: the first exit in
  map order, the original's stable sort), whoever else is nearer;
* ``weighted-altruistic`` (tau3): an assignment drawn with probability ``softmin`` of its total distance among
  the assignments that no agent is walled off from (the original's ``softmin``; the altruistic rule when fewer
  than two are finite).

Each agent draws its own assignment, so the team's joint action factorises over agents given the state.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from embodied_adhoc.domains.chapter5.grid_maps import STAY, GridMap, load_map
from embodied_adhoc.domains.pursuit4 import MIRRORED, ExactEnvironment, ExactTeam, path_lengths
from embodied_adhoc.errors import ConfigError

N_ACTIONS = 5
TEAMS = ("altruistic", "selfish", "weighted-altruistic")
MAPS = ("ntu", "isr", "pentagon")
STEP_REWARD, EXIT_REWARD = -1.0, 100.0
EPISODE_CAP = 100  # the original's evaluation episodes stop after 100 steps (a failure then scores -100)


@dataclass(frozen=True, eq=False)
class Navigation4:
    """One chapter-4 map with lookup tables for batched rules; ``map_name`` is ntu, isr, pentagon or a map
    file (N = its number of exits)."""

    map_name: str = "ntu"
    slip: float = 0.0  # the changed environment: each agent's move fails (it stays) with this probability
    mirror: bool = False  # the changed environment: the ad hoc agent's moves are mirrored (pursuit4.MIRRORED)

    teams = TEAMS
    n_actions = N_ACTIONS
    step_reward, exit_reward, episode_cap = STEP_REWARD, EXIT_REWARD, EPISODE_CAP

    def __post_init__(self) -> None:
        if not 0.0 <= self.slip < 1.0:
            raise ConfigError(f"navigation slip={self.slip!r}: give a probability in [0, 1)")
        grid = _load(self.map_name)
        n = len(grid.goals)
        if len(grid.starts) < n:
            raise ConfigError(
                f"map {self.map_name}: {n} exits 'G' need {n} agents but there are only "
                f"{len(grid.starts)} spawn cells 'S'; add spawn cells"
            )
        if n > 4:
            raise ConfigError(f"map {self.map_name}: {n} exits; chapter-4 navigation supports up to 4 agents")
        cells = np.arange(grid.n_cells)
        exit_mask = np.zeros(grid.n_cells, dtype=bool)
        exit_mask[list(grid.goals)] = True
        exit_index = np.full(grid.n_cells, -1, dtype=np.int64)
        exit_index[list(grid.goals)] = np.arange(n)
        for name, value in (
            ("grid", grid),
            ("n_agents", n),
            ("cells", grid.n_cells),
            ("neighbours", grid.moves),
            ("exits", np.array(grid.goals, dtype=np.int64)),
            ("exit_mask", exit_mask),
            ("exit_index", exit_index),
            ("starts", np.array(grid.starts, dtype=np.int64)),
            ("assignments", np.array(list(itertools.permutations(range(n))), dtype=np.int64)),
            ("_cell_ids", cells),
        ):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "_cache", {team: {} for team in TEAMS})

    @property
    def name(self) -> str:
        return self.grid.name

    # --- states -------------------------------------------------------------------------------------------
    def sample_states(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """(count, N) the agents on N distinct spawn cells, uniformly."""
        order = np.argsort(rng.random((count, self.starts.size)), axis=1)[:, : self.n_agents]
        return self.starts[order]

    def exited(self, states: np.ndarray) -> np.ndarray:
        """(B, N) whether each agent stands on an exit."""
        return self.exit_mask[states]

    def solved(self, states: np.ndarray) -> np.ndarray:
        """(B,) every agent has left (all on exits; they hold distinct cells)."""
        return self.exited(states).all(-1)

    # --- the exact environment model ---------------------------------------------------------------------
    def step(
        self, states: np.ndarray, actions: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(next states, rewards, terminal): seat-order moves, collisions stay, exits absorb (module doc)."""
        actions = np.asarray(actions, dtype=np.int64)
        if self.mirror:
            actions = np.concatenate([MIRRORED[actions[:, :1]], actions[:, 1:]], axis=1)
        if self.slip > 0:
            actions = np.where(rng.random(actions.shape) < self.slip, STAY, actions)
        nxt = np.array(states, dtype=np.int64, copy=True)
        for n in range(self.n_agents):
            here = nxt[:, n]
            target = np.where(self.exit_mask[here], here, self.neighbours[here, actions[:, n]])
            others = np.delete(nxt, n, axis=1)
            taken = (others == target[:, None]).any(axis=1)
            nxt[:, n] = np.where(taken, here, target)
        done = self.solved(nxt)
        return nxt, np.where(done, STEP_REWARD + EXIT_REWARD, STEP_REWARD), done

    # --- distances with the other agents as obstacles ---------------------------------------------------
    def exit_fields(self, states: np.ndarray) -> np.ndarray:
        """(B, N, E, C) breadth-first path lengths to each exit for each agent m, through open cells not held
        by another agent and not another exit; ``cells`` (longer than any path) where unreachable, everywhere
        when another agent holds the exit."""
        count, n = states.shape
        exits = self.exits.size
        rows = np.arange(count)
        others = np.zeros((count, n, self.cells), dtype=bool)  # cells held by an agent other than m
        for m in range(n):
            for other in range(n):
                if other != m:
                    others[rows, m, states[:, other]] = True
        other_exits = self.exit_mask[None, :] & (self.exits[:, None] != self._cell_ids[None, :])  # (E, C)
        blocked = others[:, :, None, :] | other_exits[None, None]  # (B, N, E, C)
        goals = np.broadcast_to(self.exits, (count, n, exits))
        field = path_lengths(self.neighbours, goals.reshape(-1), blocked.reshape(-1, self.cells))
        field = field.reshape(count, n, exits, self.cells)
        held = others[:, :, self.exits]  # (B, N, E)
        return np.where(held[..., None], self.cells, field)

    def distances(self, states: np.ndarray, field: np.ndarray) -> np.ndarray:
        """(B, N, E) ``d_m(g)`` as float (inf when walled off); an agent that has left: 0 to its exit, inf
        elsewhere."""
        count, n = states.shape
        d = field[
            np.arange(count)[:, None, None],
            np.arange(n)[None, :, None],
            np.arange(self.exits.size)[None, None, :],
            states[:, :, None],
        ].astype(float)
        d[d >= self.cells] = np.inf
        gone = self.exit_mask[states]
        own = self.exit_index[states][..., None] == np.arange(self.exits.size)
        return np.where(gone[..., None], np.where(own, 0.0, np.inf), d)

    def toward(self, states: np.ndarray, field: np.ndarray, distance: np.ndarray) -> np.ndarray:
        """(B, N, E, 5) each agent's move distribution towards each exit: uniform over the first moves of its
        shortest paths; stay on it (or once left); uniform over the five actions when it cannot reach it."""
        count, n = states.shape
        rows = np.arange(count)[:, None, None, None]
        agents = np.arange(n)[None, :, None, None]
        ex = np.arange(self.exits.size)[None, None, :, None]
        through = field[rows, agents, ex, self.neighbours[states, :4][:, :, None, :]]  # (B, N, E, 4)
        here = distance[..., None]
        ok = (through == here - 1) & np.isfinite(here)
        moves = np.concatenate([ok, (distance == 0)[..., None]], -1).astype(float)
        total = moves.sum(-1, keepdims=True)
        return np.where(total > 0, moves / np.maximum(total, 1.0), 1.0 / N_ACTIONS)

    # --- the teams (exact per-agent action distributions) -----------------------------------------------
    def team_policy(self, team: str, states: np.ndarray, agents=None) -> np.ndarray:
        """(B, len(agents), 5) ``pi^n(a | x)`` of ``team`` for the seats ``agents`` (default the teammates
        1..N-1), Eq. 4.2's factors; memoised per state (the planner revisits states; at most the map's
        ``C^N`` states per team: up to about 30 MB on pentagon)."""
        if team not in TEAMS:
            raise ConfigError(f"team={team!r}: choose one of {', '.join(TEAMS)}")
        states = np.asarray(states, dtype=np.int64)
        agents = list(range(1, self.n_agents)) if agents is None else list(agents)
        cache = self._cache[team]
        codes = (states @ (self.cells ** np.arange(self.n_agents, dtype=np.int64))).tolist()
        missing = [i for i, code in enumerate(codes) if code not in cache]
        if missing:
            fresh = self._policies(team, states[missing])
            for i, probs in zip(missing, fresh, strict=True):
                cache[codes[i]] = probs
        return np.stack([cache[code] for code in codes])[:, agents]

    def _policies(self, team: str, states: np.ndarray) -> np.ndarray:
        field = self.exit_fields(states)
        d = self.distances(states, field)  # (B, N, E)
        toward = self.toward(states, field, d)  # (B, N, E, 5)
        count, n = states.shape
        if team == "selfish":
            on = self.exits[None, None, :] == states[:, :, None]  # (B, N, E): agent m stands on exit e
            held = on.sum(1, keepdims=True) - on > 0  # (B, N, E) another agent holds e
            cost = np.where(held, np.inf, d)
            best = cost.min(-1, keepdims=True)
            candidates = np.where(np.isinf(best), ~held, cost == best)
            nearest = np.zeros(
                candidates.shape
            )  # the first candidate in exit order (the original's stable sort)
            np.put_along_axis(nearest, candidates.argmax(-1)[..., None], 1.0, axis=-1)
            return np.einsum("bne,bnea->bna", nearest, toward)
        perms = self.assignments  # (P, N): agent m -> exit perms[p, m]
        total = d[:, np.arange(n)[None, :], perms].sum(-1)  # (B, P)
        best = total.min(-1, keepdims=True)
        weight = (total == best).astype(float)  # ties (all infinite included)
        if team == "weighted-altruistic":
            finite = np.isfinite(total)
            soft = np.where(
                finite, np.exp(-(np.where(finite, total, 0.0) - np.where(np.isfinite(best), best, 0.0))), 0.0
            )
            weight = np.where((finite.sum(-1) > 1)[:, None], soft, weight)
        weight /= weight.sum(-1, keepdims=True)
        # pi^n(a) = sum_p w_p toward[n, perms[p, n], a]
        chosen = toward[:, np.arange(n)[None, :], perms]  # (B, P, N, 5)
        return np.einsum("bp,bpna->bna", weight, chosen)


def _load(map_name: str) -> GridMap:
    if map_name in MAPS:
        from embodied_adhoc.paths import asset

        grid = load_map(asset(f"maps/chapter4/{map_name}.txt"))
        return grid
    if not Path(map_name).is_file():
        raise ConfigError(f"navigation map {map_name!r}: choose {', '.join(MAPS)} or give a map file")
    return load_map(map_name)


__all__ = ["EPISODE_CAP", "MAPS", "TEAMS", "ExactEnvironment", "ExactTeam", "Navigation4"]
