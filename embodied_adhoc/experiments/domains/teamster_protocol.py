"""The sequential-teams protocol of thesis section 4.1.4 on chapter-4 pursuit and the navigation maps, one
(agent, trial) at a time. Every step runs in the project's one episode loop: the interaction and the evaluations
are :class:`~embodied_adhoc.envs.teamwork.TeamworkEnv` episodes through
:func:`~embodied_adhoc.episodes.loop.run_episode_loop`, the agent seated by
:class:`~embodied_adhoc.decision.agents.teamwork.EpisodeSeat`.

For each team tau_i in order (teammate-aware, greedy, probabilistic destinations):

1. the agent is paired with tau_i (:meth:`start_team`: a fresh online team model, a uniform belief);
2. it interacts for ``steps`` time steps, learning (episodes restart at a random configuration after each
   capture; the interaction is one stream of steps);
3. before the interaction and after every 10 % of it, learning pauses and the team is evaluated for
   ``eval_steps`` steps from a fresh configuration (uniform belief, nothing learned);
4. the agent stores tau_i in its library (:meth:`finish_team`);
5. it is evaluated on every team;
6. the next team.

Optionally (``mixed_steps``, pursuit only) a last phase is section 4.1.5's Performance Convergence Experiment: the
agent, its library built by steps 1-6, interacts with the *Mixed* team (seat 1 teammate-aware, seat 2 greedy,
seat 3 probabilistic destinations: :class:`MixedPursuit`) for ``mixed_steps`` steps (the thesis: 3 T = 15,000),
evaluated every ``steps / points`` steps as in step 3 (every 500 steps at T = 5000, as in the thesis); its curve is
``curves["mixed"]``. No library holds the Mixed team, so PLASTIC-Model plans with its online learned team
model there (the thesis's "reducing it to a Learns Team agent").

Optionally (``changed``) a last phase repeats steps 1-3 with the first team in a changed environment, for
``changed_steps`` steps (default ``steps``): ``changed`` = P, a probability, makes the moves (the predators', or
every agent's on a map) fail with probability P; ``changed = "mirror"`` mirrors the ad hoc agent's moves (up <->
down, left <-> right; ``pursuit4.MIRRORED``), a change that makes a model of the old rules wrong about which
action is best (the robustness experiment: a learned environment model adapts, the exact one stays the old
rules). :func:`parse_change` reads the command line's form (``fail:P``, ``mirror``, or a bare P).

The metric is the accumulated reward of an evaluation, which on pursuit is the number of prey captures (reward 1
each) in ``eval_steps`` steps; on the navigation maps (ntu, isr, pentagon: ``domains/navigation4.py``) it is the
mean accumulated reward of ``eval_episodes`` episodes of at most 100 steps (``100 - steps`` when the team gets
out, -100 when it does not), as in the thesis's Tables 4.5-4.7. The teams are the domain's (pursuit:
teammate-aware, greedy, probabilistic destinations; navigation: altruistic, selfish, weighted-altruistic), in
that order. :func:`run_trial` returns JSON-able records. Seeds: one ``SeedSequence`` per (seed, trial, agent) for the
agent and the interaction, one per evaluation, so that evaluations are reproducible and independent of the
agents' draws.
"""

from __future__ import annotations

import time
import zlib
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from embodied_adhoc.decision.agents.teamwork import EpisodeSeat
from embodied_adhoc.decision.uct import UctConfig
from embodied_adhoc.domains.navigation4 import MAPS, Navigation4
from embodied_adhoc.domains.pursuit4 import N_ACTIONS, TEAMS, ExactTeam, Pursuit4
from embodied_adhoc.envs.teamwork import TeamworkEnv
from embodied_adhoc.episodes.loop import run_episode_loop
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.blocks import one_thread
from embodied_adhoc.learning.teamster_agents import build_agent


