"""Per-member bounds of the benchmark: a random ego (lower) and the exact best response (upper), computed and cached.

The world a member makes is a finite MDP for the ego once the member's policy is folded into the joint
transitions (the lab: the human's step distribution through the lab's transition rule ``domains.lab.apply_step``;
chapter 5: Fig. 5.2's reduction, ``domains.chapter5.teammates.world_with_teammate``). A trial's return is the
undiscounted sum of rewards up to the trial cap ``H`` (the episode ends earlier in the absorbing state, whose
reward is 0), so both bounds are exact finite-horizon values from the episode's start distribution:

* ``best``: ``H`` backups of value iteration (``decision.value_iteration``, discount 1), the best response of an
  ego that observes the state and knows the member: no agent does better in expectation;
* ``random``: the same ``H`` steps evaluating the uniform ego.

The normalised score of a return ``R`` is ``(R - random) / (best - random)``: 0 for the random ego and 1 for the
best response by construction; a score above 1 is reported as it is. Bounds (per state) are cached as ``.npz`` under
``$XDG_CACHE_HOME/embodied-adhoc/bench/``, keyed by the SHA-256 of the world's arrays, the start distribution, the
horizon and this module's source, so a changed member, model or code never serves an old bound.

The grid arenas (:data:`~embodied_adhoc.teammates.populations.GRID`) have no finite model: a team's state includes
the prey's and the learned teammates' draws and memories. There a return is minus the episode's steps (the trial
cap when the task is not finished: the thesis's steps to finish), and both bounds are estimated by simulation
(:func:`simulated_bounds`) over :data:`GRID_BOUND_EPISODES` episodes of their own seed (:data:`GRID_BOUND_SEED`),
run through the trial runner: the lower bound is the random ego's mean return; the upper bound is the better of
two mean returns, the member's *trained best response* (recurrent PPO against that member alone, shipped with the
suite: :mod:`embodied_adhoc.learning.best_response`) and the *original team* (the member's own policy in the
ego's seat, as the ATLPO split normalises). The maximum, because a trained best response is a lower estimate of
the true best response: a few minutes of PPO can end below the team's own policy, and the better of two policies
is still one an ego could play. :attr:`Bounds.upper` says which one it is per member, and ``original`` and
``trained`` hold both. A member without a shipped best response has the original team's. The best response's
trials are stored under a folder named by the SHA-256 of its weights' bytes, so new weights never resume old
trials. Either way the upper bound is an estimate, not the exact best response: an agent can score above it, and
the score is reported as it is.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.errors import ConfigError

__all__ = [
    "GRID_BOUND_EPISODES",
    "GRID_BOUND_SEED",
    "ORIGINAL",
    "TRAINED",
    "Bounds",
    "bounds_cache_dir",
    "grid_return",
    "member_bounds",
    "normalise",
    "simulated_bounds",
    "start_state",
    "world_mdps",
]

GRID_BOUND_EPISODES = 16
GRID_BOUND_SEED = 7_919
"""The grid bounds' episodes and seed: their own, not an evaluation's (``evaluate --seed 0`` scores other starts)."""
GRID_UPPER = "original"
EXACT = "exact best response"
ORIGINAL = "original team (the member's policy in the ego's seat)"
TRAINED = "trained best response (recurrent PPO against the member)"


@dataclass(frozen=True)
class Bounds:
    """A member's expected returns from the episode's start distribution: ``random`` (uniform ego) and ``best``
    (exact best response); ``best_values[m]`` and ``random_values[m]`` are the same from every state of task ``m``.
    """

    random: float
    best: float
    horizon: int
    best_values: tuple = field(default=(), compare=False, repr=False)
    random_values: tuple = field(default=(), compare=False, repr=False)
    upper: str = EXACT  # what ``best`` is: the exact best response, or the original team's estimated return
    episodes: int | None = None  # the episodes each simulated bound is the mean of (None: exact)
    original: float | None = None  # simulated: the original team's mean return
    trained: float | None = None  # simulated: the trained best response's mean return (None: none shipped)

    @property
    def span(self) -> float:
        return self.best - self.random

    def on_starts(self, starts) -> tuple[float, float]:
        """``(best, random)`` expected returns averaged over the given ``(task, start state)`` pairs: the bounds on
        a run's own episodes, which an agent's mean over those episodes is compared with."""
        if not self.best_values:
            raise ConfigError(
                "simulated bounds hold no per-state values: a run's own starts have no exact bound"
            )
        best = float(np.mean([self.best_values[task][state] for task, state in starts]))
        random = float(np.mean([self.random_values[task][state] for task, state in starts]))
        return best, random


def start_state(domain: str, library, spec: dict) -> tuple[int, int]:
    """``(task, state index)`` where an episode of the trial domain's ``spec`` starts."""
    task = int(spec["task"])
    if domain == "toxic-waste":
        ground = (0,) * len(library.tasks[task])
        return task, library.states.fast_index(
            int(spec["robot_node"]), int(spec["human_node"]), ground, False
        )
    return task, int(spec["start"])


