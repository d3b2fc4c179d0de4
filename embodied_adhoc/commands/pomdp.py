"""``embodied-adhoc pomdp info|solve|export``: inspect and solve Cassandra ``.pomdp`` files; export a chapter-5
library (:mod:`embodied_adhoc.commands.pomdp_export`)."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from embodied_adhoc.commands.arguments import bounded, output_file, seed

SOLVERS = ("auto", "perseus", "hsvi", "qmdp", "vi")
AUTO_MAX_OBSERVATIONS = 4
AUTO_MIN_STATES = 200
"""``--solver auto`` picks HSVI for infinite-horizon models with at least this many states and at most that many
observations (the RockSample class: long information-gathering horizons, where trials down the optimally
reachable beliefs beat a sampled belief set), else Perseus (docs/pomdp.md, "Choosing a solver")."""
AUTO_MAX_START_SHARE = 0.1
AUTO_MAX_OBSERVATION_SHARE = 0.25
"""... and for those whose initial belief covers at most this share of the states and whose states each emit at
most that share of the observations on average (the chapter-5 navigation models: a known start, a sensor that
reads the neighbourhood): their optimally reachable beliefs stay few and narrow, so trials close the gap that a
sampled belief set leaves open. A dense observation model (the classic corpus's cit, mit, sunysb: every state
can emit most observations) or a spread start (Tag) widens every trial step, and Perseus is ahead there."""


def auto_solver(
    n_states: int,
    n_observations: int,
    discount: float,
    horizon: int | None,
    start_share: float = 1.0,
    observation_share: float = 1.0,
) -> str:
    """The solver ``--solver auto`` runs on a model of these sizes, whose initial belief covers ``start_share``
    of the states and whose states emit ``observation_share`` of the observations on average (rule:
    :data:`AUTO_MIN_STATES`, :data:`AUTO_MAX_START_SHARE`; the shares from :func:`solver_features`)."""
    if horizon is not None or discount >= 1.0 or n_states < AUTO_MIN_STATES:
        return "perseus"
    if n_observations <= AUTO_MAX_OBSERVATIONS:
        return "hsvi"
    if start_share <= AUTO_MAX_START_SHARE and observation_share <= AUTO_MAX_OBSERVATION_SHARE:
        return "hsvi"
    return "perseus"


def solver_features(pomdp) -> dict[str, float]:
    """What :func:`auto_solver` reads of a model besides its sizes: the share of states on the initial belief's
    support, and the mean over actions and end states of the share of observations with nonzero probability."""
    import numpy as np

    start = np.count_nonzero(np.asarray(pomdp.initial_belief)) / pomdp.n_states
    emitted = np.mean([np.diff(matrix.indptr).mean() for matrix in pomdp.observations])
    return {"start_share": float(start), "observation_share": float(emitted / pomdp.n_observations)}


_POSITIVE_INT = bounded(int, 1, "an integer >= 1")
_COUNT = bounded(int, 0, "an integer >= 0")
MAX_BELIEF_ENTRIES = 10**8
"""Perseus keeps its belief set as dense rows: ``--beliefs`` x |S| at most this (800 MB of float64)."""
_POSITIVE_SECONDS = bounded(float, math.ulp(0.0), "a finite number of seconds > 0")
_POSITIVE_FLOAT = bounded(float, math.ulp(0.0), "a finite number > 0")


def register(subparsers: argparse._SubParsersAction) -> None:
    group = subparsers.add_parser("pomdp", help="inspect and solve .pomdp files (Cassandra's format)")
    group.set_defaults(_parser=group)
    commands = group.add_subparsers(dest="pomdp_command", metavar="SUBCOMMAND")

    info = commands.add_parser("info", help="sizes and discount of a .pomdp file")
    _add_file(info)
    info.add_argument("--json", action="store_true", help="print one JSON object")
    info.set_defaults(func=_info)

    solve = commands.add_parser("solve", help="solve a .pomdp file and report V(b0)")
    _add_file(solve)
    solve.add_argument(
        "--solver",
        choices=SOLVERS,
        default="auto",
        help=f"default: auto = hsvi for infinite-horizon models with >= {AUTO_MIN_STATES} states and either <= "
        f"{AUTO_MAX_OBSERVATIONS} observations, or an initial belief on <= {AUTO_MAX_START_SHARE * 100:.0f}%% of "
        f"the states and states that each emit <= {AUTO_MAX_OBSERVATION_SHARE * 100:.0f}%% of the observations on "
        "average; else perseus; hsvi = heuristic search value iteration (trials "
        "from b0 guided by the bounds' gap; uses --precision, --trials, --max-depth, --time-limit, --clock, "
        "--threads)",
    )
    solve.add_argument(
        "--trials",
        type=_POSITIVE_INT,
        default=None,
        metavar="N",
        help="hsvi: stop after N trials (default 100000); the same N gives the same policy on any host",
    )
    solve.add_argument(
        "--max-depth",
        type=_POSITIVE_INT,
        default=None,
        metavar="D",
        help="hsvi: deepest belief of a trial (default: trials start cut at the effective horizon 1 / (1 - gamma), "
        "and the cut grows by that much after 5 trials in a row stall at it, up to where the initial gap meets its "
        "discounted target, 20 to 1000 steps)",
    )
    solve.add_argument(
        "--beliefs", type=_POSITIVE_INT, default=1000, help="Perseus belief-set size (default 1000)"
    )
    solve.add_argument(
        "--time-limit",
        type=_POSITIVE_SECONDS,
        default=None,
        help="the solver's time limit in seconds (> 0) of --clock (Perseus and HSVI)",
    )
    solve.add_argument(
        "--clock",
        choices=("cpu", "wall"),
        default="cpu",
        help="what --time-limit and the progress seconds count: 'cpu' (default) = this process's CPU time, as "
        "SARSOP's pomdpsol counts its timeout, so a loaded machine gives the same solve, only later (with "
        "--threads > 1: the CPU time of all threads, so a solve waits less wall time than its CPU seconds); "
        "'wall' = elapsed time",
    )
    solve.add_argument(
        "--threads",
        type=_POSITIVE_INT,
        default=None,
        metavar="N",
        help="Perseus: threads that split its large sparse products by rows (the same result for any N; default: "
        "the cores this process may use)",
    )
    solve.add_argument(
        "--max-memory",
        type=_POSITIVE_FLOAT,
        default=None,
        metavar="MB",
        help="Perseus: memory cap in MiB; before each stage and expansion the solve estimates what it allocates and "
        "stops (or stops expanding) rather than pass it, keeping its bounds and saying why on stderr (default: "
        "what the process holds plus 80%% of the host's available memory; docs/pomdp.md, Memory)",
    )
    solve.add_argument(
        "--tolerance",
        type=_POSITIVE_FLOAT,
        default=None,
        help="Perseus convergence tolerance (default 1e-3; see --stop)",
    )
    solve.add_argument(
        "--stop",
        choices=("bound", "gain"),
        default="bound",
        help="Perseus stop rule: 'bound' (default) = the bound gamma/(1-gamma) x the largest one-iteration gain "
        "on the belief set is <= tolerance; 'gain' = the classic rule, that gain itself is <= tolerance",
    )
    solve.add_argument(
        "--update",
        choices=("gauss-seidel", "perseus"),
        default="gauss-seidel",
        help="Perseus stages: 'gauss-seidel' (default) = each batch also continues with the vectors its stage "
        "already kept (fewer stages); 'perseus' = the classic stage, every backup against V_n (Spaan & Vlassis; "
        "the values of the fixed-set solver before the Gauss-Seidel stages, and chapter 5's policies)",
    )
    solve.add_argument(
        "--precision",
        type=bounded(float, 0.0, "a finite number >= 0"),
        default=1e-3,
        help="Perseus: stop when upper - lower bound at b0 <= this (default 1e-3); only this sets 'converged'",
    )
    solve.add_argument(
        "--no-expand",
        action="store_true",
        help="Perseus: keep the fixed belief set of --beliefs (default: grow it while solving, and stop at "
        "--time-limit, --precision, or when an expansion round moves neither bound by --tolerance)",
    )
    solve.add_argument(
        "--horizon", type=_POSITIVE_INT, default=None, help="finite horizon (required when discount is 1.0)"
    )
    solve.add_argument("--seed", type=seed, default=0, help="seed of belief collection and simulation (>= 0)")
    solve.add_argument(
        "--simulate", type=_COUNT, default=0, metavar="N", help="evaluate with N simulated episodes"
    )
    solve.add_argument(
        "--sim-steps",
        type=_POSITIVE_INT,
        default=None,
        help="steps per simulated episode (default: horizon, or until gamma^t < 1e-3)",
    )
    solve.add_argument(
        "--save-policy",
        type=output_file,
        default=None,
        metavar="PATH",
        help="write the policy to exactly PATH (an .npz archive); checked before solving",
    )
    solve.add_argument("--json", action="store_true", help="stdout is one JSON object")
    solve.add_argument("--quiet", action="store_true", help="no progress on stderr")
    solve.set_defaults(func=_solve)

    from embodied_adhoc.commands.pomdp_export import register_export

    register_export(commands)

    generate = commands.add_parser(
        "generate",
        help="write a generated benchmark model as a .pomdp file (rocksample: Smith & Simmons 2004)",
    )
    models = generate.add_subparsers(dest="model", metavar="MODEL", required=True)
    rock = models.add_parser(
        "rocksample",
        help="RockSample[n, k]: n x n grid, k rocks at seeded cells, 2 observations, 5 + k actions, gamma 0.95",
        description="RockSample[n, k] (Smith & Simmons 2004): rewards +10 exit east, +10 / -10 sample good / bad "
        "rock, check_i right with probability (1 + 2^(-d/20)) / 2; n^2 2^k + 1 states "
        "(embodied_adhoc.decision.rocksample).",
    )
    rock.add_argument("--n", type=_POSITIVE_INT, required=True, help="grid side")
    rock.add_argument("--k", type=_POSITIVE_INT, required=True, help="number of rocks (<= n^2)")
    rock.add_argument("--seed", type=seed, default=0, help="seed of the rock cells (>= 0)")
    rock.add_argument(
        "--out", type=output_file, required=True, metavar="FILE", help="the .pomdp file to write"
    )
    rock.add_argument("--json", action="store_true", help="print one JSON object")
    rock.set_defaults(func=_generate_rocksample)


def _generate_rocksample(args: argparse.Namespace) -> int:
    from embodied_adhoc.decision.pomdp_io import write_pomdp
    from embodied_adhoc.decision.rocksample import rock_positions, rocksample

    pomdp = rocksample(args.n, args.k, args.seed)
    path = write_pomdp(pomdp, args.out)
    report = {
        "file": str(path),
        "model": f"RockSample[{args.n},{args.k}]",
        "seed": args.seed,
        "rocks": rock_positions(args.n, args.k, args.seed).tolist(),
        "states": pomdp.n_states,
        "actions": pomdp.n_actions,
        "observations": pomdp.n_observations,
    }
    print(json.dumps(report) if args.json else " ".join(f"{key}={value}" for key, value in report.items()))
    return 0


def _add_file(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="a .pomdp path, or the name of a shipped file (e.g. tiger.95.POMDP)")
    parser.add_argument(
        "--missing-rows",
        choices=("error", "absorbing", "reset"),
        default="error",
        help="transition rows the file never writes: error (default), self-loop, or start belief",
    )


def resolve_pomdp_path(name: str) -> Path:
    """A path relative to the working directory, else a file shipped under ``assets/data/``."""
    from embodied_adhoc import paths
    from embodied_adhoc.errors import ConfigError

    path = Path(name)
    if path.is_file():
        return path
    try:
        return paths.asset(f"data/{name}")
    except FileNotFoundError:
        shipped = sorted(p.name for p in paths.assets_dir().joinpath("data").glob("*.POMDP"))
        raise ConfigError(
            f"no file '{name}' (not a path from {Path.cwd()}, nor a shipped file: {shipped})"
        ) from None


def _load(args: argparse.Namespace):
    from embodied_adhoc.decision.pomdp_io import read_pomdp

    return read_pomdp(resolve_pomdp_path(args.file), missing_rows=args.missing_rows)


def _info(args: argparse.Namespace) -> int:
    pomdp = _load(args)
    report = {
        "file": str(resolve_pomdp_path(args.file)),
        "states": pomdp.n_states,
        "actions": pomdp.n_actions,
        "observations": pomdp.n_observations,
        "discount": pomdp.discount,
        "transition_nonzeros": int(sum(m.nnz for m in pomdp.transitions)),
        "observation_nonzeros": int(sum(m.nnz for m in pomdp.observations)),
    }
    if args.json:
        print(json.dumps(report))
    else:
        for key, value in report.items():
            print(f"{key:>22}: {value}")
    return 0


def _solve(args: argparse.Namespace) -> int:
    from embodied_adhoc.errors import ConfigError

    if args.simulate and args.solver == "vi":
        raise ConfigError(
            "--simulate needs a belief policy: use --solver perseus or qmdp (vi solves the MDP)"
        )
    if args.save_policy is not None and args.solver == "vi":
        raise ConfigError(
            "--save-policy needs an alpha-vector policy: use --solver perseus or qmdp (vi solves the MDP)"
        )
    if args.solver == "hsvi" and args.horizon is not None:
        raise ConfigError(
            "--solver hsvi solves the infinite-horizon problem: drop --horizon or use --solver perseus"
        )
    if args.solver != "auto":
        _check_hsvi_flags(args)
    from embodied_adhoc.decision import memory

    memory.return_freed_memory()
    pomdp = _load(args)
    memory.trim()  # the reader's objects are gone: the solve starts from the model alone
    if args.solver == "auto":
        args.solver = auto_solver(
            pomdp.n_states, pomdp.n_observations, pomdp.discount, args.horizon, **solver_features(pomdp)
        )
        _check_hsvi_flags(args, chosen=True)
    if args.solver == "perseus" and args.beliefs * pomdp.n_states > MAX_BELIEF_ENTRIES:
        raise ConfigError(
            f"--beliefs {args.beliefs}: {args.beliefs:,} dense beliefs over {pomdp.n_states:,} states exceed the "
            f"limit of {MAX_BELIEF_ENTRIES:,} entries; give --beliefs {MAX_BELIEF_ENTRIES // pomdp.n_states} or fewer"
        )
    start, start_cpu = time.perf_counter(), time.process_time()
    report: dict = {"file": str(resolve_pomdp_path(args.file)), "solver": args.solver}
    policy = None
    if args.solver == "vi":
        from embodied_adhoc.decision.value_iteration import value_iteration

        result = value_iteration(pomdp.as_mdp(), tolerance=args.tolerance or 1e-8, horizon=args.horizon)
        report.update(
            value_b0=float(pomdp.initial_belief @ result.values),
            alpha_vectors=0,
            iterations=result.iterations,
            converged=result.converged,
        )
    else:
        if args.solver == "qmdp":
            from embodied_adhoc.decision.qmdp import qmdp

            policy = qmdp(pomdp, horizon=args.horizon)
        elif args.solver == "hsvi":
            policy = _hsvi(pomdp, args)
        else:
            from embodied_adhoc.decision.perseus import PerseusConfig, perseus
            from embodied_adhoc.experiments.executors import available_cpus

            config = PerseusConfig(
                n_beliefs=args.beliefs,
                tolerance=1e-3 if args.tolerance is None else args.tolerance,
                stop=args.stop,
                update=args.update,
                time_limit=args.time_limit,
                seed=args.seed,
                horizon=args.horizon,
                precision=args.precision,
                expand=not args.no_expand,
                clock=args.clock,
                threads=available_cpus() if args.threads is None else args.threads,
                max_memory=args.max_memory,
            )
            policy = perseus(pomdp, config, progress=None if args.quiet else _progress_printer())
        report.update(
            value_b0=policy.value(pomdp.initial_belief),
            alpha_vectors=policy.n_vectors,
            iterations=policy.stats.iterations,
            converged=policy.stats.converged,
        )
        if policy.stats.n_beliefs:
            report["beliefs"] = policy.stats.n_beliefs
        if policy.stats.stopped:  # why the solve ended (SolverStats.stopped)
            report["stopped"] = policy.stats.stopped
        if not math.isnan(policy.stats.upper):
            report.update(lower=policy.stats.lower, upper=policy.stats.upper, gap=policy.stats.gap)
    report["seconds"], report["cpu_seconds"] = time.perf_counter() - start, time.process_time() - start_cpu
    if args.save_policy is not None and policy is not None:
        report["policy"] = str(policy.save(args.save_policy))
    if args.simulate:
        from embodied_adhoc.decision.evaluation import evaluate_policy

        steps = args.sim_steps or args.horizon or _effective_horizon(pomdp.discount)
        evaluation = evaluate_policy(pomdp, policy, args.simulate, steps, seed=args.seed)
        report["simulation"] = evaluation.as_dict()
    if args.json:
        print(json.dumps(report))
    else:
        _print_report(report)
    return 0


def _check_hsvi_flags(args: argparse.Namespace, chosen: bool = False) -> None:
    from embodied_adhoc.errors import ConfigError

    for flag, value in (("--trials", args.trials), ("--max-depth", args.max_depth)):
        if value is not None and args.solver != "hsvi":
            reason = f" (--solver auto chose {args.solver} for this model)" if chosen else ""
            raise ConfigError(
                f"{flag} is an HSVI setting{reason}: add --solver hsvi, or drop {flag} for {args.solver}"
            )


def _hsvi(pomdp, args: argparse.Namespace):
    from embodied_adhoc.decision.hsvi import HsviConfig, hsvi
    from embodied_adhoc.experiments.executors import available_cpus

    config = HsviConfig(
        epsilon=args.precision,
        max_trials=args.trials or HsviConfig.max_trials,
        max_depth=args.max_depth,
        time_limit=args.time_limit,
        clock=args.clock,
        threads=available_cpus() if args.threads is None else args.threads,
    )
    return hsvi(pomdp, config, progress=None if args.quiet else _progress_printer())


def _effective_horizon(discount: float) -> int:
    return (
        1000
        if discount >= 1.0
        else max(1, min(10_000, math.ceil(math.log(1e-3) / math.log(max(discount, 1e-9)))))
    )


def _progress_printer():
    last = [0.0]

    def report(progress) -> None:
        if progress.seconds - last[0] >= 1.0 or progress.iteration <= 1:
            last[0] = progress.seconds
            bounds = (
                f"  upper {progress.upper_b0:12.6f}  gap {progress.gap:.4g}  beliefs {progress.n_beliefs}"
                if not math.isnan(progress.upper_b0)
                else ""
            )
            print(
                f"  iteration {progress.iteration:5d}  {progress.seconds:7.1f} s  lower {progress.value_b0:12.6f}"
                f"{bounds}  vectors {progress.n_vectors:6d}  improvement {progress.improvement:.3g}",
                file=sys.stderr,
                flush=True,
            )

    return report


def _print_report(report: dict) -> None:
    simulation = report.pop("simulation", None)
    for key, value in report.items():
        print(f"{key:>14}: {value:.6f}" if isinstance(value, float) else f"{key:>14}: {value}")
    if simulation:
        print(
            f"{'simulation':>14}: {simulation['mean']:.4f} +- {simulation['ci95']:.4f} (95% CI, "
            f"{simulation['episodes']} episodes x {simulation['horizon']} steps)"
        )
