"""The library-free agents (ppo-generalist, liam, meliba) against the benchmark's held-out teammates, beside the
library-based agents, and the score-vs-number-of-training-teammates curve; writes results/library-free.json and
renders its tables into docs/library_free.md (between the ``<!-- library-free start/end -->`` markers) and the
curve to docs/library_free_curve.png. The block also renders the grid arenas' train/held-out tables of
``scripts/generalist_heldout.py`` (results/library_free/<grid>-heldout/results.json) and the throughput tables of
``scripts/library_free_speed.py``, from their own result files.

    .venv/bin/python scripts/library_free_bench.py [--episodes 32] [--seed 0] [--out runs/library-free]
    .venv/bin/python scripts/library_free_bench.py --render-only
    OPENBLAS_CORETYPE=Sandybridge ATEN_CPU_CAPABILITY=default XDG_CACHE_HOME=DIR \
        .venv/bin/python scripts/library_free_bench.py --check toxic-waste,pursuit-task,ntu,curve

Every agent runs through ``embodied_adhoc.bench.evaluate`` (the ``evaluate`` command's function) on the same
suite, episodes and seed as ``scripts/bench_heldout.py``, whose result file (results/benchmark-heldout.json) gives
the library-based agents' scores: the same episodes and the same member bounds, so the normalised scores sit side
by side. The shipped agents are the plug-ins ``embodied_adhoc.learning.<kind>:plugin``; the curve's agents are
ppo-generalist on the lab trained with the first 1, 2 and 4 train members (``train ppo-generalist --teammates N``,
the folders of ``--curve-runs``) and the shipped one with all 6, each at the shipped agents' env steps.

``--check PART,...`` runs those parts (domains, or ``curve``) again in this process's environment (another BLAS
kernel: ``OPENBLAS_CORETYPE`` for numpy's OpenBLAS and ``ATEN_CPU_CAPABILITY`` for the networks' torch, with a
policy cache of that kernel's own: ``XDG_CACHE_HOME`` pointing at a fresh folder) and keeps the run in the file's
``kernel_checks``, beside the published run it never replaces, compared with ``scripts/bench_heldout.py``'s rule:
every agent's IQM and mean inside the published 95 % interval, on the same episodes, seed and members.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))  # bench_heldout's check comparison and render_results' pages
RESULT = ROOT / "results" / "library-free.json"
PLOT = ROOT / "docs" / "library_free_curve.png"
SPEED = ROOT / "results" / "library-free-speed.json"
BATCHES = ROOT / "results" / "library_free" / "collection-batches.json"
DOMAINS = ("toxic-waste", "pursuit-task", "ntu")
GRID_HELDOUT = {grid: ROOT / "results" / "library_free" / f"{grid}-heldout" / "results.json" for grid in (
    "foraging", "pursuit")}  # fmt: skip
GRID_NAMES = {"foraging": "level-based foraging", "pursuit": "predator-prey (the pursuit grid)"}
KINDS = {"ppo-generalist": "generalist", "liam": "liam", "meliba": "meliba"}
PLUGINS = {kind: f"embodied_adhoc.learning.{module}:plugin" for kind, module in (
    ("ppo-generalist", "generalist"), ("liam", "liam"), ("meliba", "meliba"))}  # fmt: skip
SEED_RUNS = "results/library_free/seeds"
"""Folders ``<domain>-seed-<n>`` of further ppo-generalist training seeds (the shipped agent's command with
``--seed n``), scored beside the shipped one and pooled with it."""
CURVE_DOMAIN = "toxic-waste"
CURVE_COUNTS = (1, 2, 4)  # and the shipped agent's, all of the train split
PARTS = (*DOMAINS, "curve")
TORCH_KERNEL = ("ATEN_CPU_CAPABILITY", "MKL_ENABLE_INSTRUCTIONS")
"""The variables that choose torch's CPU kernels, named in a check's command where set."""
PLUGIN_FILE = """from embodied_adhoc.learning.index_domains import index_agent