def normalise(returns, bounds: Bounds) -> np.ndarray:
    """``(R - random) / (best - random)``; a member where the best response does no better than random has no
    scale (refused: no score can be read off it)."""
    if not bounds.span > 1e-9:
        raise ConfigError(
            f"a member whose best response ({bounds.best:.4g}) is no better than a random ego ({bounds.random:.4g}) "
            "cannot normalise scores; drop it from the suite"
        )
    return (np.asarray(returns, dtype=np.float64) - bounds.random) / bounds.span


def bounds_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "embodied-adhoc" / "bench"


# ----------------------------------------------------------------------------------------------- worlds


def _lab_world(library, human, task: int) -> list[sp.csr_matrix]:
    """Per robot action, ``P(x' | x, a)`` of task ``task`` with ``human`` (``policy_outcomes``) in the world."""
    from embodied_adhoc.domains.lab import apply_step

    outcomes_of = getattr(human, "policy_outcomes", None)
    if outcomes_of is None:
        raise ConfigError(
            f"{type(human).__name__}: an exact best response needs the human's step distribution, "
            "policy_outcomes(human_node, ball_status) -> [HumanOutcome, ...]; add it (see embodied_adhoc.bench)"
        )
    states, graph = library.states, library.graph
    n_states, n_actions = library.n_states, library.n_actions
    rows, cols, probs = ([[] for _ in range(n_actions)] for _ in range(3))
    for s in range(n_states):
        if not states.valid[task, s]:
            for a in range(n_actions):
                rows[a].append(s), cols[a].append(s), probs[a].append(1.0)
            continue
        robot, human_node, status, _ = states.describe(s)
        outcomes = outcomes_of(human_node, status)
        for a in range(n_actions):
            for outcome in outcomes:
                nr, nh, ns, disposed = apply_step(graph, robot, human_node, status, a, outcome)
                target = states.fast_index(nr, nh, ns, disposed)
                if target < 0:
                    raise ConfigError(
                        f"{type(human).__name__}: step from {states.names()[s]} leads outside the lab's states "
                        f"(robot {nr}, human {nh}, balls {ns})"
                    )
                rows[a].append(s), cols[a].append(target), probs[a].append(outcome.probability)
    return [
        sp.csr_matrix((probs[a], (rows[a], cols[a])), shape=(n_states, n_states)) for a in range(n_actions)
    ]


def world_mdps(member, library) -> tuple[list, list[np.ndarray]]:
    """``(mdps, starts)``: per task, the ego's undiscounted MDP with ``member`` (a ``TeammateSpec``) in the world and
    the episode's start distribution over its states (the trial domain's draw: uniform over the tasks)."""
    from embodied_adhoc.decision.models import MDP

    mdps, starts = [], []
    if member.domain == "toxic-waste":
        factory = member.factory()
        states = library.states
        n = library.graph.n_nodes
        ground = (0,) * len(library.tasks[0])
        for task in range(library.n_tasks):
            human = factory(library, task)
            mdps.append(MDP(_lab_world(library, human, task), library.mdps[task].rewards, 1.0))
            start = np.zeros(library.n_states)
            for robot in range(n):
                for human_node in range(n):
                    start[states.fast_index(robot, human_node, ground, False)] += 1.0 / (n * n)
            starts.append(start)
        return mdps, starts
    from embodied_adhoc.domains.chapter5.teammates import world_with_teammate

    for m, world in enumerate(world_with_teammate(library, member.plugin)):
        mdps.append(MDP(world.transitions, world.rewards, 1.0))
        starts.append(np.asarray(library.pomdps[m].initial_belief, dtype=np.float64))
    return mdps, starts


# ----------------------------------------------------------------------------------------------- values


def _random_values(mdp, horizon: int) -> np.ndarray:
    """``H``-step values of the uniform ego."""
    values = np.zeros(mdp.n_states)
    for _ in range(horizon):
        values = (mdp.rewards + mdp.expected_next_values(values)).mean(axis=1)
    return values


def _digest(mdps, starts, horizon: int) -> str:
    digest = hashlib.sha256()
    digest.update(Path(__file__).read_bytes())
    digest.update(np.asarray([horizon, len(mdps)]).tobytes())
    for mdp, start in zip(mdps, starts, strict=True):
        for matrix in mdp.transitions:
            for array in (matrix.indptr, matrix.indices, matrix.data):
                digest.update(np.ascontiguousarray(array).tobytes())
        digest.update(np.ascontiguousarray(mdp.rewards).tobytes())
        digest.update(np.ascontiguousarray(start).tobytes())
    return digest.hexdigest()


