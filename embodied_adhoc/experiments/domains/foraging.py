"""Trial plug-ins of the grid arenas: ``embodied-adhoc trials foraging|pursuit --backend abstract|mujoco``.

Episode spec (drawn once per episode from ``(seed, episode)``, shared by every agent): ``task`` (0-based index
in the N/S/W/E task library, or fixed by ``--task``), ``team`` (uniform over ``--team``) and ``start`` (the
initial grid state as JSON, imposed through ``reset(options={"state": ...})``), so every agent faces the same
team, task and start; the prey's moves and teammates' tie-breaks then follow each trial's env seed.

Agents: ``original`` (the thesis's *original teammate*: the team's own policy, with the full state, in the ad
hoc robot's seat), ``random`` (uniform over the 5 actions), ``atlpo-mf`` (thesis chapter 6: the ATLPO agent of
the pre-trained library shipped with the package, or of ``--library DIR``; it reads the egocentric arrays
themselves, ``observes_raw``, and its task posterior is the classifier's marginal over the tasks) and
``ppo-generalist`` (the library-free recurrent PPO agent shipped with the package, trained against tau0-tau2;
it keeps no task posterior) and ``liam`` (the same network trained with LIAM's reconstruction of the teammates,
:mod:`embodied_adhoc.learning.liam`) and ``meliba`` (a policy conditioned on a variational belief over its
teammates, :mod:`embodied_adhoc.learning.meliba`). The observation index reported to the runner is a CRC-32
fingerprint of the egocentric observation (these domains have no finite observation library), or on the pair variant
(``--pairs``) the pursuit POMDP's index that its ``obs["observation_index"]`` holds.
"""

from __future__ import annotations

import argparse
import functools
import json
import zlib
from dataclasses import dataclass

import numpy as np

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning import LEARNED_AGENTS

ENV_IDS = {
    "foraging": {"abstract": "EmbodiedAdhoc/ForagingGrid-v0", "mujoco": "EmbodiedAdhoc/Foraging-v0"},
    "pursuit": {"abstract": "EmbodiedAdhoc/PursuitGrid-v0", "mujoco": "EmbodiedAdhoc/Pursuit-v0"},
    "pursuit-pairs": {
        "abstract": "EmbodiedAdhoc/PursuitPairGrid-v0",
        "mujoco": "EmbodiedAdhoc/PursuitPair-v0",
    },
}


def original_action(rules, task, team_spec, state: dict, rng: np.random.Generator) -> int:
    """The team's own action for the ad hoc robot's seat in ``state`` (``info['state']``'s form): the
    ``original`` agent's policy (a :class:`~embodied_adhoc.decision.agents.baselines.StatePolicyAgent`)."""
    from embodied_adhoc.domains.grid_rules_team import TeamSpec, team_actions
    from embodied_adhoc.envs.grid_world_env import state_from_dict

    grid_state = state_from_dict(state, rules)
    if not isinstance(team_spec, TeamSpec):  # a user's team policy (teammates.grid_plugins)
        return int(team_spec.actions(grid_state, task, rng, [0])[0])
    return int(team_actions(rules, grid_state, task, team_spec, rng, [0])[0])


@dataclass(frozen=True)
class GridLibrary:
    """The grid arenas' library for plug-in agents: ``rules`` (``GridRules``: ``rules.config`` has rows, cols,
    agents), ``tasks`` (the four forage/capture tasks), ``teams`` (team name -> team spec)."""

    rules: object
    tasks: tuple
    teams: dict
    n_actions: int = 5


