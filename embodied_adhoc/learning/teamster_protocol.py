"""The sequential-teams protocol of thesis section 4.1.4 on chapter-4 pursuit, one (agent, trial) at a time.

For each team tau_i in order (teammate-aware, greedy, probabilistic destinations):

1. the agent is paired with tau_i (:meth:`start_team`: a fresh online team model, a uniform belief);
2. it interacts for ``steps`` time steps, learning (episodes restart at a random configuration after each
   capture; the interaction is one stream of steps);
3. before the interaction and after every 10 % of it, learning pauses and the team is evaluated for
   ``eval_steps`` steps from a fresh configuration (uniform belief, nothing learned);
4. the agent stores tau_i in its library (:meth:`finish_team`);
5. it is evaluated on every team;
6. the next team.

Optionally (``changed`` > 0) a last phase repeats steps 1-3 with the teammate-aware team in a changed
environment whose predators' moves fail with probability ``changed`` (the robustness experiment: a learned
environment model adapts, the exact one stays the old rules).

The metric is the accumulated reward of an evaluation, which on pursuit is the number of prey captures (reward 1
each); :func:`run_trial` returns JSON-able records. Seeds: one ``SeedSequence`` per (seed, trial, agent) for the
agent and the interaction, one per evaluation, so that evaluations are reproducible and independent of the
agents' draws.
"""

from __future__ import annotations

import time
import zlib
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np
import torch

from embodied_adhoc.decision.agents.teamwork import sample_rows
from embodied_adhoc.decision.uct import UctConfig
from embodied_adhoc.domains.pursuit4 import TEAMS, ExactTeam, Pursuit4
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.teamster_agents import AGENTS, build_agent


@dataclass(frozen=True)
class ProtocolConfig:
    steps: int = 5000  # T per team (the thesis's mixed-team run is 15,000 = 3 x T)
    eval_steps: int = 500
    points: int = 10  # evaluations during an interaction (every 100/points %)
    size: int = 5
    changed: float = 0.0  # > 0: the changed-environment phase with this move-failure probability
    seed: int = 0
    iterations: int = 100
    depth: int = 5

    def __post_init__(self) -> None:
        for name in ("steps", "eval_steps", "points", "iterations", "depth"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ConfigError(f"teamster {name}={value!r}: give a positive integer")
        if self.steps % self.points:
            raise ConfigError(f"teamster steps={self.steps}: must be a multiple of points={self.points}")
        if not 0.0 <= self.changed < 1.0:
            raise ConfigError(f"teamster changed={self.changed}: give a move-failure probability in [0, 1)")

    def as_dict(self) -> dict:
        return asdict(self)


def _stream(config: ProtocolConfig, trial: int, *words: int | str) -> np.random.Generator:
    keys = [config.seed, trial] + [zlib.crc32(w.encode()) if isinstance(w, str) else w for w in words]
    return np.random.default_rng(np.random.SeedSequence(keys))


def play(agent, world: Pursuit4, team: ExactTeam, steps: int, rng: np.random.Generator) -> int:
    """``steps`` steps of the agent with ``team`` from a random configuration; returns the captures."""
    if hasattr(agent, "bind"):
        agent.bind(team.team)
    state = world.sample_states(rng, 1)[0]
    captures = 0
    for _ in range(steps):
        action = agent.act(state)
        joint = np.concatenate([[action], sample_rows(team.probs(state[None])[0], rng)])
        nxt, reward, done = world.step(state[None], joint[None], rng)
        agent.observe(state, joint, float(reward[0]), nxt[0], bool(done[0]))
        captures += int(done[0])
        state = world.sample_states(rng, 1)[0] if done[0] else nxt[0]
    return captures


def _evaluate(agent, world, team, config, trial, *words) -> int:
    agent.set_evaluation(True)
    try:
        return play(agent, world, team, config.eval_steps, _stream(config, trial, "eval", *words))
    finally:
        agent.set_evaluation(False)


def _interact(agent, world, team, config, trial, phase: str) -> list[list[int]]:
    """Steps 1-3: the learning curve [[step, captures in the evaluation], ...] (points + 1 entries)."""
    rng = _stream(config, trial, agent.name, phase)
    agent.start_team(rng)
    curve = [[0, _evaluate(agent, world, team, config, trial, phase, 0)]]
    chunk = config.steps // config.points
    for point in range(1, config.points + 1):
        play(agent, world, team, chunk, rng)
        curve.append([point * chunk, _evaluate(agent, world, team, config, trial, phase, point)])
    return curve


def run_trial(agent_name: str, trial: int, config: ProtocolConfig,
              tick: Callable[[], None] | None = None) -> dict:
    """The whole protocol for one agent and one trial (see the module docstring); ``tick`` after each phase."""
    if agent_name not in AGENTS:
        raise ConfigError(f"agent {agent_name!r}: choose from {', '.join(AGENTS)}")
    torch.set_num_threads(1)
    start = time.perf_counter()
    world = Pursuit4(config.size)
    teams = {name: ExactTeam(world, name) for name in TEAMS}
    uct = UctConfig(iterations=config.iterations, depth=config.depth)
    agent = build_agent(agent_name, world, _stream(config, trial, agent_name, "agent"), config.steps, uct)
    record = {"agent": agent_name, "trial": trial, "config": config.as_dict(), "curves": {}, "after": {}}
    for i, name in enumerate(TEAMS):
        record["curves"][name] = _interact(agent, world, teams[name], config, trial, name)
        agent.finish_team(name)
        record["after"][name] = {other: _evaluate(agent, world, teams[other], config, trial, "after", i, other)
                                 for other in TEAMS}
        if tick is not None:
            tick()
    if config.changed > 0:
        changed = Pursuit4(config.size, slip=config.changed)
        record["changed"] = _interact(agent, changed, ExactTeam(changed, TEAMS[0]), config, trial, "changed")
        if tick is not None:
            tick()
    record["seconds"] = round(time.perf_counter() - start, 1)
    return record