def make(library, rng_seed=0):
    return index_agent(library, "ppo-generalist", {weights!r}, name="ppo-generalist-{count}")
"""


def parse() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=32)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="runs/library-free", help="evaluate's trial folders (resumable)")
    parser.add_argument(
        "--curve-runs", default="results/library_free/curve", help="folders teammates-N of the curve's runs"
    )
    parser.add_argument(
        "--seed-runs",
        default=SEED_RUNS,
        help="folders <domain>-seed-N of further ppo-generalist training seeds",
    )
    parser.add_argument("--render-only", action="store_true")
    parser.add_argument(
        "--weights",
        help="score this ppo-generalist weights file on --domain's held-out suite, print its IQM as JSON and "
        "write nothing else (a run of your own beside the shipped agents)",
    )
    parser.add_argument("--domain", choices=DOMAINS, default="pursuit-task", help="the domain of --weights")
    parser.add_argument(
        "--only",
        choices=PARTS,
        help="run one part's trials and write nothing (parts run side by side; a full run then resumes them)",
    )
    parser.add_argument(
        "--check",
        default="",
        help="comma-separated parts (" + ", ".join(PARTS) + ") to run again as a second kernel's check "
        "(kept in the file's kernel_checks, compared with the published intervals)",
    )
    args = parser.parse_args()
    if args.episodes < 2:
        parser.error(f"--episodes {args.episodes}: at least 2 (the intervals resample episodes)")
    args.check = tuple(part for part in args.check.split(",") if part)
    unknown = [part for part in args.check if part not in PARTS]
    if unknown:
        parser.error(f"--check {','.join(unknown)}: no such part; give some of {','.join(PARTS)}")
    return args


def _provenance() -> dict:
    import numpy
    import torch

    from embodied_adhoc.experiments.identity import blas_kernel

    commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout
    return {
        "command": " ".join([".venv/bin/python", "scripts/library_free_bench.py", *sys.argv[1:]]),
        "commit": commit.strip(),
        "kernel": blas_kernel(),
        # the networks' kernels are torch's own (its vectorised ops and MKL), which OPENBLAS_CORETYPE leaves as is
        "torch_cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "python": platform.python_version(),
        "versions": {"numpy": numpy.__version__, "torch": torch.__version__},
    }


def _aggregate(summary: dict, domain: str) -> dict:
    part = summary["domains"][domain]
    return {agent: part["aggregate"][agent] for agent in part["agents"]}


def _suite(summary: dict, domain: str) -> dict:
    """The suite version and members (name and parameters) a run scored against: what a check must share."""
    rows = summary["domains"][domain]["teammates"]
    return {"version": summary["version"], "members": [[row["name"], row.get("params")] for row in rows]}


def _training(folder: Path) -> dict:
    report = json.loads((folder / "training.json").read_text())
    return {"env_steps": report["env_steps"], "train_seconds": report["train_seconds"]}


def _weights_agent(out: Path, stem: str, weights: Path, label) -> str:
    """The plug-in spec of a plug-in file ``OUT/STEM.py`` that runs the ppo-generalist ``weights`` as
    ``ppo-generalist-LABEL``."""
    plugin = out / f"{stem}.py"
    plugin.parent.mkdir(parents=True, exist_ok=True)
    plugin.write_text(PLUGIN_FILE.format(weights=str(weights.resolve()), count=label))
    return f"{plugin}:make"


def _seeds(args, domain: str, out: Path, shipped: dict, shipped_scores) -> dict | None:
    """The shipped ppo-generalist beside its further training seeds (``--seed-runs``) on ``domain``, and the
    seeds pooled: every seed's episodes per member, one stratified bootstrap."""
    import numpy as np

    from embodied_adhoc.bench.evaluate import evaluate, resolve_suite
    from embodied_adhoc.bench.scores import BENCH_REPS, aggregate

    folders = sorted(
        Path(args.seed_runs).glob(f"{domain}-seed-*"), key=lambda f: int(f.name.rsplit("-", 1)[1])
    )
    if not folders:
        return None
    folder = ROOT / "assets" / "generalist" / domain
    seed = json.loads((folder / "training.json").read_text())["settings"]["seed"]
    runs = [{"seed": seed, **shipped, **_training(folder)}]
    matrices = [shipped_scores]
    for folder in folders:
        n = int(folder.name.rsplit("-", 1)[1])
        spec = _weights_agent(
            out, f"seed_agent_{n}", folder / f"{domain}-ppo-generalist.safetensors", f"seed-{n}"
        )
        scores: dict = {}
        summary = evaluate(
            (spec,), resolve_suite("heldout", (domain,)), out / f"{domain}-seed-{n}",
            episodes=args.episodes, seed=args.seed, progress=True, plots=False, scores=scores,
        )  # fmt: skip
        used = json.loads((folder / "training.json").read_text())["settings"]["seed"]
        runs.append({"seed": used, **_aggregate(summary, domain)[spec], **_training(folder)})
        matrices.append(scores[domain][spec])
    return {
        "agent": "ppo-generalist",
        "runs": runs,
        "pooled": aggregate(np.concatenate(matrices, axis=0), BENCH_REPS),
        "pooling": "every seed's episodes per held-out member in one (episodes x members) matrix; IQM with its "
        "stratified percentile bootstrap over members (bench.scores.aggregate)",
    }


