"""``embodied-adhoc trials DOMAIN ...``: run agents over the same episodes, print statistics, write CSVs and plots.

Each registered trial domain (``embodied_adhoc.experiments.registry``) is a sub-command with the common flags
below plus its own (e.g. ``toxic-waste --human-epsilon``); see ``docs/trials.md``.
"""

from __future__ import annotations

import argparse
import json
import sys

from embodied_adhoc.commands.arguments import output_folder, seed
from embodied_adhoc.experiments.registry import get_trial_domain, trial_domain_names

EPILOG = """\
With --out DIR the run is stored and resumable: config.json, trials.csv (one row per finished trial, appended as
it finishes), steps.csv (per-step entropy and task posterior), summary.json, steps.png (Fig. 7.8 analogue) and
entropy.png (Fig. 7.9 analogue). Re-running the same command resumes (finished trials are skipped); more
--agents or --episodes extend the run; other options, changed input files (--map, --confusion, a plug-in's
source, ...) or another BLAS kernel in the same DIR are refused (--new-run writes a sibling folder instead), as is a
second process writing DIR at the same time. Damaged lines of the CSVs are moved to *.rejected on resume, with a
warning naming the line, and their trials run again (docs/trials.md).
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "trials",
        help="run agents over the same episodes of a domain: statistics, Welch tests, CSVs and plots",
        description="Run every agent on the same episodes (tasks and start states drawn once from --seed), "
        "print steps to finish (mean, 95 % percentile-bootstrap CI, IQM), success rate, steps to identify the "
        "task (thesis Metric 2), final task-belief entropy, and between agents Welch t-tests and the "
        "probability of improvement.",
    )
    domains = parser.add_subparsers(dest="domain", metavar="DOMAIN")
    for name in trial_domain_names():
        domain = get_trial_domain(name)
        sub = domains.add_parser(
            name,
            help=domain.description,
            description=domain.description,
            epilog=EPILOG,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        _add_common_arguments(sub, domain)
        domain.add_arguments(sub)
        sub.set_defaults(func=handle, _trial_domain=name)
    parser.set_defaults(_parser=parser)


def _add_common_arguments(parser: argparse.ArgumentParser, domain) -> None:
    from embodied_adhoc.experiments.executors import EXECUTORS

    parser.add_argument(
        "--backend",
        default=domain.backends[0],
        metavar="|".join(domain.backends),
        help=f"world that runs the episodes (default {domain.backends[0]}); several, comma-separated "
        f"(e.g. {','.join(domain.backends)}), run the same episodes on each and add Welch tests between them",
    )
    parser.add_argument(
        "--agents",
        default=",".join(domain.default_agents),
        metavar="A,B,...",
        help=f"comma-separated agents from {{{', '.join(domain.agent_names)}}} "
        f"(default {','.join(domain.default_agents)}), or plug-ins: MODULE:CALLABLE, path/to/file.py:CALLABLE or "
        "an installed entry point (docs/plugins.md)",
    )
    parser.add_argument("--episodes", type=int, default=32, help="episodes per agent (default 32)")
    parser.add_argument("--seed", type=seed, default=0, help="seed of the whole sweep, >= 0 (default 0)")
    parser.add_argument(
        "--max-steps",
        type=int,
        default=None,
        help="step cap per episode (default: the registered cap of the env that runs the episodes, the same "
        "TimeLimit gymnasium.make applies: 100 for toxic-waste, the thesis's cap for its simulations; 150 for "
        "pursuit --pairs, as Fig. 7.12; 200 for foraging and pursuit, whose cap the thesis does not state)",
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=1,
        help="parallel worker processes (default 1; 0 = one per CPU; capped at the CPUs available); results do "
        "not depend on it",
    )
    parser.add_argument(
        "--executor",
        choices=EXECUTORS,
        default="local",
        help="local process pool (default) or Ray (pip install 'embodied-adhoc[ray]')",
    )
    parser.add_argument(
        "--out",
        type=output_folder,
        default=None,
        metavar="DIR",
        help="store (and resume) the run in DIR, with plots",
    )
    parser.add_argument(
        "--new-run",
        action="store_true",
        help="where DIR holds a run with other options, input files or BLAS kernel, write this one to a fresh "
        "sibling DIR-2, DIR-3, ... (the first new one, or the one holding this run) instead of refusing",
    )
    parser.add_argument(
        "--record",
        type=output_folder,
        default=None,
        metavar="DIR",
        help="also record episode 0 of every agent on physics (--backend mujoco) as `run` records it: "
        "DIR/<agent>/episode.mp4, episode.rrd, metrics.json",
    )
    parser.add_argument("--json", action="store_true", help="print only the JSON summary on stdout")


def parse_agents(text: str) -> tuple[str, ...]:
    return tuple(name.strip() for name in text.split(",") if name.strip())


def handle(args: argparse.Namespace) -> int:
    from pathlib import Path

    from embodied_adhoc.errors import ConfigError
    from embodied_adhoc.experiments.executors import worker_note
    from embodied_adhoc.experiments.runner import SweepConfig

    domain = get_trial_domain(args._trial_domain)
    backends = parse_agents(args.backend)
    unknown = [b for b in backends if b not in domain.backends]
    if unknown or not backends or len(set(backends)) != len(backends):
        raise ConfigError(
            f"--backend {args.backend!r}: choose one or more (comma-separated, once each) of "
            f"{', '.join(domain.backends)}"
        )
    options = domain.options_from_args(args)
    if args.record is not None:
        from embodied_adhoc.experiments.recorded import check_recordable

        check_recordable(domain.name, backends, options, parse_agents(args.agents))
    note = worker_note(args.workers)
    if note:
        print(f"embodied-adhoc: note: {note}", file=sys.stderr)
    if "mujoco" in backends:
        from embodied_adhoc.gl import choose_gl_platform

        choose_gl_platform()  # before the MuJoCo backend imports mujoco (here or in forked workers)
    _note_single_task(domain.name, backends[0], options)
    results = {}
    for backend in backends:
        config = SweepConfig(
            domain.name,
            backend,
            options,
            parse_agents(args.agents),
            args.episodes,
            args.seed,
            _default_cap(domain.name, backend, options) if args.max_steps is None else args.max_steps,
        )
        out = None if args.out is None else Path(args.out) / (backend if len(backends) > 1 else "")
        results[backend] = _run_one(args, config, out)
    if len(backends) > 1:
        _compare_backends(args, results)
    if args.record is not None:
        _record(args, results["mujoco"].config)
    return 0


def _record(args: argparse.Namespace, config) -> None:
    """Episode 0 of every agent of the physics sweep, recorded into ``--record DIR/<agent>``."""
    import re
    from pathlib import Path

    from embodied_adhoc.experiments.recorded import record_trial_episode

    for agent in config.agents:
        folder = Path(args.record) / re.sub(r"[^A-Za-z0-9._-]+", "_", agent)
        outcome = record_trial_episode(
            config.domain, dict(config.options), agent, config.seed, config.max_steps, folder
        )
        line = f"recorded {agent} episode 0 ({outcome.metrics['outcome']}, {outcome.metrics['steps']} steps): {folder}"
        print(line, file=sys.stderr if args.json else sys.stdout)


def _note_single_task(domain_name: str, backend: str, options: dict) -> None:
    """One note when the task library holds a single task: there is nothing to identify, so the entropy plot is
    not drawn (and the identification columns are trivial)."""
    from embodied_adhoc.experiments.executors import open_session

    names = tuple(open_session(domain_name, backend, options).task_names)
    if len(names) == 1:
        hint = " (a map's tasks are the pairs of its 'G' cells: draw a third 'G' for three tasks)"
        maps = dict(options.get("library") or {}).get("map") or domain_name in (
            "ntu",
            "isr",
            "mit",
            "pentagon",
            "cit",
        )
        print(
            f"embodied-adhoc: note: {domain_name} has a single task ({names[0]}): nothing to identify, entropy.png "
            f"is not drawn{hint if maps else ''}",
            file=sys.stderr,
        )


def _privileged_agents(config) -> tuple[str, ...]:
    from embodied_adhoc.experiments import seeding
    from embodied_adhoc.experiments.executors import open_session
    from embodied_adhoc.experiments.registry import privileged_agents

    domain = get_trial_domain(config.domain)
    session = open_session(config.domain, config.backend, dict(config.options))
    spec = domain.episode_spec(dict(config.options), seeding.episode_rng(config.seed, 0))
    return privileged_agents(
        domain, session, config.agents, spec, seeding.agent_seed(config.seed, 0, "check")
    )


def _default_cap(domain_name: str, backend: str, options: dict) -> int:
    """The registered step cap (``envs/registry.py``, the one definition) of the env id the sweep runs; a plug-in
    domain whose session names no registered id (``session.env_id``) gets the runner's default."""
    from embodied_adhoc.envs.registry import ENV_SPECS
    from embodied_adhoc.experiments.executors import open_session
    from embodied_adhoc.experiments.runner import DEFAULT_MAX_STEPS

    env_id = getattr(open_session(domain_name, backend, options), "env_id", None)
    caps = {spec.id: spec.max_episode_steps for spec in ENV_SPECS}
    return caps.get(env_id) or DEFAULT_MAX_STEPS


