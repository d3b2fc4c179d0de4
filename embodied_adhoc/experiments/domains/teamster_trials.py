"""``embodied-adhoc trials pursuit4``: chapter 4's agents (TEAMSTER, PLASTIC-Model, the ablations, PLASTIC-Policy,
random, the original teammate) in the trial runner, on the grid twin and in the MuJoCo arena.

``embodied-adhoc trials pursuit4 --backend abstract,mujoco --agents plastic-model,teamster,random,original``

The world is :class:`~embodied_adhoc.envs.teamwork.TeamworkEnv` (chapter 4's pursuit rules;
``EmbodiedAdhoc/Pursuit4Grid-v0`` / ``EmbodiedAdhoc/Pursuit4-v0``), every episode run by the one episode loop with
the agent seated by :class:`~embodied_adhoc.decision.agents.teamwork.EpisodeSeat`. Each agent is first taken
through steps 1-4 of the sequential-teams protocol (section 4.1.4) on the abstract rules: ``--learn-steps``
steps with each team in turn, learning, then the team joins its library (PLASTIC-Model: the exact models). The
episodes are then evaluations as in step 5: learning paused, the team belief restarted uniform each episode.
The learned agent is built once per worker from ``--seed`` (same seed, same agent), so results do not depend on
the number of workers.

Episode spec: ``task`` (the team's index in teammate-aware, greedy, probabilistic destinations) and ``s0``..``s4``
(the start cells of the ad hoc agent, the teammates and the prey). The metric is the trial runner's: steps to
the capture (the episode ends there), capped at ``--max-steps`` (registered cap 100).
"""

from __future__ import annotations

import argparse

import numpy as np

from embodied_adhoc.domains.pursuit4 import TEAMS
from embodied_adhoc.errors import ConfigError

__all__ = ["DOMAIN", "Pursuit4Session", "Pursuit4TrialDomain"]

AGENTS = (
    "plastic-model",
    "teamster",
    "learns-team",
    "learns-environment",
    "plastic-policy",
    "random",
    "original",
)
ENV_IDS = {"abstract": "EmbodiedAdhoc/Pursuit4Grid-v0", "mujoco": "EmbodiedAdhoc/Pursuit4-v0"}
N_AGENTS = 5
_LEARNED: dict = {}  # (agent, learn_steps, learn_seed) -> the agent after learning, shared by both backends' sessions


class Pursuit4Session:
    """The learned agents (built once per process), the env of one backend."""

    blas_threads = (
        1  # trials run with one BLAS thread (executors.execute_job): the networks' products are small
    )

    def __init__(self, backend: str, options: dict) -> None:
        import gymnasium

        import embodied_adhoc.envs  # noqa: F401  (registers the ids)

        self.backend, self.options = backend, options
        self.env_id = ENV_IDS[backend]
        if self.env_id not in gymnasium.registry:
            raise ConfigError(f"--backend {backend} needs the env '{self.env_id}', which is not registered")
        self.task_names = TEAMS + ("online model",)

    def make_env(self, max_steps: int):
        import gymnasium

        return gymnasium.make(self.env_id, max_episode_steps=int(max_steps), disable_env_checker=True)

    def reset_options(self, spec: dict) -> dict:
        return {"team": TEAMS[int(spec["task"])], "state": [int(spec[f"s{i}"]) for i in range(N_AGENTS)]}

    def learned_agent(self, name: str):
        """``name`` after ``learn_steps`` steps with each team (section 4.1.4, steps 1-4), built once per process
        (episodes leave it unchanged: learning is paused, the belief restarts and the draws come from the
        episode's generator)."""
        key = (name, int(self.options["learn_steps"]), int(self.options["learn_seed"]))
        if key not in _LEARNED:
            from embodied_adhoc.domains.pursuit4 import ExactTeam, Pursuit4
            from embodied_adhoc.experiments.domains.teamster_protocol import play
            from embodied_adhoc.learning.blocks import one_thread
            from embodied_adhoc.learning.teamster_agents import build_agent

            one_thread()

            world, steps = Pursuit4(), int(self.options["learn_steps"])
            rng = np.random.default_rng(
                np.random.SeedSequence([int(self.options["learn_seed"]), N_AGENTS, AGENTS.index(name)])
            )
            agent = build_agent(name, world, rng, max(steps, 1))
            for team in TEAMS:
                agent.start_team(rng)
                if steps:
                    play(agent, world, ExactTeam(world, team), steps, rng)
                agent.finish_team(team)
            _LEARNED[key] = agent
        return _LEARNED[key]

    def make_agent(self, name: str, spec: dict, seed: int):
        from embodied_adhoc.decision.agents.teamwork import EpisodeSeat

        if name not in AGENTS:
            raise ConfigError(f"agent {name!r}: choose from {', '.join(AGENTS)}")
        agent = self.learned_agent(name)
        if hasattr(agent, "bind"):  # the original teammate is defined to be the team's own member
            agent.bind(TEAMS[int(spec["task"])])
        return EpisodeSeat(agent, N_AGENTS, evaluation=True)

    def observation_index(self, observation) -> int:
        from embodied_adhoc.envs.teamwork import state_code

        return state_code(observation[:N_AGENTS], 25)


class Pursuit4TrialDomain:
    name = "pursuit4"
    description = (
        "Chapter-4 pursuit (5x5 torus, 4 predators, teams teammate-aware/greedy/probabilistic "
        "destinations): TEAMSTER, PLASTIC-Model, ... after learning each team"
    )
    backends = ("abstract", "mujoco")
    agent_names = AGENTS
    default_agents = ("plastic-model", "random", "original")
    privileged_agents = ()  # every chapter-4 agent observes the (fully observable) state through obs

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        group = parser.add_argument_group(f"{self.name} options")
        group.add_argument(
            "--team",
            default=None,
            metavar="NAME[,NAME]",
            help=f"team(s) drawn per episode, from {', '.join(TEAMS)} (default: all three)",
        )
        group.add_argument(
            "--learn-steps",
            type=int,
            default=500,
            metavar="T",
            help="steps of learning interaction with each team before the episodes (section "
            "4.1.4's T; default 500; 0: libraries of untrained models, exact for plastic-model)",
        )

    def options_from_args(self, args: argparse.Namespace) -> dict:
        teams = tuple(t.strip() for t in args.team.split(",")) if args.team else TEAMS
        unknown = [t for t in teams if t not in TEAMS]
        if unknown or not teams:
            raise ConfigError(
                f"--team {args.team!r}: unknown {', '.join(unknown) or '(none)'}; choose from "
                f"{', '.join(TEAMS)}"
            )
        if args.learn_steps < 0:
            raise ConfigError(f"--learn-steps {args.learn_steps}: give a number of steps >= 0")
        return {"teams": list(teams), "learn_steps": int(args.learn_steps), "learn_seed": int(args.seed)}

    def episode_spec(self, options: dict, rng: np.random.Generator) -> dict:
        from embodied_adhoc.domains.pursuit4 import Pursuit4

        team = options["teams"][int(rng.integers(len(options["teams"])))]
        state = Pursuit4().sample_states(rng, 1)[0]
        return {"task": TEAMS.index(team), **{f"s{i}": int(cell) for i, cell in enumerate(state)}}

    def open_session(self, backend: str, options: dict) -> Pursuit4Session:
        return Pursuit4Session(backend, options)


DOMAIN = Pursuit4TrialDomain()
