"""Benchmark Perseus on the classic corpus against SARSOP's figures, and on a generated thesis-size model.

Prints three tables:

1. Backup speed: the vectorised point-based backup against a naive reference (per-belief Python loops over
   actions, observations and vectors on dense arrays, as in the thesis's implementation), measured in this run.
2. Corpus: V(b0) of Perseus within a time limit, SARSOP's [lb, ub] (``../shared/pomdp/README.md``, 20 s runs on a
   2-core machine), and the time Perseus needed to reach SARSOP's lb (its policy value at b0).
3. A generated sparse POMDP the size of the thesis's pursuit model (626 states, 5 actions, 81 observations),
   solved with 5,000 beliefs until convergence (the thesis: 2.5 h).
4. Time to value: the lower and upper bounds at b0 of the anytime solver (the CLI's defaults: 1,000 beliefs,
   expansion) at 1, 5, 20 and 60 s, next to SARSOP's at the same times: measured in the same run when a
   ``pomdpsol`` binary is on the PATH (optional, never a dependency), else the recorded figures; then the peak
   memory (resident set) of the whole run and the vectors it saved, and SARSOP's peak memory when measured.

    .venv/bin/python scripts/bench_solvers.py --only-anytime --problems sarsop-TagAvoid.pomdp hallway2.POMDP

    .venv/bin/python scripts/bench_solvers.py                     # everything (about 10 minutes)
    .venv/bin/python scripts/bench_solvers.py --problems tiger.95.POMDP hallway.POMDP --time-limit 20
"""

from __future__ import annotations

import json
import math
import multiprocessing
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.commands.pomdp import auto_solver, solver_features
from embodied_adhoc.decision import memory
from embodied_adhoc.decision.backup import BackupOperator
from embodied_adhoc.decision.beliefs import collect_beliefs
from embodied_adhoc.decision.hsvi import HsviConfig, hsvi
from embodied_adhoc.decision.memory import peak_mb
from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.perseus import PerseusConfig, perseus
from embodied_adhoc.decision.pomdp_io import read_pomdp, write_pomdp
from embodied_adhoc.decision.random_pomdp import check_counts, random_pomdp
from embodied_adhoc.decision.rocksample import rocksample
from embodied_adhoc.domains.chapter5 import CHAPTER5_DOMAINS, build_library
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.script_args import parse_dataclass_args

# SARSOP lower / upper bound at b0 and its run time, from ../shared/pomdp/README.md.
SARSOP = {
    "tiger.95.POMDP": (19.3711, 19.3721, 0.0),
    "4x3.95.POMDP": (1.88988, 1.89085, 0.61),
    "cheese.95.POMDP": (3.48525, 3.48624, 0.0),
    "shuttle.95.POMDP": (32.889, 32.8897, 0.0),
    "paint.95.POMDP": (3.29358, 3.29456, 0.02),
    "hallway.POMDP": (0.984593, 1.21028, 20.04),
    "hallway2.POMDP": (0.321855, 0.914326, 20.1),
    "tiger-grid.POMDP": (2.22006, 2.53665, 20.2),
    "sarsop-TagAvoid.pomdp": (-6.31682, -1.57109, 20.41),
    "mit.POMDP": (0.776127, 0.885363, 20.44),
    "pentagon.POMDP": (0.588081, 0.827328, 20.12),
    "cit.POMDP": (0.760097, 0.839946, 20.14),
    "sunysb.POMDP": (0.459403, 0.798037, 20.21),
}
# Tag's target: V(b0) >= -6.5 within 30 s (SARSOP: -6.53 at 0.75 s, -6.43 at 1.4 s)
TAG_TARGET = -6.5