@dataclass(frozen=True)
class ProtocolConfig:
    steps: int = 5000  # T per team (the thesis's mixed-team run is 15,000 = 3 x T)
    eval_steps: int = 500
    points: int = 10  # evaluations during an interaction (every 100/points %)
    size: int = 5
    changed: float | str = (
        0.0  # > 0: the changed phase with this move-failure probability; "mirror" (see above)
    )
    seed: int = 0
    iterations: int = 100
    depth: int = 5
    domain: str = "pursuit"  # or a navigation map: ntu, isr, pentagon
    eval_episodes: int = 8  # navigation: episodes per evaluation (the original's 8)
    changed_steps: int | None = None  # the changed phase's interaction steps (None: ``steps``)
    wave: int = (
        UctConfig.wave
    )  # UCT simulations that descend together (decision.uct.BatchedUct; 1: the sequential UCT)
    mixed_steps: int | None = None  # the Mixed team's phase (section 4.1.5; None: none)

    def __post_init__(self) -> None:
        if self.domain not in DOMAINS:
            raise ConfigError(f"teamster domain={self.domain!r}: choose one of {', '.join(DOMAINS)}")
        for name in ("steps", "eval_steps", "points", "iterations", "depth", "eval_episodes", "wave"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ConfigError(f"teamster {name}={value!r}: give a positive integer")
        if self.domain == "pursuit" and (not isinstance(self.size, int) or self.size < 3):
            raise ConfigError(f"teamster size={self.size!r}: pursuit's torus needs a side >= 3")
        if self.steps % self.points:
            raise ConfigError(f"teamster steps={self.steps}: must be a multiple of points={self.points}")
        object.__setattr__(self, "changed", parse_change(self.changed, "teamster changed"))
        if self.changed_steps is not None and (
            not isinstance(self.changed_steps, int)
            or self.changed_steps < 1
            or self.changed_steps % self.points
        ):
            raise ConfigError(
                f"teamster changed_steps={self.changed_steps!r}: give a positive multiple of "
                f"points={self.points}"
            )
        if self.mixed_steps is not None:
            chunk = self.steps // self.points
            if not isinstance(self.mixed_steps, int) or self.mixed_steps < 1 or self.mixed_steps % chunk:
                raise ConfigError(
                    f"teamster mixed_steps={self.mixed_steps!r}: give a positive multiple of steps / points "
                    f"= {chunk} (the phase is evaluated every {chunk} steps, as each team's interaction)"
                )
            if self.domain != "pursuit":
                raise ConfigError(f"teamster mixed_steps: the Mixed team is pursuit's, not {self.domain}'s")
            if self.changed:
                raise ConfigError(
                    "teamster mixed_steps with changed: each is its own last phase; run them in two folders"
                )

    @property
    def phase_steps(self) -> int:
        """The changed phase's interaction steps."""
        return self.steps if self.changed_steps is None else self.changed_steps

    def as_dict(self) -> dict:
        """The settings a record is stored with; pursuit's omit the navigation fields (so folders written
        before the navigation maps existed still resume)."""
        settings = asdict(self)
        for name in (
            "changed_steps",
            "mixed_steps",
        ):  # folders written before the options existed still resume
            if settings[name] is None:
                del settings[name]
        if (
            self.wave == UctConfig.wave
        ):  # the same: records carry the wave only where it is not the planner's default
            del settings["wave"]
        if self.domain == "pursuit":
            del settings["domain"], settings["eval_episodes"]
        return settings


DOMAINS = ("pursuit",) + MAPS
CHANGES = ("fail:P", "mirror")


def parse_change(value, label: str = "--changed") -> float | str:
    """The changed environment from its command-line form: ``fail:P`` or a bare ``P`` (moves fail with
    probability P in [0, 1); 0: no changed phase) or ``mirror`` (the ad hoc agent's moves mirrored); returns P
    (a float) or ``"mirror"``. Anything else: :class:`ConfigError` naming ``label``."""
    text = str(value).strip()
    if text == "mirror":
        return "mirror"
    number = text[len("fail:") :] if text.startswith("fail:") else text
    try:
        probability = float(number)
    except ValueError:
        probability = None
    if probability is None or not 0.0 <= probability < 1.0 or isinstance(value, bool):
        raise ConfigError(
            f"{label} {value!r}: give fail:P (moves fail with probability P in [0, 1)), a bare P, "
            "or mirror (the ad hoc agent's moves mirrored)"
        )
    return probability


def make_world(domain: str, size: int = 5, slip: float = 0.0, mirror: bool = False):
    """The chapter-4 world of ``domain``: 5x5 (``size``) pursuit or a navigation map; ``slip`` > 0 or ``mirror``
    is a changed environment (moves fail with that probability; the ad hoc agent's moves mirrored)."""
    if domain == "pursuit":
        return Pursuit4(size, slip=slip, mirror=mirror)
    return Navigation4(domain, slip=slip, mirror=mirror)


MIXED = "mixed"
MIXED_SEATS = ("teammate-aware", "teammate-aware", "greedy", "probabilistic-destinations")
"""The Mixed team of section 4.1.5, per predator seat: "each with a different policy (one with a teammate aware
policy, another with a greedy policy and a third with a probabilistic destinations policy)"; seat 0, the ad hoc
agent's, is teammate-aware for the ``original`` baseline (the thesis names no fourth member)."""


@dataclass(frozen=True)
class MixedPursuit(Pursuit4):
    """Pursuit whose teams include the Mixed team (:data:`MIXED_SEATS`): the same rules, and each seat's
    ``pi^n(a | x)`` (Eq. 4.2's factors) taken from its own team's exact policy."""

    teams = TEAMS + (MIXED,)

    def team_policy(self, team: str, states: np.ndarray, agents=(1, 2, 3)) -> np.ndarray:
        if team != MIXED:
            return super().team_policy(team, states, agents)
        return np.concatenate(
            [super(MixedPursuit, self).team_policy(MIXED_SEATS[a], states, (a,)) for a in agents], axis=1
        )


def changed_world(config: ProtocolConfig):
    """The changed environment of ``config.changed`` (a failure probability or ``"mirror"``)."""
    if config.changed == "mirror":
        return make_world(config.domain, config.size, mirror=True)
    return make_world(config.domain, config.size, slip=config.changed)


def _stream(config: ProtocolConfig, trial: int, *words: int | str) -> np.random.Generator:
    keys = [config.seed, trial] + [zlib.crc32(w.encode()) if isinstance(w, str) else w for w in words]
    return np.random.default_rng(np.random.SeedSequence(keys))


def _episodes(
    agent,
    world,
    team: ExactTeam,
    rng: np.random.Generator,
    steps: int | None = None,
    episodes: int | None = None,
) -> list:
    """The agent with ``team`` in ``world`` as :class:`~embodied_adhoc.envs.teamwork.TeamworkEnv` episodes through
    the one episode loop (:func:`~embodied_adhoc.episodes.loop.run_episode_loop`, the agent seated by
    :class:`~embodied_adhoc.decision.agents.teamwork.EpisodeSeat`): episode after episode, each from a random
    configuration, until ``steps`` steps have been taken (the last episode cut there) or ``episodes`` episodes
    have ended; an episode stops at its end (a capture, everyone out) or after the world's ``episode_cap``
    steps (navigation; pursuit has none). ``rng`` draws the configurations, the teammates' actions and the
    rules' chances (the env's generator); the agent keeps its own (``agent.rng``). Whether it learns is the
    caller's (``set_evaluation``). Returns the episodes' traces."""
    if hasattr(agent, "bind"):
        agent.bind(team.team)
    env = TeamworkEnv(world=world, teams=team.team)
    env.np_random = rng  # one stream for the whole interaction: episodes continue it (env_seed=None)
    seat = EpisodeSeat(agent, env.n_agents)
    cap = getattr(world, "episode_cap", None)
    traces, left = [], steps
    while (left is None or left > 0) and (episodes is None or len(traces) < episodes):
        limit = cap if left is None else (left if cap is None else min(cap, left))
        trace = run_episode_loop(
            env,
            seat,
            env_seed=None,
            agent_rng=agent.rng,
            reset_options=None,
            max_steps=limit,
            observation_index=env.observation_index,
        )
        traces.append(trace)
        left = None if left is None else left - trace.steps
    return traces


def play(agent, world, team: ExactTeam, steps: int, rng: np.random.Generator) -> int:
    """``steps`` steps of the agent with ``team`` from a random configuration; returns the episodes finished
    (the prey captures on pursuit)."""
    return sum(trace.terminated for trace in _episodes(agent, world, team, rng, steps=steps))


def play_episodes(agent, world, team: ExactTeam, episodes: int, rng: np.random.Generator) -> list[float]:
    """Each of ``episodes`` episodes' accumulated reward (an episode stopped by the cap keeps what it got)."""
    return [float(sum(trace.rewards)) for trace in _episodes(agent, world, team, rng, episodes=episodes)]


def _evaluate(agent, world, team, config, trial, *words) -> float:
    """Captures in ``eval_steps`` steps (pursuit) or the mean episode reward of ``eval_episodes`` episodes."""
    agent.set_evaluation(True)
    try:
        rng = _stream(config, trial, "eval", *words)
        if config.domain != "pursuit":
            return round(float(np.mean(play_episodes(agent, world, team, config.eval_episodes, rng))), 4)
        return play(agent, world, team, config.eval_steps, rng)
    finally:
        agent.set_evaluation(False)


def _learned_environment(agent):
    """The agent's learned environment model (one with ``transition_probs``), or None."""
    environment = getattr(agent, "environment", None)
    return environment if hasattr(environment, "transition_probs") else None


def model_fit(agent, world, rng: np.random.Generator, count: int = 256) -> list[float] | None:
    """How well a learned environment model predicts the ad hoc agent's own move in ``world``: on ``count``
    random states with uniform predator actions stepped by the true rules, the share where the model's most
    likely move class for agent 0 is the one taken, and the mean probability it gives that move (None for an
    agent without a learned transition model). Diagnoses the changed phase."""
    environment = _learned_environment(agent)
    if environment is None:
        return None
    states = world.sample_states(rng, count)
    actions = rng.integers(0, N_ACTIONS, size=(count, environment.features.n_actors))
    moved = environment.features.move_of[states[:, 0], world.step(states, actions, rng)[0][:, 0]]
    probs = environment.transition_probs(states, actions)[:, 0]
    return [
        round(float((probs.argmax(-1) == moved).mean()), 4),
        round(float(probs[np.arange(count), moved].mean()), 4),
    ]


def _interact(
    agent,
    world,
    team,
    config,
    trial,
    phase: str,
    steps: int,
    fit: list | None = None,
    chunk: int | None = None,
) -> list[list[int]]:
    """Steps 1-3 over ``steps`` steps, evaluated every ``chunk`` steps (default ``steps / points``): the learning
    curve [[step, captures in the evaluation], ...]."""
    rng = _stream(config, trial, agent.name, phase)
    agent.start_team(rng)
    curve = [[0, _evaluate(agent, world, team, config, trial, phase, 0)]]
    chunk = chunk or steps // config.points
    for point in range(steps // chunk + 1):
        if point:
            play(agent, world, team, chunk, rng)
            curve.append([point * chunk, _evaluate(agent, world, team, config, trial, phase, point)])
        if fit is not None:  # the model's fit to these rules, on probes of their own stream
            fit.append(
                [point * chunk] + (model_fit(agent, world, _stream(config, trial, "fit", phase, point)) or [])
            )
    return curve


def run_trial(
    agent_name: str, trial: int, config: ProtocolConfig, tick: Callable[[], None] | None = None
) -> dict:
    """The whole protocol for one agent and one trial (see the module docstring); ``tick`` after each phase. Runs
    on one torch thread and one BLAS thread: the networks' products are small, and a multi-threaded OpenBLAS only
    spins, costing many times the CPU of the trial itself."""
    from threadpoolctl import threadpool_limits

    one_thread()
    with threadpool_limits(limits=1, user_api="blas"):
        return _run_trial(agent_name, trial, config, tick)


def _run_trial(agent_name: str, trial: int, config: ProtocolConfig, tick: Callable[[], None] | None) -> dict:
    start = time.perf_counter()
    # with the Mixed phase the agents know the Mixed team's name (the original baseline plays its seat 0);
    # the same rules, and the Mixed team is met only in its own phase
    world = MixedPursuit(config.size) if config.mixed_steps else make_world(config.domain, config.size)
    teams = {name: ExactTeam(world, name) for name in world.teams if name != MIXED}
    uct = UctConfig(iterations=config.iterations, depth=config.depth, wave=config.wave)
    agent = build_agent(agent_name, world, _stream(config, trial, agent_name, "agent"), config.steps, uct)
    record = {"agent": agent_name, "trial": trial, "config": config.as_dict(), "curves": {}, "after": {}}
    for i, name in enumerate(teams):
        record["curves"][name] = _interact(agent, world, teams[name], config, trial, name, config.steps)
        agent.finish_team(name)
        record["after"][name] = {
            other: _evaluate(agent, world, teams[other], config, trial, "after", i, other) for other in teams
        }
        if tick is not None:
            tick()
    if config.mixed_steps is not None:  # section 4.1.5's Performance Convergence Experiment
        record["curves"][MIXED] = _interact(
            agent,
            world,
            ExactTeam(world, MIXED),
            config,
            trial,
            MIXED,
            config.mixed_steps,
            chunk=config.steps // config.points,
        )
        if tick is not None:
            tick()
    if config.changed:
        changed = changed_world(config)
        fit = [] if _learned_environment(agent) is not None else None
        record["changed"] = _interact(
            agent,
            changed,
            ExactTeam(changed, changed.teams[0]),
            config,
            trial,
            "changed",
            config.phase_steps,
            fit,
        )
        if fit is not None:  # [step, agent 0's move predicted (share), P(its move)] at each evaluation point
            record["changed_fit"] = fit
        if tick is not None:
            tick()
    record["seconds"] = round(time.perf_counter() - start, 1)
    return record