def _run_one(args: argparse.Namespace, config, out):
    """Run (or resume) one sweep; print its tables (or its JSON when it is the only one); write files to out."""
    from embodied_adhoc.atomic import atomic_write_text
    from embodied_adhoc.experiments.executors import open_session
    from embodied_adhoc.experiments.runner import run_sweep
    from embodied_adhoc.experiments.summary import summary_json
    from embodied_adhoc.experiments.tables import comparison_table, summary_table

    result = run_sweep(
        config,
        out=out,
        workers=args.workers,
        executor=args.executor,
        progress=not args.json,
        new_run=args.new_run,
    )
    out = result.out  # the sibling that --new-run chose, if it chose one
    summary = result.summary()
    document = summary_json(summary, config.describe())
    timing = getattr(open_session(config.domain, config.backend, dict(config.options)), "timing", None)
    if timing:  # seconds building the models and solving (or loading) policies, where the domain keeps them
        document["timing"] = timing
    written = []
    if out is not None:
        from embodied_adhoc.experiments.plots import plot_entropy, plot_steps

        atomic_write_text(out / "summary.json", json.dumps(document, indent=2) + "\n")
        title = f"{config.domain} ({config.backend}), {config.episodes} episodes"
        written.append(plot_steps(summary, out / "steps.png", title=f"Steps to finish / identify: {title}"))
        curves = result.curves_by_agent()
        if curves and len(result.task_names) > 1:  # one task: no belief to plot (handle's note says so)
            written.append(plot_entropy(curves, out / "entropy.png", title=f"Task-belief entropy: {title}"))
    if args.json:
        if "," not in args.backend:
            print(json.dumps(document))
        return result
    resumed = len(result.records) - result.new_trials
    print(
        f"{config.domain} on {config.backend}: {len(config.agents)} agent(s) x {config.episodes} episode(s), "
        f"seed {config.seed}, cap {config.max_steps} steps; options {json.dumps(dict(config.options))}"
    )
    print(
        f"{result.new_trials} trial(s) run in {result.wall_time_s:.2f} s"
        + (f", {resumed} resumed" if resumed else "")
    )
    print()
    print(summary_table(summary))
    marked = _privileged_agents(config)
    if marked:  # the baselines defined by privileged access, apart from the ad hoc agents
        print(
            f"privileged (observe the true state, through the env's privileged_state()): {', '.join(marked)}"
        )
    from embodied_adhoc.experiments.summary import extras_table

    extras = extras_table(summary)
    if extras:  # e.g. the physics lab's fault events per episode
        print()
        print(extras)
    if timing:  # chapter-5 domains: Table 5.5's accumulated reward beside the steps, and where the time went
        from embodied_adhoc.experiments.domains.chapter5 import return_table, timing_line

        print()
        print(return_table(summary))
        print(timing_line(timing))
    print()
    print(comparison_table(summary))
    if out is not None:
        files = "config.json trials.csv steps.csv summary.json " + " ".join(p.name for p in written)
        print(f"\nwrote {out}/: {files}")
    print()
    sys.stdout.flush()
    return result