def run(args: argparse.Namespace, parts=PARTS, out: Path | None = None) -> dict:
    """The result file's fields for ``parts`` (domains and the curve), their trials under ``out`` (resumable)."""
    from embodied_adhoc.bench.evaluate import evaluate, resolve_suite
    from embodied_adhoc.learning.index_domains import member_names

    started = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    provenance = _provenance()
    out = Path(args.out) if out is None else out
    side: dict = {}
    for domain in (d for d in DOMAINS if d in parts):
        clock = time.perf_counter()
        matrices: dict = {}
        summary = evaluate(
            tuple(PLUGINS.values()), resolve_suite("heldout", (domain,)), out / domain,
            episodes=args.episodes, seed=args.seed, progress=True, plots=False, scores=matrices,
        )  # fmt: skip
        scores = _aggregate(summary, domain)
        side[domain] = {
            **_suite(summary, domain),
            "agents": {kind: scores[PLUGINS[kind]] for kind in KINDS},
            "training": {
                kind: _training(ROOT / "assets" / folder / domain) for kind, folder in KINDS.items()
            },
        }
        generalist = PLUGINS["ppo-generalist"]
        seeds = _seeds(args, domain, out, scores[generalist], matrices[domain][generalist])
        if seeds is not None:
            side[domain]["seeds"] = seeds
        side[domain]["wall_s"] = round(time.perf_counter() - clock, 1)
    curve: list = []
    suite: dict = {}
    clock = time.perf_counter()
    for count in CURVE_COUNTS if "curve" in parts else ():
        folder = Path(args.curve_runs) / f"teammates-{count}"
        weights = folder / f"{CURVE_DOMAIN}-ppo-generalist.safetensors"
        spec = _weights_agent(out, f"curve_agent_{count}", weights, count)
        summary = evaluate(
            (spec,), resolve_suite("heldout", (CURVE_DOMAIN,)), out / f"curve-{count}",
            episodes=args.episodes, seed=args.seed, progress=True, plots=False,
        )  # fmt: skip
        curve.append({"teammates": count, **_aggregate(summary, CURVE_DOMAIN)[spec], **_training(folder)})
        suite = _suite(summary, CURVE_DOMAIN)
    if curve:
        suite["wall_s"] = round(time.perf_counter() - clock, 1)
    if CURVE_DOMAIN in side:  # the shipped agent, trained with every train member, is the curve's last point
        folder = ROOT / "assets" / "generalist" / CURVE_DOMAIN
        used = json.loads((folder / "training.json").read_text())["settings"]["teammates"]
        whole = side[CURVE_DOMAIN]["agents"]["ppo-generalist"]
        curve.append({"teammates": len(member_names(CURVE_DOMAIN, used)), **whole, **_training(folder)})
    return {
        "figure": "library-free",
        **provenance,
        "started": started,
        "finished": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "suite": "heldout",
        "episodes": args.episodes,
        "seed": args.seed,
        "domains": side,
        "curve": {"domain": CURVE_DOMAIN, "agent": "ppo-generalist", **suite, "points": curve},
    }