@dataclass(frozen=True)
class Args:
    """Benchmark options (each is also a --flag)."""

    corpus: Path = Path(__file__).resolve().parents[1] / ".." / "shared" / "pomdp"
    problems: tuple[str, ...] = tuple(SARSOP)
    beliefs: int = 3000
    """Perseus belief-set size for corpus problems"""
    time_limit: float = 60.0
    """seconds per corpus problem"""
    seed: int = 0
    generated_beliefs: int = 5000
    generated_time_limit: float = 300.0
    generated_tolerance: float = 0.01
    """the thesis's Perseus tolerance (Table 5.4)"""
    naive_beliefs: int = 3
    """beliefs backed up by the naive reference (seconds each on Tag-size models)"""
    skip_generated: bool = False
    checkpoints: tuple[float, ...] = (1.0, 5.0, 20.0, 60.0)
    """seconds at which the time-to-value table reads both solvers' bounds"""
    only_anytime: bool = False
    """print only the time-to-value table"""
    clock: str = "cpu"
    """time-to-value clock: cpu (process seconds, as pomdpsol's own timer counts) or wall"""
    side_by_side: tuple[str, ...] = ()
    """models for the side-by-side table only (this project's --solver auto choice vs pomdpsol): .pomdp paths, or
    generated ones written to a temporary folder for both solvers, rocksample:N,K (RockSample[N, K], rocks of
    seed 0, as `pomdp generate rocksample`), random:S,A,Z (the seed-0 random model of
    `embodied_adhoc.decision.random_pomdp`) or export:DOMAIN (the first model of a chapter-5 library, as
    `pomdp export DOMAIN --models 1`); a suffix @auto, @hsvi or @perseus sets that model's solver (default:
    --solver)"""
    solver: str = "auto"
    """side-by-side: auto (the CLI's rule), hsvi or perseus"""
    json_out: str = ""
    """side-by-side: also write the rows to this JSON file (e.g. /tmp/side-by-side.json); '-': print the
    JSON document alone on stdout, the table going to stderr"""


def parse_args() -> Args:
    args = parse_dataclass_args(Args, __doc__)
    if args.solver not in ("auto", "hsvi", "perseus"):
        print(f"--solver: expected auto, hsvi or perseus, got {args.solver!r}", file=sys.stderr)
        raise SystemExit(2)
    for given in args.side_by_side:
        spec, solver = split_solver(given, args.solver)
        if solver not in ("auto", "hsvi", "perseus"):
            print(
                f"--side-by-side: {given}: expected @auto, @hsvi or @perseus, got @{solver}", file=sys.stderr
            )
            raise SystemExit(2)
        problem = generated_spec(spec)
        if problem is None and not Path(spec).is_file():
            print(
                f"--side-by-side: no file {spec}; give .pomdp paths, rocksample:N,K, random:S,A,Z or export:DOMAIN",
                file=sys.stderr,
            )
            raise SystemExit(2)
        if problem is not None and problem[0] == "random":
            try:
                check_counts(*(int(count) for count in problem[1:]))
            except ConfigError as failure:
                print(f"--side-by-side: {spec}: {failure}", file=sys.stderr)
                raise SystemExit(2) from None
        exportable = [d for d in CHAPTER5_DOMAINS if d != "map"]  # a map library needs its map file
        if problem is not None and problem[0] == "export" and problem[1] not in exportable:
            print(
                f"--side-by-side: {spec}: no chapter-5 domain {problem[1]!r}; give one of {', '.join(exportable)}",
                file=sys.stderr,
            )
            raise SystemExit(2)
    if args.clock not in ("cpu", "wall"):
        print(f"--clock: expected cpu or wall, got {args.clock!r}", file=sys.stderr)
        raise SystemExit(2)
    return args


