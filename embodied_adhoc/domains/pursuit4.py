"""Chapter-4 pursuit (thesis section 4.1.1): four predators and one prey on a toroidal ``M x M`` grid, fully
observable, the teammates' actions visible. Batched over B states; numpy only, no gymnasium.

Why not :mod:`embodied_adhoc.domains.grid_rules`: those rules are chapter 6's (an explicit *Capture* action, a
task of fixed offsets, simultaneous claims *all* fail). Chapter 4's differ: a capture is the four predators on
the four cells around the prey (any predator on any side), and "if any two agents (predator or prey) try to move
to the same cell, only one of the two succeeds (selected randomly)". This module implements that by moving the
five agents one at a time in a uniformly random order, each into its target cell if that cell is free at its
turn (the usual implementation of Barrett's pursuit): a random winner for every conflict, chains allowed when
the leader moves first. It reuses :data:`grid_rules.MOVES` (up, down, left, right, stay) as the action set.

State: ``(B, 5)`` flat cells ``row * M + col``: column 0 the ad hoc agent, 1-3 the teammates, 4 the prey.
Predator actions (B, 4): 0 up, 1 down, 2 left, 3 right, 4 stay. The prey moves uniformly to one of its four
neighbours (it never stays on purpose). Reward 1 on a capture (terminal), else 0.

Teams (section 4.1.1), each given as the exact per-predator action distribution ``pi^n(a | x)`` (Eq. 4.2's
factors), so that PLASTIC-Model's planner can use them and the team belief can score observed actions (the
arenas' and chapter 5's teammates of the same names are other policies, for other rules:
:mod:`embodied_adhoc.teammates.pursuit_teams` says how they differ):

* ``teammate-aware`` (tau1): the four cells around the prey are assigned to the predators by the least total
  toroidal distance (ties: the first permutation), and each walks a shortest path (breadth-first search) to its
  cell treating the other agents as immovable obstacles; uniform among equally short first moves; stays once
  there. Walled off: the moves that shorten the plain toroidal distance.
* ``greedy`` (tau2): each predator heads for its nearest cell around the prey not held by another predator
  (ties: uniform), uniformly among the moves that shorten the toroidal distance, not avoiding the others.
* ``probabilistic-destinations`` (tau3): each step a destination is drawn among the cells not taken by another
  agent with weight ``exp(-2 d(cell, prey))`` times 8 for the cells around the prey and 2 for the cells two
  steps away (circling positions), then a move shortening the distance to it; the policy is that mixture.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from embodied_adhoc.domains.grid_rules import MOVES
from embodied_adhoc.errors import ConfigError

N_PREDATORS = 4
N_AGENTS = 5
PREY = 4
N_ACTIONS = 5
STAY = 4
TEAMS = ("teammate-aware", "greedy", "probabilistic-destinations")
_PERMUTATIONS = np.array(list(itertools.permutations(range(4))), dtype=np.int64)  # (24, 4)
MIRRORED = np.array([1, 0, 3, 2, 4])
"""The mirrored changed environment: action a of the ad hoc agent (seat 0) moves it as MIRRORED[a] (up <-> down,
left <-> right, stay stays), so that a model of the old rules is wrong about which action is best."""


@dataclass(frozen=True)
class Pursuit4:
    """Geometry of one toroidal ``size x size`` world, with lookup tables for batched rules."""

    size: int = 5
    slip: float = 0.0  # the changed environment: each predator's move fails (it stays) with this probability
    mirror: bool = False  # the changed environment: the ad hoc predator's moves are mirrored (MIRRORED)
    teams = TEAMS

    def __post_init__(self) -> None:
        if not isinstance(self.size, int) or self.size < 3:
            raise ConfigError(f"pursuit size={self.size!r}: give an integer >= 3 (the thesis's world is 5)")
        if not 0.0 <= self.slip < 1.0:
            raise ConfigError(f"pursuit slip={self.slip!r}: give a probability in [0, 1)")
        m = self.size
        cells = np.arange(m * m)
        row, col = np.divmod(cells, m)
        nb = ((row[:, None] + MOVES[None, :, 0]) % m) * m + (col[:, None] + MOVES[None, :, 1]) % m
        gap_r = np.abs(row[:, None] - row[None, :])
        gap_c = np.abs(col[:, None] - col[None, :])
        dist = np.minimum(gap_r, m - gap_r) + np.minimum(gap_c, m - gap_c)
        # GOOD[c, d, a]: uniform over the moves from c that shorten the distance to d (stay where c == d)
        shorter = dist[nb[:, :4], :].transpose(0, 2, 1) < dist[:, :, None]  # (c, d, 4)
        good = np.concatenate([shorter, (cells[:, None] == cells[None, :])[..., None]], axis=-1).astype(float)
        object.__setattr__(self, "neighbours", nb)  # (C, 5)
        object.__setattr__(self, "distance", dist)  # (C, C)
        object.__setattr__(self, "good_moves", good / good.sum(-1, keepdims=True))
        object.__setattr__(self, "cells", m * m)
        half = m // 2
        delta_r = (row[None, :] - row[:, None] + half) % m - half  # (from, to) in [-half, m - 1 - half]
        delta_c = (col[None, :] - col[:, None] + half) % m - half
        object.__setattr__(self, "delta", np.stack([delta_r, delta_c], axis=-1))

    # --- states -------------------------------------------------------------------------------------------
    def sample_states(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """(count, 5) random configurations of five distinct cells that are not captures."""
        out = np.empty((count, N_AGENTS), dtype=np.int64)
        todo = np.arange(count)
        while todo.size:
            draw = np.argsort(rng.random((todo.size, self.cells)), axis=1)[:, :N_AGENTS]
            out[todo] = draw
            todo = todo[self.captured(out[todo])]
        return out

    def captured(self, states: np.ndarray) -> np.ndarray:
        """(B,) whether the four predators occupy the four cells around the prey."""
        around = self.neighbours[states[:, PREY], :4]  # (B, 4)
        hit = (around[:, :, None] == states[:, None, :N_PREDATORS]).any(-1)
        return hit.all(-1)

    # --- the exact environment model ---------------------------------------------------------------------
    def step(
        self, states: np.ndarray, predator_actions: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(next states, rewards, terminal) of the true dynamics; draws the prey's move, the move order (and
        the slips, when ``slip`` > 0); with ``mirror`` the ad hoc agent's action ``a`` moves it as
        ``MIRRORED[a]``."""
        count = states.shape[0]
        actions = np.empty((count, N_AGENTS), dtype=np.int64)
        actions[:, :N_PREDATORS] = predator_actions
        if self.mirror:
            actions[:, 0] = MIRRORED[actions[:, 0]]
        if self.slip > 0:
            actions[:, :N_PREDATORS][rng.random((count, N_PREDATORS)) < self.slip] = STAY
        actions[:, PREY] = rng.integers(0, 4, size=count)
        order = np.argsort(rng.random((count, N_AGENTS)), axis=1)
        nxt = states.copy()
        rows = np.arange(count)
        for turn in range(N_AGENTS):
            agent = order[:, turn]
            target = self.neighbours[nxt[rows, agent], actions[rows, agent]]
            taken = (nxt == target[:, None]).any(axis=1)
            nxt[rows, agent] = np.where(taken, nxt[rows, agent], target)
        done = self.captured(nxt)
        return nxt, done.astype(np.float64), done

    # --- the teams (exact per-predator action distributions) --------------------------------------------
    def team_policy(self, team: str, states: np.ndarray, agents=(1, 2, 3)) -> np.ndarray:
        """(B, len(agents), 5) ``pi^n(a | x)`` of ``team`` for the predators ``agents`` (Eq. 4.2's factors)."""
        if team == "teammate-aware":
            return self._teammate_aware(states, np.asarray(agents))
        elif team == "greedy":
            probs = self._greedy(states)
        elif team == "probabilistic-destinations":
            probs = self._probabilistic_destinations(states)
        else:
            raise ConfigError(f"team={team!r}: choose one of {', '.join(TEAMS)}")
        return probs[:, list(agents)]

    def _greedy(self, states: np.ndarray) -> np.ndarray:
        around = self.neighbours[states[:, PREY], :4]  # (B, 4)
        pred = states[:, :N_PREDATORS]
        d = self.distance[pred[:, :, None], around[:, None, :]].astype(float)  # (B, 4 pred, 4 targets)
        # a cell around the prey held by another predator is not a target (its own cell is)
        held = (around[:, None, :, None] == pred[:, None, None, :]) & ~np.eye(4, dtype=bool)[:, None, :]
        d = np.where(held.any(-1), np.inf, d)
        d = np.where(np.isinf(d).all(-1, keepdims=True), 0.0, d)  # all held: any cell around the prey
        nearest = (d == d.min(-1, keepdims=True)).astype(float)
        nearest /= nearest.sum(-1, keepdims=True)
        moves = self.good_moves[pred[:, :, None], around[:, None, :]]  # (B, 4, 4, 5)
        return np.einsum("bpt,bpta->bpa", nearest, moves)

    def _teammate_aware(self, states: np.ndarray, agents: np.ndarray) -> np.ndarray:
        count, k = states.shape[0], agents.size
        rows = np.arange(count)[:, None]
        around = self.neighbours[states[:, PREY], :4]
        pred = states[:, :N_PREDATORS]
        d = self.distance[pred[:, :, None], around[:, None, :]]  # (B, 4, 4)
        cost = d[:, np.arange(4)[None, :], _PERMUTATIONS].sum(-1)  # (B, 24)
        dest = around[rows, _PERMUTATIONS[cost.argmin(1)][:, agents]]  # (B, k) the asked predators' cells
        mine = pred[:, agents]  # (B, k)
        # obstacles of each asked predator: every other agent's cell (its own is free to it)
        blocked = np.zeros((count, k, self.cells), dtype=bool)
        for other in range(N_AGENTS):
            blocked[rows, np.arange(k)[None, :], states[:, other][:, None]] = True
        blocked[rows, np.arange(k)[None, :], mine] = False
        field = self.path_lengths(dest.reshape(-1), blocked.reshape(-1, self.cells)).reshape(count, k, -1)
        through = field[rows[..., None], np.arange(k)[None, :, None], self.neighbours[mine, :4]]  # (B, k, 4)
        here = field[rows, np.arange(k)[None, :], mine]
        ok = (through == through.min(-1, keepdims=True)) & (through < here[..., None])
        moves = np.concatenate([ok, (mine == dest)[..., None]], -1).astype(float)
        total = moves.sum(-1, keepdims=True)
        # walled off: the moves that shorten the plain distance
        return np.where(total > 0, moves / np.maximum(total, 1), self.good_moves[mine, dest])

    def path_lengths(self, goals: np.ndarray, blocked: np.ndarray) -> np.ndarray:
        """(R, C) breadth-first path lengths to ``goals`` (R,) through cells not ``blocked`` (R, C)."""
        return path_lengths(self.neighbours, goals, blocked)

    def _probabilistic_destinations(self, states: np.ndarray) -> np.ndarray:
        count = states.shape[0]
        prey_d = self.distance[states[:, PREY]]  # (B, C)
        weight = np.exp(-2.0 * prey_d.astype(float)) * np.where(
            prey_d == 1, 8.0, np.where(prey_d == 2, 2.0, 1.0)
        )
        weight[np.arange(count), states[:, PREY]] = 0.0
        out = np.empty((count, N_PREDATORS, N_ACTIONS))
        for p in range(N_PREDATORS):
            w = weight.copy()
            for other in range(N_PREDATORS):
                if other != p:
                    w[np.arange(count), states[:, other]] = 0.0
            w /= w.sum(-1, keepdims=True)
            out[:, p] = np.einsum("bc,bca->ba", w, self.good_moves[states[:, p]])
        return out