class GridTrialSession:
    def __init__(self, domain: str, backend: str, options: dict) -> None:
        import gymnasium

        import embodied_adhoc.envs  # noqa: F401  (registers the ids)

        self.env_id = ENV_IDS["pursuit-pairs" if options.get("pairs") else domain][backend]
        self.domain, self.library = domain, options.get("library")
        self.env_kwargs = env_kwargs(options)
        probe = gymnasium.make(self.env_id, **self.env_kwargs).unwrapped
        self.rules, self.tasks, self.teams = probe.core.rules, probe.core.tasks, probe.core.teams
        probe.close()
        self.task_names = tuple(task.name for task in self.tasks)
        # what a plug-in agent's factory receives (experiments.registry.build_agent): the arena's rules, tasks
        # and named teams; the actions are the indices of domains.grid_rules.ACTION_NAMES
        self.agent_library = GridLibrary(self.rules, self.tasks, self.teams)

    def make_env(self, max_steps: int):
        import gymnasium

        return gymnasium.make(
            self.env_id, max_episode_steps=int(max_steps), disable_env_checker=True, **self.env_kwargs
        )

    def reset_options(self, spec: dict) -> dict:
        return {"task": int(spec["task"]) + 1, "team": spec["team"], "state": json.loads(spec["start"])}

    def make_agent(self, name: str, spec: dict, seed: int):
        if name == "random":  # uniform over the five actions
            from embodied_adhoc.decision.agents.baselines import RandomAgent

            return RandomAgent(5, name=name)
        if name == "original":
            from embodied_adhoc.decision.agents.baselines import StatePolicyAgent

            task, team = self.tasks[int(spec["task"])], self.teams[spec["team"]]
            return StatePolicyAgent(functools.partial(original_action, self.rules, task, team), name=name)
        if name == "atlpo-mf":
            from embodied_adhoc.learning.atlpo import library_agent

            return library_agent(self.domain, self.library, self.rules.config, name=name)
        if name == "ppo-generalist":
            from embodied_adhoc.learning.generalist import generalist_agent

            return generalist_agent(self.domain, None, self.rules.config, name=name)
        if name == "liam":
            from embodied_adhoc.learning.liam import liam_agent

            return liam_agent(self.domain, None, self.rules.config, name=name)
        if name == "meliba":
            from embodied_adhoc.learning.meliba import meliba_agent

            return meliba_agent(self.domain, None, self.rules.config, name=name)
        raise ConfigError(f"agent '{name}': the grid arenas offer {GridTrialDomain.agent_names}")

    def observation_index(self, observation) -> int:
        if isinstance(observation, dict):  # the pair variant: the pursuit POMDP's observation index
            return int(observation["observation_index"])
        return zlib.crc32(np.ascontiguousarray(observation).tobytes())


def library_folder(domain: str, folder) -> str:
    """``--library DIR`` checked (it holds a ``library.json``) and made absolute (trial options are stored)."""
    from pathlib import Path

    if not (Path(folder) / "library.json").is_file():
        raise ConfigError(
            f"--library {folder}: no library.json there; train one with `embodied-adhoc train atlpo "
            f"--domain {domain} --set task+team --out {folder}`"
        )
    return str(Path(folder).resolve())


def env_kwargs(options: dict) -> dict:
    kwargs = {
        "rows": options["rows"],
        "cols": options["cols"],
        "toroidal": options["toroidal"],
        "teams": options["teams"],
    }
    if options["domain"] == "pursuit" and options["pairs"]:
        kwargs["pairs"] = True
    else:
        kwargs["n_agents"] = options["agents"]
    return kwargs


