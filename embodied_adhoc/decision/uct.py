"""UCT (Kocsis and Szepesvari 2006) for the ad hoc agent of chapter 4, batched, and the team belief update.

The planner needs a *simulator*: ``simulate(states (B, S), actions (B,), rng) -> (next states, rewards,
terminal)`` that draws the teammates' actions from the selected team model and the next state from the
environment model (exact for PLASTIC-Model, learned for TEAMSTER). States are integer arrays; tree nodes are
keyed by (depth, state code), so the tree is closed-loop over sampled states.

:class:`BatchedUct` runs the iterations in waves of ``wave`` simulations that descend in lock step: at each depth
every live simulation picks its action (UCB1 in the tree, uniform in the rollout after the node it expanded) in
Python, then one simulator call advances all of them. A selection counts as a visit immediately (visit counts
raised on the way down, values backed up after the wave), so simulations of one wave spread over the untried
and less-visited actions instead of repeating each other. With ``wave=1`` it is exactly the sequential
algorithm, which :class:`PlainUct` spells out node by node as the reference of ``scripts/bench_uct.py``.

Table 4.1 (pursuit): 100 iterations, rollout depth 5, UCB exploration sqrt(2), discount 0.95.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from embodied_adhoc.errors import ConfigError

Simulator = Callable[[np.ndarray, np.ndarray, np.random.Generator], tuple[np.ndarray, np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class UctConfig:
    """Table 4.1's hyperparameters (pursuit row by default) and the wave size of the batched search."""

    iterations: int = 100
    depth: int = 5
    exploration: float = math.sqrt(2.0)
    discount: float = 0.95
    actions: int = 5
    wave: int = 20

    def __post_init__(self) -> None:
        for name in ("iterations", "depth", "actions", "wave"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ConfigError(f"UctConfig.{name}={value!r}: give a positive integer")
        if not (self.exploration >= 0 and 0 < self.discount <= 1):
            raise ConfigError(
                f"UctConfig: exploration={self.exploration} must be >= 0 and discount="
                f"{self.discount} in (0, 1]"
            )


class _Node:
    __slots__ = ("visits", "counts", "values")

    def __init__(self, actions: int) -> None:
        self.visits = 0
        self.counts = [0] * actions
        self.values = [0.0] * actions

    def select(self, exploration: float, rng: np.random.Generator) -> int:
        """UCB1: an untried action first (uniformly among them), else the largest upper bound."""
        counts = self.counts
        if self.visits < len(counts):  # untried actions come first, so some are left exactly while this holds
            untried = [a for a, n in enumerate(counts) if n == 0]
            return untried[int(rng.integers(len(untried)))] if len(untried) > 1 else untried[0]
        log_n = math.log(self.visits)
        best, best_value = 0, -math.inf
        for a, (n, q) in enumerate(zip(self.counts, self.values, strict=True)):
            value = q + exploration * math.sqrt(log_n / n)
            if value > best_value:
                best, best_value = a, value
        return best

    def visit(self, action: int) -> None:
        self.visits += 1
        self.counts[action] += 1

    def back(self, action: int, value: float) -> None:
        self.values[action] += (value - self.values[action]) / self.counts[action]

    def best(self) -> int:
        """The action of highest mean value (ties: the most visited, then the lowest index)."""
        return max(
            range(len(self.counts)),
            key=lambda a: (self.values[a] if self.counts[a] else -math.inf, self.counts[a], -a),
        )


def _codes(states: np.ndarray) -> list[int]:
    """Hashable keys of the rows of ``states`` (non-negative ints below 2**12 each)."""
    return (
        (states.astype(np.int64) @ (4096 ** np.arange(states.shape[1], dtype=np.int64))).tolist()
        if states.shape[1] <= 5
        else [row.tobytes() for row in states]
    )


class BatchedUct:
    """UCT whose simulations advance in waves through one batched simulator call per depth."""

    def __init__(self, config: UctConfig = UctConfig()) -> None:
        self.config = config
        self.last_root: _Node | None = None

    def plan(self, state: np.ndarray, simulate: Simulator, rng: np.random.Generator) -> int:
        cfg = self.config
        tree: dict[tuple[int, int], _Node] = {}
        root_key = (0, _codes(state[None])[0])
        done = 0
        while done < cfg.iterations:
            width = min(cfg.wave, cfg.iterations - done)
            self._wave(np.repeat(state[None], width, axis=0), root_key, tree, simulate, rng)
            done += width
        self.last_root = tree[root_key]
        return self.last_root.best()

    def _wave(
        self, states: np.ndarray, root_key, tree: dict, simulate: Simulator, rng: np.random.Generator
    ) -> None:
        cfg = self.config
        width, actions_n, exploration = states.shape[0], cfg.actions, cfg.exploration
        paths: list[list[tuple[_Node, int]]] = [[] for _ in range(width)]
        in_tree = list(range(width))  # the simulations still descending the tree, in index order
        live = np.ones(width, dtype=bool)
        rewards = np.zeros((cfg.depth, width))
        for depth in range(cfg.depth):
            index = np.flatnonzero(live) if depth else np.arange(width)
            if index.size == 0:
                break
            actions = np.empty(width, dtype=np.int64)
            if in_tree:
                keys = [root_key[1]] * width if depth == 0 else _codes(states[in_tree])
                still = []
                for i, code in zip(in_tree, keys, strict=True):
                    key = (depth, code)
                    node = tree.get(key)
                    if node is None:
                        node = tree[key] = _Node(actions_n)
                    else:
                        still.append(i)  # a known node: the simulation stays in the tree
                    action = node.select(exploration, rng)
                    node.visits += 1
                    node.counts[action] += 1
                    paths[i].append((node, action))
                    actions[i] = action
                # live in-tree simulations that expanded a node continue as rollouts from the next depth
                rolling = live.copy()
                rolling[in_tree] = False
                in_tree = still
            else:
                rolling = live
            out = np.flatnonzero(rolling)
            if out.size:  # uniform rollout actions, one draw for the whole wave at this depth
                actions[out] = rng.integers(0, actions_n, size=out.size)
            nxt, reward, terminal = simulate(states[index], actions[index], rng)
            states[index] = nxt
            rewards[depth, index] = reward
            ended = index[np.asarray(terminal, dtype=bool)]
            if ended.size:
                live[ended] = False
                if in_tree:
                    in_tree = [i for i in in_tree if live[i]]
        acc = np.zeros(width)
        returns = np.zeros_like(rewards)
        for depth in range(cfg.depth - 1, -1, -1):
            acc = rewards[depth] + cfg.discount * acc
            returns[depth] = acc
        by_simulation = returns.T.tolist()
        for path, values in zip(paths, by_simulation, strict=True):
            for (node, action), value in zip(path, values, strict=False):
                node.values[action] += (value - node.values[action]) / node.counts[action]


class PlainUct:
    """The textbook sequential UCT, one simulation and one single-state simulator call per step: the reference
    the batched search is measured against (same tree rules, ``wave=1``)."""

    def __init__(self, config: UctConfig = UctConfig()) -> None:
        self.config = config

    def plan(self, state: np.ndarray, simulate: Simulator, rng: np.random.Generator) -> int:
        cfg = self.config
        tree: dict[tuple[int, int], _Node] = {}
        root_key = (0, _codes(state[None])[0])
        for _ in range(cfg.iterations):
            current = state[None].copy()
            path, rewards, expanded = [], [], False
            for depth in range(cfg.depth):
                key = (depth, _codes(current)[0]) if depth else root_key
                if not expanded:
                    node = tree.get(key)
                    if node is None:
                        node = tree[key] = _Node(cfg.actions)
                        expanded = True
                    action = node.select(cfg.exploration, rng)
                    node.visit(action)
                    path.append((node, action))
                else:
                    action = int(rng.integers(0, cfg.actions))
                current, reward, terminal = simulate(current, np.array([action]), rng)
                rewards.append(float(reward[0]))
                if terminal[0]:
                    break
            value = 0.0
            returns = []
            for reward in reversed(rewards):
                value = reward + cfg.discount * value
                returns.append(value)
            returns.reverse()
            for (node, action), value in zip(path, returns, strict=False):
                node.back(action, value)
        return tree[root_key].best()


def update_team_belief(
    belief: np.ndarray, likelihoods: np.ndarray, eta: float = 0.1, rule: str = "plastic", floor: float = 1e-3
) -> np.ndarray:
    """The team belief after observing the teammates' actions, given each model's ``pi(A | x)`` (the product
    of Eq. 4.2, computed by the caller).

    * ``plastic`` (Algorithm 2, PLASTIC's bounded loss): ``loss = 1 - pi(A | x)``, ``p' ∝ p (1 - eta * loss)``;
      ``eta`` in (0, 1) bounds the loss (Barrett et al. 2017 use 0.1). A sharp model that is right now and
      then gains on a diffuse model that is never sure (measured in docs/teamster.md).
    * ``bayes``: the posterior ``p' ∝ p max(pi(A | x), floor)`` (the floor keeps a model that was wrong once
      alive)."""
    if rule == "plastic":
        if not 0 < eta < 1:
            raise ConfigError(f"eta={eta}: the PLASTIC update needs 0 < eta < 1")
        updated = belief * (1.0 - eta * (1.0 - likelihoods))
    elif rule == "bayes":
        updated = belief * np.maximum(likelihoods, floor)
    else:
        raise ConfigError(f"rule={rule!r}: choose plastic or bayes")
    return updated / updated.sum()