def generated_pursuit_size_pomdp(seed: int, side: int = 5, noise: float = 0.2) -> POMDP:
    """A seeded pursuit POMDP of the thesis's size: 626 states, 5 actions, 81 observations, sparse.

    States: (robot cell, prey cell) on a ``side x side`` grid (625) plus an absorbing "captured" state. Actions
    move the robot (N, S, E, W, stay; walls block); the prey then moves to a random neighbouring cell or stays
    (its move probabilities drawn from the seed), so each row has at most 5 successors. Moving onto the prey
    captures it (+10, then absorbing); every other step costs 1. The robot observes the prey's offset
    (dx, dy in -4..4: 81 observations), with probability ``noise`` off by one cell along a random axis.
    """
    rng = np.random.default_rng(seed)
    cells = [(x, y) for x in range(side) for y in range(side)]
    moves = [(0, 1), (0, -1), (1, 0), (-1, 0), (0, 0)]
    n_cells = len(cells)
    n_states, captured, n_obs = n_cells * n_cells + 1, n_cells * n_cells, (2 * side - 1) ** 2

    def step(cell: int, move: tuple[int, int]) -> int:
        x, y = cells[cell]
        nx, ny = x + move[0], y + move[1]
        return nx * side + ny if 0 <= nx < side and 0 <= ny < side else cell

    prey_weights = rng.dirichlet(np.ones(5) * 2.0, size=n_cells)  # each cell's own prey move distribution
    transitions = []
    for move in moves:
        rows, columns, values = [captured], [captured], [1.0]
        for robot in range(n_cells):
            for prey in range(n_cells):
                state, moved = robot * n_cells + prey, step(robot, move)
                if moved == prey:
                    rows.append(state), columns.append(captured), values.append(1.0)
                    continue
                successors: dict[int, float] = {}
                for weight, prey_move in zip(prey_weights[prey], moves, strict=True):
                    target = moved * n_cells + step(prey, prey_move)
                    successors[target] = successors.get(target, 0.0) + weight
                for target, weight in successors.items():
                    rows.append(state), columns.append(target), values.append(weight)
        transitions.append(sp.csr_matrix((values, (rows, columns)), shape=(n_states, n_states)))

    def offset_index(dx: int, dy: int) -> int:
        clip = side - 1
        return (int(np.clip(dx, -clip, clip)) + clip) * (2 * side - 1) + int(np.clip(dy, -clip, clip)) + clip

    observation = np.zeros((n_states, n_obs))
    observation[captured, offset_index(0, 0)] = 1.0
    for robot in range(n_cells):
        for prey in range(n_cells):
            dx, dy = cells[prey][0] - cells[robot][0], cells[prey][1] - cells[robot][1]
            row = observation[robot * n_cells + prey]
            row[offset_index(dx, dy)] += 1.0 - noise
            for ex, ey in moves[:4]:
                row[offset_index(dx + ex, dy + ey)] += noise / 4
    rewards = np.full((n_states, len(moves)), -1.0)
    rewards[captured] = 0.0
    for a, move in enumerate(moves):
        for robot in range(n_cells):
            moved = step(robot, move)
            rewards[robot * n_cells + moved, a] = 10.0
    initial = np.zeros(n_states)
    initial[:captured] = 1.0 / captured
    return POMDP(
        transitions=transitions,
        rewards=rewards,
        discount=0.95,
        observations=[sp.csr_matrix(observation)] * len(moves),
        initial_belief=initial,
    )


def naive_backup(
    pomdp: POMDP, transitions: list, observations: list, belief: np.ndarray, alphas: np.ndarray
) -> tuple[np.ndarray, float]:
    """The textbook point-based backup with Python loops over a, z and vectors on dense arrays (the reference)."""
    best_vector, best_value = None, -np.inf
    for action in range(pomdp.n_actions):
        vector = pomdp.rewards[:, action].copy()
        for observation in range(pomdp.n_observations):
            projected = [
                pomdp.discount * transitions[action] @ (observations[action][:, observation] * alpha)
                for alpha in alphas
            ]
            vector += max(projected, key=lambda g: float(belief @ g))
        if float(belief @ vector) > best_value:
            best_vector, best_value = vector, float(belief @ vector)
    return best_vector, best_value