class GridTrialDomain:
    backends = ("abstract", "mujoco")
    agent_names = ("original", "random", "atlpo-mf", *LEARNED_AGENTS)
    default_agents = ("original", "random")
    privileged_agents = ("original",)  # observes_state: marked in the tables

    def __init__(self, name: str, description: str, team_names: tuple[str, ...]) -> None:
        self.name, self.description, self.team_names = name, description, team_names

    def input_files(self, options: dict) -> dict:
        """The files a run reads, by flag (their content is part of its identity: experiments/identity.py)."""
        from embodied_adhoc.experiments.identity import plugin_source

        files = {f"--team {team}": plugin_source("teammate", team, "--team") for team in options["teams"]}
        if options.get("library"):
            files["--library"] = options["library"]
        return files

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        group = parser.add_argument_group(f"{self.name} options")
        group.add_argument(
            "--team",
            default=None,
            metavar="NAME[,NAME]",
            help=f"team type(s) drawn per episode, from {', '.join(self.team_names)} "
            "(default: tau0,tau1,tau2), or a user team MODULE:CALLABLE (docs/plugins.md)",
        )
        group.add_argument(
            "--task",
            type=int,
            default=None,
            metavar="K",
            help="fix the task to K in 1..4 (N/S/W/E assignment rotated K-1 times; default: uniform)",
        )
        group.add_argument("--rows", type=int, default=5, help="grid rows (default 5)")
        group.add_argument("--cols", type=int, default=5, help="grid columns (default 5)")
        group.add_argument(
            "--n-agents", type=int, default=4, help="robots incl. the ad hoc one, 2-4 (default 4)"
        )
        group.add_argument("--toroidal", action="store_true", help="wrap-around grid (abstract backend only)")
        group.add_argument(
            "--library",
            default=None,
            metavar="DIR",
            help="atlpo-mf: a library folder written by `embodied-adhoc train atlpo` (default: the "
            "pre-trained task+team library shipped with the package)",
        )
        if self.name == "pursuit":
            group.add_argument(
                "--pairs",
                action="store_true",
                help="Fig. 7.12 variant: 2 predators, capture pairs N+S, W+E, SW+NE, NW+SE, "
                "teams greedy/aware",
            )

    def options_from_args(self, args: argparse.Namespace) -> dict:
        pairs = bool(getattr(args, "pairs", False))
        default = ("greedy", "aware") if pairs else ("tau0", "tau1", "tau2")
        teams = tuple(args.team.split(",")) if args.team else default
        allowed = ("greedy", "aware") if pairs else ("tau0", "tau1", "tau2")
        from embodied_adhoc.plugins import names_plugin, resolve

        if any(t not in allowed and not names_plugin("teammate", t) for t in teams):
            raise ConfigError(
                f"--team {args.team}: choose from {', '.join(allowed)}, or MODULE:CALLABLE (a user "
                "team: embodied_adhoc.teammates.grid_plugins)"
            )
        for team in teams:  # a user team that cannot be imported stops here, before any work
            resolve("teammate", team, builtin=allowed, flag="--team")
        if args.task is not None and not 1 <= args.task <= 4:
            raise ConfigError(f"--task {args.task}: the task library is 1..4")
        library = getattr(args, "library", None)
        if library is not None:
            library = library_folder(self.name, library)
        options = {
            "domain": self.name,
            "teams": list(teams),
            "task": args.task,
            "rows": args.rows,
            "cols": args.cols,
            "agents": 2 if pairs else args.n_agents,
            "toroidal": bool(args.toroidal),
            "pairs": pairs,
        }
        if library is not None:  # only then: stored runs of the other agents keep their identity
            options["library"] = library
        return options

    def episode_spec(self, options: dict, rng: np.random.Generator) -> dict:
        from embodied_adhoc.domains.grid_rules import GridConfig, GridRules

        drawn_task = int(rng.integers(4))
        team = options["teams"][int(rng.integers(len(options["teams"])))]
        config = GridConfig(
            domain=options["domain"],
            rows=options["rows"],
            cols=options["cols"],
            n_agents=options["agents"],
            toroidal=options["toroidal"],
        )
        start = GridRules(config).sample_state(rng)
        task = drawn_task if options.get("task") is None else int(options["task"]) - 1
        return {"task": task, "team": team, "start": json.dumps(start.as_dict())}

    def open_session(self, backend: str, options: dict) -> GridTrialSession:
        if backend == "mujoco" and options["toroidal"]:
            raise ConfigError("--toroidal: a physical arena cannot wrap; use --backend abstract")
        return GridTrialSession(self.name, backend, options)


DOMAIN = GridTrialDomain(
    "foraging",
    "Level-based foraging: 4 foragers, N/S/W/E forage positions, teams tau0-2 (thesis ch. 6)",
    ("tau0", "tau1", "tau2"),
)