def _part(result: dict, part: str) -> dict:
    """A part's scored agents (name: IQM and mean with intervals) and the suite it ran on; the curve's agents are
    its trained-with-N runs (its last point is the shipped agent, the lab part's), a domain's are the shipped agents
    and the further training seeds."""
    if part == "curve":
        scope = result["curve"]
        scores = {
            f"{scope['agent']}-{point['teammates']}": point
            for point in scope["points"]
            if point["teammates"] in CURVE_COUNTS
        }
    else:
        scope = result["domains"][part]
        seeds = scope.get("seeds", {"runs": []})
        further = {f"{seeds['agent']}-seed-{entry['seed']}": entry for entry in seeds["runs"][1:]}
        scores = scope["agents"] | further
    keys = ("iqm", "iqm_ci", "mean", "mean_ci")
    return {
        "version": scope.get("version"),
        "members": scope.get("members", []),
        "wall_s": scope.get("wall_s"),
        "aggregate": {agent: {key: entry[key] for key in keys} for agent, entry in scores.items()},
    }


def kernel_prefix(kernel: str) -> str:
    """The environment a check's command names: the OpenBLAS kernel threadpoolctl reports, and torch's kernel
    variables where set."""
    torch = (f"{name}={os.environ[name]}" for name in TORCH_KERNEL if name in os.environ)
    return " ".join([f"OPENBLAS_CORETYPE={kernel}", *torch])


def run_check(args: argparse.Namespace) -> dict:
    """``args.check``'s parts run again (resumable under ``--out``/check-<kernels>): the file's ``kernel_checks``
    entries for them, in the shape ``bench_heldout.compare_check`` reads."""
    from embodied_adhoc.experiments.identity import blas_kernel

    kernel = blas_kernel().split(":")[-1]
    clock = time.process_time()
    provenance = _provenance()
    fresh = run(args, args.check, Path(args.out) / f"check-{kernel}-{provenance['torch_cpu_capability']}")
    cpu = round(time.process_time() - clock, 1)
    checks = {}
    for name in args.check:
        part = _part(fresh, name)
        checks[name] = {
            "kernel": fresh["kernel"],
            "torch_cpu_capability": fresh["torch_cpu_capability"],
            "commit": fresh["commit"],
            "command": f"{kernel_prefix(kernel)} {fresh['command']}",
            "wall_s": part["wall_s"],
            "cpu_s_all_checked_parts": cpu,
            "episodes": fresh["episodes"],
            "seed": fresh["seed"],
            "version": part["version"],
            "members": part["members"],
            "aggregate": {
                agent: {key: values[key] for key in ("iqm", "mean")}
                for agent, values in part["aggregate"].items()
            },
        }
    return checks


def merge(previous: dict, fresh: dict | None = None, checks: dict | None = None) -> dict:
    """The result file: ``fresh``'s run (or else ``previous``'s) as the published one, with the second-kernel
    checks of both files (``checks`` replacing a part's earlier one), each compared with the published run."""
    from bench_heldout import compare_check

    published = fresh or previous
    kept = previous.get("kernel_checks", {}) | (checks or {})
    kernel_checks = {}
    for name, check in kept.items():
        part = _part(published, name)
        view = {
            "episodes": published["episodes"],
            "seed": published["seed"],
            "kernel": published["kernel"],
            "version": part["version"],
            "teammates": [{"name": member, "params": params} for member, params in part["members"]],
            "aggregate": part["aggregate"],
        }
        entry = {key: value for key, value in check.items() if key != "comparison"}
        kernel_checks[name] = entry | {"comparison": compare_check(entry, view)}
    return published | ({"kernel_checks": kernel_checks} if kernel_checks else {})