def backup_speed_table(pomdp: POMDP, name: str, args: Args) -> None:
    policy = perseus(pomdp, PerseusConfig(n_beliefs=200, time_limit=3.0, seed=args.seed))
    beliefs = collect_beliefs(pomdp, max(args.naive_beliefs, 256), np.random.default_rng(args.seed))
    operator = BackupOperator(pomdp)
    start = time.perf_counter()
    vectors, _, values = operator.backup(beliefs, policy.alphas)
    fast = (time.perf_counter() - start) / len(beliefs)
    transitions = [m.toarray() for m in pomdp.transitions]
    observations = [m.toarray() for m in pomdp.observations]
    start = time.perf_counter()
    for index in range(args.naive_beliefs):
        _, value = naive_backup(pomdp, transitions, observations, beliefs[index], policy.alphas)
        assert abs(value - values[index]) < 1e-8 * max(1.0, abs(value)), (
            "vectorised backup disagrees with naive"
        )
    naive = (time.perf_counter() - start) / args.naive_beliefs
    print(
        f"| {name} | {pomdp.n_states} | {policy.n_vectors} | {naive * 1e3:.2f} | {fast * 1e3:.4f} | "
        f"{naive / fast:,.0f}x |"
    )


def corpus_row(name: str, args: Args) -> None:
    pomdp = read_pomdp(args.corpus / name)
    lb, ub, sarsop_seconds = SARSOP.get(name, (np.nan, np.nan, np.nan))
    config = PerseusConfig(n_beliefs=args.beliefs, time_limit=args.time_limit, seed=args.seed, tolerance=1e-4)
    policy = perseus(pomdp, config)
    value = policy.value(pomdp.initial_belief)
    reached = next((seconds for seconds, v in policy.stats.trace if v >= lb), None)
    tag = ""
    if name == "sarsop-TagAvoid.pomdp":
        at_target = next((seconds for seconds, v in policy.stats.trace if v >= TAG_TARGET), None)
        tag = (
            f" (>= {TAG_TARGET} at {at_target:.1f} s)"
            if at_target is not None
            else f" (never >= {TAG_TARGET})"
        )
    inside = "yes" if lb - 1e-9 <= value <= ub + 1e-9 else ("above ub!" if value > ub else "below lb")
    reached_text = f"{reached:.1f}" if reached is not None else "-"
    print(
        f"| {name} | {pomdp.n_states} | {value:.4f}{tag} | {lb:g} | {ub:g} | {inside} | {reached_text} | "
        f"{sarsop_seconds:g} | {policy.stats.seconds:.1f} | {policy.stats.iterations} | {policy.n_vectors} |"
    )


# SARSOP's lower bound over time where it was recorded (../shared/pomdp/README.md, 2-core machine, undated):
# (seconds, lb). Other files: only the 20 s figures of SARSOP above.
SARSOP_TRACES = {
    "sarsop-TagAvoid.pomdp": [
        (0.17, -9.71),
        (0.48, -6.76),
        (0.75, -6.53),
        (1.4, -6.43),
        (2.1, -6.37),
        (7.0, -6.33),
        (20.0, -6.32),
        (120.0, -6.18),
    ],
}


def split_solver(given: str, default: str) -> tuple[str, str]:
    """A side-by-side model's spec and solver: ``MODEL@SOLVER``, or ``MODEL`` with the default solver."""
    spec, at, solver = given.rpartition("@")
    return (spec, solver) if at else (given, default)


def generated_spec(spec: str) -> tuple[str, ...] | None:
    """``("rocksample", N, K)``, ``("random", S, A, Z)`` or ``("export", DOMAIN)`` for a generated model's spec,
    None for a path."""
    rock = re.fullmatch(r"rocksample:([1-9][0-9]*),([1-9][0-9]*)", spec)
    if rock:
        return ("rocksample", rock[1], rock[2])
    drawn = re.fullmatch(r"random:([1-9][0-9]*),([1-9][0-9]*),([1-9][0-9]*)", spec)
    if drawn:
        return ("random", drawn[1], drawn[2], drawn[3])
    export = re.fullmatch(r"export:([a-z0-9-]+)", spec)
    return ("export", export[1]) if export else None


