"""Held-out-teammate protocol for ATLPO (beyond the thesis, as current ad hoc teamwork benchmarks evaluate):
teams no library member was trained with, scores normalised between random (0) and the original teammate (1),
summarised by the interquartile mean with percentile-bootstrap intervals
(``experiments.stats.summarise_sample``, passed to :func:`normalised_scores`).

A *team* is a callable ``team(rules, state, task, rng, members) -> actions`` giving the actions of the listed
agents (``members``, a list of indices) in a grid state, the signature of
:func:`embodied_adhoc.domains.grid_rules_team.team_actions` without the spec. The split (:func:`held_out_teams`):

* ``<tau>+noise<e>``: a thesis team whose every member takes a uniformly random action with probability ``e``;
* ``mixed-<a>/<b>/<c>``: teammates of different thesis types in one team (agent 0's type, used only by the
  original-teammate baseline, is the first);
* a user's team, ``module:callable`` (imported; called with the signature above).

Each episode runs one task (cycling 1..4) with the team in the seats of agents 1..N-1, on the grid twin's core
(its rules, observation function and episode draw; the team replaces the core's scripted team). Agents:
``original`` (the team's own policy for agent 0, full state), ``known-task`` (the library member trained on the
true task with team tau1: knows the task, not the team), ``atlpo-mf`` and ``random``.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass

import gymnasium
import numpy as np

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.atlpo import AtlpoAgent, LibraryEnvironment, PolicyLibrary
from embodied_adhoc.learning.classifier import RecurrentBayesianClassifier
from embodied_adhoc.learning.vector_grid import GRID_IDS
from embodied_adhoc.teammates.grid_members import SeatTeam

AGENTS = ("original", "known-task", "atlpo-mf", "random")
NOISE = 0.2
MIXED = (
    ("tau1", "tau0", "tau1", "tau2"),
    ("tau2", "tau2", "tau0", "tau0"),
)  # agent 0's type, then teammates'

Team = Callable[..., np.ndarray]


@dataclass(frozen=True)
class HeldOutTeam:
    name: str
    act: Team


def thesis_team(specs: dict, types: tuple[str, ...], noise: float = 0.0) -> Team:
    """Agent ``i`` plays thesis team ``types[i]`` (one type: an ordinary team); with ``noise`` each listed
    agent's action is replaced by a uniform one with that probability (both draws made every call): the
    benchmark's :class:`~embodied_adhoc.teammates.grid_members.SeatTeam`, called as a held-out team is."""
    if not 0.0 <= noise <= 1.0:
        raise ConfigError(f"noise={noise}: a probability in [0, 1]")
    seats = tuple(specs[name] for name in types)

    def act(rules, state, task, rng, members) -> np.ndarray:
        return SeatTeam(rules, seats, noise).actions(state, task, rng, members)

    return act


def user_team(reference: str) -> HeldOutTeam:
    """``module:callable`` imported, called as ``callable(rules, state, task, rng, members)``."""
    module_name, _, attribute = reference.partition(":")
    if not module_name or not attribute:
        raise ConfigError(f"--team {reference!r}: give module:callable, e.g. mypackage.teams:cautious")
    try:
        act = getattr(importlib.import_module(module_name), attribute)
    except (ImportError, AttributeError) as error:
        raise ConfigError(f"--team {reference!r}: cannot import it ({error})") from None
    if not callable(act):
        raise ConfigError(f"--team {reference!r}: {attribute} is not callable")
    return HeldOutTeam(reference, act)


def held_out_teams(domain: str, user: str | None = None) -> tuple[HeldOutTeam, ...]:
    """The split of :mod:`this module <embodied_adhoc.learning.atlpo_heldout>` for ``domain``."""
    import embodied_adhoc.envs  # noqa: F401  (registers the ids)

    probe = gymnasium.make(GRID_IDS[domain])
    specs = probe.unwrapped.core.teams
    probe.close()
    teams = [
        HeldOutTeam(f"{tau}+noise{NOISE}", thesis_team(specs, (tau,), NOISE))
        for tau in ("tau0", "tau1", "tau2")
    ]
    teams += [HeldOutTeam("mixed-" + "/".join(types[1:]), thesis_team(specs, types)) for types in MIXED]
    if user:
        teams.append(user_team(user))
    return tuple(teams)


def _checked(team: HeldOutTeam, actions, members: list[int]) -> np.ndarray:
    actions = np.asarray(actions)
    if (
        actions.shape != (len(members),)
        or not np.issubdtype(actions.dtype, np.integer)
        or (len(actions) and (actions.min() < 0 or actions.max() > 4))
    ):
        raise ConfigError(
            f"team {team.name}: returned {actions!r} for members {members}; it must return one "
            "action in 0..4 per listed member"
        )
    return actions.astype(np.int64)