def _interval(entry: dict) -> str:
    low, high = entry["iqm_ci"]
    return f"{entry['iqm']:.2f} [{low:.2f}, {high:.2f}]"


def table(result: dict) -> str:
    """The markdown between the page's markers: held-out IQM per agent and domain, then the curve."""
    from embodied_adhoc.experiments.registry import get_trial_domain

    library = json.loads((ROOT / "results" / "benchmark-heldout.json").read_text())["suites"]["heldout"]
    lines = [
        f"Held-out suite, {result['episodes']} episodes per teammate, seed {result['seed']}; normalised IQM with "
        "95 % stratified-bootstrap interval (0: the random ego, 1: the exact best response). Library-free rows: "
        f"this file's run (`{result['command']}`, commit {result['commit'][:7]}, {result['kernel']}); "
        "library-based rows: results/benchmark-heldout.json (same suite, episodes and seed). Statistical "
        f"({_seed_count(result)}, one evaluation run).",
        "",
        "| domain | agent | family | held-out IQM [95 % CI] | training env steps | training loop s (wall) |",
        "|---|---|---|---|---|---|",
    ]
    for domain, part in result["domains"].items():
        for kind, entry in part["agents"].items():
            cost = part["training"][kind]
            lines.append(
                f"| {domain} | {kind} | library-free | {_interval(entry)} | {cost['env_steps']:,} | "
                f"{cost['train_seconds']:.0f} |"
            )
        others = library.get(domain, {}).get("aggregate", {})
        privileged = set(getattr(get_trial_domain(domain), "privileged_agents", ()))
        for agent, entry in others.items():
            family = "library-based, sees the state" if agent in privileged else "library-based"
            lines.append(f"| {domain} | {agent} | {family} | {_interval(entry)} | - | - |")
    for domain, part in result["domains"].items():
        if "seeds" in part:
            lines += ["", *seed_table(domain, part["seeds"])]
    curve = result["curve"]
    lines += [
        "",
        f"Score against the number of distinct training teammates ({curve['agent']}, {curve['domain']}, the "
        "first N members of the train split, equal env steps):",
        "",
        "| training teammates | held-out IQM [95 % CI] | env steps |",
        "|---|---|---|",
    ]
    for point in curve["points"]:
        lines.append(f"| {point['teammates']} | {_interval(point)} | {point['env_steps']:,} |")
    if result.get("kernel_checks"):
        from bench_heldout import kernel_check_lines

        lines += kernel_check_lines(result["kernel_checks"])
    for grid, path in GRID_HELDOUT.items():
        if path.is_file():
            lines += ["", *grid_table(grid, json.loads(path.read_text()))]
    if SPEED.is_file():
        lines += ["", *speed_table(json.loads(SPEED.read_text()))]
    if BATCHES.is_file():
        lines += ["", *batch_table(json.loads(BATCHES.read_text()))]
    return "\n".join(lines)


def _seed_count(result: dict) -> str:
    more = [
        f"{len(part['seeds']['runs'])} for {part['seeds']['agent']} on {domain}"
        for domain, part in result["domains"].items()
        if "seeds" in part
    ]
    return "one training seed per agent" + (f" ({'; '.join(more)})" if more else "")


def seed_table(domain: str, seeds: dict) -> list[str]:
    """The shipped agent's training seed beside the further ones, and the seeds pooled."""
    lines = [
        f"Training seeds ({seeds['agent']}, {domain}, the shipped agent's command with `--seed N`; further seeds' "
        f"weights in `{SEED_RUNS}/`): held-out IQM per seed and pooled ({seeds['pooling']}).",
        "",
        "| training seed | held-out IQM [95 % CI] | training env steps | training loop s (wall) |",
        "|---|---|---|---|",
    ]
    for entry in seeds["runs"]:
        lines.append(
            f"| {entry['seed']} | {_interval(entry)} | {entry['env_steps']:,} | {entry['train_seconds']:.0f} |"
        )
    runs = seeds["runs"]
    steps = sum(entry["env_steps"] for entry in runs)
    lines.append(f"| pooled ({len(runs)} seeds) | {_interval(seeds['pooled'])} | {steps:,} in all | - |")
    return lines