def _compare_backends(args: argparse.Namespace, results: dict) -> None:
    """Same agents, episodes and seeds on each backend: per-agent Welch tests and probabilities of improvement between
    backends (the thesis's
    simulation-vs-reality comparison, here abstract vs physics)."""
    from pathlib import Path

    from embodied_adhoc.atomic import atomic_write_text
    from embodied_adhoc.experiments.summary import (
        comparisons_between_runs,
        comparisons_json,
        statistics_json,
        summary_json,
    )
    from embodied_adhoc.experiments.tables import comparison_table

    first = next(iter(results.values()))
    tests = comparisons_between_runs({b: r.records for b, r in results.items()}, first.config.agents)
    document = {
        "backends": {b: summary_json(r.summary(), r.config.describe()) for b, r in results.items()},
        "backend_comparisons": comparisons_json(tests),
        "statistics": statistics_json(),
    }
    if args.out is not None:
        from embodied_adhoc.experiments.plots import plot_settings

        out = Path(args.out)
        atomic_write_text(out / "comparison.json", json.dumps(document, indent=2) + "\n")
        plot_settings(
            {b: r.summary() for b, r in results.items()},
            out / "backends.png",
            title=f"{first.config.domain}: steps to finish per backend",
        )
    if args.json:
        print(json.dumps(document))
        return
    print(comparison_table(tests))
    if args.out is not None:
        print(f"\nwrote {args.out}/: comparison.json backends.png (and one folder per backend)")
