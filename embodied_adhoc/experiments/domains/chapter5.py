"""Chapter-5 trial domains: ``embodied-adhoc trials DOMAIN`` for every library of
:mod:`embodied_adhoc.domains.chapter5`.

Episode spec (drawn once per episode, shared by every agent): ``task`` (the true model, uniform over the library,
or fixed by ``--task``) and ``start`` (a state drawn from that model's initial belief). The world is the true
model itself (:class:`~embodied_adhoc.envs.library_env.LibraryEnv`, a generative POMDP simulator with
Gymnasium's ``reset``/``step``); an episode ends in the absorbing state (after the +100) or at the cap, which
defaults to Table 5.2's horizon ``h``, so the trial's total reward is Table 5.5's accumulated reward. The world's
teammate (``--teammate``) comes from :mod:`embodied_adhoc.domains.chapter5.teammates`.

Agents (section 5.2.4):

* ``value-iteration``: sees the state and knows the model (greedy on ``Q*`` of the true model);
* ``perseus``: knows the model, not the state (the true model's Perseus policy on its belief);
* ``atpo``: ATPO over the library (:class:`~embodied_adhoc.decision.agents.atpo.AtpoAgent`);
* ``random-picker``: ATPO's policies with one model picked at random per episode (its belief still tracked);
* ``bopa``: BOPA (section 5.1), where the state is observable and shared (not the power plant);
* ``random``: uniform actions.

Perseus policies are solved once per model and settings and cached on disk
(:mod:`embodied_adhoc.experiments.policy_cache`; ``--no-cache`` bypasses it). A solve's budget is a number of
Perseus stages (``--solve-stages``, default :data:`SOLVE_STAGES` per domain), with Table 5.4's tolerance as the stop
rule before it: the policy is then a function of the model, the settings and the seed alone, the same on an idle
and on a loaded machine, so the tables do not depend on the load. ``--solve-seconds`` adds a wall-clock limit
(off by default; it makes the policy depend on the machine's speed and load). The session's ``timing`` (seconds
building the library and solving or loading its policies) goes into ``--json``. A solve that stopped at
``--solve-seconds`` before Perseus' first backup (the blind policy, ``policy_cache.is_blind``) is refused with the
models named, never used silently, and never cached.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from embodied_adhoc.decision.agents.baselines import RandomPickerAgent
from embodied_adhoc.domains.chapter5.teammates import (
    GENERIC_HELP,
    TEAMMATE_HELP,
    world_teammate_names,
    world_with_teammate,
)
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning import LEARNED_AGENTS, LEARNED_CHAPTER5_DOMAINS

__all__ = ["CHAPTER5_AGENTS", "Chapter5Domain", "return_table", "timing_line"]

CHAPTER5_AGENTS = ("value-iteration", "perseus", "atpo", "random-picker", "bopa", "random")
TABLE_5_2_HORIZON = {
    "gridworld": 50, "pursuit-task": 75, "pursuit-teammate": 85, "pursuit-both": 85, "power-plant": 50,
    "ntu": 75, "isr": 75, "mit": 75, "pentagon": 75, "cit": 85, "overcooked": 50, "map": 75,
    "panic-buttons": 2000,
}  # fmt: skip
SOLVER_TOLERANCE = 0.01  # Table 5.4
SOLVE_STAGES = {
    "gridworld": 14, "pursuit-task": 45, "pursuit-teammate": 45, "pursuit-both": 45, "power-plant": 40,
    "ntu": 12, "isr": 30, "mit": 30, "pentagon": 16, "cit": 30, "overcooked": 40, "map": 30,
    "panic-buttons": 40,
}  # fmt: skip
"""Perseus stages per model by default (``--solve-stages``): a deterministic budget, where the original ran to
convergence (hours to days per model, Table 5.3). Perseus stops earlier where Table 5.4's tolerance is met on the
belief set. The numbers are where the lower bound at b0 of the domain's first model stops moving much, measured
in CPU seconds per stage (docs/atpo.md, "The solve budget"). isr's budget lets its first model converge on the
belief set (stage 29): with fewer stages the value has not reached the beliefs of a start on the top row, far from
the goal, where every vector then ties at the blind value -1 / (1 - gamma) and the first one, "up" for ever, wins;
against the wall that move changes nothing, so Perseus and ATPO repeat it until the horizon."""


class Chapter5Session:
    """One library built and its policies solved (lazily, cached) per process; envs and agents made from it."""

    blas_threads = (
        1  # trials (and the lazy solves inside them) run with one BLAS thread (executors.execute_job):
    )
    # their products are small, and OpenBLAS's default pool spins on the cores the worker processes need

    def __init__(self, domain: str, options: dict) -> None:
        from embodied_adhoc.domains.chapter5 import build_library

        start = time.perf_counter()
        self.library = build_library(domain, **options["library"])
        self.timing = {
            "build_seconds": time.perf_counter() - start,
            "solve_seconds": 0.0,
            "policies_from_cache": 0,
        }
        self.options = options
        self.task_names = self.library.task_names
        self._policies = None
        self._kernels = None
        self._q = None

    def make_env(self, max_steps: int):
        from embodied_adhoc.envs.library_env import LibraryEnv

        world = None
        if self.options.get("teammate"):
            world = world_with_teammate(self.library, self.options["teammate"])
        return LibraryEnv(self.library, world)

    def reset_options(self, spec: dict) -> dict:
        return {"task": int(spec["task"]), "start": int(spec["start"])}

    def observation_index(self, observation) -> int:
        return int(observation)

    def policies(self) -> tuple:
        if self._policies is None:
            from embodied_adhoc.experiments.policy_cache import is_blind, solve_cached

            settings = solver_settings(self.library, self.options)
            start = time.perf_counter()
            solved = [solve_cached(p, settings, self.options["cache"]) for p in self.library.pomdps]
            self.timing["solve_seconds"] += time.perf_counter() - start
            self.timing["policies_from_cache"] = sum(hit for _, hit in solved)
            self.timing["solver_settings"] = settings
            blind = [
                name for name, (policy, _) in zip(self.task_names, solved, strict=True) if is_blind(policy)
            ]
            if blind:
                raise ConfigError(
                    f"{self.library.domain}: Perseus stopped at --solve-seconds {settings['time_limit']:g} before "
                    f"its first backup for model(s) {', '.join(blind)}: that policy is the blind one (one action "
                    "for ever), so perseus, atpo and random-picker would be measured on no solution; raise "
                    "--solve-seconds or drop it (--solve-stages alone is a budget that no load can cut short)"
                )
            self._policies = tuple(policy for policy, _ in solved)
        return self._policies

    def kernels(self):
        if self._kernels is None:
            from embodied_adhoc.decision.agents.task_beliefs import LibraryKernels

            self._kernels = LibraryKernels.build(self.library.pomdps)
        return self._kernels

    def q_values(self) -> np.ndarray:
        if self._q is None:
            from embodied_adhoc.decision.value_iteration import value_iteration

            start = time.perf_counter()
            self._q = np.stack(
                [value_iteration(p.as_mdp(), tolerance=1e-8).q_values for p in self.library.pomdps]
            )
            self.timing["value_iteration_seconds"] = time.perf_counter() - start
        return self._q

    def make_agent(self, name: str, spec: dict, seed: int):
        from embodied_adhoc.decision.agents.atpo import AtpoAgent
        from embodied_adhoc.decision.agents.baselines import OracleAgent, RandomAgent
        from embodied_adhoc.decision.agents.bopa import BopaAgent

        task = int(spec["task"])
        if name == "value-iteration":
            agent = OracleAgent(self.q_values()[task], name=name)
        elif name == "perseus":
            prior = np.eye(self.library.n_models)[task]
            agent = AtpoAgent(self.kernels(), self.policies(), prior=prior, name=name)
        elif name == "atpo":
            agent = AtpoAgent(self.kernels(), self.policies(), name=name)
        elif name == "random-picker":
            agent = RandomPickerAgent(self.kernels(), self.policies(), name=name)
        elif name == "bopa":
            if not self.library.shares_states:
                raise ConfigError(
                    f"bopa needs one state space shared by the models; {self.library.domain} has not"
                )
            agent = BopaAgent(self.library.mdps, self.q_values(), name=name)
        elif name == "random":
            agent = RandomAgent(self.library.n_actions, name=name)
        elif name in LEARNED_AGENTS and self.library.domain in LEARNED_CHAPTER5_DOMAINS:
            from embodied_adhoc.learning.index_domains import index_agent

            return index_agent(self.library, name, name=name)
        else:
            raise ConfigError(f"unknown agent '{name}'; choose from {', '.join(CHAPTER5_AGENTS)}")
        agent.rng = np.random.default_rng(seed)
        return agent


_SESSION_CACHE: dict[str, Chapter5Session] = {}


class Chapter5Domain:
    """The trial plug-in of one chapter-5 domain (see :mod:`embodied_adhoc.experiments.registry`)."""

    backends = ("abstract",)
    blas_dependent = True  # Perseus' policies and the agents' belief products come from BLAS sums
    privileged_agents = ("value-iteration", "bopa")  # observes_state: marked in the tables

    def __init__(self, name: str, description: str) -> None:
        self.name, self.description = name, description
        self.agent_names = (
            CHAPTER5_AGENTS if name != "power-plant" else tuple(a for a in CHAPTER5_AGENTS if a != "bopa")
        )
        if name == "panic-buttons":
            self.default_agents = ("value-iteration", "bopa", "random")
        else:
            self.default_agents = self.agent_names
        # where the library-free agents' weights ship; not among the defaults
        if name in LEARNED_CHAPTER5_DOMAINS:
            self.agent_names = (*self.agent_names, *LEARNED_AGENTS)

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        from embodied_adhoc.checks import bounded, positive_int
        from embodied_adhoc.experiments.domains.chapter5_options import add_library_arguments
        from embodied_adhoc.experiments.policy_cache import cache_dir

        add_library_arguments(parser, self.name)
        group = parser.add_argument_group(f"{self.name} solver and episodes")
        group.add_argument(
            "--task", type=int, default=None, metavar="K", help="fix the true model to K (default: uniform)"
        )
        if self.name != "panic-buttons":  # panic buttons: --teammate picks the library's
            group.add_argument(
                "--teammate",
                default=None,
                metavar="NAME|MODULE:CALLABLE",
                help="the world's teammate instead of the library's (the agents keep their library: a "
                f"model-mismatch test): {', '.join(world_teammate_names(self.name))} "
                f"({TEAMMATE_HELP.get(self.name, GENERIC_HELP)}), or MODULE:CALLABLE, CALLABLE(library, model) "
                "returning its policy, an (S x B) array over its B actions",
            )
        group.add_argument(
            "--beliefs", type=int, default=None, help="Perseus belief-set size (default: Table 5.2's)"
        )
        group.add_argument(
            "--solve-stages",
            type=positive_int,
            default=None,
            metavar="N",
            help=f"Perseus stages per model at most (default {SOLVE_STAGES[self.name]} here; it stops earlier at "
            f"tolerance {SOLVER_TOLERANCE}): the same policy on any load",
        )
        group.add_argument(
            "--solve-seconds",
            type=bounded(float, math.ulp(0.0), "a finite number of seconds > 0"),
            default=None,
            metavar="S",
            help="also stop each solve after S wall-clock seconds (default: no time limit; with one, the policy "
            "depends on the machine's speed and load)",
        )
        group.add_argument(
            "--no-cache",
            action="store_true",
            help=f"solve again; do not read or write the policy cache ({cache_dir()})",
        )
        parser.set_defaults(max_steps=TABLE_5_2_HORIZON[self.name])

    def options_from_args(self, args: argparse.Namespace) -> dict:
        from embodied_adhoc.experiments.domains.chapter5_options import library_options

        if args.beliefs is not None and args.beliefs < 1:
            raise ConfigError(f"--beliefs must be >= 1, got {args.beliefs}")
        options = {
            "library": library_options(self.name, args, ignore=("teammate",)),
            "task": args.task,
            "beliefs": args.beliefs,
            "solve_stages": args.solve_stages or SOLVE_STAGES[self.name],
            "solve_seconds": args.solve_seconds,
            "cache": not args.no_cache,
        }
        if self.name != "panic-buttons":
            options["teammate"] = args.teammate
        session = self._session(options)
        n_models = session.library.n_models
        if options.get("teammate"):
            world_with_teammate(
                session.library, options["teammate"]
            )  # refuse a bad teammate before any trial
        if args.task is not None and not 0 <= args.task < n_models:
            raise ConfigError(f"--task {args.task} is outside the library's models 0..{n_models - 1}")
        return options

    def _session(self, options: dict) -> Chapter5Session:
        import json

        key = json.dumps([self.name, options["library"]], sort_keys=True)
        if key not in _SESSION_CACHE:
            _SESSION_CACHE[key] = Chapter5Session(self.name, options)
        return _SESSION_CACHE[key]

    def input_files(self, options: dict) -> dict:
        """The files a run reads, by flag (their content is part of its identity: experiments/identity.py)."""
        from embodied_adhoc.domains.chapter5.grid_maps import BUILTIN_MAPS
        from embodied_adhoc.experiments.identity import plugin_source
        from embodied_adhoc.paths import asset

        files = {}
        name = options["library"].get("map")
        if name is not None:
            files["--map"] = asset(f"maps/{name}.txt") if name in BUILTIN_MAPS else name
        files["--teammate"] = plugin_source("teammate", options.get("teammate"), "--teammate")
        return files

    def episode_spec(self, options: dict, rng: np.random.Generator) -> dict:
        library = self._session(options).library
        drawn = int(rng.integers(library.n_models))
        task = drawn if options.get("task") is None else int(options["task"])
        start = library.pomdps[task].sample_initial_state(rng)
        return {"task": task, "start": int(start)}

    def open_session(self, backend: str, options: dict) -> Chapter5Session:
        session = self._session(options)
        if session.options != options:  # same library, other solver settings
            session = Chapter5Session(self.name, options)
        return session


_DESCRIPTIONS = {
    "panic-buttons": "Panic Buttons (Table 5.1): 2 agents press 2 buttons; BOPA vs greedy and random",
    "gridworld": "gridworld 5x5 (Table 5.5): 2 agents, 2 goal cells, four noisy sensors",
    "pursuit-task": "pursuit, 4 capture configurations, greedy teammate (Table 5.5)",
    "pursuit-teammate": "pursuit, greedy or teammate-aware teammate (Table 5.5)",
    "pursuit-both": "pursuit, 4 configurations x 2 teammates (Table 5.5)",
    "power-plant": "abandoned power plant: explore or clean (Table 5.5)",
    "ntu": "ntu map navigation (Table 5.5)",
    "isr": "isr map navigation (Table 5.5)",
    "mit": "mit map navigation (Table 5.5)",
    "pentagon": "pentagon map navigation (Table 5.5)",
    "cit": "cit map navigation (Table 5.5)",
    "overcooked": "overcooked: helper and cook, 4 cooks (Table 5.5)",
    "map": "navigation on any map file (--map PATH)",
}


def domain(name: str) -> Chapter5Domain:
    return Chapter5Domain(name, _DESCRIPTIONS[name])


def __getattr__(attribute: str):
    """``embodied_adhoc.experiments.domains.chapter5:DOMAIN_<name>`` import strings for the registry."""
    if attribute.startswith("DOMAIN_"):
        name = attribute[len("DOMAIN_") :].replace("_", "-")
        if name in _DESCRIPTIONS:
            return domain(name)
    raise AttributeError(attribute)


def return_table(summary, markdown: bool = False) -> str:
    """Per agent: the accumulated reward (Table 5.5's measure): mean ± sd, its 95 % percentile-bootstrap interval
    (:mod:`embodied_adhoc.experiments.stats`) and IQM, beside the success rate."""
    from embodied_adhoc.experiments.tables import CI_HEADER, fmt, format_table, interval, mean_sd

    rows = [
        [
            s.agent,
            str(s.trials),
            mean_sd(s.total_reward),
            interval(s.total_reward),
            fmt(s.total_reward.iqm),
            fmt(s.success_rate),
        ]  # fmt: skip
        for s in summary.agents.values()
    ]
    headers = ("agent", "trials", "return mean ± sd", f"return {CI_HEADER}", "return IQM", "success")
    return format_table(headers, rows, markdown)


def timing_line(timing: dict) -> str:
    """One line: seconds building the library, solving (or loading) its policies, value iteration."""
    parts = [f"library built in {timing['build_seconds']:.2f} s"]
    if "solver_settings" in timing:
        parts.append(
            f"policies solved or loaded in {timing['solve_seconds']:.2f} s ({timing['policies_from_cache']} from "
            "the cache)"
        )
    if "value_iteration_seconds" in timing:
        parts.append(f"value iteration {timing['value_iteration_seconds']:.2f} s")
    return "; ".join(parts)


TABLE_5_5_DOMAINS = ("gridworld", "pursuit-both", "pursuit-task", "pursuit-teammate", "power-plant", "ntu",
                     "overcooked", "isr", "mit", "pentagon", "cit")  # fmt: skip
"""Table 5.5's domains, in its order."""


def table_agents(domain_name: str) -> tuple[str, ...]:
    """The agents of a Table 5.5 row (no BOPA on the power plant, whose tasks have their own state spaces)."""
    return domain(domain_name).agent_names


def sweep_config(
    domain_name: str,
    library: dict | None = None,
    agents: tuple[str, ...] | None = None,
    episodes: int = 32,
    seed: int = 0,
    solve_stages: int | None = None,
    beliefs: int | None = None,
    solve_seconds: float | None = None,
):
    """The :class:`~embodied_adhoc.experiments.runner.SweepConfig` of one Table 5.5 cell row (the options
    ``trials DOMAIN`` would pass; Table 5.2's horizon as the cap; ``solve_stages`` None: :data:`SOLVE_STAGES`),
    shared by the reproduction and benchmark scripts so that their policies share the cache."""
    from embodied_adhoc.experiments.runner import SweepConfig

    options = {
        "library": dict(library or {}),
        "task": None,
        "beliefs": beliefs,
        "solve_stages": solve_stages or SOLVE_STAGES[domain_name],
        "solve_seconds": solve_seconds,
        "cache": True,
    }
    if domain_name != "panic-buttons":
        options["teammate"] = None
    agents = table_agents(domain_name) if agents is None else tuple(agents)
    return SweepConfig(
        domain_name, "abstract", options, agents, episodes, seed, TABLE_5_2_HORIZON[domain_name]
    )


def solver_settings(library, options: dict) -> dict:
    """The Perseus settings (``PerseusConfig`` fields, part of the policy-cache key) of a session's ``options``:
    Table 5.2's belief-set size unless ``beliefs``, Table 5.4's tolerance, at most ``solve_stages`` stages (default
    :data:`SOLVE_STAGES`), ``solve_seconds`` of wall-clock time if given (else none), seed 0, classic Perseus stages
    (``update="perseus"``)."""
    stages = options.get("solve_stages") or SOLVE_STAGES.get(library.domain, SOLVE_STAGES["map"])
    return {
        "n_beliefs": int(options.get("beliefs") or library.n_beliefs),
        "tolerance": SOLVER_TOLERANCE,
        "max_iterations": int(stages),
        "time_limit": options.get("solve_seconds"),
        "seed": 0,
        "update": "perseus",  # the thesis's solver (Perseus' own stages): the tables keep their policies
    }


def forget_sessions() -> None:
    """Drop every library and policy this process holds (a benchmark's next run builds and loads them again)."""
    from embodied_adhoc.experiments.executors import close_sessions

    _SESSION_CACHE.clear()
    close_sessions()
