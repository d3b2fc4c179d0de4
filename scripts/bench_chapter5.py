"""Build (and optionally solve) every chapter-5 library and print the thesis's Table 5.3 times beside ours.

Building is timed per library (all its models, teammate policies by value iteration on the MMDPs included); the
thesis's setup time is per POMDP, so its column is multiplied by the library size for the ratio. With ``--solve``
each model is also solved by Perseus with the settings of ``trials`` (``chapter5.solver_settings``: Table 5.2's
belief-set size, tolerance 0.01, the domain's ``SOLVE_STAGES`` stages at most; no cache) and its CPU seconds (this
process's, so the load of other processes counts little) are printed beside the thesis's mean solve time per POMDP::

    .venv/bin/python scripts/bench_chapter5.py [--solve] [--repeats 3]

With ``--executors local ray`` it times instead the whole Table 5.5 (every library built, its policies solved or
read from the policy cache, 32 episodes x 6 agents x 11 domains, the configs of ``reproduce_atpo.py``) once per
executor in this one run, the first as the reference of the ratios, and checks that every executor gives the same
returns. ``ray`` joins the cluster at ``RAY_ADDRESS`` (see docs/atpo.md for a local head + worker)::

    RAY_ADDRESS=127.0.0.1:6380 .venv/bin/python scripts/bench_chapter5.py --executors local ray

With ``--budget`` it checks the stage budget instead: each domain's first model solved with the trials' settings
but ``--past`` stages more than the domain's ``SOLVE_STAGES``, the lower bound at b0 read stage by stage (Perseus'
progress reports, this process's CPU seconds): its value at the budget beside its value after the extra stages
(or where Perseus converged first), and the CPU seconds each took::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python scripts/bench_chapter5.py --budget [--past 3] --markdown

A cold cache (``XDG_CACHE_HOME`` pointing at an empty folder) times solving too; a warm one times the trials and
the building. The policies do not depend on the load (a stage budget), so the first executor's pass may run cold
and the next ones warm. Times are wall-clock on the machine at hand, with this process's CPU seconds beside them
(say how loaded the machine was when you quote them).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

from embodied_adhoc.domains.chapter5 import build_library
from embodied_adhoc.experiments.domains.chapter5 import (
    TABLE_5_5_DOMAINS,
    forget_sessions,
    solver_settings,
    sweep_config,
)
from embodied_adhoc.experiments.script_args import parse_dataclass_args
from embodied_adhoc.experiments.tables import format_table

# Table 5.3: mean seconds per POMDP (setup, solve)
THESIS = {
    "gridworld": (27.4, 2463), "pursuit-task": (218, 9055), "pursuit-teammate": (201, 9084),
    "pursuit-both": (211, 10983), "power-plant": (1.41, 43.3), "ntu": (14.0, 605), "overcooked": (241, 323),
    "isr": (503, 21779), "mit": (701, 20599), "pentagon": (975, 17750), "cit": (3105, 42810),
}  # fmt: skip


@dataclass(frozen=True)
class Args:
    solve: bool = False
    """also solve every model (the trials' solver settings, no cache; default: build only)"""
    repeats: int = 3
    """builds per library (the fastest is reported)"""
    markdown: bool = False
    """print a Markdown table"""
    executors: tuple[str, ...] = ()
    """time the whole Table 5.5 sweep with each of these executors (local, ray) instead"""
    workers: int = 1
    """worker processes of the local executor (ray: the cluster's CPUs)"""
    episodes: int = 32
    """episodes per agent and domain in the Table 5.5 sweep"""
    domains: tuple[str, ...] = TABLE_5_5_DOMAINS
    """the Table 5.5 rows to time (default: all eleven)"""
    budget: bool = False
    """solve each domain's first model --past stages past its stage budget and print the lower bound at b0 at the
    budget and after (instead of Table 5.3)"""
    past: int = 3
    """with --budget: the stages solved past the budget"""
    returns_json: str = ""
    """write the first executor's returns ({domain: [[agent, episode, return], ...]}) to this JSON file (to compare
    runs: the same returns on any load)"""


def time_table_5_5(args: Args) -> None:
    """The whole Table 5.5 once per executor, fresh sessions each time (libraries built and policies solved or
    loaded again in every run); the same returns are required of every executor."""
    from embodied_adhoc.experiments.runner import run_sweep

    rows, reference, first = [], None, None
    for executor in args.executors:
        forget_sessions()
        start, cpu_start = time.perf_counter(), time.process_time()
        returns, trials = {}, 0
        for domain in args.domains:
            config = sweep_config(
                domain, episodes=args.episodes
            )  # reproduce_atpo.py's: the same cache entries
            result = run_sweep(config, workers=args.workers, executor=executor)
            trials += len(result.records)
            returns[domain] = sorted((r.agent, r.episode, r.total_reward) for r in result.records)
        seconds, cpu = time.perf_counter() - start, time.process_time() - cpu_start
        if reference is None:
            reference, first = seconds, returns
            if args.returns_json:
                Path(args.returns_json).write_text(json.dumps(returns, indent=0))
        same = "yes" if returns == first else "NO"
        rows.append(
            [executor, str(trials), f"{seconds:.1f}", f"{cpu:.1f}", f"{seconds / reference:.2f}", same]
        )
    headers = ["executor", "trials", "Table 5.5 s (wall)", "driver CPU s", f"ratio to {args.executors[0]}",
               "same returns"]  # fmt: skip
    print(format_table(headers, rows, args.markdown))
    if any(row[-1] == "NO" for row in rows):
        raise SystemExit("executors disagree on the returns: a seeding bug")


def stage_budget(args: Args) -> None:
    """Per domain: model 0 solved ``args.past`` stages past the budget; V(b0) and CPU seconds at the budget and at
    the end, as two tables (the values depend on the model and settings only, the seconds on the host)."""
    from embodied_adhoc.decision.perseus import PerseusConfig, perseus

    values, seconds = [], []
    for domain in args.domains:
        library = build_library(domain)
        settings = solver_settings(library, {})
        budget = settings["max_iterations"]
        config = PerseusConfig(**{**settings, "max_iterations": budget + args.past, "clock": "cpu"})
        reports = []
        perseus(library.pomdps[0], config, reports.append)
        at = next((r for r in reports if r.iteration == budget), reports[-1])
        end = reports[-1]
        values.append([domain, str(budget), f"{at.value_b0:.4f}", str(end.iteration), f"{end.value_b0:.4f}",
                       f"{end.value_b0 - at.value_b0:.4f}", str(at.n_vectors)])  # fmt: skip
        seconds.append([domain, f"{at.seconds:.1f}", f"{end.seconds:.1f}"])
    print(f"The lower bound at b0 of each domain's first model at its stage budget and up to {args.past} stages "
          f"past it (Perseus' own stop rule may end a solve first)")  # fmt: skip
    headers = ["domain", "budget (stages)", "V(b0) at the budget (or where Perseus stopped first)", "stages done",
               "V(b0) then", "change", "vectors at the budget"]  # fmt: skip
    print(format_table(headers, values, args.markdown))
    print()
    print("CPU seconds of this process from the start of the solve")
    print(format_table(["domain", "CPU s to the budget", "CPU s to the end"], seconds, args.markdown))


def main() -> None:
    from embodied_adhoc.decision.perseus import PerseusConfig, perseus

    args = parse_dataclass_args(Args, __doc__)
    if args.executors:
        time_table_5_5(args)
        return
    if args.budget:
        stage_budget(args)
        return
    rows = []
    total_build = total_solve = 0.0
    for domain, (thesis_setup, thesis_solve) in THESIS.items():
        times = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            library = build_library(domain)
            times.append(time.perf_counter() - start)
        build = min(times)
        total_build += build
        row = [domain, str(library.n_models), f"{build:.3f}", f"{thesis_setup * library.n_models:.0f}",
               f"{thesis_setup * library.n_models / build:.0f}x"]  # fmt: skip
        if args.solve:
            config = PerseusConfig(**solver_settings(library, {}))
            start = time.process_time()
            stages = [perseus(pomdp, config).stats.iterations for pomdp in library.pomdps]
            solve = (time.process_time() - start) / library.n_models
            total_solve += solve * library.n_models
            row += [f"{config.max_iterations} ({min(stages)}-{max(stages)})", f"{solve:.1f}", f"{thesis_solve:.0f}",
                    f"{thesis_solve / solve:.0f}x"]  # fmt: skip
        rows.append(row)
    headers = ["domain", "models", "build s (ours)", "setup s (thesis, x models)", "thesis / ours"]
    if args.solve:
        headers += [
            "stages: budget (done)",
            "solve CPU s per model (ours)",
            "solve s per model (thesis)",
            "thesis / ours",
        ]
    print(format_table(headers, rows, args.markdown))
    print(
        f"\nall libraries built in {total_build:.2f} s"
        + (f", solved in {total_solve:.0f} CPU s" if total_solve else "")
    )


if __name__ == "__main__":
    main()
