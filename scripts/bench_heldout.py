"""The held-out benchmark for the shipped agents: ``embodied-adhoc evaluate`` on each domain's held-out suite (and its
validation suite beside it), written to ``results/benchmark-heldout.json`` with its provenance, and the table
between the ``<!-- bench:heldout start/end -->`` markers of ``docs/benchmark.md`` rendered from that file.

    .venv/bin/python scripts/bench_heldout.py                 # run (resumable under runs/bench/) and render
    .venv/bin/python scripts/bench_heldout.py --domains ntu,cit   # these domains only, merged into the file
    .venv/bin/python scripts/bench_heldout.py --physics       # the lab's physics subset beside its abstract runs
    .venv/bin/python scripts/bench_heldout.py --render-only   # render the page from the result file
    OPENBLAS_CORETYPE=Sandybridge .venv/bin/python scripts/bench_heldout.py --check toxic-waste,power-plant

``--check D,...`` runs those domains' held-out suite again (under another BLAS kernel: ``OPENBLAS_CORETYPE``, with
a policy cache of that kernel's own: ``XDG_CACHE_HOME``) and keeps it in the file's ``kernel_checks``, beside the
published entries it does not replace, with the comparison: every agent's mean and IQM inside the published 95 %
interval.

Every agent of a domain runs on every member for the same episodes on the abstract backends. A run replaces the
entries of the suites and domains it ran in the result file and keeps the others, each entry with the commit,
BLAS kernel and wall seconds of its own run. ``--physics`` runs :data:`PHYSICS_AGENTS` on
:data:`PHYSICS_MEMBERS` of the lab's held-out split on the MuJoCo backend and on the abstract one for the same
episodes, and compares the two per agent with Welch's test (``experiments.stats.welch_test``).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import platform
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from embodied_adhoc.teammates.populations import CHAPTER5, GRID

ROOT = Path(__file__).resolve().parent.parent
RESULT = ROOT / "results" / "benchmark-heldout.json"
CHAPTER5_AGENTS = ("atpo", "bopa", "perseus", "value-iteration", "random-picker", "random")
GRID_AGENTS = ("atlpo-mf", "ppo-generalist", "liam", "meliba", "random")
"""The agents that run on the grid arenas (the upper bound is the better of ``original``, the member's own policy, and
the member's trained best response: ``bench.bounds``)."""
AGENTS = {
    "toxic-waste": ("hotspot", "atpo", "bopa", "known-task", "oracle", "random"),
    **dict.fromkeys(CHAPTER5, CHAPTER5_AGENTS),
    "power-plant": tuple(a for a in CHAPTER5_AGENTS if a != "bopa"),  # its tasks share no state space
    **dict.fromkeys(GRID, GRID_AGENTS),
}
PRIVILEGED = ("oracle", "bopa", "value-iteration")
DROPPED = ("profiles",)
ROW_DROPPED = ("domain", "split", "version")
"""Summary fields the result file leaves out (each run's ``summary.json`` under ``--out`` keeps them, with its plots):
the performance profiles (no table reads them), each teammate row's domain, split and version (its entry's), and of
the probabilities of improvement the pairs ``b > a`` with ``b`` after ``a`` in the agent order (``P(b > a) = 1 -
P(a > b)``, ties counting one half)."""


def _slim(scope: dict) -> dict:
    """A domain's summary as the result file keeps it (see :data:`DROPPED`)."""
    agents = list(scope.get("aggregate", {}))
    kept = {k: v for k, v in scope.items() if k not in DROPPED}
    kept["teammates"] = [{k: v for k, v in row.items() if k not in ROW_DROPPED} for row in scope["teammates"]]
    kept["probability_of_improvement"] = {
        pair: value
        for pair, value in scope.get("probability_of_improvement", {}).items()
        if agents.index(pair.split(" > ")[0]) < agents.index(pair.split(" > ")[1])
    }
    return kept


PHYSICS_MEMBERS = ("order-210", "wander-p40", "quiet-p100", "mislead-p50")
"""The lab's held-out humans run on physics: those whose behaviour the physics lab acts out (its walker does not
let a ball fall, so ``drop-p30`` is not among them)."""
PHYSICS_AGENTS = ("hotspot", "known-task")


@dataclass
class Args:
    episodes: int = 32  # per member and agent
    seed: int = 0
    suites: tuple[str, ...] = ("heldout", "validation")
    domains: tuple[str, ...] = tuple(AGENTS)
    out: str = "runs/bench"  # one folder per suite and domain below it
    physics: bool = False
    physics_episodes: int = 8  # per member and agent on each backend
    render_only: bool = False
    no_render: bool = False  # write the result file only (the pages are rendered later by render_results)
    check: tuple[str, ...] = ()  # domains whose held-out suite runs as a second kernel's check
    agents: tuple[str, ...] = ()  # a subset of each domain's AGENTS (none: all of them)


SUITE_COMMAND = ".venv/bin/python scripts/bench_heldout.py"
"""The file's ``command``: the whole suite (every domain, both suites), which reproduces every part; each part keeps
the command of its own run."""


def parse() -> Args:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=Args.episodes)
    parser.add_argument("--seed", type=int, default=Args.seed)
    parser.add_argument("--suites", default=",".join(Args.suites))
    parser.add_argument("--domains", default=",".join(Args.domains), help="default: every domain")
    parser.add_argument("--out", default=Args.out)
    parser.add_argument(
        "--physics", action="store_true", help="run the lab's physics subset only (MUJOCO_GL=egl)"
    )
    parser.add_argument("--physics-episodes", type=int, default=Args.physics_episodes)
    parser.add_argument("--render-only", action="store_true")
    parser.add_argument(
        "--no-render",
        action="store_true",
        help="write the result file only; render the pages later with scripts/render_results.py render",
    )
    parser.add_argument(
        "--check",
        default="",
        help="domains whose held-out suite to run as a second kernel's check (kernel_checks)",
    )
    parser.add_argument(
        "--agents",
        default="",
        help="run only these of each domain's agents (a later run with more resumes the stored trials)",
    )
    ns = parser.parse_args()
    domains = tuple(d for d in ns.domains.split(",") if d)
    check = tuple(d for d in ns.check.split(",") if d)
    for flag, names in (("--domains", domains), ("--check", check)):
        unknown = [d for d in names if d not in AGENTS]
        if unknown:
            parser.error(f"{flag} {','.join(unknown)}: choose from {', '.join(AGENTS)}")
    unknown = [a for a in ns.agents.split(",") if a and not any(a in names for names in AGENTS.values())]
    if unknown:
        parser.error(f"--agents {','.join(unknown)}: no domain runs it (see AGENTS)")
    if ns.episodes < 2 or ns.physics_episodes < 2:
        parser.error("--episodes and --physics-episodes: at least 2 (the intervals resample episodes)")
    return Args(
        ns.episodes,
        ns.seed,
        tuple(ns.suites.split(",")),
        domains,
        ns.out,
        ns.physics,
        ns.physics_episodes,
        ns.render_only,
        ns.no_render,
        check,
        tuple(a for a in ns.agents.split(",") if a),
    )


