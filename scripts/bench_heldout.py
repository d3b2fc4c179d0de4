"""The held-out benchmark for the shipped agents: ``embodied-adhoc evaluate`` on each domain's held-out suite (and its
validation suite beside it), written to ``results/benchmark-heldout.json`` with its provenance, and the table
between the ``<!-- bench:heldout start/end -->`` markers of ``docs/benchmark.md`` rendered from that file.

    .venv/bin/python scripts/bench_heldout.py                 # run (resumable under runs/bench-*) and render
    .venv/bin/python scripts/bench_heldout.py --render-only   # render the page from the result file

Every agent of a domain runs on every member for the same episodes; the lab runs on its abstract backend.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import platform
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULT = ROOT / "results" / "benchmark-heldout.json"
PAGE = ROOT / "docs" / "benchmark.md"
START, END = "<!-- bench:heldout start -->", "<!-- bench:heldout end -->"
AGENTS = {
    "toxic-waste": ("hotspot", "atpo", "bopa", "known-task", "oracle", "random"),
    "pursuit-task": ("atpo", "bopa", "perseus", "value-iteration", "random-picker", "random"),
    "gridworld": ("atpo", "bopa", "perseus", "value-iteration", "random-picker", "random"),
}
PRIVILEGED = ("oracle", "bopa", "value-iteration")


@dataclass
class Args:
    episodes: int = 32  # per member and agent
    seed: int = 0
    suites: tuple[str, ...] = ("heldout", "validation")
    out: str = "runs/bench"  # one folder per suite and domain below it
    render_only: bool = False


def parse() -> Args:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=Args.episodes)
    parser.add_argument("--seed", type=int, default=Args.seed)
    parser.add_argument("--suites", default=",".join(Args.suites))
    parser.add_argument("--out", default=Args.out)
    parser.add_argument("--render-only", action="store_true")
    ns = parser.parse_args()
    return Args(ns.episodes, ns.seed, tuple(ns.suites.split(",")), ns.out, ns.render_only)


def run(args: Args) -> dict:
    from embodied_adhoc.bench.evaluate import evaluate, resolve_suite
    from embodied_adhoc.experiments.identity import blas_kernel

    started = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    results = {}
    for suite_name in args.suites:
        for domain, agents in AGENTS.items():
            suite = resolve_suite(suite_name, (domain,))
            out = Path(args.out) / f"{suite_name}-{domain}"
            summary = evaluate(agents, suite, out, episodes=args.episodes, seed=args.seed, progress=True)
            results.setdefault(suite_name, {})[domain] = summary["domains"][domain] | {
                "version": summary["version"],
                "episodes": summary["episodes"],
                "seed": summary["seed"],
                "bootstrap": summary["bootstrap"],
            }
    checks = best_response_check(results)
    print(
        f"best-response check: {checks['checked']} (teammate, agent) cells, {len(checks['above'])} above",
        file=sys.stderr,
    )
    commit = subprocess.run(
        ["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True
    ).stdout.strip()
    return {
        "figure": "benchmark-heldout",
        "command": " ".join([".venv/bin/python", "scripts/bench_heldout.py", *sys.argv[1:]]),
        "commit": commit,
        "kernel": blas_kernel(),
        "python": platform.python_version(),
        "started": started,
        "finished": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "suites": results,
        "best_response_check": checks,
    }


def best_response_check(results: dict) -> dict:
    """Every (teammate, agent) cell whose normalised mean exceeds the best response's expected score from the same
    starts by more than a one-sided 99 % t bound (none is expected: the best response is exact)."""
    from scipy import stats

    above, checked = [], 0
    for suite_name, domains in results.items():
        for domain, scope in domains.items():
            n = scope["episodes"]
            for row in scope["teammates"]:
                for agent, values in row["agents"].items():
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


def table(result: dict) -> str:
    """Per domain and agent: held-out IQM and mean (95 % stratified-bootstrap intervals), the validation IQM."""
    held, validation = result["suites"]["heldout"], result["suites"].get("validation", {})
    first = next(iter(held.values()))
    lines = [
        f"Suite v{first['version']}, {first['episodes']} episodes per teammate and agent, seed "
        f"{first.get('seed', 0)}, abstract backends; scores normalised per teammate (0 random ego, 1 exact "
        f"best response); agents marked * observe the true state. Generated by `{result['command']}` at commit "
        f"{result['commit'][:10]} (BLAS {result['kernel']}).",
        "",
        "| domain | agent | held-out IQM [95% CI] | held-out mean [95% CI] | validation IQM [95% CI] |",
        "|---|---|---|---|---|",
    ]
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
    return "\n".join(lines)


def render(result: dict) -> None:
    text = PAGE.read_text()
    if START not in text or END not in text:
        raise SystemExit(f"{PAGE}: the markers {START} and {END} are missing")
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    PAGE.write_text(f"{head}{START}\n{table(result)}\n{END}{tail}")


def main() -> int:
    args = parse()
    if not args.render_only:
        from embodied_adhoc.atomic import atomic_write_text

        result = run(args)
        atomic_write_text(RESULT, json.dumps(result, indent=1) + "\n")
    render(json.loads(RESULT.read_text()))
    print(table(json.loads(RESULT.read_text())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