def member_bounds(member, library, horizon: int, cache: bool = True) -> Bounds:
    """The :class:`Bounds` of ``member`` (a ``TeammateSpec``) in ``library``'s domain at trial cap ``horizon``
    (cached; see the module docstring)."""
    from embodied_adhoc.atomic import atomic_open
    from embodied_adhoc.decision.value_iteration import value_iteration

    mdps, starts = world_mdps(member, library)
    path = bounds_cache_dir() / f"{_digest(mdps, starts, horizon)}.npz"
    best_values = random_values = None
    if cache and path.is_file():
        try:
            with np.load(path, allow_pickle=False) as stored:
                best_values = tuple(stored[f"best_{m}"] for m in range(len(mdps)))
                random_values = tuple(stored[f"random_{m}"] for m in range(len(mdps)))
        except (OSError, ValueError, KeyError, EOFError):
            best_values = None  # a damaged entry is computed again and overwritten
    if best_values is None:
        best_values = tuple(value_iteration(mdp, horizon=horizon).values for mdp in mdps)
        random_values = tuple(_random_values(mdp, horizon) for mdp in mdps)
        if cache:
            path.parent.mkdir(parents=True, exist_ok=True)
            arrays = {f"best_{m}": v for m, v in enumerate(best_values)}
            arrays |= {f"random_{m}": v for m, v in enumerate(random_values)}
            with atomic_open(path) as stream:
                np.savez(stream, **arrays)
    best = float(np.mean([start @ v for start, v in zip(starts, best_values, strict=True)]))
    random = float(np.mean([start @ v for start, v in zip(starts, random_values, strict=True)]))
    return Bounds(random, best, horizon, best_values, random_values)


# ----------------------------------------------------------------------------------------------- grid arenas


def grid_return(record) -> float:
    """A grid arena trial's benchmark return: minus its steps (the trial cap when the task is not finished)."""
    return -float(record.steps)


def _trained_agent(domain: str, options: dict) -> tuple[str, str] | None:
    """``(agent spec, weights digest)`` of the shipped best response to the member ``options`` puts in the teammate
    seats (its ``bench_member``), or None where there is none."""
    member = (options.get("bench_member") or {}).get("name")
    if member is None:
        return None
    from embodied_adhoc.teammates.best_responses import agent_spec, shipped_path, weights_digest

    path = shipped_path(domain, member)
    if not path.is_file():
        return None
    return agent_spec(domain, member), weights_digest(path)


def _mean_returns(config, out, agents: tuple[str, ...], sweep: dict) -> dict[str, float]:
    from embodied_adhoc.experiments.runner import run_sweep

    result = run_sweep(config, out=out, **sweep)
    returns: dict[str, list[float]] = {agent: [] for agent in agents}
    for record in result.records:
        returns[record.agent].append(grid_return(record))
    return {agent: float(np.mean(values)) for agent, values in returns.items()}


def simulated_bounds(
    domain: str,
    options: dict,
    max_steps: int,
    out: str | Path,
    episodes: int = GRID_BOUND_EPISODES,
    seed: int = GRID_BOUND_SEED,
    trained: bool = True,
    **sweep,
) -> Bounds:
    """A grid member's bounds (see the module docstring): the random ego's mean :func:`grid_return`, and the better
    of the original team's and (with ``trained``, where the member has one) its trained best response's, over
    ``episodes`` episodes of ``seed`` with the trial ``options`` that put the member in the teammate seats
    (``options["bench_member"]`` names it), on the abstract backend, stored (and resumed) under ``out``, the best
    response's under ``out/best-response-<digest>``; ``sweep`` goes to the trial runner (workers, executor,
    progress)."""
    from embodied_adhoc.experiments.runner import SweepConfig

    agents = ("random", GRID_UPPER)
    config = SweepConfig(domain, "abstract", options, agents, episodes, seed, max_steps)
    means = _mean_returns(config, out, agents, sweep)
    found = _trained_agent(domain, options) if trained else None
    trained_mean = None
    if found is not None:
        agent, digest = found
        config = SweepConfig(domain, "abstract", options, (agent,), episodes, seed, max_steps)
        trained_mean = _mean_returns(config, Path(out) / f"best-response-{digest[:16]}", (agent,), sweep)[
            agent
        ]
    use_trained = trained_mean is not None and trained_mean > means[GRID_UPPER]
    return Bounds(
        means["random"],
        trained_mean if use_trained else means[GRID_UPPER],
        int(max_steps),
        upper=TRAINED if use_trained else ORIGINAL,
        episodes=int(episodes),
        original=means[GRID_UPPER],
        trained=trained_mean,
    )