def _provenance() -> dict:
    from embodied_adhoc.experiments.identity import blas_kernel

    commit = subprocess.run(
        ["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True
    ).stdout.strip()
    return {
        "command": " ".join([".venv/bin/python", "scripts/bench_heldout.py", *sys.argv[1:]]),
        "commit": commit,
        "kernel": blas_kernel(),
        "python": platform.python_version(),
    }


def run(args: Args) -> dict:
    """The suites and domains of ``args`` run (or resumed): the result file's fields for them."""
    from embodied_adhoc.bench.evaluate import evaluate, resolve_suite

    started = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    provenance = _provenance()
    results: dict = {}
    for suite_name in args.suites:
        for domain in args.domains:
            suite = resolve_suite(suite_name, (domain,))
            out = Path(args.out) / f"{suite_name}-{domain}"
            clock = time.perf_counter()
            agents = tuple(a for a in AGENTS[domain] if not args.agents or a in args.agents)
            summary = evaluate(agents, suite, out, episodes=args.episodes, seed=args.seed, progress=True)
            results.setdefault(suite_name, {})[domain] = summary["domains"][domain] | {
                "version": summary["version"],
                "episodes": summary["episodes"],
                "seed": summary["seed"],
                "bootstrap": summary["bootstrap"],
                # this entry's own run: what it ran at, and its wall time (cold or warm caches: see the docs)
                "commit": provenance["commit"],
                "kernel": provenance["kernel"],
                "command": provenance["command"],
                "wall_s": round(time.perf_counter() - clock, 1),
            }
    return {
        "figure": "benchmark-heldout",
        **provenance,
        "command": SUITE_COMMAND,
        "started": started,
        "finished": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "suites": results,
    }


def merge(previous: dict, fresh: dict) -> dict:
    """The result file's data with ``fresh``'s suites and domains (or physics part) replacing their old entries,
    the others kept, and the best-response check over all of them."""
    made = {
        k: previous[k] for k in ("commit", "kernel") if k in previous
    }  # entries from before per-entry fields
    suites = {
        suite: {
            domain: made | _own_command(previous, suite, domain) | _slim(scope)
            for domain, scope in domains.items()
        }
        for suite, domains in previous.get("suites", {}).items()
    }
    for suite, domains in fresh.get("suites", {}).items():
        suites.setdefault(suite, {}).update({domain: _slim(scope) for domain, scope in domains.items()})
    kernel_checks = previous.get("kernel_checks", {}) | fresh.get("kernel_checks", {})
    merged = previous | fresh | {"suites": suites, "command": SUITE_COMMAND}
    if kernel_checks:
        merged["kernel_checks"] = {
            domain: entry | {"comparison": compare_check(entry, suites["heldout"][domain])}
            for domain, entry in kernel_checks.items()
        }
    checks = best_response_check(suites)
    print(
        f"best-response check: {checks['checked']} (teammate, agent) cells, {len(checks['above'])} above",
        file=sys.stderr,
    )
    return merged | {"best_response_check": checks}


def _own_command(previous: dict, suite: str, domain: str) -> dict:
    """An entry's own command where the file's top-level one is a partial run's that names its suite and domain
    (files from before per-entry commands); otherwise none is known."""
    command = previous.get("command", "")
    words = command.split()
    named = {
        flag: words[words.index(flag) + 1].split(",")
        for flag in ("--domains", "--suites")
        if flag in words[:-1]
    }
    if command == SUITE_COMMAND or "--domains" not in named:
        return {}
    return (
        {"command": command}
        if domain in named["--domains"] and suite in named.get("--suites", Args.suites)
        else {}
    )


def run_check(args: Args) -> dict:
    """The held-out suite of ``args.check``'s domains run again (resumable under ``--out``/check-<kernel>): the
    file's ``kernel_checks`` fields for them."""
    from embodied_adhoc.experiments.identity import blas_kernel

    kernel = blas_kernel().split(":")[-1]
    clock = time.process_time()
    fresh = run(Args(args.episodes, args.seed, ("heldout",), args.check, f"{args.out}/check-{kernel}"))
    cpu = round(time.process_time() - clock, 1)
    return {
        "kernel_checks": {
            domain: {
                "kernel": entry["kernel"],
                "commit": entry["commit"],
                "command": " ".join([f"OPENBLAS_CORETYPE={kernel}", SUITE_COMMAND, *sys.argv[1:]]),
                "wall_s": entry["wall_s"],
                "cpu_s_all_checked_domains": cpu,
                "episodes": entry["episodes"],
                "seed": entry["seed"],
                "version": entry["version"],
                "members": [[row["name"], row["params"]] for row in entry["teammates"]],
                "aggregate": {
                    agent: {key: values[key] for key in ("iqm", "mean")}
                    for agent, values in entry["aggregate"].items()
                },
            }
            for domain, entry in fresh["suites"]["heldout"].items()
        }
    }


def compare_check(check: dict, published: dict) -> dict:
    """A second kernel's run against the published entry: each agent's IQM and mean inside the published 95 %
    interval (same episodes, seed and members, by name and parameters, asked for; a difference in any is reported,
    not compared)."""
    same = {k: (check[k], published.get(k)) for k in ("episodes", "seed") if check[k] != published.get(k)}
    members = [[row["name"], row.get("params")] for row in published.get("teammates", [])]
    # another suite version may keep a domain's members as they were: members are compared, not version labels
    if check.get("members", members) != members:
        same["members"] = (check["members"], members)
    outside = [
        f"{agent} {key} {values[key]:.4g} not in {published['aggregate'][agent][f'{key}_ci']}"
        for agent, values in check["aggregate"].items()
        for key in ("iqm", "mean")
        if not published["aggregate"][agent][f"{key}_ci"][0]
        <= values[key]
        <= published["aggregate"][agent][f"{key}_ci"][1]
    ]
    identical = all(
        float(f"{values[key]:.6g}") == float(f"{published['aggregate'][agent][key]:.6g}")
        for agent, values in check["aggregate"].items()
        for key in ("iqm", "mean")
    )
    return {
        "published_kernel": published.get("kernel"),
        "second_kernel": check["kernel"] != published.get("kernel"),
        "versions": [check["version"], published.get("version")],
        "settings_differ": {k: list(v) for k, v in same.items()},
        "outside": outside,
        "identical_to_6_digits": identical,
        "inside": not outside and not same,
        "rule": "every agent's IQM and mean inside the published 95 % stratified-bootstrap interval",
    }


def run_physics(args: Args) -> dict:
    """:data:`PHYSICS_AGENTS` on :data:`PHYSICS_MEMBERS` on both lab backends (same episodes), compared per agent."""
    from embodied_adhoc.bench.evaluate import Suite, backend_difference, evaluate
    from embodied_adhoc.teammates.populations import LAB, find_member

    specs = tuple(find_member(LAB, name) for name in PHYSICS_MEMBERS)
    suite = Suite("heldout", specs[0].version, {LAB: specs})
    scores, summaries, wall = {}, {}, {}
    for backend in ("abstract", "mujoco"):
        clock = time.perf_counter()
        out = Path(args.out) / f"physics-{backend}"
        found: dict = {}
        summary = evaluate(
            PHYSICS_AGENTS,
            suite,
            out,
            episodes=args.physics_episodes,
            seed=args.seed,
            backend=backend,
            progress=True,
            scores=found,
        )
        wall[backend] = round(time.perf_counter() - clock, 1)
        scores[backend], summaries[backend] = found[LAB], summary["domains"][LAB]
    physics = {
        **_provenance(),
        "members": list(PHYSICS_MEMBERS),
        "agents": list(PHYSICS_AGENTS),
        "episodes": args.physics_episodes,
        "seed": args.seed,
        "wall_s": wall,
        "bounds": "each member's exact bounds of the abstract lab (the physics lab has no tabular model)",
        **{
            backend: {
                "aggregate": summaries[backend]["aggregate"],
                "teammates": [
                    {"name": row["name"], "agents": row["agents"]} for row in summaries[backend]["teammates"]
                ],
            }
            for backend in ("abstract", "mujoco")
        },
        "difference": backend_difference(scores["abstract"], scores["mujoco"], list(PHYSICS_MEMBERS)),
    }
    return {"physics": physics}


def best_response_check(results: dict) -> dict:
    """Every (teammate, agent) cell whose normalised mean exceeds the best response's expected score from the same
    starts by more than a one-sided 99 % t bound (none is expected: the best response is exact)."""
    from scipy import stats

    above, checked = [], 0
    for suite_name, domains in results.items():
        for domain, scope in domains.items():
            n = scope["episodes"]
            for row in (r for r in scope["teammates"] if r.get("best_on_episodes") is not None):
                for agent, values in row["agents"].items():  # simulated bounds (the grids) have no exact best
                    checked += 1
                    margin = stats.t.ppf(0.99, n - 1) * (values["normalised_sd"] or 0.0) / n**0.5
                    if values["normalised_mean"] - margin > row["best_on_episodes"]:
                        above.append(f"{suite_name}/{domain}/{row['name']}/{agent}")
    return {
        "checked": checked,
        "above": above,
        "rule": "mean - t(0.99, n-1) sd / sqrt(n) <= best on the same starts",
    }


def _cell(values: dict, key: str) -> str:
    low, high = values[f"{key}_ci"]
    interval = f" [{low:.2f}, {high:.2f}]" if low is not None and high is not None else ""
    return f"{values[key]:.2f}{interval}"


def _runs(result: dict) -> str:
    """Which run made each domain's entries: suite version, commit, BLAS kernel and wall seconds per suite."""
    groups: dict[tuple, list[str]] = {}
    for domain in result["suites"]["heldout"]:
        entries = [
            result["suites"][suite][domain] for suite in result["suites"] if domain in result["suites"][suite]
        ]
        entry = entries[0]
        commit = entry.get("commit", result["commit"])[:10]
        wall = "+".join(f"{e['wall_s']:.0f}" for e in entries if "wall_s" in e)
        key = (entry["version"], commit, entry.get("kernel", result["kernel"]))
        groups.setdefault(key, []).append(domain + (f" {wall} s" if wall else ""))
    parts = [
        f"suite v{version} at {commit} ({kernel}): {', '.join(domains)}"
        for (version, commit, kernel), domains in groups.items()
    ]
    return "Runs (wall seconds of the held-out + validation runs where recorded): " + "; ".join(parts) + "."


def kernel_check_lines(kernel_checks: dict) -> list[str]:
    """The second-kernel checks: per domain, its kernel, command and cost, and whether every agent's held-out IQM
    and mean lies inside the published interval."""
    if not kernel_checks:
        return []
    lines = [
        "",
        "Second-kernel checks of the held-out suite (every agent's IQM and mean against the published 95 % "
        "interval):",
    ]
    for domain, check in kernel_checks.items():
        comparison = check["comparison"]
        verdict = (
            "every agent inside"
            + (" (identical to 6 significant digits)" if comparison["identical_to_6_digits"] else "")
            if comparison["inside"]
            else "outside: "
            + "; ".join(
                comparison["outside"] + [f"{k} {v}" for k, v in comparison["settings_differ"].items()]
            )
        )
        members = "other" if "members" in comparison["settings_differ"] else "same"
        lines.append(
            f"- {domain}: {check['kernel']}, suite v{comparison['versions'][0]} (published "
            f"{comparison['published_kernel']}, v{comparison['versions'][1]}; {members} members and parameters), "
            f"`{check['command']}` at "
            f"commit {check['commit'][:10]}, {check['wall_s']:.0f} s wall: {verdict}."
        )
    return lines


def physics_table(physics: dict) -> list[str]:
    """The lab's physics subset: per agent, the normalised mean on each backend over the same episodes, the
    difference and Welch's test, pooled and per member."""
    difference = physics["difference"]
    lines = [
        "",
        f"The physics lab (`--backend mujoco`) beside the abstract one: {', '.join(physics['agents'])} on the "
        f"held-out humans {', '.join(physics['members'])}, {physics['episodes']} episodes each on each backend "
        f"(the same episode specs), seed {physics['seed']}, scored between each member's bounds in the abstract "
        f"lab; {difference['method']} (physics - abstract). Generated by `{physics['command']}` at commit "
        f"{physics['commit'][:10]} (BLAS {physics['kernel']}; wall s: "
        + ", ".join(f"{k} {v:.0f}" for k, v in physics["wall_s"].items())
        + ").",
        "",
        "| agent | teammate | abstract mean | physics mean | difference | Welch t | p |",
        "|---|---|---|---|---|---|---|",
    ]

    def number(value, digits=2):
        return "-" if value is None else f"{value:.{digits}f}"

    for agent, values in difference["agents"].items():
        rows = [("all", values), *values["per_member"].items()]
        for name, row in rows:
            lines.append(
                f"| {agent} | {name} | {number(row['first_mean'])} | {number(row['second_mean'])} | "
                f"{number(row['difference'])} | {number(row['t'])} | {number(row['p'], 3)} |"
            )
    return lines


def simulated_bounds_lines(held: dict) -> list[str]:
    """A sentence per domain whose bounds are simulated (the grid arenas): what its return and upper bound are, and
    per teammate which policy the upper bound is (``bench.bounds``: the better of a trained best response and the
    original team)."""
    from embodied_adhoc.bench.bounds import TRAINED

    lines = []
    for domain, scope in held.items():
        rows = [row for row in scope["teammates"] if row.get("bounds", {}).get("episodes")]
        if not rows:
            continue
        first = rows[0]["bounds"]
        start = f"{domain}: a return is minus the steps to finish (the cap, {first['horizon']}, when unfinished), "
        trained = [row["name"] for row in rows if row["bounds"]["upper"] == TRAINED]
        if not trained:
            lines += [
                "",
                start
                + f"and the upper bound is the {first['upper']}, not a best response: the random ego's and "
                f"its mean over {first['episodes']} episodes of their own seed, so an agent that beats the original "
                "team scores above 1 and `BR` is not known.",
            ]
            continue
        others = [row["name"] for row in rows if row["bounds"]["upper"] != TRAINED]
        lines += [
            "",
            start + "and the upper bound is the better of two mean returns over "
            f"{first['episodes']} episodes of their own seed, the teammate's trained best response (recurrent PPO "
            "against that teammate alone, shipped with the suite) and the original team (its policy in the ego's "
            f"seat): the trained best response for {', '.join(trained)}"
            + (f"; the original team for {', '.join(others)}" if others else "")
            + ". Both are estimates below the true best response, so an agent can score above 1, and `BR` (the "
            "exact best response's score) is not known.",
        ]
    return lines


def table(result: dict) -> str:
    """Per domain and agent: held-out IQM and mean (95 % stratified-bootstrap intervals), the validation IQM."""
    held, validation = result["suites"]["heldout"], result["suites"].get("validation", {})
    first = next(iter(held.values()))
    fewer = ", ".join(
        f"{d} {scope['episodes']}" for d, scope in held.items() if scope["episodes"] != first["episodes"]
    )
    lines = [
        f"{first['episodes']} episodes per teammate and agent{f' ({fewer})' if fewer else ''}, seed "
        f"{first.get('seed', 0)}, abstract backends; "
        "scores normalised per teammate (0 random ego, 1 exact best response); agents marked * observe the true "
        f"state. The whole suite: `{result['command']}` (each part was run on its own with `--domains`; the file "
        f"keeps each part's command); the last part merged at commit {result['commit'][:10]} (BLAS "
        f"{result['kernel']}). {_runs(result)}",
        "",
        "| domain | agent | held-out IQM [95% CI] | held-out mean [95% CI] | validation IQM [95% CI] |",
        "|---|---|---|---|---|",
    ]
    lines[1:1] = simulated_bounds_lines(held)
    for domain, scope in held.items():
        for agent, values in scope["aggregate"].items():
            check = validation.get(domain, {}).get("aggregate", {}).get(agent)
            name = f"{agent}*" if agent in PRIVILEGED else agent
            lines.append(
                f"| {domain} ({scope['members']}) | {name} | {_cell(values, 'iqm')} | {_cell(values, 'mean')} | "
                f"{_cell(check, 'iqm') if check else '-'} |"
            )
    check = result.get("best_response_check")
    if check:
        above = ", ".join(check["above"]) or "none"
        lines += [
            "",
            f"Best-response check over {check['checked']} (teammate, agent) cells of both suites: cells whose "
            f"normalised mean exceeds the best response's expected score from the same starts beyond a one-sided "
            f"99 % t bound: {above}.",
        ]
    lines += kernel_check_lines(result.get("kernel_checks", {}))
    lines += [
        "",
        "Per held-out teammate: each agent's normalised mean and, in parentheses, its mean final posterior on the "
        "true task (an agent without a task posterior shows none); `BR` is the best response's expected score from "
        "the run's own starts.",
    ]
    for domain, scope in held.items():
        agents = list(scope["aggregate"])
        lines += ["", f"| {domain} teammate | type | BR | " + " | ".join(agents) + " |"]
        lines.append("|---|---|---|" + "---|" * len(agents))
        for row in scope["teammates"]:
            cells = []
            for agent in agents:
                values = row["agents"][agent]
                belief = values.get("true_task_probability")
                cells.append(
                    f"{values['normalised_mean']:.2f}" + (f" ({belief:.2f})" if belief is not None else "")
                )
            best = row.get("best_on_episodes")
            lines.append(
                f"| {row['name']} | {row['type']} | {best:.2f} | " + " | ".join(cells) + " |"
                if best is not None
                else f"| {row['name']} | {row['type']} | - | " + " | ".join(cells) + " |"
            )
    if result.get("physics"):
        lines += physics_table(result["physics"])
    return "\n".join(lines)


def render() -> None:
    """Every generated page, this script's block among them, so the block, its class line, the results index and
    the README's headline change together (``render_results.py`` renders the block with this script's ``table``)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import render_results

    render_results.render()


def dumps(value, indent: int = 0) -> str:
    """JSON with one level per line, and lists of numbers or names and objects of such values on one line (the file
    stays small and diffable); floats to 6 significant digits, far below the intervals' widths."""
    pad, inner = " " * indent, " " * (indent + 1)
    if isinstance(value, dict):
        if not value:
            return "{}"
        if all(not isinstance(v, dict) and "\n" not in dumps(v) for v in value.values()):
            return "{" + ", ".join(f"{json.dumps(str(k))}: {dumps(v)}" for k, v in value.items()) + "}"
        items = [f"{inner}{json.dumps(str(k))}: {dumps(v, indent + 1)}" for k, v in value.items()]
        return "{\n" + ",\n".join(items) + f"\n{pad}}}"
    if isinstance(value, list | tuple):
        if all(not isinstance(v, dict | list | tuple) for v in value):
            return "[" + ", ".join(dumps(v) for v in value) + "]"
        return "[\n" + ",\n".join(f"{inner}{dumps(v, indent + 1)}" for v in value) + f"\n{pad}]"
    if isinstance(value, float):
        return json.dumps(float(f"{value:.6g}"))
    return json.dumps(value)


def main() -> int:
    args = parse()
    if not args.render_only:
        from embodied_adhoc.atomic import atomic_write_text

        fresh = run_physics(args) if args.physics else run_check(args) if args.check else run(args)
        previous = json.loads(RESULT.read_text()) if RESULT.is_file() else {}  # read now: runs may overlap
        atomic_write_text(RESULT, dumps(merge(previous, fresh)) + "\n")
    if not args.no_render:
        render()
    print(table(json.loads(RESULT.read_text())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