def grid_table(grid: str, record: dict) -> list[str]:
    """``scripts/generalist_heldout.py``'s run on a grid arena: per team of the ATLPO split (train, then held-out),
    each agent's normalised IQM, and each library-free agent's training budget."""
    settings, training = record["settings"], record["training"]
    agents = (*training, "atlpo-mf", "known-task")
    budgets = "; ".join(
        f"{agent} {cost['env_steps']:,} env steps ({cost['train_seconds']:.0f} s)"
        for agent, cost in training.items()
    )
    lines = [
        f"{GRID_NAMES[grid]}, teams of the ATLPO split (`{record['command']}`, "
        f"`results/library_free/{grid}-heldout/`): normalised score (0: random, 1: the original teammate), IQM "
        f"with 95 % percentile-bootstrap interval over {settings['episodes']} episodes per team (tasks cycling "
        f"1..4, cap {settings['max_steps']}, seed {settings['seed']}); training budgets: {budgets}; atlpo-mf and "
        "known-task are the library-based agents.",
        "",
        "| split | team | " + " | ".join(agents) + " |",
        "|---|---|" + "---|" * len(agents),
    ]
    for split, teams in record["scores"].items():
        for team, row in teams.items():
            cells = (f"{row[a]['iqm']:.2f} [{row[a]['ci'][0]:.2f}, {row[a]['ci'][1]:.2f}]" for a in agents)
            lines.append(f"| {split} | {team} | " + " | ".join(cells) + " |")
    return lines


def speed_table(speed: dict) -> list[str]:
    """The throughput table of ``scripts/library_free_speed.py --json`` (results/library-free-speed.json)."""
    reference = speed["reference"]
    lines = [
        f"Training throughput (`{speed['command']}`, {speed['kernel']}; machine- and load-dependent, one run): "
        f"env steps per second, and the ratio to {speed['reference_agent']} on {speed['reference_domain']} in "
        "the same run.",
        "",
        "| agent | domain | end to end (steps/s) | x reference | collection alone (steps/s) | x reference |",
        "|---|---|---|---|---|---|",
    ]
    for row in speed["rows"]:
        lines.append(
            f"| {row['agent']} | {row['domain']} | {row['train_steps_per_s']:.0f} | "
            f"{row['train_steps_per_s'] / reference['train_steps_per_s']:.2f} | "
            f"{row['collect_steps_per_s']:.0f} | "
            f"{row['collect_steps_per_s'] / reference['collect_steps_per_s']:.2f} |"
        )
    return lines