def model_path(spec: str, folder: Path) -> Path:
    """The .pomdp file both solvers read for ``spec``: the path itself, or the generated model written into
    ``folder`` (the name says what it is: ``rocksample-7-8.pomdp``, ``isr-m0.pomdp``)."""
    problem = generated_spec(spec)
    if problem is None:
        return Path(spec)
    if problem[0] == "rocksample":
        pomdp = rocksample(int(problem[1]), int(problem[2]), seed=0)
        return write_pomdp(pomdp, folder / f"rocksample-{problem[1]}-{problem[2]}.pomdp")
    if problem[0] == "random":
        pomdp = random_pomdp(*(int(count) for count in problem[1:]), seed=0)
        return write_pomdp(pomdp, folder / f"random-{'-'.join(problem[1:])}.pomdp")
    library = build_library(problem[1], n_models=1)
    return write_pomdp((library.native_pomdps or library.pomdps)[0], folder / f"{problem[1]}-m0.pomdp")


def _at(trace: list[tuple[float, float, float]], seconds: float) -> tuple[float, float] | None:
    """(lower, upper) of the last trace point at or before ``seconds``."""
    before = [point for point in trace if point[0] <= seconds]
    return (before[-1][1], before[-1][2]) if before else None


def sarsop_trace(
    path: Path, seconds: float
) -> tuple[list[tuple[float, float, float]], float, bool, float] | None:
    """Run ``pomdpsol`` for ``seconds``: its progress table (time, #trial, #backup, lb, ub, ...) parsed, its
    peak resident memory in MB (its ``VmHWM``, read every 20 ms while it runs: the rusage of its wait would carry
    this process's own peak over the fork and exec), whether it stopped at its target precision, and the unit of
    the last digit it printed of its final lower bound."""
    binary = shutil.which("pomdpsol")
    if binary is None:
        return None
    with tempfile.TemporaryDirectory() as folder:
        process = subprocess.Popen(
            [binary, str(path), "--timeout", f"{seconds:g}", "--output", str(Path(folder) / "out.policy")],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )
        peaks = [0.0]

        def watch() -> None:
            while process.poll() is None:
                peaks.append(peak_mb(process.pid) or peaks[-1])
                time.sleep(0.02)

        watcher = threading.Thread(target=watch, daemon=True)
        watcher.start()
        output = process.stdout.read()
        process.wait()
        watcher.join()
    trace, resolution = [], 0.0
    for line in output.splitlines():
        fields = line.split()
        if len(fields) >= 5 and all(re.fullmatch(r"-?[0-9.]+(e[-+]?[0-9]+)?", f) for f in fields[:5]):
            trace.append((float(fields[0]), float(fields[3]), float(fields[4])))
            resolution = printed_resolution(fields[3])
    # pomdpsol ends its run with the reason it stopped: its target precision (a certificate) or the timeout
    converged = "target precision reached" in output.lower()
    return trace, max(peaks), converged, resolution


def printed_resolution(number: str) -> float:
    """The last printed digit's unit of a decimal number as pomdpsol prints it (``13.3119``: 1e-4)."""
    mantissa, _, exponent = number.lower().partition("e")
    decimals = len(mantissa.partition(".")[2])
    return 10.0 ** (int(exponent or 0) - decimals)


def _measured_solve(path: Path, config, results) -> None:
    """In a fresh process: the solve's progress points, its saved vectors and the process' peak memory (MB);
    ``config`` is a PerseusConfig or an HsviConfig, which picks the solver."""
    points: list[tuple[float, float, float]] = []
    solve = hsvi if isinstance(config, HsviConfig) else perseus
    # As `pomdp solve` does: large arrays mapped on their own, and the reader's objects given back before solving.
    memory.return_freed_memory()
    pomdp = read_pomdp(path)
    memory.trim()
    policy = solve(pomdp, config, progress=lambda r: points.append((r.seconds, r.value_b0, r.upper_b0)))
    # VmHWM: the spawned interpreter's ru_maxrss would start at the launching process's peak
    results.put((points, len(policy.alphas), peak_mb(), bool(policy.stats.converged)))