def play(
    library: PolicyLibrary,
    classifier: RecurrentBayesianClassifier,
    team: HeldOutTeam,
    agent: str,
    task: int,
    seed: int,
    max_steps: int,
) -> tuple[int, bool]:
    """One episode of ``agent`` with ``team`` on ``task`` (1-based): (steps, finished). ``agent`` is one of
    :data:`AGENTS` or an Agent that reads the egocentric arrays (``observes_raw``: a learned agent)."""
    import embodied_adhoc.envs  # noqa: F401

    env = gymnasium.make(GRID_IDS[library.domain], **{**library.env_kwargs, "tasks": (task,)})
    observation, _ = env.reset(seed=seed)
    core = env.unwrapped.core
    rng = np.random.default_rng(seed + 1)
    teammates = list(range(1, core.config.n_agents))
    learned = None
    if agent in ("known-task", "atlpo-mf"):
        known = (
            library.environments.index(LibraryEnvironment(task, "tau1")) if agent == "known-task" else None
        )
        learned = AtlpoAgent(library, classifier, known=known)
    elif not isinstance(agent, str):
        learned = agent
    if learned is not None:
        learned.reset(rng)
        learned.start(observation)
    try:
        for step in range(1, max_steps + 1):
            state = core.episode.state
            if agent == "random":
                action = int(rng.integers(5))
            elif agent == "original":
                action = int(_checked(team, team.act(core.rules, state, core.task, rng, [0]), [0])[0])
            else:
                action = learned.act()
            others = _checked(team, team.act(core.rules, state, core.task, rng, teammates), teammates)
            core.step(np.concatenate([[action], others]))
            if not core.episode.state.alive.any():
                return step, True
            observation = core.observe(0)
            if learned is not None:
                learned.observe(action, observation)
        return max_steps, False
    finally:
        env.close()


def evaluate_held_out(
    library: PolicyLibrary,
    classifier: RecurrentBayesianClassifier,
    teams: tuple[HeldOutTeam, ...],
    episodes: int,
    seed: int,
    max_steps: int = 200,
    extra_agents: dict[str, Callable[[], object]] | None = None,
) -> dict:
    """Per team and agent: steps and finished flags of ``episodes`` episodes (task ``1 + e % 4``), the same
    episodes (seeds) for every agent. ``extra_agents`` (name -> factory of an ``observes_raw`` Agent) are played
    beside :data:`AGENTS`, a fresh agent per episode."""
    extra_agents = dict(extra_agents or {})
    results = {}
    for t, team in enumerate(teams):
        rows = {name: {"steps": [], "finished": []} for name in (*AGENTS, *extra_agents)}
        for episode in range(episodes):
            episode_seed = seed * 1_000_003 + 50_021 * (t + 1) + episode
            for name in rows:
                agent = extra_agents[name]() if name in extra_agents else name
                steps, finished = play(
                    library, classifier, team, agent, 1 + episode % 4, episode_seed, max_steps
                )
                rows[name]["steps"].append(steps)
                rows[name]["finished"].append(finished)
        results[team.name] = rows
    return results


def normalised_scores(cells: list[dict], summarise: Callable) -> dict:
    """Pool the evaluations of several seeds (``cells``) per team; each agent's episode score is
    ``(mean random steps - steps) / (mean random steps - mean original steps)`` over that team's pooled episodes
    (random 0, original teammate 1), summarised by ``summarise`` (the project's one summary,
    ``experiments.stats.summarise_sample``, passed in: ``learning/`` does not import ``experiments/``): its IQM
    and mean with percentile-bootstrap intervals."""
    scores = {}
    for team in dict.fromkeys(name for cell in cells for name in cell):
        agents = tuple(dict.fromkeys(agent for c in cells if team in c for agent in c[team]))
        pooled = {
            agent: np.concatenate([np.asarray(c[team][agent]["steps"], float) for c in cells if team in c])
            for agent in agents
        }
        solved = {
            agent: float(np.mean(np.concatenate([c[team][agent]["finished"] for c in cells if team in c])))
            for agent in agents
        }
        random_mean, original_mean = pooled["random"].mean(), pooled["original"].mean()
        span = random_mean - original_mean
        row = {
            "episodes": int(pooled["random"].size),
            "steps": {a: float(v.mean()) for a, v in pooled.items()},
            "solved": solved,
        }
        for agent in (a for a in agents if a not in ("original", "random")):
            if span <= 0:  # the team does no better than random: no scale to normalise on
                row[agent] = {"iqm": float("nan"), "ci": [float("nan")] * 2, "mean": float("nan")}
                continue
            summary = summarise((random_mean - pooled[agent]) / span)
            row[agent] = {
                "iqm": summary.iqm,
                "ci": [summary.iqm_ci_low, summary.iqm_ci_high],
                "mean": summary.mean,
            }
        scores[team] = row
    return scores