def path_lengths(neighbours: np.ndarray, goals: np.ndarray, blocked: np.ndarray) -> np.ndarray:
    """(R, C) breadth-first path lengths to ``goals`` (R,) on the cell graph ``neighbours`` (C, 5: the cell each
    action leads to) through cells not ``blocked`` (R, C); the goal counts as reachable; unreachable cells get
    ``C`` (longer than any path). Shared by pursuit's teammate-aware team and the navigation teams."""
    cells = neighbours.shape[0]
    rows = np.arange(goals.size)
    field = np.full((goals.size, cells), cells, dtype=np.int64)
    field[rows, goals] = 0
    passable = ~blocked
    passable[rows, goals] = True
    step = neighbours[:, :4]
    for _ in range(cells):
        grown = np.where(passable, np.minimum(field, field[:, step].min(-1) + 1), cells)
        if (grown == field).all():
            break
        field = grown
    return field


class ExactTeam:
    """The exact team model of one team (PLASTIC-Model's library entry): ``probs`` for the teammates (1-3 on
    pursuit); any chapter-4 world with ``teams`` and ``team_policy`` (pursuit, the navigation maps)."""

    def __init__(self, world, team: str) -> None:
        if team not in world.teams:
            raise ConfigError(f"team={team!r}: choose one of {', '.join(world.teams)}")
        self.world, self.team, self.name = world, team, team

    def probs(self, states: np.ndarray) -> np.ndarray:
        return self.world.team_policy(self.team, states)

    def seat(self, states: np.ndarray) -> np.ndarray:
        """(B, 5) the team's own policy for the ad hoc seat (the "original teammate" baseline)."""
        return self.world.team_policy(self.team, states, agents=(0,))[:, 0]


class ExactEnvironment:
    """The exact environment model (the true rules) with the planner's interface."""

    def __init__(self, world: Pursuit4) -> None:
        self.world = world

    def step(self, states, joint_actions, rng):
        return self.world.step(states, joint_actions, rng)