def perseus_measured(path: Path, config) -> tuple[list[tuple[float, float, float]], int, float, bool]:
    """Progress points, saved vectors, peak resident memory (MB) and convergence (the gap at b0 within the
    solver's precision) of one solve, run in a spawned process so that the peak is that solve's alone (reading
    the file included, as the CLI does)."""
    context = multiprocessing.get_context("spawn")
    results = context.Queue()
    child = context.Process(target=_measured_solve, args=(path, config, results))
    child.start()
    measured = results.get()
    child.join()
    return measured


def _reached(trace: list[tuple[float, float, float]], value: float) -> float | None:
    """The first time a trace's lower bound is at or above ``value`` (None: never)."""
    return next((point[0] for point in trace if point[1] >= value), None)


def side_by_side_row(path: Path, args: Args, solver: str | None = None) -> dict:
    """One model: pomdpsol for the longest checkpoint, then this project's solve for the same CPU seconds (the
    CLI's choice of ``solver``, default --solver, and its defaults), their bounds at each checkpoint, the time
    each needs to SARSOP's final lower bound, and both peaks."""
    pomdp = read_pomdp(path)
    horizon = max(args.checkpoints)
    solver = solver or args.solver
    if solver == "auto":
        solver = auto_solver(
            pomdp.n_states, pomdp.n_observations, pomdp.discount, None, **solver_features(pomdp)
        )
    if solver == "hsvi":
        config = HsviConfig(time_limit=horizon, clock=args.clock)
    else:
        config = PerseusConfig(
            n_beliefs=1000, time_limit=horizon, seed=args.seed, expand=True, clock=args.clock
        )
    sarsop = sarsop_trace(path, horizon)
    points, vectors, peak, converged = perseus_measured(path, config)
    row = {
        "file": path.name,
        "states": pomdp.n_states,
        "actions": pomdp.n_actions,
        "observations": pomdp.n_observations,
        "solver": solver,
        "clock": args.clock,
        "seconds": horizon,
        "ours": {f"{t:g}": _at(points, t) for t in args.checkpoints},
        "ours_peak_mb": peak,
        "ours_vectors": vectors,
        "ours_converged": converged,
        # the last progress report is the one that closed the gap
        "ours_seconds_to_converge": points[-1][0] if converged and points else None,
    }
    if sarsop is not None:
        trace, sarsop_peak, sarsop_converged, resolution = sarsop
        target = trace[-1][1] if trace else math.nan
        # pomdpsol prints its bounds rounded: a lower bound within half its last digit of the printed one reached it
        ours_time = _reached(points, target - resolution / 2)
        row.update(
            sarsop={f"{t:g}": _at(trace, t) for t in args.checkpoints},
            sarsop_peak_mb=sarsop_peak,
            sarsop_final_lower=target,
            sarsop_seconds_to_final_lower=_reached(trace, target),
            ours_seconds_to_sarsop_lower=ours_time,
            time_ratio=None if ours_time is None else ours_time / horizon,
            memory_ratio=peak / sarsop_peak if sarsop_peak else None,
            sarsop_converged=sarsop_converged,
            sarsop_seconds_to_converge=trace[-1][0] if sarsop_converged and trace else None,
        )
    return row


def side_by_side_table(args: Args) -> None:
    """The table, a row per model as it finishes; with ``--json-out`` the rows so far are written after each one,
    so that a run stopped early keeps the models it finished."""
    to_stdout = args.json_out == "-"
    table = sys.stderr if to_stdout else sys.stdout
    binary = shutil.which("pomdpsol")
    source = "pomdpsol measured in this run" if binary else "pomdpsol not on the PATH"
    print(
        f"\n## Side by side: --solver {args.solver} vs SARSOP ({source}, {args.clock} seconds)\n", file=table
    )
    header = " | ".join(f"ours {t:g} s | SARSOP {t:g} s" for t in args.checkpoints)
    print(
        f"| file | S | Z | solver | {header} | our time to SARSOP's final lb (ratio to its budget) | "
        "converged ours / SARSOP (CPU s) | peak memory ours / SARSOP (ratio) |",
        file=table,
    )
    print("|---|---|---|---|" + "---|" * (2 * len(args.checkpoints) + 3), file=table)
    rows = []
    document = {
        "command": " ".join(sys.argv),
        "pomdpsol": binary,
        "models": list(args.side_by_side),
        "rows": rows,
    }
    with tempfile.TemporaryDirectory() as folder:
        for given in args.side_by_side:
            spec, solver = split_solver(given, args.solver)
            row = side_by_side_row(model_path(spec, Path(folder)), args, solver)
            row["model"] = given
            rows.append(row)
            print(side_by_side_line(row, args.checkpoints), file=table, flush=True)
            if args.json_out and not to_stdout:
                out = Path(args.json_out)
                out.parent.mkdir(parents=True, exist_ok=True)
                out.write_text(json.dumps(document, indent=1) + "\n")
    if to_stdout:
        print(json.dumps(document))