def batch_table(speed: dict) -> list[str]:
    """The foraging collection sweep of ``scripts/library_free_speed.py --batches`` (per CPU second)."""
    first = speed["batches"][0]
    lines = [
        f"Collection on the foraging grid against the number of sub-envs (`{speed['command']}`, "
        f"{speed['kernel']}, one run on a 2-core host; class: timing, the ratios within the run carry over, the "
        "rates depend on the host and its load, which the result file records): env steps per CPU "
        "second of the vector env under random actions, and of the training loop's rollout (the shipped "
        "ppo-generalist's action draw, then the vector env's step), each with its ratio to the first row.",
        "",
        "| sub-envs | vector env, random actions (steps/CPU s) | x first | rollout with the policy (steps/CPU s) "
        "| x first | env's share of the rollout |",
        "|---|---|---|---|---|---|",
    ]
    for row in speed["batches"]:
        lines.append(
            f"| {row['envs']} | {row['random_env_steps_per_cpu_s']:,.0f} | "
            f"{row['random_env_steps_per_cpu_s'] / first['random_env_steps_per_cpu_s']:.2f} | "
            f"{row['rollout_steps_per_cpu_s']:,.0f} | "
            f"{row['rollout_steps_per_cpu_s'] / first['rollout_steps_per_cpu_s']:.2f} | "
            f"{row['rollout_env_share']:.2f} |"
        )
    if all("pipelined_steps_per_s" in row for row in speed["batches"]):
        lines += [
            "",
            "The same rollout per wall second, as `train` runs it (`rollout_pipeline.rollout_steps`), over one "
            "vector env and with `--pipeline` (the sub-envs in two halves, one half's policy on a second thread "
            "while the other half's env steps), with their ratio and whether the two chose the same actions "
            "from the same seeds:",
            "",
            "| sub-envs | rollout (steps/s) | pipelined (steps/s) | x rollout | same actions |",
            "|---|---|---|---|---|",
        ]
        for row in speed["batches"]:
            lines.append(
                f"| {row['envs']} | {row['rollout_steps_per_s']:,.0f} | {row['pipelined_steps_per_s']:,.0f} | "
                f"{row['pipelined_steps_per_s'] / row['rollout_steps_per_s']:.2f} | "
                f"{'yes' if row['pipelined_same_actions'] else 'no'} |"
            )
    return lines


def plot(result: dict) -> None:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    points = result["curve"]["points"]
    counts = [p["teammates"] for p in points]
    iqm = [p["iqm"] for p in points]
    low = [p["iqm"] - p["iqm_ci"][0] for p in points]
    high = [p["iqm_ci"][1] - p["iqm"] for p in points]
    figure, axis = plt.subplots(figsize=(5, 3.2))
    axis.errorbar(counts, iqm, yerr=[low, high], marker="o", capsize=4)
    axis.set_xscale("log", base=2)
    axis.set_xticks(counts, [str(c) for c in counts])
    axis.set_xlabel("distinct training teammates (train split)")
    axis.set_ylabel("held-out normalised IQM")
    axis.set_title(f"{result['curve']['agent']} on {result['curve']['domain']}")
    axis.grid(alpha=0.3)
    figure.savefig(PLOT, dpi=110, bbox_inches="tight")
    plt.close(figure)


def render() -> None:
    """Every generated page, this script's block among them, so the block, its class line, the results index and
    the README's headline change together (``render_results.py`` renders the block with this script's ``table``)."""
    import render_results

    render_results.render()


def score_weights(args: argparse.Namespace) -> dict:
    """The held-out IQM of the ppo-generalist weights ``args.weights`` on ``args.domain`` (the bench's episodes,
    seed and plug-in file)."""
    from embodied_adhoc.bench.evaluate import evaluate, resolve_suite

    weights = Path(args.weights).resolve()
    if not weights.is_file():
        raise SystemExit(f"--weights {args.weights}: no such file; give a ppo-generalist .safetensors")
    out = Path(args.out) / f"weights-{weights.stem}"
    spec = _weights_agent(out, "agent", weights, weights.stem)
    summary = evaluate(
        (spec,), resolve_suite("heldout", (args.domain,)), out / "eval",
        episodes=args.episodes, seed=args.seed, progress=False, plots=False,
    )  # fmt: skip
    return _aggregate(summary, args.domain)[spec]


def main() -> int:
    args = parse()
    if args.weights:
        print(json.dumps(score_weights(args)))
        return 0
    if args.only:
        run(args, (args.only,))
        return 0
    if not args.render_only:
        from embodied_adhoc.atomic import atomic_write_text

        checks = run_check(args) if args.check else None
        fresh = None if args.check else run(args)
        previous = json.loads(RESULT.read_text()) if RESULT.is_file() else {}  # read now: runs may overlap
        atomic_write_text(RESULT, json.dumps(merge(previous, fresh, checks), indent=1) + "\n")
    result = json.loads(RESULT.read_text())
    render()
    plot(result)
    print(table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
