"""``embodied-adhoc bench teammates --domain D`` (a population's members) and ``embodied-adhoc evaluate`` (agents on
a suite, scored between each member's bounds); see :mod:`embodied_adhoc.bench` and ``docs/benchmark.md``."""

from __future__ import annotations

import argparse
import json


def _split_list(text: str) -> tuple[str, ...]:
    return tuple(part.strip() for part in text.split(",") if part.strip())


def handle_teammates(args: argparse.Namespace) -> int:
    from embodied_adhoc.teammates.populations import SUITE_VERSION, population

    specs = population(args.domain)
    if args.json:
        print(json.dumps({"version": SUITE_VERSION, "members": [s.describe() for s in specs]}, indent=1))
        return 0
    print(f"{args.domain}: benchmark population v{SUITE_VERSION} ({len(specs)} members)")
    width = max(len(s.name) for s in specs)
    for spec in specs:
        params = ", ".join(f"{k}={v}" for k, v in spec.params.items())
        print(f"  {spec.split:<10}  {spec.name:<{width}}  {spec.type_label}: {params}")
    return 0


def format_summary(summary: dict) -> str:
    """Per scope, one line per agent: normalised IQM and mean with their intervals."""
    lines = [f"suite {summary['suite']} v{summary['version']}, {summary['episodes']} episodes per teammate"]
    scopes = {**summary["domains"], "overall": summary["overall"]}
    for name, scope in scopes.items():
        if not scope.get("aggregate"):
            continue
        lines.append(f"\n{name} ({scope['members']} teammates)")
        lines.append(f"  {'agent':<16} {'IQM':>7}  {'95% CI':<16} {'mean':>7}  95% CI")
        for agent, values in scope["aggregate"].items():
            iqm_ci = "[{:.3f}, {:.3f}]".format(*values["iqm_ci"]) if None not in values["iqm_ci"] else "-"
            mean_ci = "[{:.3f}, {:.3f}]".format(*values["mean_ci"]) if None not in values["mean_ci"] else "-"
            lines.append(f"  {agent:<16} {values['iqm']:7.3f}  {iqm_ci:<16} {values['mean']:7.3f}  {mean_ci}")
    return "\n".join(lines)


def handle_evaluate(args: argparse.Namespace) -> int:
    from embodied_adhoc.bench.evaluate import evaluate, resolve_suite
    from embodied_adhoc.errors import ConfigError

    domains = _split_list(args.domains) if args.domains else None
    suite = resolve_suite(args.suite, domains)
    agents = _split_list(args.agents)
    if not agents:
        raise ConfigError("--agents: give at least one agent, e.g. --agents hotspot,atpo,random")
    summary = evaluate(
        agents,
        suite,
        args.out,
        episodes=args.episodes,
        seed=args.seed,
        backend=args.backend,
        workers=args.workers,
        executor=args.executor,
        progress=not args.json,
        plots=not args.no_plots,
    )
    print(json.dumps(summary, indent=1) if args.json else format_summary(summary))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    from embodied_adhoc.checks import positive_int
    from embodied_adhoc.teammates.populations import BENCH_DOMAINS

    bench = subparsers.add_parser(
        "bench",
        help="the held-out benchmark's teammate populations",
        description="List a domain's benchmark teammates (train, validation, held-out) with their parameters.",
    )
    bench.set_defaults(_parser=bench)
    commands = bench.add_subparsers(dest="bench_command", metavar="SUBCOMMAND")
    teammates = commands.add_parser("teammates", help="list a domain's population")
    teammates.add_argument(
        "--domain",
        required=True,
        help="a domain with a population: " + ", ".join(BENCH_DOMAINS),
    )
    teammates.add_argument("--json", action="store_true", help="print the members as JSON")
    teammates.set_defaults(func=handle_teammates)

    evaluate = subparsers.add_parser(
        "evaluate",
        help="score agents on a benchmark suite (normalised between random and the best response)",
        description="Run every agent on every teammate of a suite (same episodes for all agents), normalise each "
        "return between the teammate's random-ego and exact best-response returns, and report per domain and "
        "overall the IQM and mean with stratified-bootstrap intervals, the probability of improvement of every "
        "pair and performance profiles. Resumable: rerun the same command to continue.",
    )
    evaluate.add_argument(
        "--agents",
        required=True,
        metavar="A,B,...",
        help="agents: built-in names, MODULE:CALLABLE or entry points",
    )
    evaluate.add_argument(
        "--suite", default="heldout", metavar="heldout|validation|train|FILE.json", help="default heldout"
    )
    evaluate.add_argument(
        "--domains", default=None, metavar="D,...", help="default: every domain of the suite"
    )
    evaluate.add_argument(
        "--episodes", type=positive_int, default=32, metavar="N", help="per teammate (default 32)"
    )
    evaluate.add_argument("--seed", type=int, default=0)
    evaluate.add_argument(
        "--backend",
        default="abstract",
        choices=("abstract", "mujoco"),
        help="abstract (default) or mujoco: the physics lab (toxic-waste only; MUJOCO_GL=egl), scored between the "
        "abstract lab's bounds",
    )
    evaluate.add_argument(
        "--workers", type=int, default=1, metavar="W", help="worker processes (0 = one per CPU)"
    )
    evaluate.add_argument(
        "--executor",
        default="local",
        choices=("local", "ray"),
        help="where trials run (default local; see docs/ray.md)",
    )
    evaluate.add_argument("--out", required=True, metavar="DIR", help="where runs, summary.json and plots go")
    evaluate.add_argument("--no-plots", action="store_true", help="write summary.json only")
    evaluate.add_argument("--json", action="store_true", help="print summary.json instead of the table")
    evaluate.set_defaults(func=handle_evaluate)