def peaks(row: dict) -> str:
    """Both peaks and their ratio; pomdpsol's is unknown when it ended before the first reading (20 ms)."""
    if not row.get("memory_ratio"):
        return f"{row['ours_peak_mb']:.0f} MB / - (pomdpsol ended before its memory was read)"
    return f"{row['ours_peak_mb']:.0f} / {row['sarsop_peak_mb']:.0f} MB ({row['memory_ratio']:.1f}x)"


def side_by_side_line(row: dict, checkpoints: tuple[float, ...]) -> str:
    """One model's row of the side-by-side table."""

    def cell(bounds) -> str:
        return "-" if bounds is None else f"{bounds[0]:.4f} / {bounds[1]:.4f}"

    def certificate(converged: bool, seconds: float | None) -> str:
        if not converged:
            return "no"
        return "yes" if seconds is None else f"yes ({seconds:.1f})"

    cells = []
    for t in checkpoints:
        cells.append(cell(row["ours"][f"{t:g}"]))
        cells.append(cell(row["sarsop"][f"{t:g}"]) if "sarsop" in row else "-")
    ours = certificate(row["ours_converged"], row["ours_seconds_to_converge"])
    if "sarsop" in row:
        reached = row["ours_seconds_to_sarsop_lower"]
        cells.append(
            f"never (target {row['sarsop_final_lower']:.4f})"
            if reached is None
            else f"{reached:.1f} s ({row['time_ratio']:.2f}x)"
        )
        cells.append(f"{ours} / {certificate(row['sarsop_converged'], row['sarsop_seconds_to_converge'])}")
        cells.append(peaks(row))
    else:
        cells += ["-", f"{ours} / -", f"{row['ours_peak_mb']:.0f} MB / -"]
    return (
        f"| {row['file']} | {row['states']} | {row['observations']} | {row['solver']} | "
        + " | ".join(cells)
        + " |"
    )


def anytime_row(name: str, args: Args) -> None:
    pomdp = read_pomdp(args.corpus / name)
    horizon = max(args.checkpoints)
    # SARSOP first, then Perseus, one after the other in the same run: same machine, same load (roughly).
    sarsop = sarsop_trace(args.corpus / name, horizon)
    measured, sarsop_peak = (None, None) if sarsop is None else sarsop
    # pomdpsol times itself in CPU seconds (clock()), so under load "20 s" of it is far more than 20 s of wall
    # clock; --clock cpu runs Perseus on its CPU clock too (the CLI's default), so both get the same CPU seconds.
    config = PerseusConfig(n_beliefs=1000, time_limit=horizon, seed=args.seed, expand=True, clock=args.clock)
    points, vectors, peak = perseus_measured(args.corpus / name, config)
    cells = []
    for seconds in args.checkpoints:
        ours = _at(points, seconds)
        cells.append("-" if ours is None else f"{ours[0]:.4f} / {ours[1]:.4f}")
        if measured is not None:
            theirs = _at(measured, seconds)
            cells.append("-" if theirs is None else f"{theirs[0]:.4f} / {theirs[1]:.4f}")
        elif name in SARSOP_TRACES:
            theirs = _at([(t, lb, math.nan) for t, lb in SARSOP_TRACES[name]], seconds)
            cells.append("-" if theirs is None else f"{theirs[0]:.4f} (recorded)")
        else:
            lb, _, sarsop_seconds = SARSOP.get(name, (math.nan, math.nan, math.nan))
            cells.append(f"{lb:g} at {sarsop_seconds:g} s (recorded)" if seconds == 20.0 else "-")
    cells.append(f"{peak:.0f} MB, {vectors:,} vectors")
    cells.append("-" if sarsop_peak is None else f"{sarsop_peak:.0f} MB")
    print(f"| {name} | {pomdp.n_states} | " + " | ".join(cells) + " |", flush=True)


def anytime_table(args: Args) -> None:
    source = (
        "measured in this run"
        if shutil.which("pomdpsol")
        else "recorded (../shared/pomdp/README.md, undated)"
    )
    print(
        f"\n## Time to value: lower / upper bound at b0, Perseus (CLI defaults) vs SARSOP ({source}, "
        f"{args.clock} seconds)\n"
    )
    header = " | ".join(f"Perseus {t:g} s | SARSOP {t:g} s" for t in args.checkpoints)
    print(f"| file | S | {header} | Perseus peak memory, saved vectors | SARSOP peak memory |")
    print("|---|---|" + "---|" * (2 * len(args.checkpoints) + 2))
    for name in args.problems:
        anytime_row(name, args)


def main() -> None:
    args = parse_args()
    if args.side_by_side:
        side_by_side_table(args)
        return
    if args.only_anytime:
        anytime_table(args)
        return
    print("## Backup speed: vectorised vs naive reference (ms per belief, same run)\n")
    print("| problem | S | vectors | naive ms | vectorised ms | speed-up |")
    print("|---|---|---|---|---|---|")
    for name in ("hallway.POMDP", "sarsop-TagAvoid.pomdp"):
        if name in args.problems:
            backup_speed_table(read_pomdp(args.corpus / name), name, args)
    generated = generated_pursuit_size_pomdp(args.seed)
    backup_speed_table(generated, "generated 626x5x81", args)

    print(f"\n## Corpus: Perseus ({args.beliefs} beliefs, limit {args.time_limit:g} s) vs SARSOP\n")
    print(
        "| file | S | Perseus V(b0) | SARSOP lb | SARSOP ub | in [lb, ub] | s to reach lb | SARSOP s | "
        "Perseus s | iterations | vectors |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.problems:
        corpus_row(name, args)

    if not args.skip_generated:
        print(
            f"\n## Generated 626-state, 5-action, 81-observation sparse POMDP, {args.generated_beliefs} beliefs\n"
        )
        print(
            "| stop rule | stages | beliefs | tolerance | converged on B | seconds | vs classic | iterations "
            "| vectors | "
            "V(b0) | residual | thesis |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|---|---|")
        # Both stop rules at the thesis's tolerance: the classic Perseus rule ("gain") and our stricter "bound"; each
        # with the classic stage (the reference) and the default Gauss-Seidel stage.
        for stop in ("gain", "bound"):
            reference = None
            for update in ("perseus", "gauss-seidel"):
                config = PerseusConfig(
                    n_beliefs=args.generated_beliefs,
                    time_limit=args.generated_time_limit,
                    tolerance=args.generated_tolerance,
                    stop=stop,
                    seed=args.seed,
                    update=update,
                )
                policy = perseus(generated, config)
                stats = policy.stats
                reference = stats.seconds if reference is None else reference
                print(
                    f"| {stop} | {update} | {stats.n_beliefs} | {args.generated_tolerance:g} | "
                    f"{stats.converged_on_beliefs} | {stats.seconds:.1f} | {stats.seconds / reference:.2f}x | "
                    f"{stats.iterations} | {policy.n_vectors} | {policy.value(generated.initial_belief):.4f} | "
                    f"{stats.residual:.2e} | 2.5 h |",
                    flush=True,
                )
    anytime_table(args)


if __name__ == "__main__":
    main()
