"""Published tables generated from result files, each saying how it reproduces.

Every table of the README and docs/ that this script knows (``FIGURES``) is produced in two steps:

1. ``run NAME`` executes the figure's commands (a ``trials``/``pomdp`` CLI call or a
   ``scripts/reproduce_*.py`` / ``scripts/bench_*.py`` script), one at a time, and writes
   ``results/NAME.json``: the numbers plus their provenance (the git commit it ran, from a copy of that
   commit's code, the exact commands, the OpenBLAS kernel that threadpoolctl reports in the same environment,
   numpy/scipy/mujoco/torch versions, the date). ``run NAME --kernel Haswell`` runs the same commands under
   ``OPENBLAS_CORETYPE=Haswell`` and adds that run to the file as a check of the published one. For a figure
   whose script prints Markdown tables, ``run NAME --extra '--domains isr'`` re-makes some rows only: they replace
   the published ones and the run is kept beside the published one as the part that made them (a check with the
   same ``--extra`` runs that part's code);
2. ``render`` writes one ``docs/results/`` page per figure (``NAME.md`` plus ``docs/results/index.md``) and
   replaces, in README.md and docs/**/*.md, whatever lies between ``<!-- results:NAME start -->`` and
   ``<!-- results:NAME end -->`` (``NAME`` alone: every table of the figure; ``NAME.KEY``: one of them).

Each table states its class, derived from the runs in its result file, never typed:

* *exact on any host*: a second kernel's run gives the same numbers (the data compare equal byte for byte);
* *statistical*: the numbers differ between kernels, and the figure's own check passes (each second-kernel
  mean lies inside the published 95 % interval, every thesis claim keeps its verdict; for a solver value the
  second kernel's lower bound lies in the published [lower, upper] bracket);
* *timing*: seconds and ratios of seconds, which depend on the host and its load; recorded, never compared;
* *not re-checked*: only one kernel has run it;
* "... (the part checked)": every check ran some of the commands or rows only, and the class holds for those.

Tables that no run of this script made are marked the same way: ``RECORDED`` ones are generated from a result
file that its own script wrote (an asset, or a file whose run needs what a frozen copy of the commit lacks, e.g. a
solver binary on the PATH; class *not re-run*, with the provenance the file holds), and ``UNRUN`` ones render as a
block that names the command, what a run costs and the class the table will have, and prints no number.

``--check`` renders in memory and exits 1 when a committed page differs from what the committed result files
render, naming the page, the table and the command to re-run (fast: nothing is solved or simulated)::

    .venv/bin/python scripts/render_results.py run arenas [--kernel Haswell]
    .venv/bin/python scripts/render_results.py render
    .venv/bin/python scripts/render_results.py --check
"""

from __future__ import annotations

import argparse
import ast
import datetime as dt
import hashlib
import importlib.util
import itertools
import json
import math
import os
import re
import shlex
import shutil
import subprocess
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results"
PAGES = ROOT / "docs" / "results"
SCRIPT = "scripts/render_results.py"
RUN_DIR = "runs/render-results"
"""The frozen copies of the code that figures run from, each with its runs' ``--out`` folders (cleared before
a run, so that a run never resumes an older one)."""
CACHE_DIR = "runs/render-results/cache"
"""Policy cache per kernel (``XDG_CACHE_HOME``): one kernel's solved policies never serve another's run."""
MARKER = re.compile(r"^<!-- results:(?P<name>[A-Za-z0-9_-]+(?:\.[A-Za-z0-9_-]+)?) (?P<edge>start|end) -->$")
STATISTICAL, TIMING = "statistical", "timing"
VERDICTS = ("holds", "significant", ">= 80 %", "> 70 %")
"""Columns whose cells are a claim's verdict: a second kernel's run must keep them."""
PROBE = (
    "import json, importlib.metadata as m, threadpoolctl\n"
    "import numpy, embodied_adhoc\n"
    "info = [i for i in threadpoolctl.threadpool_info() if i.get('internal_api') == 'openblas']\n"
    "versions = {}\n"
    "for name in ('numpy', 'scipy', 'mujoco', 'torch'):\n"
    "    try:\n"
    "        versions[name] = m.version(name)\n"
    "    except m.PackageNotFoundError:\n"
    "        pass\n"
    "print(json.dumps({'kernel': info[0].get('architecture') if info else None, 'versions': versions,\n"
    "                  'package': embodied_adhoc.__file__}))\n"
)
"""What a run records about its numerical environment, probed in a process with the run's own environment."""
NUMBER = r"-?\d+(?:\.\d+)?(?:e[-+]?\d+)?"
MEAN_CELL = re.compile(rf"^\**(?P<mean>{NUMBER})(?: ± {NUMBER})?")
CI_CELL = re.compile(rf"^\[(?P<low>{NUMBER}), (?P<high>{NUMBER})\]$")


@dataclass(frozen=True)
class Table:
    key: str
    caption: str
    headers: list[str]
    rows: list[list[str]]

    def markdown(self) -> str:
        lines = ["| " + " | ".join(self.headers) + " |", "|" + "|".join("---" for _ in self.headers) + "|"]
        return "\n".join(lines + ["| " + " | ".join(row) + " |" for row in self.rows])


@dataclass(frozen=True)
class Figure:
    """One published figure: the commands that produce it and how its output becomes tables."""

    name: str
    title: str
    commands: dict[str, list[str]]
    """key -> argv, run in the root of a copy of the committed code; ``{python}``: the venv's python;
    ``{out}``: a fresh run folder"""
    extract: Callable[[dict[str, str]], dict]
    """stdout per command -> the result data (JSON); timings go under the data's ``"timing"`` key"""
    tables: Callable[[dict], list[Table]]
    compare: Callable[[dict, dict], list[str]] | None
    """published data, check data -> the check's failures (None: a timing figure, never compared)"""
    pages: tuple[str, ...] = ()
    """pages that embed the figure between markers (for the reader; the renderer finds the markers itself)"""
    notes: str = ""
    checked: str = "every second-kernel mean lies inside the published 95 % interval and keeps every verdict"
    """what ``compare`` holds a second kernel's run to, in the words the class statement uses"""
    torch: bool = False
    """whether its commands use torch (its version is recorded then)"""
    partial_checks: bool = False
    """whether a check may run some commands only (the data holds one entry per command under ``"runs"``)"""
    markdown: bool = False
    """whether its one command prints Markdown tables (a check may then add arguments and print fewer rows)"""
    timing_tables: tuple[str, ...] = ()
    """keys of its tables that print seconds or rates (class *timing*, never compared; kept under ``"timing"``)"""
    files: tuple[str, ...] = ()
    """files outside ``CODE`` that its commands run (a test module): copied from the run's commit into each command's
    ``{out}`` folder, their blob hashes recorded with the run"""
    prose: Callable[[dict], dict[str, tuple[str | None, str]]] | None = None
    """the data -> sentences that pages embed beside the tables (``results:NAME.KEY`` blocks), each with the key
    of the table whose numbers it reads (None: the figure's one table), so that a page types no measurement"""
    plot: tuple[str, Callable[[dict, Path], object]] | None = None
    """(the image's path in the repository, data -> that image): the figure's plot, which ``plot NAME`` draws from
    its result file (images are not compared by ``--check``: matplotlib's bytes vary by version)"""
    parallel: bool = False
    """whether its commands are independent lanes that run at the same time (each one BLAS thread: a study split by
    agent, whose records do not depend on which agents share a process)"""


# ------------------------------------------------------------------------------------------ extraction


def trial_agents(summary: dict) -> dict:
    """The per-agent figures of a ``trials --json`` summary that tables print (no timings in it)."""
    keep = ("trials", "steps_mean", "steps_sd", "steps_ci95", "success_rate", "identify_steps_mean")
    return {agent: {k: stats[k] for k in keep} for agent, stats in summary["agents"].items()}


def markdown_tables(text: str) -> list[dict]:
    """The pipe tables in a script's ``--markdown`` output, each captioned by the line of text above it."""
    tables, lines, caption = [], text.splitlines(), ""
    index = 0
    while index < len(lines):
        line = lines[index]
        if line.startswith("|") and index + 1 < len(lines) and re.match(r"^\|(?:-+\|)+$", lines[index + 1]):
            rows = []
            index += 2
            while index < len(lines) and lines[index].startswith("|"):
                rows.append(split_row(lines[index]))
                index += 1
            tables.append({"caption": caption, "headers": split_row(line), "rows": rows})
            caption = ""
            continue
        if line.strip():
            caption = line.strip()
        index += 1
    return tables


def split_row(line: str) -> list[str]:
    cells = re.split(r"(?<!\\)\|", line.strip())
    return [cell.strip() for cell in cells[1:-1]]


# ---------------------------------------------------------------------------------------------- checks


def mean_of(cell: str) -> float | None:
    match = MEAN_CELL.match(cell.replace("%", "").strip())
    return float(match["mean"]) if match else None


def ci_of(cell: str) -> tuple[float, float] | None:
    match = CI_CELL.match(cell.strip())
    return (float(match["low"]), float(match["high"])) if match else None


def compare_trial_agents(published: dict, check: dict, label: str = "") -> list[str]:
    """Each agent's second-kernel mean steps lies inside the published 95 % interval of the mean."""
    failures = []
    for agent, stats in published.items():
        low, high = stats["steps_ci95"]
        mean = check[agent]["steps_mean"]
        if not low <= mean <= high:
            failures.append(f"{label}{agent}: mean {mean:.2f} outside the published [{low:.2f}, {high:.2f}]")
    return failures


VALUE_CELL = re.compile(rf"\**(?:{NUMBER}(?: ± {NUMBER})?(?: %)?|\[{NUMBER}, {NUMBER}\]|n/a|-)\**")


def row_label(row: Sequence[str]) -> tuple[str, ...]:
    """A table row's leading label cells (domain, agent, ...): what names the row in another run's table."""
    values = [i for i, cell in enumerate(row) if VALUE_CELL.fullmatch(cell.strip())]
    return tuple(row[: values[0] if values else len(row)])


def compare_markdown_tables(published: dict, check: dict) -> list[str]:
    """Every mean with a published interval beside it lies inside it in the check; verdict columns agree.
    Rows are matched by their labels, so a check that ran some rows (e.g. some domains) is held to those."""
    failures = []
    for ours, theirs in zip(published["tables"], check["tables"], strict=True):
        headers = ours["headers"]
        others = {row_label(row): row for row in theirs["rows"]}
        for row in ours["rows"]:
            other = others.get(row_label(row))
            if other is None:
                continue
            name = f"{ours['caption'][:40]} / {' '.join(row_label(row))}"
            for column, cell in enumerate(row):
                if headers[column].lower() in VERDICTS:
                    if cell != other[column]:
                        failures.append(f"{name}: {headers[column]} {cell} -> {other[column]}")
                    continue
                interval = ci_of(cell)
                if interval is None or column == 0:
                    continue
                mean = mean_of(other[column - 1])
                if mean is not None and not interval[0] <= mean <= interval[1]:
                    failures.append(f"{name}: {headers[column - 1]} {mean} outside the published {cell}")
    return failures


def compare_bracket(published: dict, check: dict) -> list[str]:
    """V* lies in each run's [lower, upper]; the check's lower bound must lie in the published bracket."""
    low, high = published["lower"], published["upper"]
    if low - 1e-9 <= check["lower"] <= high + 1e-9:
        return []
    return [f"lower bound {check['lower']:.6f} outside the published [{low:.6f}, {high:.6f}]"]


# --------------------------------------------------------------------------------------------- figures


def tiger_extract(outputs: dict[str, str]) -> dict:
    solved = json.loads(outputs["solve"])
    timing = {k: solved.pop(k) for k in ("seconds", "cpu_seconds")}
    solved["file"] = Path(solved["file"]).name  # the CLI prints the resolved path, which names this checkout
    return {**solved, "timing": timing}


def tiger_tables(data: dict) -> list[Table]:
    headers = [
        "file",
        "solver",
        "V(b0) (lower bound)",
        "upper bound",
        "gap",
        "alpha vectors",
        "stages",
        "converged",
    ]
    row = [
        Path(data["file"]).name,
        data["solver"],
        f"{data['lower']:.6f}",
        f"{data['upper']:.6f}",
        f"{data['gap']:.2e}",
        str(data["alpha_vectors"]),
        str(data["iterations"]),
        "yes" if data["converged"] else "no",
    ]
    return [Table("solve", "", headers, [row])]


def steps_cell(stats: dict) -> str:
    return f"{stats['steps_mean']:.2f} ± {stats['steps_sd']:.2f}"


def ci_cell(interval: Sequence[float]) -> str:
    return f"[{interval[0]:.2f}, {interval[1]:.2f}]"


def lab_agents_extract(outputs: dict[str, str]) -> dict:
    return {"agents": trial_agents(json.loads(outputs["trials"]))}


def lab_agents_tables(data: dict) -> list[Table]:
    headers = ["agent", "steps", "steps 95% CI (bootstrap)", "success", "identify"]
    rows = [
        [
            agent,
            steps_cell(s),
            ci_cell(s["steps_ci95"]),
            f"{s['success_rate']:.2f}",
            "n/a" if s["identify_steps_mean"] is None else f"{s['identify_steps_mean']:.2f}",
        ]
        for agent, s in data["agents"].items()
    ]
    return [Table("agents", "", headers, rows)]


ARENA_CELLS = [
    (domain, grid, team)
    for domain in ("foraging", "pursuit")
    for grid in ("walls", "torus")
    for team in ("tau0", "tau1", "tau2")
] + [("pairs", "walls", "greedy"), ("pairs", "walls", "aware")]
ARENA_THESIS = {  # thesis ch. 6 and Fig. 7.12: the original teammate (task id set) and the random agent
    "foraging": ("6.72", "59.05"),
    "pursuit": ("9.36", "50.66"),
    "pairs": ("6.75 (optimal, full obs.)", "76.06"),
}
ARENA_LABELS = {"foraging": "LBF", "pursuit": "pursuit", "pairs": "pair (Fig. 7.12)"}


def arena_command(domain: str, grid: str, team: str) -> list[str]:
    pairs = domain == "pairs"
    command = [
        ".venv/bin/embodied-adhoc",
        "trials",
        "pursuit" if pairs else domain,
        "--backend",
        "abstract",
        "--team",
        team,
        "--agents",
        "original,random",
        "--episodes",
        "32" if pairs else "64",
        "--max-steps",
        "150" if pairs else "200",
        "--seed",
        "0",
        "--workers",
        "1",
        "--json",
    ]
    return command + (["--pairs"] if pairs else []) + (["--toroidal"] if grid == "torus" else [])


def arenas_extract(outputs: dict[str, str]) -> dict:
    return {"runs": {key: trial_agents(json.loads(text)) for key, text in outputs.items()}}


def arenas_tables(data: dict) -> list[Table]:
    headers = [
        "domain",
        "grid",
        "team",
        "original teammate",
        "random",
        "thesis original (task id)",
        "thesis random",
    ]
    rows, seen = [], set()
    for domain, grid, team in ARENA_CELLS:
        run = data["runs"][f"{domain}-{grid}-{team}"]
        original, random = run["original"], run["random"]
        thesis = ARENA_THESIS[domain] if (domain, grid) not in seen else ("", "")
        seen.add((domain, grid))
        rows.append(
            [
                ARENA_LABELS[domain],
                grid,
                team,
                f"{steps_cell(original)} {ci_cell(original['steps_ci95'])}",
                f"{random['steps_mean']:.1f} ± {random['steps_sd']:.1f} "
                f"({100 * random['success_rate']:.0f} % solved)",
                *thesis,
            ]
        )
    return [Table("original", "", headers, rows)]


def arenas_compare(published: dict, check: dict) -> list[str]:
    failures = []
    for key, agents in published["runs"].items():
        failures += compare_trial_agents(agents, check["runs"][key], f"{key} ")
    return failures


PHYSICS_THESIS = {
    "hotspot": "12.88 ± 1.87; live robot mean 12.3",
    "known-task": "11.81 ± 1.72",
}  # thesis ch. 7


def physics_extract(outputs: dict[str, str]) -> dict:
    document = json.loads(outputs["trials"])
    backends = {backend: trial_agents(summary) for backend, summary in document["backends"].items()}
    tests = {
        c["a"].split(" (")[0]: {"p": c["p"], "significant": c["significant"]}
        for c in document["backend_comparisons"]
    }
    return {"backends": backends, "welch": tests}


def physics_tables(data: dict) -> list[Table]:
    def cell(stats: dict) -> str:
        identify = stats["identify_steps_mean"]
        return steps_cell(stats) + (f" (identifies at {identify:.2f})" if identify else "")

    abstract, physics = data["backends"]["abstract"], data["backends"]["mujoco"]
    headers = ["agent", "abstract", "physics (MuJoCo)", "Welch p", "thesis"]
    rows = [
        [
            {"hotspot": "hotspot (TEBOPA)"}.get(agent, agent),
            cell(abstract[agent]),
            cell(physics[agent]),
            f"{data['welch'][agent]['p']:.3g}",
            PHYSICS_THESIS.get(agent, "-"),
        ]
        for agent in abstract
    ]
    return [Table("backends", "", headers, rows)]


def physics_compare(published: dict, check: dict) -> list[str]:
    failures = []
    for backend, agents in published["backends"].items():
        failures += compare_trial_agents(agents, check["backends"][backend], f"{backend} ")
    for agent, test in published["welch"].items():
        if test["significant"] != check["welch"][agent]["significant"]:
            failures.append(
                f"{agent}: abstract vs physics significant {test['significant']} -> "
                f"{check['welch'][agent]['significant']}"
            )
    return failures


BENCH_LINE = re.compile(
    r"^\s*(?P<name>.+?)\s{2,}(?P<value>[\d.]+) (?P<unit>s|us)\b(?:\s+(?P<ratio>[\d.]+) x)?"
)


def bench_trials_extract(outputs: dict[str, str]) -> dict:
    rows = []
    for line in outputs["bench"].splitlines():
        match = BENCH_LINE.match(line)
        if match:
            rows.append(
                [
                    match["name"].strip(),
                    f"{match['value']} {match['unit'].replace('us', 'µs')}",
                    f"{match['ratio']}x" if match["ratio"] else "",
                ]
            )
        elif line.startswith("CLI in a fresh process"):
            rows.append([line.split(":")[0], line.split(":")[1].strip(), ""])
    return {"timing": {"rows": rows, "stdout": outputs["bench"]}}


def bench_trials_tables(data: dict) -> list[Table]:
    rows = data["timing"]["rows"]
    return [Table("speed", "", ["measurement", "value", "ratio to raw POMDP.step"], rows)]


def markdown_extract(command: str) -> Callable[[dict[str, str]], dict]:
    def extract(outputs: dict[str, str]) -> dict:
        return {"tables": markdown_tables(outputs[command])}

    return extract


def reproduce_atpo_command(*extra: str) -> list[str]:
    """``scripts/reproduce_atpo.py`` printing Markdown into a fresh run folder, with ``extra`` arguments."""
    return ["{python}", "scripts/reproduce_atpo.py", "--out", "{out}", "--markdown", *extra]


def markdown_figure_tables(keys: Sequence[str]) -> Callable[[dict], list[Table]]:
    def tables(data: dict) -> list[Table]:
        return [
            Table(key, table["caption"], table["headers"], table["rows"])
            for key, table in zip(keys, data["tables"], strict=True)
        ]

    return tables


ARENA_TASK_DOMAINS = {"foraging": "LBF", "pursuit": "pursuit"}
ARENA_TEAMS = ("tau0", "tau1", "tau2")


def arena_task_command(
    domain: str,
    team: str,
    task: int | None,
    backend: str = "abstract",
    episodes: int = 16,
    agent: str = "original",
) -> list[str]:
    """One cell of the per-task tables: ``agent`` beside ``team`` on ``task`` (None: the tasks drawn per episode)."""
    return [
        ".venv/bin/embodied-adhoc",
        "trials",
        domain,
        "--backend",
        backend,
        "--team",
        team,
        *(["--task", str(task)] if task is not None else []),
        "--agents",
        agent,
        "--episodes",
        str(episodes),
        "--max-steps",
        "200",
        "--seed",
        "0",
        "--workers",
        "1",
        "--json",
    ]


def solved_cell(stats: dict) -> str:
    return f"{stats['steps_mean']:.2f} {ci_cell(stats['steps_ci95'])} ({100 * stats['success_rate']:.0f} % solved)"


def arena_tasks_table(data: dict, backend: str) -> Table:
    headers = ["domain", "team", *(f"task {task}" for task in range(1, 5))]
    rows = [
        [
            f"{label}, {backend}",
            team,
            *(solved_cell(data["runs"][f"{domain}-{team}-task{task}"]["original"]) for task in range(1, 5)),
        ]
        for domain, label in ARENA_TASK_DOMAINS.items()
        for team in ARENA_TEAMS
    ]
    return Table("tasks", "", headers, rows)


def arena_tasks_tables(data: dict) -> list[Table]:
    return [arena_tasks_table(data, "grid twin")]


ARENA_RANDOM_TEAM = "tau1"
"""The team beside which the MuJoCo per-task figure measures random in the ad hoc seat (tasks drawn per episode)."""


def arena_tasks_mujoco_tables(data: dict) -> list[Table]:
    random = [
        [
            f"{label}, MuJoCo",
            ARENA_RANDOM_TEAM,
            solved_cell(data["runs"][f"{domain}-{ARENA_RANDOM_TEAM}-random"]["random"]),
        ]
        for domain, label in ARENA_TASK_DOMAINS.items()
    ]
    return [
        arena_tasks_table(data, "MuJoCo"),
        Table("random", "Random in the ad hoc seat:", ["domain", "team", "random"], random),
    ]


ALL_FAULTS = (
    "--wheel-slip 0.02 --encoder-noise 0.05 --rfid-miss 0.5 --lidar-noise 0.05 --lidar-dropout 0.3 "
    "--speech-failure 0.3"
)
FAULT_SETTINGS = {
    "none": "",
    "wheel-slip": "--wheel-slip 0.02",
    "encoder-noise": "--encoder-noise 0.05",
    "rfid-miss": "--rfid-miss 0.5",
    "rfid-miss-model-not-told": "--rfid-miss 0.5 --model-rfid-miss 0",
    "lidar-noise": "--lidar-noise 0.05",
    "lidar-dropout": "--lidar-dropout 0.3",
    "speech-failure": "--speech-failure 0.3",
    "all": ALL_FAULTS,
    "all-model-not-told": f"{ALL_FAULTS} --model-rfid-miss 0",
}
"""The fault table's settings (key -> the options added to the trials): each fault alone, then all six together,
each RFID setting once with the agents' model told the miss rate (the default) and once not."""
FAULT_COLUMNS = (
    ("RFID missed / reads", ("fault_rfid_misses", "event_rfid_reads")),
    (
        "replies lost / no location / asked",
        ("fault_replies_lost", "fault_replies_no_location", "event_replies"),
    ),
    ("lidar beams dropped / read", ("fault_lidar_dropped_beams", "event_lidar_beams")),
    ("wheel slip (m)", ("fault_wheel_slip_m",)),
    ("encoder noise (m)", ("fault_encoder_noise_m",)),
    ("re-localisations", ("fault_relocalisations",)),
    ("blocked / moves", ("fault_blocked_moves", "event_moves")),
    ("robot node unknown / readings", ("fault_robot_node_unknown", "event_robot_node_readings")),
)
"""The fault counts table: header -> the trial columns (``fault_*``, ``event_*``) its cell prints, per episode."""


def fault_command(options: str) -> list[str]:
    return [
        ".venv/bin/embodied-adhoc",
        "trials",
        "toxic-waste",
        "--backend",
        "mujoco",
        "--agents",
        "hotspot",
        "--episodes",
        "8",
        "--seed",
        "100",
        "--workers",
        "1",
        "--json",
        *options.split(),
    ]


def faults_extract(outputs: dict[str, str]) -> dict:
    """Per setting and agent: the steps figures, the fault counts per episode and the cap reasons counted."""
    runs = {}
    for key, text in outputs.items():
        summary = json.loads(text)
        runs[key] = {
            agent: {
                **stats,
                "per_episode_mean": summary["agents"][agent].get("per_episode_mean", {}),
                "cap_reason": summary["agents"][agent].get("counts", {}).get("cap_reason", {}),
            }
            for agent, stats in trial_agents(summary).items()
        }
        missing = [
            c for _, cs in FAULT_COLUMNS for c in cs if c not in runs[key]["hotspot"]["per_episode_mean"]
        ]
        if missing:
            sys.exit(f"fault-table {key}: the trials' --json reports no {', '.join(missing)} per episode")
    return {"runs": runs}


def fault_label(key: str) -> str:
    options = FAULT_SETTINGS[key]
    if key.startswith("all"):
        return "all six" + (", `--model-rfid-miss 0`" if key != "all" else "")
    return f"`{options}`" if options else "(no fault option)"


def per_episode(value: float) -> str:
    """A mean count per episode: three decimals at most (eight episodes give multiples of 0.125), no trailing 0."""
    return f"{value:.3f}".rstrip("0").rstrip(".")


def fault_tables(data: dict) -> list[Table]:
    outcomes, counts = [], []
    for key in FAULT_SETTINGS:
        stats = data["runs"][key]["hotspot"]
        capped = ", ".join(f"`{code}` x{n}" for code, n in sorted(stats["cap_reason"].items()))
        outcomes.append(
            [
                fault_label(key),
                f"{round(stats['success_rate'] * stats['trials'])}/{stats['trials']}",
                steps_cell(stats),
                ci_cell(stats["steps_ci95"]),
                capped or "-",
            ]
        )
        faults = stats["per_episode_mean"]
        counts.append(
            [
                fault_label(key),
                *(" / ".join(per_episode(faults[c]) for c in cs) for _, cs in FAULT_COLUMNS),
            ]
        )
    headers = ["fault", "success", "steps (mean ± sd)", "steps 95% CI (bootstrap)", "capped: reason"]
    return [
        Table("outcomes", "", headers, outcomes),
        Table(
            "counts",
            "Fault events and what they are counted out of, means per episode:",
            ["fault", *(h for h, _ in FAULT_COLUMNS)],
            counts,
        ),
    ]


def bench_sim_extract(outputs: dict[str, str]) -> dict:
    """The tours' table without its real-time-factor column (a rate of this run's CPU), and the rates apart."""
    tours, measures = markdown_tables(outputs["bench"])[:2]
    rtf = tours["headers"].index("RTF")
    rows = [[cell for i, cell in enumerate(row) if i != rtf] for row in tours["rows"]]
    headers = [h for i, h in enumerate(tours["headers"]) if i != rtf]
    summary = [
        line for line in outputs["bench"].splitlines() if line.startswith(("drift after", "node-estimate"))
    ]
    return {
        "tours": {"headers": headers, "rows": rows},
        "summary": summary,
        "timing": {
            "rtf": [row[rtf] for row in tours["rows"]],
            "measures": measures,
            "stdout": outputs["bench"],
        },
    }


def bench_sim_tables(data: dict) -> list[Table]:
    return [
        Table("tours", "; ".join(data["summary"]), data["tours"]["headers"], data["tours"]["rows"]),
        Table("speed", "", data["timing"]["measures"]["headers"], data["timing"]["measures"]["rows"]),
    ]


def bench_sim_compare(published: dict, check: dict) -> list[str]:
    """Every tour arrives at every node with the node estimate right and without wall contact in both runs, and
    the check's mean drift lies inside the published mean's 95 % t-interval."""
    failures = []
    columns = published["tours"]["headers"]
    drift = columns.index("drift after tour (m)")
    for ours, theirs in zip(published["tours"]["rows"], check["tours"]["rows"], strict=True):
        for column in ("node estimate correct", "arrived", "wall contacts"):
            index = columns.index(column)
            if ours[index] != theirs[index]:
                failures.append(f"seed {ours[0]}: {column} {ours[index]} -> {theirs[index]}")
    ours = [float(row[drift]) for row in published["tours"]["rows"]]
    theirs = [float(row[drift]) for row in check["tours"]["rows"]]
    low, high = t_interval(ours)
    mean = sum(theirs) / len(theirs)
    if not low <= mean <= high:
        failures.append(f"mean drift {mean:.3f} m outside the published [{low:.3f}, {high:.3f}]")
    return failures


T_975 = {2: 12.706, 3: 4.303, 4: 3.182, 5: 2.776, 6: 2.571, 7: 2.447, 8: 2.365, 9: 2.306, 10: 2.262}
"""Student's t 97.5 % quantile by sample size (n - 1 degrees of freedom); 1.96 beyond."""


def t_interval(values: Sequence[float]) -> tuple[float, float]:
    n = len(values)
    mean = sum(values) / n
    sd = (sum((v - mean) ** 2 for v in values) / (n - 1)) ** 0.5 if n > 1 else 0.0
    half = T_975.get(n, 1.96) * sd / n**0.5
    return mean - half, mean + half


def tag_extract(outputs: dict[str, str]) -> dict:
    solved = json.loads(outputs["solve"])
    timing = {k: solved.pop(k) for k in ("seconds", "cpu_seconds")}
    keep = ("lower", "upper", "alpha_vectors", "iterations", "converged", "beliefs", "simulation")
    return {
        "file": Path(solved["file"]).name,
        **{k: solved[k] for k in keep if k in solved},
        "timing": timing,
    }


def simulated_interval(simulated: dict) -> tuple[float, float]:
    """The 95 % interval of a ``pomdp solve --simulate`` mean (the CLI prints its half-width)."""
    return simulated["mean"] - simulated["ci95"], simulated["mean"] + simulated["ci95"]


def tag_tables(data: dict) -> list[Table]:
    simulated = data["simulation"]
    low, high = simulated_interval(simulated)
    headers = [
        "file",
        "stages",
        "V(b0) claimed (lower bound)",
        "upper bound",
        "saved policy's vectors",
        f"simulated return ({simulated['episodes']} episodes x {simulated['horizon']} steps)",
        "95% CI",
    ]
    row = [
        data["file"],
        str(data["iterations"]),
        f"{data['lower']:.6f}",
        f"{data['upper']:.6f}",
        str(data["alpha_vectors"]),
        f"{simulated['mean']:.2f} ± {simulated['std']:.2f}",
        f"[{low:.2f}, {high:.2f}]",
    ]
    return [Table("fixed-set", "", headers, [row])]


def tag_compare(published: dict, check: dict) -> list[str]:
    """A second kernel's claimed value lies in the published bracket, its simulated mean in the published CI."""
    failures = compare_bracket(published, check)
    low, high = simulated_interval(published["simulation"])
    mean = check["simulation"]["mean"]
    if not low <= mean <= high:
        failures.append(f"simulated mean {mean:.3f} outside the published [{low:.3f}, {high:.3f}]")
    return failures


SPEECH_CONFUSIONS = ("thesis", "measured")
SPEECH_AGENT_LABELS = {"hotspot": "hotspot (TEBOPA)", "oracle": "oracle (full observability)"}


def speech_confusion_command(confusion: str) -> list[str]:
    return [
        ".venv/bin/embodied-adhoc",
        "trials",
        "toxic-waste",
        "--agents",
        "hotspot,known-task,oracle",
        "--confusion",
        confusion,
        "--episodes",
        "32",
        "--seed",
        "7",
        "--workers",
        "1",
        "--json",
    ]


def speech_confusions_tables(data: dict) -> list[Table]:
    headers = [
        "confusion",
        "agent",
        "steps to finish (mean ± sd)",
        "steps 95% CI (bootstrap)",
        "success",
        "identify",
    ]
    rows = [
        [
            confusion,
            SPEECH_AGENT_LABELS.get(agent, agent),
            steps_cell(s),
            ci_cell(s["steps_ci95"]),
            f"{s['success_rate']:.2f}",
            "n/a" if s["identify_steps_mean"] is None else f"{s['identify_steps_mean']:.2f}",
        ]
        for confusion in SPEECH_CONFUSIONS
        for agent, s in data["runs"][confusion].items()
    ]
    return [Table("agents", "", headers, rows)]


GENERATED_IO = re.compile(
    r"^generated (?P<model>.+?) \((?P<mb>[\d.]+) MB\): format (?P<format>[\d.]+) s, write (?P<write>[\d.]+) s, "
    r"read (?P<read>[\d.]+) s \(floor (?P<floor>[\d.]+) s, (?P<ratio>[\d.]+)x\); round trip identical: "
    r"(?P<same>\w+)$"
)


def pomdp_io_extract(outputs: dict[str, str]) -> dict:
    """The reader's table per corpus file and the generated model's round trip: timings, all of it."""
    text = outputs["bench"]
    (read,) = markdown_tables(text)
    match = next(filter(None, map(GENERATED_IO.match, text.splitlines())), None)
    if match is None:
        sys.exit("pomdp-io: no line on the generated model's round trip in the script's output")
    generated = [match["model"], match["mb"], match["format"], match["write"], match["read"], match["floor"],
                 f"{match['ratio']}x", "yes" if match["same"] == "True" else "no"]  # fmt: skip
    return {"timing": {"read": read, "generated": generated, "stdout": text}}


def pomdp_io_tables(data: dict) -> list[Table]:
    read = data["timing"]["read"]
    headers = ["generated model", "MB", "format s", "write s", "read s", "floor s", "read / floor",
               "round trip identical"]  # fmt: skip
    return [
        Table("read", "", read["headers"], read["rows"]),
        Table("generated", "", headers, [data["timing"]["generated"]]),
    ]


ARENA_RATE = re.compile(r"^(?P<name>\S.*?)\s+(?P<rate>\d+\.\d)\s+(?P<ratio>\d+\.\d{3})$")
ARENA_DOMAINS = ("foraging", "pursuit")


def arena_speed_extract(outputs: dict[str, str]) -> dict:
    """Per domain: each env's steps per CPU second and its ratio to the reference, and the macro-step lines."""
    runs = {}
    for domain, text in outputs.items():
        lines = text.splitlines()
        rates = [m.groupdict() for m in map(ARENA_RATE.match, lines) if m]
        notes = [
            line for line in lines if line.startswith(("ratios against", "MuJoCo macro step", "HOTSPOT in"))
        ]
        runs[domain] = {"rates": rates, "notes": notes}
    return {"timing": {"runs": runs, "stdout": outputs}}


def arena_speed_tables(data: dict) -> list[Table]:
    runs = data["timing"]["runs"]
    rows = [[domain, r["name"], r["rate"], r["ratio"]] for domain, run in runs.items() for r in run["rates"]]
    notes = [[domain, note] for domain, run in runs.items() for note in run["notes"]]
    return [
        Table("rates", "", ["run", "env", "steps per CPU s", "ratio to the first row of its run"], rows),
        Table("macro-steps", "", ["run", "measurement"], notes),
    ]


FIG5_9_HEADER = "library size"


def fig5_9_extract(outputs: dict[str, str]) -> dict:
    """The library-size table of ``reproduce_atpo.py``'s output (the gridworld Table 5.5 rows it normalises by are
    Table 5.5's figure)."""
    tables = [t for t in markdown_tables(outputs["reproduce"]) if t["headers"][:1] == [FIG5_9_HEADER]]
    if len(tables) != 1:
        sys.exit(f"fig5-9: reproduce_atpo.py printed {len(tables)} tables headed '{FIG5_9_HEADER}', not one")
    return {"tables": [{**tables[0], "caption": ""}]}


LOCALISER_COST_SECONDS = 300
"""Simulated seconds of the cost figure's scripted drive (15,000 control steps: under a CPU minute)."""
LOCALISER_COST = re.compile(
    r"^cost per control step \((?P<control_steps>\d+) steps of 20 ms, this process, CPU time\): physics "
    r"(?P<physics_ms>[\d.]+) ms \(the same scene without the lidar's rangefinders: (?P<physics_without_lidar_ms>"
    r"[\d.]+) ms\), localiser (?P<localiser_ms>[\d.]+) ms \([\d.]+x the physics\), "
    r"odometry (?P<odometry_ms>[\d.]+) ms$",
    re.MULTILINE,
)
LOCALISER_COST_ROWS = (
    ("physics (`mj_step`, the control step's substeps)", "physics_ms"),
    ("physics of the scene without the lidar's rangefinders", "physics_without_lidar_ms"),
    ("localiser (lidar scan and filter: `LabWorld.sense` less the odometry)", "localiser_ms"),
    ("odometry (`LabWorld.sense` with the localiser detached)", "odometry_ms"),
)


def localiser_cost_extract(outputs: dict[str, str]) -> dict:
    match = LOCALISER_COST.search(outputs["bench"])
    if match is None:
        sys.exit("localiser-cost: bench_faults.py printed no 'cost per control step (... CPU time)' line")
    numbers = {key: float(value) for key, value in match.groupdict().items()}
    return {"timing": {**numbers, "control_steps": int(numbers["control_steps"]), "stdout": outputs["bench"]}}


def localiser_cost_tables(data: dict) -> list[Table]:
    cost = data["timing"]
    rows = [
        [label, f"{cost[key]:.3f}", f"{cost[key] / cost['physics_ms']:.2f}x"]
        for label, key in LOCALISER_COST_ROWS
    ]
    return [Table("cost", "", ["part of a control step", "CPU ms per step", "ratio to the physics"], rows)]


REALTIME_EPISODES, REALTIME_PACED = 12, 4
"""Episodes per mode of the real-time figure, and of its paced mode (each paced one takes minutes of wall clock at
this load): about 10 min of wall clock in all."""
REALTIME_REFERENCE = "turn-based"


def realtime_extract(outputs: dict[str, str]) -> dict:
    """The modes whose episodes do not depend on wall time (turn-based, unpaced: the same per seed on any host) apart
    from the paced ones and every mode's wall seconds (timing)."""
    result = json.loads(outputs["bench"])
    modes = result["modes"]
    if REALTIME_REFERENCE not in modes:
        sys.exit(f"live-realtime: bench_realtime.py --json reports no '{REALTIME_REFERENCE}' mode")
    paced = [mode for mode in modes if mode.startswith("real-time, paced")]
    return {
        "agent": result["agent"],
        "modes": {
            mode: {key: stats[key] for key in ("success", "n", "steps", "sim_s")}
            for mode, stats in modes.items()
            if mode not in paced
        },
        "timing": {
            "paced": {mode: modes[mode] for mode in paced},
            "modes": modes,
            "stdout": outputs["bench"],
        },
    }


def realtime_row(mode: str, stats: dict, reference: dict, wall: bool = False) -> list[str]:
    def cell(pair: Sequence[float]) -> str:
        return f"{pair[0]:.1f} ± {pair[1]:.1f}"

    return [
        mode,
        f"{stats['success']}/{stats['n']}",
        cell(stats["steps"]),
        cell(stats["sim_s"]),
        *([cell(stats["wall_s"])] if wall else []),
        f"{stats['steps'][0] / reference['steps'][0]:.2f}",
        f"{stats['sim_s'][0] / reference['sim_s'][0]:.2f}",
    ]


def realtime_tables(data: dict) -> list[Table]:
    reference = data["modes"][REALTIME_REFERENCE]
    headers = ["mode", "success", "steps", "simulated seconds to finish", "steps ratio", "seconds ratio"]
    everything = data["timing"]["modes"]
    return [
        Table("modes", "", headers, [realtime_row(m, s, reference) for m, s in data["modes"].items()]),
        Table(
            "wall",
            "Every mode with its wall seconds per episode (the paced mode's steps depend on them):",
            [*headers[:4], "wall s / episode", *headers[4:]],
            [realtime_row(m, s, everything[REALTIME_REFERENCE], wall=True) for m, s in everything.items()],
        ),
    ]


def realtime_compare(published: dict, check: dict) -> list[str]:
    """Each mode's second-kernel mean steps and simulated seconds lie inside the published mean ± half-width."""
    failures = []
    for mode, stats in published["modes"].items():
        for key in ("steps", "sim_s"):
            (mean, half), other = stats[key], check["modes"][mode][key][0]
            if not mean - half <= other <= mean + half:
                failures.append(f"{mode} {key}: {other:.1f} outside the published {mean:.1f} ± {half:.1f}")
    return failures


def values_and_timing(command: str, keys: tuple[str, str]) -> tuple[Callable, Callable]:
    """(extract, tables) of a command that prints two Markdown tables: the values (fixed by the inputs and
    settings; table key ``keys[0]``) and then CPU seconds or rates (timing; ``keys[1]``), kept apart."""
    values_key, timing_key = keys

    def extract(outputs: dict[str, str]) -> dict:
        values, timing = markdown_tables(outputs[command])[:2]
        return {"tables": [values], "timing": {timing_key: timing, "stdout": outputs[command]}}

    def tables(data: dict) -> list[Table]:
        values, timing = data["tables"][0], data["timing"][timing_key]
        return [
            Table(values_key, values["caption"], values["headers"], values["rows"]),
            Table(timing_key, timing["caption"], timing["headers"], timing["rows"]),
        ]

    return extract, tables


budget_extract, budget_tables = values_and_timing("budget", ("values", "seconds"))
speech_tuning_extract, speech_tuning_tables = values_and_timing("tune", ("accuracy", "cpu"))


LATENCY_PAGE = re.compile(
    rf"^(?P<what>frame interval ms \(page\)|key press to motion on the page ms): mean (?P<mean>{NUMBER}), median "
    rf"(?P<p50>{NUMBER}), p95 (?P<p95>{NUMBER}), max (?P<max>{NUMBER}) \(n=(?P<n>\d+)\)$",
    re.MULTILINE,
)
LATENCY_ROWS = (
    ("frame interval at the page", "frame interval ms (page)"),
    ("frame interval at the server (sent)", "frame_interval_sent_ms"),
    ("key press to motion on the page", "key press to motion on the page ms"),
    ("key press to motion in the simulation", "key_to_motion_in_simulation_ms"),
)


def latency_extract(outputs: dict[str, str]) -> dict:
    """The page's figures the browser test prints, and the server's from its ``session.json`` (printed as a dict)."""
    text = outputs["browser"]
    figures = {
        match["what"]: {"n": int(match["n"]), **{k: float(match[k]) for k in ("mean", "p50", "p95", "max")}}
        for match in LATENCY_PAGE.finditer(text)
    }
    server = re.search(r"^server side: (?P<latency>\{.*\})$", text, re.MULTILINE)
    if server is None or len(figures) != 2:
        sys.exit("live-latency: the browser test printed no page or server latency (run it with -s)")
    figures |= ast.literal_eval(server["latency"])
    return {"timing": {"latency_ms": figures, "stdout": text}}


def latency_tables(data: dict) -> list[Table]:
    figures = data["timing"]["latency_ms"]
    rows = []
    for label, key in LATENCY_ROWS:
        stats = figures.get(key)
        cells = (
            ["-"] * 5
            if stats is None
            else [str(stats["n"])] + [f"{stats[k]:.0f}" for k in ("mean", "p50", "p95", "max")]
        )
        rows.append([label, *cells])
    return [Table("latency", "", ["quantity", "n", "mean ms", "median ms", "p95 ms", "max ms"], rows)]


FAULT_SWEEP_EPISODES = 4
"""Episodes per fault row and localiser mode of the sweep figure (8 rows x 2 modes: 64 physics episodes)."""
FAULT_SWEEP_WALL = "wall s/episode"


def fault_sweep_extract(outputs: dict[str, str]) -> dict:
    """The sweep's table without its wall-seconds column (kept apart, as timing)."""
    tables = markdown_tables(outputs["sweep"])
    if not tables or FAULT_SWEEP_WALL not in tables[0]["headers"]:
        sys.exit(f"fault-sweep: bench_faults.py printed no sweep table with a '{FAULT_SWEEP_WALL}' column")
    table = tables[0]
    wall = table["headers"].index(FAULT_SWEEP_WALL)
    return {
        "tables": [
            {
                "caption": table["caption"],
                "headers": [h for i, h in enumerate(table["headers"]) if i != wall],
                "rows": [[cell for i, cell in enumerate(row) if i != wall] for row in table["rows"]],
            }
        ],
        "timing": {"wall_s_per_episode": [row[wall] for row in table["rows"]], "stdout": outputs["sweep"]},
    }


def fault_sweep_compare(published: dict, check: dict) -> list[str]:
    """Each row's (fault, localiser) second-kernel mean steps lies inside the published bootstrap interval."""
    ours, theirs = published["tables"][0], check["tables"][0]
    mean, interval = ours["headers"].index("mean steps"), ours["headers"].index("steps 95% CI (bootstrap)")
    others = {tuple(row[:2]): row for row in theirs["rows"]}
    failures = []
    for row in ours["rows"]:
        other = others.get(tuple(row[:2]))
        if other is None:
            failures.append(f"{' '.join(row[:2])}: no such row in the check")
            continue
        low, high = ci_of(row[interval])
        if not low <= float(other[mean]) <= high:
            failures.append(
                f"{' '.join(row[:2])}: mean steps {other[mean]} outside the published {row[interval]}"
            )
    return failures


def hotspot_prose(data: dict) -> dict[str, tuple[str | None, str]]:
    """The steps table's headline cells and the claims' verdicts in a sentence (the hotspot page's summary)."""
    steps, claims = data["tables"]
    columns = steps["headers"]
    cells = {(row[0], row[1]): dict(zip(columns, row, strict=True)) for row in steps["rows"]}

    def ours(setting: str, agent: str, thesis: bool = True) -> str:
        row = cells[(setting, agent)]
        return row["steps (ours)"] + (f" (thesis {row['steps (thesis)']})" if thesis else "")

    held = sum(row[claims["headers"].index("holds")] == "yes" for row in claims["rows"])
    with_comm, without = ("communication", "hotspot"), ("no-communication", "hotspot")
    return {
        "measured": (
            "steps",
            f"With communication HOTSPOT (TEBOPA) takes {ours(*with_comm)} steps and identifies the task at step "
            f"{cells[with_comm]['identify'].split(' ')[0]} on average, known-task "
            f"{ours('communication', 'known-task')}, "
            f"oracle {ours('communication', 'oracle', thesis=False)}; without communication HOTSPOT takes "
            f"{ours(*without)} with success {cells[without]['success']} and final task entropy "
            f"{cells[without]['final H']}, known-task {ours('no-communication', 'known-task')}. {held} of the "
            f"{len(claims['rows'])} thesis claims tested hold (Welch, alpha 0.05).",
        )
    }


def thesis_differences(table: dict, rows=None) -> tuple[list[str], list[str]]:
    """Table 5.5's rows (``rows``: a subset) whose Welch p against the thesis is below 0.05, higher and lower."""
    column = table["headers"].index
    higher, lower = [], []
    for row in table["rows"] if rows is None else rows:
        p, ours, theirs = (
            row[column("Welch p vs thesis")],
            row[column("reward (ours)")],
            row[column("reward (thesis)")],
        )
        if not re.fullmatch(NUMBER, p) or float(p) >= 0.05:
            continue
        (higher if mean_of(ours) > mean_of(theirs) else lower).append(f"{row[0]} {row[1]} (p {p})")
    return higher, lower


def chapter5_prose(data: dict) -> dict[str, tuple[str | None, str]]:
    """Table 5.5's rows whose Welch p against the thesis is below 0.05, higher and lower than the thesis's."""
    higher, lower = thesis_differences(data["tables"][0])
    return {
        "differences": (
            "table5_5",
            f"Rows of Table 5.5 whose reward differs from the thesis's (Welch, alpha 0.05): higher here, "
            f"{', '.join(higher) or 'none'}; lower here, {', '.join(lower) or 'none'}.",
        )
    }


def chapter5_bugs_prose(data: dict) -> dict[str, tuple[str | None, str]]:
    """How many rows of the fixed and of the buggy models differ from the thesis's (Welch, alpha 0.05)."""
    table = data["tables"][0]
    parts = []
    for label, buggy in (("the models rebuilt with the bugs", True), ("the fixed models", False)):
        rows = [row for row in table["rows"] if row[0].endswith("(bug)") == buggy]
        higher, lower = thesis_differences(table, rows)
        named = "; ".join(
            f"{side} here: {', '.join(found)}"
            for side, found in (("higher", higher), ("lower", lower))
            if found
        )
        parts.append(
            f"{label}, {len(higher) + len(lower)} of {len(rows)} rows" + (f" ({named})" if named else "")
        )
    sentence = "Rows of the table whose reward differs from the thesis's (Welch, alpha 0.05): " + "; ".join(
        parts
    )
    return {"differences": ("table5_5", sentence + ".")}


def fig5_9_prose(data: dict) -> dict[str, tuple[str | None, str]]:
    """Whether the thesis's "stays above 70 %" holds per library size for the mean and for the whole interval."""
    table = data["tables"][0]
    column = table["headers"].index
    means, intervals = column("ATPO normalised (ours)"), column("95% CI (bootstrap), %")
    below = [row[0] for row in table["rows"] if mean_of(row[means]) <= 70]
    reaching = [
        row[0] for row in table["rows"] if mean_of(row[means]) > 70 and ci_of(row[intervals])[0] <= 70
    ]
    sentence = (
        f"The thesis's claim that the score stays above 70 %: the mean is at or below it for "
        f"{', '.join(below) or 'no size'}; the interval reaches 70 % or below for {', '.join(reaching) or 'no size'}"
        f"{' (the claim holds for the means there, not at 95 % confidence)' if reaching else ''}."
    )
    return {"claim": (None, sentence)}


def welch_p(a: dict, b: dict) -> float:
    """Welch's test of two agents' mean steps from their summaries (mean, sample sd, trials): the project's one
    Welch test, ``experiments.stats.welch_test_from_stats``."""
    from embodied_adhoc.experiments.stats import welch_test_from_stats

    stats = ("steps_mean", "steps_sd", "trials")
    return welch_test_from_stats(*(a[k] for k in stats), *(b[k] for k in stats))[1]


def significance(p: float) -> str:
    return "significant" if p < 0.05 else "not significant"


def speech_confusions_prose(data: dict) -> dict[str, tuple[str | None, str]]:
    thesis, measured = data["runs"]["thesis"], data["runs"]["measured"]
    between = [
        f"{SPEECH_AGENT_LABELS.get(agent, agent)} p = {welch_p(thesis[agent], measured[agent]):.3g}"
        for agent in ("hotspot", "known-task")
    ]
    within = [welch_p(run["hotspot"], run["known-task"]) for run in (thesis, measured)]
    verdict = "no" if all(welch_p(thesis[a], measured[a]) >= 0.05 for a in ("hotspot", "known-task")) else "a"
    return {
        "welch": (
            None,
            f"Welch t-tests of the steps to finish, measured vs thesis matrix: {', '.join(between)}: {verdict} "
            f"significant difference to the team at alpha 0.05. HOTSPOT vs known-task: p = {within[0]:.3g} "
            f"(thesis matrix, {significance(within[0])}), {within[1]:.3g} (measured, {significance(within[1])}).",
        )
    }


ABLATION_CELL = re.compile(rf"^(?P<mean>{NUMBER}) ± (?P<sd>{NUMBER})(?: \(p (?P<p>[^)]*)\))?$")
EPISODES_PER_CELL = re.compile(r"(?P<episodes>\d+) episodes per cell")


def ablation_extract(outputs: dict[str, str]) -> dict:
    """The deviations table and the episodes per cell its caption names (the check's intervals need them)."""
    (table,) = markdown_tables(outputs["ablate"])
    match = EPISODES_PER_CELL.search(table["caption"])
    if match is None:
        sys.exit(f"fig7-12-ablation: the table's caption names no episode count: {table['caption']!r}")
    return {"tables": [table], "episodes": int(match["episodes"])}


ABLATION_THESIS_ROW = "thesis (original's result files)"


def ablation_prose(data: dict) -> dict[str, tuple[str | None, str]]:
    """Which model and protocol rows agree with the thesis (every agent's Welch p >= 0.05) and which row comes
    closest to each of the thesis's bars, read off the table."""
    (table,) = data["tables"]
    agents = table["headers"][1:]
    thesis = next(row for row in table["rows"] if row[0] == ABLATION_THESIS_ROW)
    rows = [row for row in table["rows"] if row[0] != ABLATION_THESIS_ROW]

    def cell(row: Sequence[str], agent: str) -> tuple[float, float]:
        match = ABLATION_CELL.match(row[1 + agents.index(agent)])
        return float(match["mean"]), float(match["p"]) if match["p"] not in (None, "n/a") else float("nan")

    agree = [row[0] for row in rows if all(cell(row, agent)[1] >= 0.05 for agent in agents)]
    closest = []
    for agent in agents:
        target = cell(thesis, agent)[0]
        best = min(rows, key=lambda row: abs(cell(row, agent)[0] - target))
        mean, p = cell(best, agent)
        closest.append(f"{agent} {mean:.2f} in \u201c{best[0]}\u201d (thesis {target:.2f}, p {p:.3g})")
    quoted = ", ".join(f"\u201c{label}\u201d" for label in agree) or "none"
    return {
        "readings": (
            None,
            f"At {data['episodes']} episodes per cell, the rows in which no agent differs from the thesis (Welch, "
            f"alpha 0.05): {quoted}. The row closest to each thesis bar: {'; '.join(closest)}.",
        )
    }


def ablation_compare(published: dict, check: dict) -> list[str]:
    """Every cell's second-kernel mean lies inside the published mean's 95 % t-interval (from the published sd
    and the episodes per cell); the rows are matched by their label."""
    failures = []
    (ours,), (theirs,) = published["tables"], check["tables"]
    others = {row[0]: row for row in theirs["rows"]}
    half = T_975.get(published["episodes"], 1.96) / published["episodes"] ** 0.5
    for row in ours["rows"]:
        other = others.get(row[0])
        if other is None:
            failures.append(f"{row[0]}: no such row in the check")
            continue
        for header, cell, their in zip(ours["headers"][1:], row[1:], other[1:], strict=True):
            mine, seen = ABLATION_CELL.match(cell), ABLATION_CELL.match(their)
            if mine is None or mine["p"] is None:
                continue  # the thesis's row: constants
            mean, sd = float(mine["mean"]), float(mine["sd"])
            if seen is None or not mean - half * sd <= float(seen["mean"]) <= mean + half * sd:
                failures.append(
                    f"{row[0]} / {header}: {their} outside the published {mean:.2f} ± {half * sd:.2f}"
                )
    return failures


TEAMSTER_T5000 = ("--trials", "8", "--steps", "5000", "--eval-steps", "100", "--points", "10")
"""Part D's protocol: the thesis's 8 trials and T = 5000 per team, evaluations of 100 steps every 10 %."""
TEAMSTER_LANES = {
    "teamster-plastic-model": "teamster,plastic-model",
    "the-others": "learns-environment,learns-team,plastic-policy,random,original",
}
"""The study in two lanes of about the same CPU time (records depend on the agent and trial, not on the lane)."""
TEAMSTER_TEAMS = ("teammate-aware", "greedy", "probabilistic-destinations")
TEAMSTER_MAPS = ("ntu", "isr", "pentagon")
"""Chapter 4's navigation maps (Tables 4.5-4.7), in the thesis's order."""
TEAMSTER_ORDER = (
    "original",
    "random",
    "plastic-policy",
    "teamster",
    "plastic-model",
    "learns-environment",
    "learns-team",
)
THESIS_TABLE_4_4 = {
    # (after learning, agent) -> the thesis's accumulated episode reward, mean (± its spread), per evaluation team
    ("-", "original"): ((92.84, 6.76), (94.28, 5.35), (94.09, 4.69)),
    ("-", "random"): ((39.84, 63.84), (56.88, 35.47), (45.66, 62.64)),
    ("teammate-aware", "plastic-policy"): ((90.25, 7.77), (82.06, 21.49), (79.31, 19.85)),
    ("teammate-aware", "teamster"): ((92.69, 5.45), (91.47, 4.95), (89.91, 8.01)),
    ("teammate-aware", "plastic-model"): ((93.47, 4.69), (84.28, 12.86), (88.91, 9.55)),
    ("teammate-aware", "learns-environment"): ((85.59, 16.93), (81.78, 15.16), (82.94, 19.45)),
    ("teammate-aware", "learns-team"): ((92.25, 7.33), (90.72, 7.7), (92.72, 5.67)),
    ("greedy", "plastic-policy"): ((86.31, 13.11), (86.81, 11.04), (84.19, 12.6)),
    ("greedy", "teamster"): ((89.22, 11.13), (92.94, 5.7), (90.94, 7.13)),
    ("greedy", "plastic-model"): ((94.66, 2.68), (96.47, 2.83), (92.53, 4.98)),
    ("greedy", "learns-environment"): ((85.62, 11.59), (93.19, 4.81), (89.78, 9.78)),
    ("greedy", "learns-team"): ((90.25, 7.79), (95.66, 3.07), (93.5, 5.41)),
    ("probabilistic-destinations", "plastic-policy"): ((84.81, 13.28), (86.41, 8.26), (76.78, 43.89)),
    ("probabilistic-destinations", "teamster"): ((91.16, 8.64), (94.56, 3.46), (93.06, 5.63)),
    ("probabilistic-destinations", "plastic-model"): ((94.5, 3.83), (94.25, 4.42), (94.88, 3.72)),
    ("probabilistic-destinations", "learns-environment"): ((84.41, 14.19), (93.53, 5.16), (87.81, 12.39)),
    ("probabilistic-destinations", "learns-team"): ((90.38, 9.14), (95.75, 3.64), (94.34, 4.1)),
}
"""Thesis Table 4.4 (pursuit), as printed: the original teammate and random have one row each."""


def teamster_t5000_extract(outputs: dict[str, str]) -> dict:
    """The lanes' ``teamster --json`` summaries as one: per agent its curves and after-learning matrix (captures
    per 500 steps, per-trial values with the mean and bootstrap CI); the seconds per trial are timing."""
    agents, config, seconds = {}, None, {}
    for key, text in outputs.items():
        result = json.loads(text)
        if config is not None and result["config"] != config:
            sys.exit(f"teamster-t5000: lane {key} ran another protocol: {result['config']} vs {config}")
        config = result["config"]
        for agent, entry in result["agents"].items():
            seconds[agent] = entry["seconds"]
            agents[agent] = {
                "trials": entry["trials"],
                "curves": {
                    t: [{"step": p["step"], **p["per_500"]} for p in c] for t, c in entry["curves"].items()
                },
                "after": {
                    learned: {t: cells["per_500"] for t, cells in evals.items()}
                    for learned, evals in entry["after"].items()
                },
            }
    missing = [a for a in TEAMSTER_ORDER if a not in agents]
    if missing:
        sys.exit(f"teamster-t5000: no lane ran {', '.join(missing)}")
    return {
        "config": config,
        "agents": {a: agents[a] for a in TEAMSTER_ORDER},
        "timing": {"wall_seconds_per_trial": seconds},
    }


def _bracket(cell: dict) -> tuple[str, str]:
    low, high = cell["ci"]
    return f"{cell['mean']:.1f}", f"[{low:.1f}, {high:.1f}]"


def teamster_claims(data: dict) -> list[list[str]]:
    """The thesis's claims on Table 4.4 and Fig. 4.7, each tested on the per-trial values (Welch's test where a
    claim says one agent scores more than another)."""
    from embodied_adhoc.experiments.stats import welch_test

    agents = data["agents"]
    last = TEAMSTER_TEAMS[-1]

    def after(agent, learned, team):
        return agents[agent]["after"][learned][team]

    rows = []
    # 1. Fig. 4.7: sample efficiency, the first evaluation after learning began with the first team
    first = {a: agents[a]["curves"][TEAMSTER_TEAMS[0]][1] for a in ("teamster", "plastic-policy")}
    _, pvalue = welch_test(first["teamster"]["values"], first["plastic-policy"]["values"])
    step = first["teamster"]["step"]
    rows.append(
        [
            f"Fig. 4.7: after {step} steps with the first team, TEAMSTER scores more than PLASTIC-Policy",
            f"{first['teamster']['mean']:.1f} vs {first['plastic-policy']['mean']:.1f}, Welch p = {pvalue:.2g}",
            "yes" if first["teamster"]["mean"] > first["plastic-policy"]["mean"] and pvalue < 0.05 else "no",
        ]
    )
    # 2. Table 4.4: after all three teams, TEAMSTER above PLASTIC-Policy on every team
    tests = [
        welch_test(after("teamster", last, t)["values"], after("plastic-policy", last, t)["values"])
        for t in TEAMSTER_TEAMS
    ]
    higher = all(
        after("teamster", last, t)["mean"] > after("plastic-policy", last, t)["mean"] for t in TEAMSTER_TEAMS
    )
    rows.append(
        [
            "Table 4.4: after learning all three teams, TEAMSTER scores more than PLASTIC-Policy on every team",
            "Welch p = " + " / ".join(f"{p:.2g}" for _, p in tests),
            "yes" if higher and all(p < 0.05 for _, p in tests) else "no",
        ]
    )
    # 3. Table 4.4: TEAMSTER close to PLASTIC-Model (the thesis: within 4 % in every cell after all three teams)
    ratios = [
        after("teamster", last, t)["mean"] / max(after("plastic-model", last, t)["mean"], 1e-9)
        for t in TEAMSTER_TEAMS
    ]
    rows.append(
        [
            "Table 4.4: after learning all three teams, TEAMSTER reaches 95 % of PLASTIC-Model on every team "
            "(the thesis: 96-100 %)",
            "TEAMSTER / PLASTIC-Model = " + " / ".join(f"{r:.2f}" for r in ratios),
            "yes" if min(ratios) >= 0.95 else "no",
        ]
    )
    # 4. Section 4.1.4's discussion: on greedy after the first team only, the learned team models beat the
    # hand-coded ones (TEAMSTER 91.47, Learns Team 90.72 against PLASTIC-Model 84.28, Learns Environment 81.78)
    learned, team = TEAMSTER_TEAMS[0], TEAMSTER_TEAMS[1]
    means = {
        a: after(a, learned, team)["mean"]
        for a in ("teamster", "learns-team", "plastic-model", "learns-environment")
    }
    rows.append(
        [
            "Section 4.1.4: on greedy after learning only the first team, TEAMSTER and Learns Team score more than "
            "PLASTIC-Model and Learns Environment",
            ", ".join(f"{a} {m:.1f}" for a, m in means.items()),
            "yes"
            if min(means["teamster"], means["learns-team"])
            > max(means["plastic-model"], means["learns-environment"])
            else "no",
        ]
    )
    return rows


def _end_rows(agents: dict, teams: Sequence[str]) -> tuple[list[str], list[list[str]]]:
    """The headers and rows (agent, then each team's curve end with its interval) of a study's end table."""
    headers = ["agent", *(h for t in teams for h in (f"end of {t}", "95 % CI"))]
    rows = [
        [agent, *(x for t in teams for x in _bracket(entry["curves"][t][-1]))]
        for agent, entry in agents.items()
    ]
    return headers, rows


def _after_table(key: str, caption: str, agents: dict, thesis: dict, teams: Sequence[str]) -> Table:
    """A thesis table's layout (Tables 4.4-4.7): per (after learning, agent) row of ``thesis``, each team's cell with
    its interval beside the thesis's; an agent that learns nothing ("-") reads its row after the last team."""
    rows = []
    for (learned, agent), cells in thesis.items():
        if agent not in agents:
            continue
        ours = agents[agent]["after"][teams[-1] if learned == "-" else learned]
        rows.append(
            [
                learned,
                agent,
                *(
                    x
                    for team, (mean, spread) in zip(teams, cells, strict=True)
                    for x in (*_bracket(ours[team]), f"{mean:.2f} ± {spread:.2f}")
                ),
            ]
        )
    headers = ["after learning", "agent", *(h for t in teams for h in (f"eval {t}", "95 % CI", "thesis"))]
    return Table(key, caption, headers, rows)


def teamster_t5000_tables(data: dict) -> list[Table]:
    agents = data["agents"]
    end_headers, end = _end_rows(agents, TEAMSTER_TEAMS)
    seconds = data["timing"]["wall_seconds_per_trial"]
    return [
        Table("end", "", end_headers, end),
        _after_table("after", "", agents, THESIS_TABLE_4_4, TEAMSTER_TEAMS),
        Table("claims", "", ["claim", "measured", "holds"], teamster_claims(data)),
        Table("seconds", "", ["agent", "wall seconds per trial"], [[a, f"{seconds[a]:.0f}"] for a in agents]),
    ]


def teamster_t5000_plot(data: dict, path: Path) -> object:
    """Fig. 4.7's layout: captures per 500 steps against interaction steps, one panel per team, CI bands."""
    from embodied_adhoc.experiments.domains.teamster import plot_curves

    return plot_curves(_study_summary(data["agents"], "per_500"), path)


TEAMSTER_CHECK_ALPHA = 0.05
"""The family-wise level of the second-kernel check of Part D's cells (Welch per cell, Holm over all cells)."""


def cells_welch_p(first: dict, second: dict) -> float:
    """Welch's p between two cells' per-trial ``values``; two samples without variance (every trial alike) differ
    exactly when their means do (p 0 or 1)."""
    from embodied_adhoc.experiments.stats import welch_test

    p = welch_test(first["values"], second["values"])[1]
    return (1.0 if first["mean"] == second["mean"] else 0.0) if math.isnan(p) else p


def cells_that_differ(cells: Sequence[tuple[str, dict, dict]]) -> list[str]:
    """The cells ``(label, published, check)`` whose per-trial ``values`` differ between two runs: Welch's test per
    cell, Holm-adjusted over every cell, at family-wise level :data:`TEAMSTER_CHECK_ALPHA`."""
    from embodied_adhoc.experiments.stats import holm_adjusted

    pvalues = [cells_welch_p(ours, theirs) for _, ours, theirs in cells]
    return [
        f"{label}: {theirs['mean']:.2f} against the published {ours['mean']:.2f} (Welch p {p:.2g}, "
        f"Holm-adjusted over {len(cells)} cells {adjusted:.2g})"
        for (label, ours, theirs), p, adjusted in zip(cells, pvalues, holm_adjusted(pvalues), strict=True)
        if adjusted < TEAMSTER_CHECK_ALPHA
    ]


def verdicts_that_change(
    ours: list[list[str]], theirs: list[list[str]], width: int | None = None
) -> list[str]:
    """A failure per claim row (claim, measured, verdict) whose verdict differs between two runs, named by the
    claim (its first ``width`` characters where given)."""
    return [
        f"claim '{mine[0][:width]}': {mine[-1]} -> {other[-1]}"
        for mine, other in zip(ours, theirs, strict=True)
        if mine[-1] != other[-1]
    ]


def teamster_t5000_compare(published: dict, check: dict) -> list[str]:
    """No cell (curve ends, the after-learning matrix) differs between the two runs: Welch's test on each cell's
    per-trial values, Holm-adjusted over every cell, at family-wise level :data:`TEAMSTER_CHECK_ALPHA`; every claim
    keeps its verdict. (A second run's mean falls outside the first run's 95 % interval about one time in six for
    two samples of one distribution, so with 84 cells that rule fails a faithful rerun almost surely.)"""
    cells = []
    for agent, entry in published["agents"].items():
        other = check["agents"][agent]
        cells += [
            (agent, f"end of {t}", entry["curves"][t][-1], other["curves"][t][-1]) for t in TEAMSTER_TEAMS
        ]
        cells += [
            (agent, f"after {learned} / eval {t}", entry["after"][learned][t], other["after"][learned][t])
            for learned in entry["after"]
            for t in TEAMSTER_TEAMS
        ]
    failures = cells_that_differ([(f"{agent} {label}", ours, theirs) for agent, label, ours, theirs in cells])
    return failures + verdicts_that_change(teamster_claims(published), teamster_claims(check), 60)


MAP_TEAMS = ("altruistic", "selfish", "weighted-altruistic")
"""The navigation maps' teams tau_1-tau_3 (Sec. 4.1.2), in the thesis's order."""
TEAMSTER_NTU_LANES = {
    "teamster-learns-team": "teamster,learns-team,random",
    "the-others": "learns-environment,plastic-model,plastic-policy,original",
}
"""The ntu study in two lanes of about the same CPU time (records depend on the agent and trial, not the lane)."""
TEAMSTER_NTU = (
    "--trials",
    "2",
    "--steps",
    "500",
    "--points",
    "5",
    "--eval-episodes",
    "8",
    "--changed",
    "0.25",
)
TEAMSTER_EXACT_MAPS = ("isr", "pentagon")
TEAMSTER_EXACT_AGENTS = "learns-team,plastic-model,original"
TEAMSTER_EXACT = ("--trials", "2", "--steps", "200", "--points", "2", "--eval-episodes", "4")
"""isr and pentagon with the agents that plan in the exact environment: two trials of T = 200 per team (TEAMSTER's
learned-model planning at Table 4.1's depths costs tens of CPU minutes per trial there)."""
# Tables 4.5-4.7 as printed: per (after learning, agent) the mean and spread on tau_1, tau_2, tau_3; the original
# teammate and random have one row each.
_THESIS_MAP_ROWS = {
    "ntu": """
        - original 98.0 0.0 98.0 0.0 97.83 0.55 | - random 79.58 22.72 69.0 30.37 69.12 30.12
        altruistic plastic-policy 98.0 0.0 98.0 0.0 97.75 0.66 | altruistic teamster 97.96 0.2 98.0 0.0 97.92 0.4
        altruistic plastic-model 98.0 0.0 97.96 0.2 97.58 0.81
        altruistic learns-environment 98.0 0.0 97.92 0.28 97.96 0.2
        altruistic learns-team 98.0 0.0 97.96 0.2 98.0 0.0
        selfish plastic-policy 98.0 0.0 98.0 0.0 97.92 0.4 | selfish teamster 98.0 0.0 98.0 0.0 97.92 0.4
        selfish plastic-model 97.92 0.28 98.0 0.0 97.92 0.4
        selfish learns-environment 97.83 0.37 97.96 0.2 97.88 0.6
        selfish learns-team 97.92 0.4 98.0 0.0 97.29 1.51
        weighted-altruistic plastic-policy 98.0 0.0 98.0 0.0 98.0 0.0
        weighted-altruistic teamster 98.0 0.0 98.0 0.0 97.88 0.44
        weighted-altruistic plastic-model 98.0 0.0 97.96 0.2 97.67 0.75
        weighted-altruistic learns-environment 97.96 0.2 97.96 0.2 97.96 0.2
        weighted-altruistic learns-team 97.96 0.2 98.0 0.0 97.71 0.68""",
    "isr": """
        - original 94.0 0.0 94.0 0.0 94.0 0.0 | - random 60.0 28.4 69.17 24.5 64.04 22.52
        altruistic plastic-policy 74.0 38.48 88.71 18.99 85.75 26.16
        altruistic teamster 93.04 1.97 80.33 31.05 93.71 0.79
        altruistic plastic-model 92.79 1.55 92.0 2.12 92.71 2.88
        altruistic learns-environment 93.46 1.29 92.29 2.19 92.92 3.12
        altruistic learns-team 92.96 1.88 92.5 3.34 93.33 1.4
        selfish plastic-policy 93.21 1.91 93.12 1.64 93.08 1.75
        selfish teamster 92.96 1.77 93.08 1.98 93.38 1.65
        selfish plastic-model 92.71 2.15 93.17 1.28 93.25 1.05
        selfish learns-environment 93.21 1.63 92.83 1.91 93.12 1.76
        selfish learns-team 92.71 1.86 92.08 3.17 93.33 1.7
        weighted-altruistic plastic-policy 93.29 1.88 93.21 1.63 93.42 0.81
        weighted-altruistic teamster 93.42 1.35 92.75 1.81 93.04 2.01
        weighted-altruistic plastic-model 92.71 2.01 92.62 1.98 93.62 0.7
        weighted-altruistic learns-environment 93.04 1.81 93.21 1.47 92.62 2.67
        weighted-altruistic learns-team 93.0 1.85 91.96 3.96 92.17 2.53""",
    "pentagon": """
        - original 91.67 0.94 88.0 0.0 91.83 0.9 | - random 66.17 29.44 61.92 26.31 80.79 12.8
        altruistic plastic-policy 80.29 30.74 81.54 24.98 76.54 34.69
        altruistic teamster 83.54 25.61 84.29 7.07 91.04 2.68
        altruistic plastic-model 91.12 1.94 82.67 17.79 91.67 1.34
        altruistic learns-environment 91.54 2.38 77.08 26.42 83.42 25.52
        altruistic learns-team 91.83 0.99 83.88 5.95 90.88 1.45
        selfish plastic-policy 91.5 1.87 89.25 1.81 87.46 18.55
        selfish teamster 86.5 18.35 89.17 1.43 90.96 1.65
        selfish plastic-model 91.04 2.51 83.83 12.86 90.5 2.52
        selfish learns-environment 87.83 18.58 85.79 5.47 89.67 5.97
        selfish learns-team 90.79 2.12 88.71 1.34 90.54 1.55
        weighted-altruistic plastic-policy 90.92 2.86 89.04 2.19 91.38 1.49
        weighted-altruistic teamster 83.79 25.15 82.83 9.18 87.62 18.58
        weighted-altruistic plastic-model 91.54 1.61 84.08 10.15 91.21 1.53
        weighted-altruistic learns-environment 84.0 25.66 84.46 17.88 90.83 2.03
        weighted-altruistic learns-team 91.33 1.21 85.38 5.2 91.04 1.62""",
}


def _thesis_map_table(text: str) -> dict[tuple[str, str], tuple[tuple[float, float], ...]]:
    rows = {}
    for row in text.replace("|", "\n").split("\n"):
        if row.strip():
            learned, agent, *numbers = row.split()
            values = [float(x) for x in numbers]
            rows[learned, agent] = tuple(zip(values[::2], values[1::2], strict=True))
    return rows


THESIS_MAP_TABLES = {name: _thesis_map_table(text) for name, text in _THESIS_MAP_ROWS.items()}
"""Thesis Tables 4.5 (ntu), 4.6 (isr) and 4.7 (pentagon): accumulated episode reward, mean (± its spread) over 8
trials, per evaluation team."""


def teamster_study_extract(outputs: dict[str, str]) -> dict:
    """The ``teamster DOMAIN --json`` summaries (one per lane or map) as one document per domain (under ``maps``,
    pursuit included): per agent its curves (each evaluation's mean episode reward on a map, captures per 500 steps
    on pursuit), after-learning matrix and, with a changed phase, that phase's curve, the per-trial robustness
    measure and a learned model's fit to the changed rules; the seconds per trial are timing."""
    from embodied_adhoc.experiments.domains.teamster import trial_cell

    maps, seconds = {}, {}
    for key, text in outputs.items():
        result = json.loads(text)
        config, domain = result["config"], result["domain"]
        entry = maps.setdefault(domain, {"config": config, "agents": {}})
        if entry["config"] != config:
            sys.exit(f"teamster study: {key} ran another protocol: {config} vs {entry['config']}")
        for agent, summary in result["agents"].items():
            metric = summary["metric"]
            seconds.setdefault(domain, {})[agent] = summary["seconds"]
            cells = {
                "trials": summary["trials"],
                "curves": {
                    t: [{"step": p["step"], **p[metric]} for p in c] for t, c in summary["curves"].items()
                },
                "after": {
                    learned: {t: cell[metric] for t, cell in evals.items()}
                    for learned, evals in summary["after"].items()
                },
            }
            if "changed_after" in summary:
                cells["changed"] = [{"step": p["step"], **p[metric]} for p in summary["changed"]]
                cells["changed_after"] = trial_cell(summary["changed_after"], 1.0)
            if "changed_fit" in summary:
                cells["changed_fit"] = summary["changed_fit"]
            entry["agents"][agent] = cells
    for entry in maps.values():
        entry["agents"] = {a: entry["agents"][a] for a in TEAMSTER_ORDER if a in entry["agents"]}
    return {"maps": maps, "timing": {"wall_seconds_per_trial": seconds}}


def _map_cells(data: dict) -> list[tuple[str, str, str, dict]]:
    """Every cell of a sequential-teams study that a check compares: (domain, agent, label, cell)."""
    cells = []
    for name, entry in data["maps"].items():
        for agent, summary in entry["agents"].items():
            cells += [(name, agent, f"end of {t}", curve[-1]) for t, curve in summary["curves"].items()]
            cells += [
                (name, agent, f"after {learned} / eval {t}", cell)
                for learned, evals in summary["after"].items()
                for t, cell in evals.items()
            ]
            if "changed_after" in summary:
                cells.append((name, agent, "changed environment", summary["changed_after"]))
    return cells


def teamster_ntu_claims(data: dict) -> list[list[str]]:
    """Sec. 4.1.4 on Tables 4.4-4.7: experience with one team gives near-optimal play with the other two, most
    evident on ntu; tested on the agents that plan in the exact environment (the others learn it first)."""
    agents = data["maps"]["ntu"]["agents"]
    first = MAP_TEAMS[0]
    original = {t: agents["original"]["after"][MAP_TEAMS[-1]][t]["mean"] for t in MAP_TEAMS}
    ratios = {
        a: min(agents[a]["after"][first][t]["mean"] / original[t] for t in MAP_TEAMS[1:])
        for a in ("plastic-model", "learns-team")
    }
    return [
        [
            "Sec. 4.1.4: on ntu, after learning only the first team, the exact-environment agents reach 95 % of the "
            "original teammate on the two other teams",
            ", ".join(f"{a} {r:.3f}" for a, r in ratios.items()) + " (lowest ratio)",
            "yes" if min(ratios.values()) >= 0.95 else "no",
        ]
    ]


def _with_changed(headers: list[str], rows: list[list[str]], agents: dict, label: str) -> list[str]:
    """Append the changed environment's measure and its interval to an end table (in place); its headers."""
    for row, summary in zip(rows, agents.values(), strict=True):
        row += _bracket(summary["changed_after"])
    return [*headers, label, "95 % CI"]


def _map_study_tables(name: str, entry: dict, prefix: str) -> list[Table]:
    agents = entry["agents"]
    end_headers, end = _end_rows(agents, MAP_TEAMS)
    if any("changed_after" in a for a in agents.values()):
        end_headers = _with_changed(end_headers, end, agents, "changed environment")
    caption = f"{name}: after learning each team (Table 4.{5 + TEAMSTER_MAPS.index(name)})"
    return [
        Table(
            f"{prefix}end", f"{name}: mean episode reward at the end of each interaction", end_headers, end
        ),
        _after_table(f"{prefix}after", caption, agents, THESIS_MAP_TABLES[name], MAP_TEAMS),
    ]


def _map_seconds_table(data: dict) -> Table:
    seconds = data["timing"]["wall_seconds_per_trial"]
    rows = [
        [name, agent, f"{s:.0f}"] for name, per_agent in seconds.items() for agent, s in per_agent.items()
    ]
    return Table("seconds", "", ["map", "agent", "wall seconds per trial"], rows)


def teamster_ntu_tables(data: dict) -> list[Table]:
    return [
        *_map_study_tables("ntu", data["maps"]["ntu"], ""),
        Table("claims", "", ["claim", "measured", "holds"], teamster_ntu_claims(data)),
        _map_seconds_table(data),
    ]


def teamster_exact_maps_tables(data: dict) -> list[Table]:
    tables = [
        t for name in TEAMSTER_EXACT_MAPS for t in _map_study_tables(name, data["maps"][name], f"{name}-")
    ]
    return [*tables, _map_seconds_table(data)]


def teamster_study_compare(
    claims: Callable[[dict], list[list[str]]] | None = None,
) -> Callable[[dict, dict], list[str]]:
    """As :func:`teamster_t5000_compare`, on a sequential-teams study's cells (curve ends, the after-learning
    matrix, the changed environment's measure): Welch per cell on the per-trial values, Holm over every cell; the
    ``claims`` keep their verdicts."""

    def compare(published: dict, check: dict) -> list[str]:
        ours, theirs = _map_cells(published), _map_cells(check)
        if [c[:3] for c in ours] != [c[:3] for c in theirs]:
            return ["the check ran other domains, agents or teams than the published run"]
        failures = cells_that_differ(
            [
                (f"{name} {agent} {label}", a, b)
                for (name, agent, label, a), (*_, b) in zip(ours, theirs, strict=True)
            ]
        )
        return failures + (verdicts_that_change(claims(published), claims(check)) if claims else [])

    return compare


TEAMSTER_CHECKED = (
    "no cell differs from the published run (Welch's test on the per-trial values, Holm-adjusted over every cell, "
    "family-wise level 0.05)"
)
"""What the second-kernel check of a TEAMSTER study asserts (:func:`cells_that_differ`)."""


def teamster_commands(
    domain: str | None, lanes: dict[str, str], protocol: Sequence[str]
) -> dict[str, list[str]]:
    """One ``teamster DOMAIN --agents AGENTS PROTOCOL --json`` command per lane (``domain`` None: the lane's key is
    the domain)."""
    return {
        key: [
            ".venv/bin/embodied-adhoc", "teamster", domain or key, "--agents", agents, *protocol,
            "--out", "{out}", "--json", "--quiet",
        ]
        for key, agents in lanes.items()
    }  # fmt: skip


TEAMSTER_T500 = ("--steps", "500", "--eval-steps", "50", "--points", "5")
"""Parts B2, B3 and the Mixed team: T = 500 per team, 50-step evaluations at every 20 %."""
TEAMSTER_CHANGED = ("--trials", "12", *TEAMSTER_T500, "--changed", "0.5")
"""Part B2: 12 trials at T = 500 per team, 50-step evaluations at every 20 %, then predator moves fail w.p. 0.5."""
TEAMSTER_MIRROR = ("--trials", "8", *TEAMSTER_T500, "--changed", "mirror", "--changed-steps", "2500")
"""Part B3: 8 trials at T = 500 per team, then 2,500 steps with the ad hoc agent's moves mirrored."""
TEAMSTER_MIRROR_LANES = {"teamster": "teamster", "the-others": "plastic-model,learns-team,plastic-policy"}


def _pursuit_changed_claims(data: dict, rivals: Sequence[str]) -> list[list[str]]:
    """Sec. 4.1.4's robustness claim on the pre-stated measure (each trial's mean evaluation after learning began
    in the changed environment): TEAMSTER scores more than each of ``rivals``, Welch p < 0.05."""
    from embodied_adhoc.experiments.stats import welch_test

    agents = data["maps"]["pursuit"]["agents"]
    ours = agents["teamster"]["changed_after"]
    rows = []
    for rival in rivals:
        theirs = agents[rival]["changed_after"]
        t, p = welch_test(ours["values"], theirs["values"])
        rows.append(
            [
                f"Sec. 4.1.4: in the changed environment TEAMSTER scores more than {rival}",
                f"{ours['mean']:.1f} vs {theirs['mean']:.1f}, Welch t = {t:.2f}, p = {p:.2g}",
                "yes" if ours["mean"] > theirs["mean"] and p < 0.05 else "no",
            ]
        )
    return rows


def teamster_changed_claims(data: dict) -> list[list[str]]:
    return _pursuit_changed_claims(data, ("plastic-model",))


def teamster_mirror_claims(data: dict) -> list[list[str]]:
    return _pursuit_changed_claims(data, ("plastic-model", "learns-team"))


def _pursuit_study_tables(data: dict, claims: Callable[[dict], list[list[str]]]) -> list[Table]:
    """The changed-environment studies on pursuit: the curves' ends and the pre-stated measure per agent, the
    changed phase's curve, Welch's test between every two agents on the measure, the learned environment model's
    fit to the changed rules, the claims and the seconds per trial."""
    from embodied_adhoc.experiments.stats import compare_pairs

    agents = data["maps"]["pursuit"]["agents"]
    end_headers, end = _end_rows(agents, list(next(iter(agents.values()))["curves"]))
    end_headers = _with_changed(end_headers, end, agents, "changed environment, after learning began")
    steps = [p["step"] for p in next(iter(agents.values()))["changed"]]
    changed = [
        [agent, *(x for p in summary["changed"] for x in _bracket(p))] for agent, summary in agents.items()
    ]
    pairs = [
        [f"{c.first} vs {c.second}", f"{c.statistic:.2f}", f"{c.p_value:.2g}", f"{c.improvement:.2f}"]
        for c in compare_pairs(
            {a: s["changed_after"]["values"] for a, s in agents.items()}, "changed", lower_is_better=False
        )
    ]
    fit = [
        [agent, *(f"{p['share']['mean']:.2f}" for p in summary["changed_fit"])]
        for agent, summary in agents.items()
        if "changed_fit" in summary
    ]
    tables = [
        Table("end", "", end_headers, end),
        Table("changed", "", ["agent", *(h for s in steps for h in (f"{s} steps", "95 % CI"))], changed),
        Table("pairs", "", ["a vs b", "Welch t", "p", "P(a scores more)"], pairs),
    ]
    if fit:
        fit_steps = [p["step"] for p in next(s for s in agents.values() if "changed_fit" in s)["changed_fit"]]
        tables.append(Table("fit", "", ["agent", *(f"{s} steps" for s in fit_steps)], fit))
    return [
        *tables,
        Table("claims", "", ["claim", "measured", "holds"], claims(data)),
        _map_seconds_table(data),
    ]


def teamster_changed_tables(data: dict) -> list[Table]:
    return _pursuit_study_tables(data, teamster_changed_claims)


def teamster_mirror_tables(data: dict) -> list[Table]:
    return _pursuit_study_tables(data, teamster_mirror_claims)


TEAMSTER_MIXED = ("--trials", "8", *TEAMSTER_T500, "--mixed-steps", "1500")
"""Section 4.1.5's Mixed team at a tenth of the thesis's scale: 8 trials, T = 500 per team, then three times T with
the Mixed team, evaluated every 100 steps."""
TEAMSTER_MIXED_LANES = {"teamster": "teamster", "the-others": "plastic-model,plastic-policy"}
MIXED_EARLY = 6
"""The thesis's "first six evaluation checkpoints" of the Mixed phase, where TEAMSTER "hints of a better
performance" than PLASTIC-Policy."""


def _mixed_early(summary: dict) -> list[float]:
    """Each trial's mean over the Mixed phase's first :data:`MIXED_EARLY` evaluations after learning began."""
    points = summary["curves"]["mixed"][1 : 1 + MIXED_EARLY]
    trials = len(points[0]["values"])
    return [sum(p["values"][k] for p in points) / len(points) for k in range(trials)]


def teamster_mixed_claims(data: dict) -> list[list[str]]:
    """Fig. 4.12's reading (section 4.1.5): PLASTIC-Model learns most stably, TEAMSTER leads PLASTIC-Policy early,
    and by the end every agent reaches the same level."""
    from embodied_adhoc.experiments.stats import welch_test

    agents = data["maps"]["pursuit"]["agents"]
    mixed = {a: s["curves"]["mixed"][1:] for a, s in agents.items()}
    widths = {a: sum(p["ci"][1] - p["ci"][0] for p in c) / len(c) for a, c in mixed.items()}
    early = {a: _mixed_early(s) for a, s in agents.items()}
    t, p = welch_test(early["teamster"], early["plastic-policy"])
    means = {a: sum(v) / len(v) for a, v in early.items()}
    last = {a: c[-1] for a, c in mixed.items()}
    ends = {(a, b): cells_welch_p(last[a], last[b]) for a, b in itertools.combinations(last, 2)}
    return [
        [
            "Fig. 4.12: PLASTIC-Model learns the Mixed team most stably (the narrowest mean 95 % interval over the "
            "phase's evaluations)",
            ", ".join(f"{a} {w:.1f}" for a, w in widths.items()),
            "yes" if min(widths, key=widths.get) == "plastic-model" else "no",
        ],
        [
            f"Fig. 4.12: over the Mixed phase's first {MIXED_EARLY} evaluations TEAMSTER scores more than "
            "PLASTIC-Policy",
            f"{means['teamster']:.1f} vs {means['plastic-policy']:.1f}, Welch t = {t:.2f}, p = {p:.2g}",
            "yes" if means["teamster"] > means["plastic-policy"] and p < 0.05 else "no",
        ],
        [
            "Fig. 4.12: by the end of the Mixed phase every agent reaches the same level (no pair differs at its last "
            "evaluation, Welch p >= 0.05)",
            ", ".join(f"{a} {last[a]['mean']:.1f}" for a in last)
            + "; p "
            + ", ".join(f"{pv:.2g}" for pv in ends.values()),
            "yes" if all(pv >= 0.05 for pv in ends.values()) else "no",
        ],
    ]


def teamster_mixed_tables(data: dict) -> list[Table]:
    agents = data["maps"]["pursuit"]["agents"]
    end_headers, end = _end_rows(agents, list(next(iter(agents.values()))["curves"]))
    steps = [p["step"] for p in next(iter(agents.values()))["curves"]["mixed"]]
    shown = [i for i, step in enumerate(steps) if step % 300 == 0]
    mixed = [
        [agent, *(x for i in shown for x in _bracket(summary["curves"]["mixed"][i]))]
        for agent, summary in agents.items()
    ]
    return [
        Table("end", "", end_headers, end),
        Table("mixed", "", ["agent", *(h for i in shown for h in (f"{steps[i]} steps", "95 % CI"))], mixed),
        Table("claims", "", ["claim", "measured", "holds"], teamster_mixed_claims(data)),
        _map_seconds_table(data),
    ]


def _study_summary(agents: dict, metric: str) -> dict:
    """A study's agents in the shape of :func:`embodied_adhoc.experiments.domains.teamster.summarise`, which its
    plots read (``metric``: per_500 on pursuit, reward on a map)."""
    out = {}
    for agent, entry in agents.items():
        summary = {
            "metric": metric,
            "curves": {t: [{"step": p["step"], metric: p} for p in c] for t, c in entry["curves"].items()},
        }
        if "changed" in entry:
            summary["changed"] = [{"step": p["step"], metric: p} for p in entry["changed"]]
        if "changed_fit" in entry:
            summary["changed_fit"] = entry["changed_fit"]
        out[agent] = summary
    return out


def teamster_curves_plot(domain: str) -> Callable[[dict, Path], object]:
    def plot(data: dict, path: Path) -> object:
        from embodied_adhoc.experiments.domains.teamster import plot_curves

        agents = data["maps"][domain]["agents"]
        return plot_curves(_study_summary(agents, "per_500" if domain == "pursuit" else "reward"), path)

    return plot


def teamster_changed_plot(data: dict, path: Path) -> object:
    from embodied_adhoc.experiments.domains.teamster import plot_changed

    return plot_changed(_study_summary(data["maps"]["pursuit"]["agents"], "per_500"), path)


ATLPO_TEAMS_COLUMNS = (1, 2, 3, 4, 6, 8, 10)
"""The transitions after which the team-identifiability table reads each accuracy."""
ATLPO_TEAMS_RUNS = {
    "foraging": ("--domain", "foraging"),
    "pursuit": ("--domain", "pursuit"),
    "foraging-10x": (
        "--domain",
        "foraging",
        "--train-episodes",
        "2560",
        "--iterations",
        "2400",
        "--views",
        "5",
    ),
}
"""The diagnostic per domain with the library's classifier settings, and LBF's 5x5 classifier with ten times the
episodes and four times the iterations."""
_ATLPO_DOMAIN_LABEL = {"foraging": "LBF", "pursuit": "pursuit"}


def atlpo_teams_extract(outputs: dict[str, str]) -> dict:
    return {"runs": {key: json.loads(text.strip().splitlines()[-1]) for key, text in outputs.items()}}


def _atlpo_teams_series(data: dict) -> list[tuple[str, list[float], list[int], list[float] | None]]:
    """(row label, held-out accuracy per step, episodes per step, training accuracy per step or None)."""
    series = []
    for key, run in data["runs"].items():
        label = _ATLPO_DOMAIN_LABEL[run["domain"]]
        if key == run["domain"]:
            reach = run["episodes_reaching_step"]
            series.append(
                (
                    f"{label}, oracle (full state, exact team models)",
                    run["oracle_full_state_held_out"],
                    reach,
                    None,
                )
            )
        for view in (5, 9):
            if f"classifier_view{view}_held_out" not in run:
                continue
            window = "5x5" if view == 5 else "9x9 (full view)"
            more = (
                f", {run['train_episodes_per_team']:,} episodes per team and {run['iterations']:,} iterations"
                if key != run["domain"]
                else ""
            )
            series.append(
                (
                    f"{label}, classifier on {window}{more}, held out (training)",
                    run[f"classifier_view{view}_held_out"],
                    run[f"classifier_view{view}_held_out_episodes"],
                    run[f"classifier_view{view}_training"],
                )
            )
    return series


def atlpo_teams_claims(data: dict) -> list[list[str]]:
    """Section 6's reading of the diagnostic: the teams are distinguishable from the full state, the classifier is
    far below that bound whatever its window, and more data lifts it."""
    runs, t = data["runs"], ATLPO_TEAMS_COLUMNS[-1]
    rows = []
    oracle = {d: runs[d]["oracle_full_state_held_out"][t] for d in ("foraging", "pursuit")}
    rows.append(
        [
            f"the teams are distinguishable: the oracle's accuracy after {t} transitions is above 0.8 on both domains",
            ", ".join(f"{_ATLPO_DOMAIN_LABEL[d]} {v:.2f}" for d, v in oracle.items()),
            "yes" if min(oracle.values()) > 0.8 else "no",
        ]
    )
    for view, what in ((5, "on ATLPO's 5x5 window"), (9, "with the whole grid in view (9x9)")):
        gaps = {d: oracle[d] - runs[d][f"classifier_view{view}_held_out"][t] for d in oracle}
        rows.append(
            [
                f"the classifier {what} stays more than 0.2 below the oracle after {t} transitions on both domains",
                ", ".join(f"{_ATLPO_DOMAIN_LABEL[d]} gap {v:.2f}" for d, v in gaps.items()),
                "yes" if min(gaps.values()) > 0.2 else "no",
            ]
        )
    more, base = (
        runs["foraging-10x"]["classifier_view5_held_out"][t],
        runs["foraging"]["classifier_view5_held_out"][t],
    )
    rows.append(
        [
            f"it is data-limited: ten times the episodes lift LBF's 5x5 classifier after {t} transitions by more "
            "than 0.1",
            f"{base:.2f} -> {more:.2f}",
            "yes" if more - base > 0.1 else "no",
        ]
    )
    return rows


def atlpo_teams_tables(data: dict) -> list[Table]:
    rows = []
    for label, held_out, _, training in _atlpo_teams_series(data):
        cells = [
            f"{held_out[t]:.2f}" if training is None else f"{held_out[t]:.2f} ({training[t]:.2f})"
            for t in ATLPO_TEAMS_COLUMNS
        ]
        rows.append([label, *cells])
    headers = ["", *(f"t={t}" if i == 0 else str(t) for i, t in enumerate(ATLPO_TEAMS_COLUMNS))]
    return [
        Table("accuracy", "", headers, rows),
        Table("claims", "", ["claim", "measured", "holds"], atlpo_teams_claims(data)),
    ]


def atlpo_teams_compare(published: dict, check: dict) -> list[str]:
    """No held-out accuracy differs between the two runs (Fisher's exact test on each cell's correct and wrong
    episodes, Holm-adjusted over every cell and step shown, family-wise level 0.05), and every claim keeps its
    verdict. Training accuracies are the fit, not a measurement on held-out episodes, and are not tested."""
    from scipy import stats

    from embodied_adhoc.experiments.stats import holm_adjusted

    cells = []
    for (label, ours, counts, _), (_, theirs, their_counts, _) in zip(
        _atlpo_teams_series(published), _atlpo_teams_series(check), strict=True
    ):
        for t in ATLPO_TEAMS_COLUMNS:
            a, n, b, m = (
                round(ours[t] * counts[t]),
                counts[t],
                round(theirs[t] * their_counts[t]),
                their_counts[t],
            )
            cells.append(
                (f"{label} t={t}", ours[t], theirs[t], stats.fisher_exact([[a, n - a], [b, m - b]])[1])
            )
    adjusted = holm_adjusted([c[-1] for c in cells])
    failures = [
        f"{label}: {theirs:.2f} against the published {ours:.2f} (Fisher p {p:.2g}, Holm-adjusted over "
        f"{len(cells)} cells {q:.2g})"
        for (label, ours, theirs, p), q in zip(cells, adjusted, strict=True)
        if q < 0.05
    ]
    return failures + verdicts_that_change(atlpo_teams_claims(published), atlpo_teams_claims(check))


SIDE_BY_SIDE_MODELS = (
    "{corpus}/sarsop-TagAvoid.pomdp",
    "{corpus}/cit.POMDP",
    "{corpus}/hallway2.POMDP",
    "rocksample:5,6",
    "rocksample:5,7",
    "rocksample:7,8",
    "random:250,5,10",
    "export:isr@perseus",
    "export:isr",
    "export:pentagon",
)
"""The side-by-side's models: three of the classic corpus with many observations, this project's RockSample
instances (few observations, 1,601 to 12,545 states), a 250-state random model and two chapter-5 navigation
models (81 observations), isr's under Perseus too, the default rule's choice there before the rule read the
start and the sensor."""
SIDE_BY_SIDE_CHECKPOINTS = ("5", "20", "60")


def side_by_side_extract(outputs: dict[str, str]) -> dict:
    """``bench_solvers.py --side-by-side ... --json-out -``'s document, with the SHA-256 of the ``pomdpsol`` it ran:
    every number in it is a bound reached within CPU seconds, or a time or a peak (class timing)."""
    document = json.loads(outputs["bench"].strip().splitlines()[-1])
    binary = document.get("pomdpsol")
    if binary is None:
        sys.exit(
            "solvers-side-by-side: pomdpsol is not on the PATH; build SARSOP (docs/pomdp.md) and put it there"
        )
    digest = hashlib.sha256(Path(binary).read_bytes()).hexdigest()
    return {"timing": {**document, "pomdpsol_sha256": digest}}


def side_by_side_tables(data: dict) -> list[Table]:
    """``bench_solvers.py --side-by-side``'s rows: each solver's lower / upper bound at each checkpoint, the time
    this project needs to reach SARSOP's final lower bound, whether each closed its gap, and both peaks."""
    data = data.get("timing", data)
    rows, checkpoints = [], list(data["rows"][0]["ours"]) if data["rows"] else []

    def bounds(pair: Sequence[float] | None) -> str:
        return "-" if pair is None else f"{pair[0]:.4f} / {pair[1]:.4f}"

    def certificate(row: dict, who: str) -> str:
        if who + "_converged" not in row:  # a file written before the solvers' convergence was recorded
            return "-"
        seconds = row[who + "_seconds_to_converge"]
        if not row[who + "_converged"]:
            return "no"
        return "yes" if seconds is None else f"yes ({seconds:.1f} s)"

    certified = any("ours_converged" in row for row in data["rows"])
    for row in data["rows"]:
        sarsop = row.get("sarsop", {})
        reached = row.get("ours_seconds_to_sarsop_lower")
        if not sarsop:
            to_sarsop, memory = "-", f"{row['ours_peak_mb']:.0f} MB / -"
        else:
            to_sarsop = (
                f"never (target {row['sarsop_final_lower']:.4f})"
                if reached is None
                else f"{reached:.1f} s ({row['time_ratio']:.2f}x)"
            )
            memory = (
                f"{row['ours_peak_mb']:.0f} / {row['sarsop_peak_mb']:.0f} MB ({row['memory_ratio']:.1f}x)"
                if row.get("memory_ratio")
                else f"{row['ours_peak_mb']:.0f} MB / - (pomdpsol ended before its memory was read)"
            )
        cells = [cell for t in checkpoints for cell in (bounds(row["ours"][t]), bounds(sarsop.get(t)))]
        converged = [f"{certificate(row, 'ours')} / {certificate(row, 'sarsop')}"] if certified else []
        rows.append(
            [
                row["file"],
                str(row["states"]),
                str(row["observations"]),
                row["solver"],
                *cells,
                to_sarsop,
                *converged,
                memory,
            ]
        )
    clock = data["rows"][0]["clock"] if data["rows"] else "cpu"
    headers = [
        "file",
        "S",
        "Z",
        "solver",
        *(f"{who} {t} s" for t in checkpoints for who in ("ours", "SARSOP")),
        f"our {clock} s to SARSOP's final lower bound (ratio to the budget)",
        *(["converged ours / SARSOP (gap <= 0.001 at b0)"] if certified else []),
        "peak memory ours / SARSOP (ratio)",
    ]
    return [Table("rows", "", headers, rows)]


FIGURES = {
    figure.name: figure
    for figure in (
        Figure(
            "tiger",
            "Tiger (tiger.95): Perseus's value at b0",
            {"solve": [".venv/bin/embodied-adhoc", "pomdp", "solve", "tiger.95.POMDP", "--json"]},
            tiger_extract,
            tiger_tables,
            compare_bracket,
            ("docs/pomdp.md",),
            checked="the second kernel's lower bound lies inside the published [lower, upper] bracket",
        ),
        Figure(
            "lab-agents",
            "HOTSPOT lab: ATPO, BOPA and HOTSPOT on the episodes of Figs. 7.8-7.11 "
            "(abstract, 32 episodes, seed 7)",
            {
                "trials": [
                    ".venv/bin/embodied-adhoc",
                    "trials",
                    "toxic-waste",
                    "--agents",
                    "atpo,bopa,hotspot",
                    "--episodes",
                    "32",
                    "--seed",
                    "7",
                    "--confusion",
                    "thesis",
                    "--workers",
                    "1",
                    "--json",
                ]
            },
            lab_agents_extract,
            lab_agents_tables,
            lambda published, check: compare_trial_agents(published["agents"], check["agents"]),
            ("docs/hotspot.md",),
        ),
        Figure(
            "arenas",
            "Foraging and pursuit arenas: the original teammate and random in the ad hoc seat "
            "(grid twin, seed 0)",
            {"-".join(cell): arena_command(*cell) for cell in ARENA_CELLS},
            arenas_extract,
            arenas_tables,
            arenas_compare,
            ("docs/arenas.md",),
            partial_checks=True,
            notes="Mean steps ± sd to finish and the 95 % bootstrap interval of the mean, cap 200 "
            "(150 for the pair "
            "rows, 32 episodes each); a failure counts as the cap. The thesis does not state its cap.",
        ),
        Figure(
            "sim-vs-physics",
            "HOTSPOT lab: the same episodes on the abstract simulator and on physics (32 episodes, seed 7)",
            {
                "trials": [
                    ".venv/bin/embodied-adhoc",
                    "trials",
                    "toxic-waste",
                    "--backend",
                    "abstract,mujoco",
                    "--agents",
                    "hotspot,known-task",
                    "--episodes",
                    "32",
                    "--seed",
                    "7",
                    "--confusion",
                    "thesis",
                    "--workers",
                    "1",
                    "--json",
                ]
            },
            physics_extract,
            physics_tables,
            physics_compare,
            ("docs/hotspot.md", "README.md"),
            notes="Steps to finish, mean ± sd; the Welch test compares the backends' episodes per agent.",
        ),
        Figure(
            "bench-trials",
            "Trial runner speed on the abstract lab (32 trials x 4 agents, cold caches)",
            {"bench": ["{python}", "scripts/bench_trials.py"]},
            bench_trials_extract,
            bench_trials_tables,
            None,
            ("docs/hotspot.md",),
            notes="Seconds on the machine named below, at its load then; ratios are to raw POMDP.step "
            "sampling "
            "measured in the same run.",
        ),
        Figure(
            "hotspot",
            "HOTSPOT: thesis Figs. 7.8, 7.9 and 7.11 (abstract simulator, 32 episodes, seed 7, cap 100)",
            {"reproduce": ["{python}", "scripts/reproduce_hotspot.py", "--out", "{out}", "--markdown"]},
            markdown_extract("reproduce"),
            markdown_figure_tables(("steps", "claims")),
            compare_markdown_tables,
            ("docs/hotspot.md", "README.md"),
            markdown=True,
            prose=hotspot_prose,
        ),
        Figure(
            "bopa",
            "BOPA: thesis Table 5.1 (Panic Buttons, 32 episodes per agent and setting, seed 0)",
            {"reproduce": ["{python}", "scripts/reproduce_bopa.py", "--out", "{out}", "--markdown"]},
            markdown_extract("reproduce"),
            markdown_figure_tables(("table5_1", "bopa_vs_greedy")),
            compare_markdown_tables,
            ("docs/atpo.md",),
            markdown=True,
        ),
        Figure(
            "chapter5",
            "ATPO: thesis Tables 5.5 and 5.6 and the belief dynamics "
            "(32 episodes per agent and domain, seed 0)",
            {"reproduce": reproduce_atpo_command("--skip-fig59")},
            markdown_extract("reproduce"),
            markdown_figure_tables(("table5_5", "table5_6", "beliefs")),
            compare_markdown_tables,
            ("docs/atpo.md", "README.md"),
            markdown=True,
            prose=chapter5_prose,
        ),
        Figure(
            "chapter5-bugs",
            "ATPO: Tables 5.5 and 5.6 on ntu, mit and overcooked beside the same domains rebuilt with the "
            "original's model bugs (32 episodes per agent and domain, seed 0)",
            {
                "reproduce": reproduce_atpo_command(
                    "--domains", "ntu", "mit", "overcooked", "--with-bugs", "--skip-fig59"
                )
            },
            markdown_extract("reproduce"),
            markdown_figure_tables(("table5_5", "table5_6", "beliefs")),
            compare_markdown_tables,
            ("docs/atpo.md",),
            markdown=True,
            notes="Rows '(bug)' rebuild the domain with the original implementation's model bug "
            "(`bug_compatible`); the other rows are the fixed models, as in Table 5.5's figure.",
            prose=chapter5_bugs_prose,
        ),
        Figure(
            "arena-tasks",
            "Foraging and pursuit arenas: each team with its original teammate on each task "
            "(grid twin, 16 episodes per cell, seed 0)",
            {
                f"{domain}-{team}-task{task}": arena_task_command(domain, team, task)
                for domain in ARENA_TASK_DOMAINS
                for team in ARENA_TEAMS
                for task in range(1, 5)
            },
            arenas_extract,
            arena_tasks_tables,
            arenas_compare,
            ("docs/arenas.md",),
            partial_checks=True,
            notes="Mean steps to finish, the 95 % bootstrap interval of the mean and the share solved within the "
            "cap of 200 steps.",
        ),
        Figure(
            "arena-tasks-mujoco",
            "Foraging and pursuit arenas on MuJoCo physics: each team with its original teammate on each task "
            "(4 episodes per cell, seed 0), and random beside tau1",
            {
                **{
                    f"{domain}-{team}-task{task}": arena_task_command(domain, team, task, "mujoco", 4)
                    for domain in ARENA_TASK_DOMAINS
                    for team in ARENA_TEAMS
                    for task in range(1, 5)
                },
                **{
                    f"{domain}-{ARENA_RANDOM_TEAM}-random": arena_task_command(
                        domain, ARENA_RANDOM_TEAM, None, "mujoco", 4, "random"
                    )
                    for domain in ARENA_TASK_DOMAINS
                },
            },
            arenas_extract,
            arena_tasks_mujoco_tables,
            arenas_compare,
            ("docs/arenas.md",),
            partial_checks=True,
            notes="Mean steps to finish, the 95 % bootstrap interval of the mean (4 episodes: a wide one) and the "
            "share solved within the cap of 200 steps; random's episodes draw their task, a capped one counts 200.",
        ),
        Figure(
            "sim-tours",
            "Physics lab: dead reckoning over full tours and the simulator's rates (10 tours, seeds 0-9)",
            {"bench": ["{python}", "scripts/bench_sim.py", "--tours", "10"]},
            bench_sim_extract,
            bench_sim_tables,
            bench_sim_compare,
            ("docs/sim.md",),
            timing_tables=("speed",),
            checked="every tour arrives at every node with a correct node estimate and no wall contact in both "
            "runs, and the second kernel's mean drift lies inside the published mean's 95 % t-interval",
            notes="Each tour starts at the door and drives every edge in both directions at the default encoder "
            "noise and wheel slip; the rates are per CPU second of the process (physics) and per wall second "
            "(rendering), on the machine and at the load of the run.",
        ),
        Figure(
            "tag-fixed-set",
            "Tag (sarsop-TagAvoid): the fixed-set solver with classic Perseus stages, and what its saved policy "
            "earns",
            {
                "solve": [
                    ".venv/bin/embodied-adhoc",
                    "pomdp",
                    "solve",
                    "{corpus}/sarsop-TagAvoid.pomdp",
                    "--beliefs",
                    "1000",
                    "--seed",
                    "0",
                    "--update",
                    "perseus",
                    "--no-expand",
                    "--simulate",
                    "2000",
                    "--json",
                ]
            },
            tag_extract,
            tag_tables,
            tag_compare,
            ("docs/pomdp.md",),
            checked="the second kernel's claimed value lies inside the published [lower, upper] bracket and its "
            "simulated mean inside the published 95 % interval",
        ),
        Figure(
            "speech-confusions",
            "HOTSPOT lab with the thesis's and the measured speech confusion (abstract, 32 episodes, seed 7)",
            {confusion: speech_confusion_command(confusion) for confusion in SPEECH_CONFUSIONS},
            arenas_extract,
            speech_confusions_tables,
            arenas_compare,
            ("docs/speech.md",),
            prose=speech_confusions_prose,
            partial_checks=True,
            notes="The matrix is both the env's channel and the agents' model; a task counts as identified when its "
            "posterior leads every other task by more than 1e-6.",
        ),
        Figure(
            "speech-tuning",
            "Speech recogniser settings: dictionary, beams and adaptation on the tuning set (seed 1, 60 phrases per "
            "voice, clean speech)",
            {"tune": ["{python}", "scripts/tune_speech.py", "--workers", "1"]},
            speech_tuning_extract,
            speech_tuning_tables,
            compare_markdown_tables,
            ("docs/speech.md",),
            timing_tables=("cpu",),
            notes="Seven settings of the recogniser, each decoding the same synthesised utterances (espeak-ng, six "
            "voices); the eval's held-out utterances use seed 0 and the MLLR transform seed 2.",
        ),
        Figure(
            "fig7-12",
            "Fig. 7.12 in the pursuit arena: seven agents on the grid twin and on MuJoCo physics "
            "(32 episodes per agent and backend, seed 0, cap 150)",
            {
                "reproduce": [
                    "{python}",
                    "scripts/reproduce_fig7_12.py",
                    "--out",
                    "{out}",
                    "--workers",
                    "2",
                    "--markdown",
                ]
            },
            markdown_extract("reproduce"),
            markdown_figure_tables(("steps", "claims")),
            compare_markdown_tables,
            ("docs/arenas.md",),
            markdown=True,
            notes="Steps are counted to entering the capture state; the thesis counts one more per captured trial, "
            "hence its column in our count. ATPO's four policies are solved in the run (`pursuit_pairs.ATPO_SOLVER`).",
        ),
        Figure(
            "fig7-12-ablation",
            "Fig. 7.12's deviations from the thesis: the decision layer under the original experiment's model and "
            "protocol variants (32 episodes per cell, seed 0, cap 150)",
            {"ablate": ["{python}", "scripts/ablate_fig7_12.py", "--episodes", "32", "--markdown"]},
            ablation_extract,
            markdown_figure_tables(("steps",)),
            ablation_compare,
            ("docs/arenas.md",),
            prose=ablation_prose,
            checked="every second-kernel mean lies inside the published mean's 95 % t-interval (the published sd "
            "over the episodes per cell)",
            notes="Steps to the capture reward (the original's count: ours + 1 per captured episode), mean ± sd "
            "(ddof 1) and the Welch p-value against the thesis's 32 trials; the same episode draws in every row "
            "of a column.",
        ),
        Figure(
            "teamster-reference",
            "TEAMSTER Part A: the PLASTIC reference, captures per 500 steps with the teammate-aware team "
            "(4 runs of 500 steps per agent, seed 0)",
            {
                "reference": [
                    "{python}",
                    "scripts/reproduce_teamster.py",
                    "--trials",
                    "4",
                    "--skip-protocol",
                    "--markdown",
                ]
            },
            markdown_extract("reference"),
            markdown_figure_tables(("captures",)),
            compare_markdown_tables,
            ("docs/teamster.md",),
            torch=True,
            checked="every second-kernel mean lies inside the published 95 % interval",
            notes="The ad hoc seat filled by each of the team's own policies, by random and by PLASTIC-Model that "
            "already knows the three teams (Table 4.1's UCT each step); the PLASTIC reference is Barrett et al.'s "
            "count (results-to-reproduce.md), and the deviation from it is explained on docs/teamster.md.",
        ),
        Figure(
            "teamster-maps",
            "TEAMSTER Part C: the navigation maps' baselines beside Tables 4.5-4.7 (40 episodes per row, seed 0)",
            {
                "maps": [
                    "{python}",
                    "scripts/reproduce_teamster.py",
                    "--maps",
                    ",".join(TEAMSTER_MAPS),
                    "--episodes",
                    "40",
                    "--skip-protocol",
                    "--skip-pursuit",
                    "--markdown",
                ]
            },
            markdown_extract("maps"),
            markdown_figure_tables(TEAMSTER_MAPS),
            compare_markdown_tables,
            ("docs/teamster.md",),
            torch=True,
            checked="every second-kernel mean lies inside the published 95 % interval",
            notes="The ad hoc seat filled by the team's own policy (the thesis's Original Teammate), by random and by "
            "PLASTIC-Model that knows the three teams' exact models and plans with Table 4.1's UCT for the map; "
            "an episode cut at 100 steps counts -100 in the mean; 'ended' is the share that ended within 100 steps "
            "and 'mean of ended' the mean over those, which is what the thesis's final tables report (its "
            "PLASTIC-Model column is the row after learning the third team).",
        ),
        Figure(
            "pomdp-io",
            "The .pomdp reader's speed per corpus file, against the floor and an earlier reader",
            {"bench": ["{python}", "scripts/bench_pomdp_io.py", "--corpus", "{corpus}"]},
            pomdp_io_extract,
            pomdp_io_tables,
            None,
            ("docs/pomdp.md",),
            notes="Best of 5 reads per file in wall seconds on the machine named below, at its load then; the floor "
            "is reading the file and splitting it on whitespace, measured in the same run; the earlier reader is "
            "loaded from git (`scripts/compare_pomdp_parsers.py`'s `BASE`).",
        ),
        Figure(
            "arena-speed",
            "Arena env speed: steps per CPU second, as ratios to a reference measured in the same run (lbforaging "
            "where it is installed, else the grid twin)",
            {domain: ["{python}", "scripts/bench_arenas.py", "--domain", domain] for domain in ARENA_DOMAINS},
            arena_speed_extract,
            arena_speed_tables,
            None,
            ("docs/arenas.md",),
            notes="Rates per CPU second of the process on the machine named below, at its load then; the ratios "
            "swing less than the rates.",
        ),
        Figure(
            "table5-3",
            "ATPO: thesis Table 5.3, build and solve time of every chapter-5 library beside the thesis's",
            {"bench": ["{python}", "scripts/bench_chapter5.py", "--solve", "--repeats", "1", "--markdown"]},
            markdown_extract("bench"),
            markdown_figure_tables(("table5_3",)),
            None,
            ("docs/atpo.md",),
            notes="One process; build in wall seconds (the fastest of the repeats), solve in this process's CPU "
            "seconds per model, with the trials' solver settings and no cache; the thesis's setup time is per "
            "POMDP, so its column is multiplied by the library size.",
            markdown=True,
        ),
        Figure(
            "teamster-t5000",
            "TEAMSTER Part D: the thesis's protocol on pursuit, 8 trials of seven agents at T = 5000 per team",
            teamster_commands("pursuit", TEAMSTER_LANES, TEAMSTER_T5000),
            teamster_t5000_extract,
            teamster_t5000_tables,
            teamster_t5000_compare,
            ("docs/teamster.md",),
            notes="Prey captures per 500 steps of an evaluation (100 steps, learning paused, a fresh configuration), "
            "mean over 8 trials with the 95 % percentile-bootstrap interval; the thesis's Table 4.4 reports an "
            "accumulated episode reward near 90 for every agent, mean ± its spread, so only orderings and ratios "
            "compare. The original teammate's and random's rows are after all three teams (they learn nothing). The "
            "claims' Welch tests run on the per-trial values. Seconds per trial are each agent's mean wall seconds "
            "(timing: its lane shared the host with the other lane).",
            checked=TEAMSTER_CHECKED + " and every claim keeps its verdict",
            timing_tables=("seconds",),
            plot=("docs/images/teamster-curves-t5000.png", teamster_t5000_plot),
            parallel=True,
        ),
        Figure(
            "atlpo-teams",
            "ATLPO: are the teams distinguishable? The Bayes-optimal posterior against the classifier",
            {
                key: ["{python}", "scripts/diagnose_atlpo.py", "--what", "teams", *arguments]
                for key, arguments in ATLPO_TEAMS_RUNS.items()
            },
            atlpo_teams_extract,
            atlpo_teams_tables,
            atlpo_teams_compare,
            ("docs/atlpo.md",),
            torch=True,
            notes="Seed 0, one thread. Accuracy of the posterior's argmax after t transitions on the same held-out "
            "episodes (32 per team of tau0-tau2, task 1; chance 0.33), the ad hoc agent taking the team policy's "
            "action half the time, else a uniform one; in brackets the classifier's accuracy on its own training "
            "episodes (256 per team, 600 iterations: the library's settings, unless the row says otherwise). The "
            "oracle is the Bayes posterior from the full state with each team's exact scripted policy as its "
            "likelihood (Monte Carlo over its tie-break uniforms, 256 draws).",
            checked="no held-out accuracy differs from the published run (Fisher's exact test per cell, Holm-adjusted "
            "over every cell, family-wise level 0.05) and every claim keeps its verdict",
            parallel=True,
        ),
        Figure(
            "teamster-changed",
            "TEAMSTER Part B2: 12 trials at T = 500 per team and a changed environment (predator moves fail w.p. 0.5)",
            teamster_commands("pursuit", {a: a for a in ("teamster", "plastic-model")}, TEAMSTER_CHANGED),
            teamster_study_extract,
            teamster_changed_tables,
            teamster_study_compare(teamster_changed_claims),
            ("docs/teamster.md",),
            notes="Seed 0, Table 4.1's pursuit UCT (100 iterations, depth 5), one thread per agent. Captures per 500 "
            "steps of 50-step evaluations (learning paused; each capture moves a cell by 10), mean over 12 trials "
            "with the 95 % percentile-bootstrap interval. The pre-stated measure of the changed environment is each "
            "trial's mean over that phase's evaluations after learning began (100-500 steps); Welch's test and "
            "P(a scores more) (rliable's probability of improvement) run on those per-trial values. Seconds per "
            "trial: timing (the two agents ran at once).",
            checked=TEAMSTER_CHECKED + " and the claim keeps its verdict",
            timing_tables=("seconds",),
            plot=("docs/images/teamster-curves-t500.png", teamster_curves_plot("pursuit")),
            parallel=True,
        ),
        Figure(
            "teamster-mirror",
            "TEAMSTER Part B3: the mirrored environment, 8 trials of four agents",
            teamster_commands("pursuit", TEAMSTER_MIRROR_LANES, TEAMSTER_MIRROR),
            teamster_study_extract,
            teamster_mirror_tables,
            teamster_study_compare(teamster_mirror_claims),
            ("docs/teamster.md",),
            notes="Seed 0, Table 4.1's pursuit UCT, one thread per lane. Captures per 500 steps of 50-step evaluations "
            "(learning paused; each capture moves a cell by 10), mean over 8 trials with the 95 % "
            "percentile-bootstrap interval; the changed phase (2,500 steps with the first team, the ad hoc agent's "
            "moves mirrored) is evaluated every 500 steps. The pre-stated measure is each trial's mean over that "
            "phase's evaluations after learning began (500-2,500 steps); Welch's test and P(a scores more) "
            "(rliable's probability of improvement) run on those per-trial values. The fit is the learned "
            "environment model's share of agent 0's moves predicted under the mirrored rules (256 random states), "
            "mean over trials. Seconds per trial: timing (the two lanes ran at once).",
            checked=TEAMSTER_CHECKED + " and every claim keeps its verdict",
            timing_tables=("seconds",),
            plot=("docs/images/teamster-mirror-changed.png", teamster_changed_plot),
            parallel=True,
        ),
        Figure(
            "teamster-mixed",
            "TEAMSTER section 4.1.5: the Mixed team at a tenth of the thesis's scale (8 trials, T = 500 per team, "
            "1,500 Mixed steps)",
            teamster_commands("pursuit", TEAMSTER_MIXED_LANES, TEAMSTER_MIXED),
            teamster_study_extract,
            teamster_mixed_tables,
            teamster_study_compare(teamster_mixed_claims),
            ("docs/teamster.md",),
            notes="Seed 0, Table 4.1's pursuit UCT, one thread per lane. After the three teams (T = 500 each, the "
            "library they build kept), each agent plays the Mixed team (one teammate-aware, one greedy, one "
            "probabilistic-destinations seat) for 1,500 steps, three times T as in the thesis (15,000 after T = "
            "5,000). Captures per 500 steps of 50-step evaluations every 100 steps (learning paused; each capture "
            "moves a cell by 10), mean over 8 trials with the 95 % percentile-bootstrap interval; the Mixed table "
            "shows every third evaluation, the claims read all of them. Seconds per trial: timing (the two lanes ran "
            "at once).",
            checked=TEAMSTER_CHECKED + " and every claim keeps its verdict",
            timing_tables=("seconds",),
            plot=("docs/images/teamster-mixed-curves.png", teamster_curves_plot("pursuit")),
            parallel=True,
        ),
        Figure(
            "teamster-ntu",
            "TEAMSTER on ntu: two trials of seven agents at T = 500 per team and a changed environment",
            teamster_commands("ntu", TEAMSTER_NTU_LANES, TEAMSTER_NTU),
            teamster_study_extract,
            teamster_ntu_tables,
            teamster_study_compare(teamster_ntu_claims),
            ("docs/teamster.md",),
            notes="Seed 0, Table 4.1's ntu UCT (100 iterations, depth 10), one thread per lane. Mean episode reward "
            "of 8-episode evaluations (learning paused) before and every 100 steps, mean over 2 trials with the 95 % "
            "percentile-bootstrap interval (over two trials it spans their two values). The changed environment: "
            "after the three teams, every move fails w.p. 0.25; its column is each trial's mean over the "
            "evaluations after learning began there. The thesis's Table 4.5 ran 8 trials of T = 100,000 per team, "
            "mean ± its spread. The original teammate's and random's rows are after all three teams (they learn "
            "nothing). Seconds per trial are each agent's mean wall seconds (timing: its lane shared the host). With "
            "two trials per cell the check's Welch tests detect only large shifts; the claim's verdict is the "
            "sharper check.",
            checked=TEAMSTER_CHECKED + " and the claim keeps its verdict",
            timing_tables=("seconds",),
            plot=("docs/images/teamster-ntu-curves.png", teamster_curves_plot("ntu")),
            parallel=True,
        ),
        Figure(
            "teamster-isr-pentagon",
            "TEAMSTER on isr and pentagon: the exact-environment agents, two trials at T = 200 per team",
            teamster_commands(
                None, dict.fromkeys(TEAMSTER_EXACT_MAPS, TEAMSTER_EXACT_AGENTS), TEAMSTER_EXACT
            ),
            teamster_study_extract,
            teamster_exact_maps_tables,
            teamster_study_compare(),
            ("docs/teamster.md",),
            notes="Seed 0, Table 4.1's UCT (isr 300 iterations to depth 50, pentagon 300 to depth 25), one thread per "
            "map. Mean episode reward of 4-episode evaluations (learning paused) at 0, 100 and 200 steps, mean over "
            "2 trials with the 95 % percentile-bootstrap interval (over two trials it spans their two values). The "
            "thesis's Tables 4.6 and 4.7 ran 8 trials of T = 100,000 (isr) and 125,000 (pentagon) per team, mean ± "
            "its spread. The original teammate's rows are after all three teams. Seconds per trial: timing (the two "
            "maps ran at once). With two trials per cell the check's Welch tests detect only large shifts.",
            checked=TEAMSTER_CHECKED,
            timing_tables=("seconds",),
            parallel=True,
        ),
        Figure(
            "fig5-9",
            "ATPO: thesis Fig. 5.9, the normalised score on gridworld by library size (32 episodes per size, seed 0)",
            {
                "reproduce": [
                    "{python}",
                    "scripts/reproduce_atpo.py",
                    "--out",
                    "{out}",
                    "--domains",
                    "gridworld",
                    "--markdown",
                ]
            },  # fmt: skip
            fig5_9_extract,
            markdown_figure_tables(("fig5_9",)),
            compare_markdown_tables,
            ("docs/atpo.md",),
            notes="ATPO's score normalised between random (0 %) and value iteration (100 %) on the 4-model library "
            "(Table 5.5's gridworld row of the same run), with the bootstrap interval of ATPO's mean reward mapped "
            "through the same normalisation (the reference's means held fixed); the libraries are nested, each size "
            "draws its own true models; Perseus at most the domain's stage budget per model.",
            prose=fig5_9_prose,
        ),
        Figure(
            "localiser-cost",
            f"The localiser's cost per 20 ms control step ({LOCALISER_COST_SECONDS} s of scripted driving, this "
            "process's CPU time)",
            {
                "bench": [
                    "{python}",
                    "scripts/bench_faults.py",
                    "--no-sweep",
                    "--cost-seconds",
                    str(LOCALISER_COST_SECONDS),
                ]
            },  # fmt: skip
            localiser_cost_extract,
            localiser_cost_tables,
            None,
            ("docs/localisation.md",),
            notes="One process on the machine named below, at its load then: CPU seconds of the process per control "
            "step, the ratios to the physics step measured in the same run.",
        ),
        Figure(
            "live-realtime",
            f"HOTSPOT turn-based against real time, scripted human (physics lab, seeds 0-{REALTIME_EPISODES - 1}: "
            f"{REALTIME_EPISODES} episodes per mode, the paced mode {REALTIME_PACED} at x20)",
            {
                "bench": [
                    "{python}",
                    "scripts/bench_realtime.py",
                    "--episodes",
                    str(REALTIME_EPISODES),
                    "--paced-episodes",
                    str(REALTIME_PACED),
                    "--json",
                ]
            },
            realtime_extract,
            realtime_tables,
            realtime_compare,
            ("docs/live.md",),
            timing_tables=("wall",),
            checked="each mode's second-kernel mean steps and simulated seconds lie inside the published mean ± "
            "95 % half-width",
            notes="Means ± the 95 % normal-approximation half-width (1.96 sd / sqrt(n)) over the episodes; "
            '"seconds" are simulated seconds until the three balls are in the container; ratios are to the '
            "turn-based mode. The turn-based and unpaced episodes cost no simulated time to decide (the same per "
            "seed on any host); the paced mode lets the agent's wall time to decide pass in the simulation, so its "
            "steps and seconds depend on the host and its load (class timing, with the wall seconds).",
        ),
        Figure(
            "chapter5-budget",
            "Chapter 5's solve budget: Perseus' lower bound at b0 of each domain's first model at its stage budget "
            "and 3 stages past it",
            {"budget": ["{python}", "scripts/bench_chapter5.py", "--budget", "--past", "3", "--markdown"]},
            budget_extract,
            budget_tables,
            compare_markdown_tables,
            ("docs/atpo.md",),
            timing_tables=("seconds",),
            notes="One process; the trials' solver settings (Table 5.2's belief-set size, tolerance 0.01, seed 0) with "
            "the stage limit raised by 3, no cache; the values are Perseus' progress reports after each stage.",
        ),
        Figure(
            "solvers-side-by-side",
            "This project's solver beside SARSOP (Tag, cit, hallway2, generated RockSample and random models, "
            "chapter-5 navigation models): lower / upper bounds at CPU-second checkpoints, time to SARSOP's final "
            "lower bound, convergence, peak memory",
            {
                "bench": [
                    "{python}",
                    "scripts/bench_solvers.py",
                    "--side-by-side",
                    *SIDE_BY_SIDE_MODELS,
                    "--checkpoints",
                    *SIDE_BY_SIDE_CHECKPOINTS,
                    "--json-out",
                    "-",
                ]
            },
            side_by_side_extract,
            side_by_side_tables,
            None,
            ("docs/pomdp.md",),
            notes="One process per solver and model, one after the other, each single-threaded: pomdpsol (SARSOP, "
            "built from AdaCompNUS/sarsop; the binary's SHA-256 is in the result file) for the longest checkpoint "
            "with its default target precision 0.001, then `pomdp solve`'s `--solver auto` choice and defaults for "
            "the same CPU seconds; bounds are read from each solver's progress at the checkpoints, peaks are each "
            "process's VmHWM. Both budgets are CPU seconds, so a loaded host runs them longer in wall time; how far "
            "a CPU second goes still depends on the host (class timing).",
        ),
        Figure(
            "live-latency",
            "Latency of the live page: frame intervals and key press to motion (headless Chromium on loopback, real "
            "time, 10 frames/s)",
            {
                "browser": [
                    "{python}",
                    "-m",
                    "pytest",
                    "-q",
                    "-s",
                    "-p",
                    "no:cacheprovider",
                    "{out}/test_live_browser.py",
                    "-k",
                    "typing",
                ]
            },
            latency_extract,
            latency_tables,
            None,
            ("docs/live.md",),
            files=("tests/live/test_live_browser.py", "tests/live/live_harness.py"),
            notes="One session of `tests/live/test_live_browser.py`'s typing test (the run's commit's copy): the "
            "page's figures from `performance.now` in the page, the server's from the run's `session.json`; wall "
            "milliseconds on the machine named below, at its load then, with the browser, the server and the "
            "simulation sharing its cores.",
        ),
        Figure(
            "fault-sweep",
            f"The fault sweep of bench_faults.py: HOTSPOT with and without the localiser under each fault (physics "
            f"lab, {FAULT_SWEEP_EPISODES} episodes per row and mode, seed 0, cap 100)",
            {
                "sweep": [
                    "{python}",
                    "scripts/bench_faults.py",
                    "--episodes",
                    str(FAULT_SWEEP_EPISODES),
                    "--cost-seconds",
                    "0",
                ]
            },
            fault_sweep_extract,
            markdown_figure_tables(("sweep",)),
            fault_sweep_compare,
            ("docs/localisation.md",),
            checked="every row's second-kernel mean steps lies inside the published 95 % bootstrap interval",
            notes="Mean steps count a capped episode with its 100 steps; the 95 % interval is the percentile "
            "bootstrap of the mean; the worst pose error is over every step of every episode of the row; the "
            "agents' RFID model is a perfect reader in every row (the faults are not told to it). The wall seconds "
            "per episode are in the result file (timing).",
        ),
        Figure(
            "fault-table",
            "HOTSPOT under each fault option (physics lab, seeds 100-107: 8 episodes per setting, cap 100)",
            {key: fault_command(options) for key, options in FAULT_SETTINGS.items()},
            faults_extract,
            fault_tables,
            arenas_compare,
            ("docs/localisation.md",),
            partial_checks=True,
            checked="every setting's second-kernel mean steps lies inside the published 95 % interval (the fault "
            "counts are printed beside it, not compared)",
            notes="Steps to finish, mean ± sd, and the 95 % percentile-bootstrap interval of the mean; a capped "
            "episode counts with its 100 steps. The counts are the trials' fault columns (`--json`'s "
            "`per_episode_mean`), means per episode; `capped: reason` counts the `cap_reason` codes of the episodes "
            'that hit the cap. "all six" is every fault option of the rows above it together; `--model-rfid-miss '
            "0` keeps the agents' model of the RFID reader perfect while the reader misses.",
        ),
    )
}


@dataclass(frozen=True)
class Unrun:
    """A published table that no result file holds yet and that costs too much to re-run on a shared machine: its
    marked block names the command that makes it, what a run costs and the class it will have, and prints no
    number (a typed number is what this script replaces). The last hand-recorded figures stay in the changelog's
    measurement history."""

    name: str
    title: str
    command: str
    cost: str
    """what one run of ``command`` costs, as its page measured it"""
    klass: str
    """the class the table gets once its script writes a result file: statistical, timing or exact"""


UNRUN_HISTORY = "docs/changelog.md"
"""Where the hand-recorded figures of the ``UNRUN`` tables are kept, with the runs that made them."""
UNRUN = {
    entry.name: entry
    for entry in (
        Unrun(
            "atlpo-chapter6",
            "ATLPO: the chapter-6 table and the held-out teammates",
            ".venv/bin/python scripts/reproduce_atlpo.py --out DIR",
            "three training seeds of the task, team and task+team libraries of both domains: 7-17 min of wall "
            "clock per library and seed on the loaded machine, hours in all",
            STATISTICAL,
        ),
        Unrun(
            "atlpo-mb",
            "ATLPO-MB on the thesis's 3 training seeds",
            "nice -n 10 .venv/bin/python scripts/reproduce_atlpo.py --out DIR --mb --domains D --seeds S "
            "--no-held-out --threads 1, then --seeds 0 1 2 --report-only",
            "a world model and its latent policy per member, domain and seed: hours",
            STATISTICAL,
        ),
        Unrun(
            "chapter5-executors",
            "The whole Table 5.5 timed per executor (local processes, Ray)",
            "RAY_ADDRESS=127.0.0.1:6390 .venv/bin/python scripts/bench_chapter5.py --executors local local ray "
            "--workers 2 --markdown",
            "three passes of the whole sweep (the first cold: about 5 min of wall time) and a local Ray cluster; "
            "ray is an optional extra that this checkout's .venv does not install, so it cannot run here",
            TIMING,
        ),
    )
}


@dataclass(frozen=True)
class Recorded:
    """Tables generated from a result file that ships in the repository, written by its own script (an asset the
    package reads, or a run that needs what a frozen copy of the commit lacks), not re-run by this script: the pages
    print what the file holds and the provenance it records."""

    name: str
    title: str
    source: str
    """the result file, relative to the repository root"""
    tables: Callable[[dict], list[Table]]
    cost: str
    """what a re-run of the file's command costs"""
    command: str = ""
    """the command that wrote the file, where its provenance does not name it"""


SPEECH_THESIS = ("257", "58.62 %", "77.77 %", "74.07 %")
"""The thesis's live recogniser (thesis ch. 7, M4-M6): utterances and the three accuracies."""


def percent(value: float) -> str:
    return f"{100 * value:.2f} %"


def speech_eval_tables(data: dict) -> list[Table]:
    provenance = data["provenance"]
    headers = ["condition", "n", "transcript (M4)", "place (M5)", "node (M6)", "latency ms (wall)", "CPU ms",
               "real-time factor"]  # fmt: skip

    def row(label: str, c: dict) -> list[str]:
        return [
            label,
            str(c["n"]),
            percent(c["transcript_accuracy"]),
            percent(c["place_accuracy"]),
            percent(c["node_accuracy"]),
            f"{c['latency_ms_mean']:.0f}",
            f"{c['cpu_ms_mean']:.0f}",
            f"{c['real_time_factor']:.3f}",
        ]

    conditions = [
        row("clean" if c["snr_db"] is None else f"SNR {c['snr_db']:g} dB", c)
        for c in provenance["conditions"]
    ]
    conditions.append(["thesis (online recogniser, live)", *SPEECH_THESIS, "-", "-", "-"])
    voices = [
        [voice, percent(c["transcript_accuracy"]), percent(c["place_accuracy"]), percent(c["node_accuracy"])]
        for voice, c in provenance["clean_by_voice"].items()
    ]
    thesis = json.loads((ROOT / "assets" / "data" / "speech_confusion_thesis.json").read_text())["matrix"]
    matrix = [
        [f"{i} {node}", *(f"{p:.3f}".lstrip("0") for p in values)]
        for i, (node, values) in enumerate(zip(data["nodes"], data["matrix"], strict=True))
    ]
    matrix.append(
        [
            "thesis row 0..4 diagonal",
            *(f"{thesis[i][i]:.3f}".lstrip("0") for i in range(len(thesis))),
            "/".join(f"{row[-1]:.3f}".lstrip("0") for row in thesis),
        ]
    )
    return [
        Table("conditions", "", headers, conditions),
        Table("voices", "", ["voice", "transcript", "place", "node"], voices),
        Table(
            "confusion", "", ["true \\ heard", *(str(i) for i in range(len(data["nodes"]))), "failed"], matrix
        ),
    ]


def localisation_model_tables(data: dict) -> list[Table]:
    counts = data["provenance"]["pooled_counts"]
    headers = ["true \\ reported", *data["nodes"], "unknown", "readings"]
    rows = [
        [node, *(f"{p:.3f}" for p in values), str(sum(row))]
        for node, values, row in zip(data["nodes"], data["matrix"], counts, strict=True)
    ]
    return [Table("matrix", "", headers, rows)]


RECORDED = {
    entry.name: entry
    for entry in (
        Recorded(
            "speech-eval",
            "Offline speech pipeline: recognition per noise condition and voice, and the measured confusion matrix",
            "assets/data/speech_confusion_measured.json",
            speech_eval_tables,
            "1,440 utterances synthesised and recognised, seconds each in noise: tens of minutes on two cores",
        ),
        Recorded(
            "localisation-model",
            "The measured robot-node model: the localiser's readings per true area (HOTSPOT episodes and tours)",
            "assets/data/localisation_confusion_measured.json",
            localisation_model_tables,
            "the fault sweep's physics episodes and scripted tours with the localiser on",
            "MUJOCO_GL=egl .venv/bin/python scripts/bench_faults.py --confusion-out PATH",
        ),
    )
}


@dataclass(frozen=True)
class SelfRendered:
    """A result file that its own script writes and renders into its own marked block of a page (one run, with its
    provenance at the file's top level and no check runs in it). This script renders that block the same way (the
    script's own function, so the two never disagree), checks it with the other pages, and states the file's class
    in its ``results:NAME`` block, in the index and in the README's headline."""

    name: str
    title: str
    source: str
    """the result file, relative to the repository root"""
    script: str
    """the script that writes the file and renders its block (its ``table(result)`` gives the block's text)"""
    page: str
    markers: tuple[str, str]
    """the script's own start and end markers on ``page``"""
    klass: str
    """the class a second kernel's run inside the file's intervals would give it"""


SELF_RENDERED = {
    entry.name: entry
    for entry in (
        SelfRendered(
            "benchmark-heldout",
            "The held-out benchmark: the shipped agents against held-out teammates, normalised scores per domain",
            "results/benchmark-heldout.json",
            "scripts/bench_heldout.py",
            "docs/benchmark.md",
            ("<!-- bench:heldout start -->", "<!-- bench:heldout end -->"),
            STATISTICAL,
        ),
        SelfRendered(
            "library-free",
            "The library-free agents (ppo-generalist, liam, meliba) on the held-out suite beside the library-based "
            "agents, and the score against the number of training teammates",
            "results/library-free.json",
            "scripts/library_free_bench.py",
            "docs/library_free.md",
            ("<!-- library-free start -->", "<!-- library-free end -->"),
            STATISTICAL,
        ),
    )
}


def self_rendered_script(entry: SelfRendered):
    """The entry's script as a module (its ``table`` function and constants)."""
    path = ROOT / entry.script
    spec = importlib.util.spec_from_file_location(f"_self_rendered_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses resolve annotations through sys.modules
    spec.loader.exec_module(module)
    return module


def self_rendered_class(entry: SelfRendered, data: dict) -> str:
    # A file merged from several runs records each part's kernel beside it; a part's second-kernel run, where the
    # script made one, lies in ``kernel_checks`` with the script's own comparison against the published intervals.
    kernels = {data["kernel"]} | {
        part["kernel"]
        for parts in data.get("suites", {}).values()
        for part in parts.values()
        if isinstance(part, dict) and part.get("kernel")
    }
    comparisons = {
        part: check["comparison"]
        for part, check in data.get("kernel_checks", {}).items()
        if check["comparison"]["second_kernel"]
    }
    failed = sorted(part for part, comparison in comparisons.items() if not comparison["inside"])
    if failed:
        return (
            f"check failed ({', '.join(failed)}: a second kernel's run lies outside the published intervals)"
        )
    if not comparisons:
        return (
            f"not re-checked (one run of each part, under {' and '.join(sorted(kernels))} only; class once "
            f"a second kernel's run lies inside its intervals: {entry.klass})"
        )
    parts = sorted(
        {domain for suite in data.get("suites", {}).values() for domain in suite}
        | set(data.get("domains", {}))  # a file whose parts are its domains and its curve (library-free)
        | ({"curve"} if data.get("curve", {}).get("points") else set())
    )
    unchecked = [part for part in parts if part not in comparisons]
    if not unchecked:
        return entry.klass
    return (
        f"{entry.klass} (the part checked: {', '.join(sorted(comparisons))} re-ran under a second kernel inside "
        f"the published intervals; {', '.join(unchecked)} one kernel's run only)"
    )


def self_rendered_block(entry: SelfRendered, page: Path) -> str:
    data = json.loads((ROOT / entry.source).read_text())
    return (
        f"Class: **{self_rendered_class(entry, data)}**. *Generated by `{entry.script}` from `{entry.source}`, "
        f"which `{data['command']}` wrote last at commit {data['commit'][:10]} on {data['started'][:10]}; "
        f"`{SCRIPT} --check` checks the table against the file.*"
    )


def with_self_rendered_tables(page: Path, text: str) -> str:
    """``text`` with the blocks that a self-rendering script writes on ``page`` as that script renders them."""
    for entry in SELF_RENDERED.values():
        if page != ROOT / entry.page:
            continue
        start, end = entry.markers
        if start not in text or end not in text:
            sys.exit(f"{entry.page}: the markers {start} and {end} of `{entry.script}` are missing")
        head, rest = text.split(start, 1)
        tail = rest.split(end, 1)[1]
        table = self_rendered_script(entry).table(json.loads((ROOT / entry.source).read_text()))
        text = f"{head}{start}\n{table}\n{end}{tail}"
    return text


def recorded_block(entry: Recorded, key: str | None, page: Path) -> str:
    data = json.loads((ROOT / entry.source).read_text())
    tables = [t for t in entry.tables(data) if key is None or t.key == key]
    if not tables:
        sys.exit(
            f"{page.relative_to(ROOT)}: marker results:{entry.name}.{key}: no such table in {entry.source}"
        )
    command, date = recorded_provenance(entry, data)
    when = (
        f"wrote on {date[:10]} with its provenance inside"
        if date
        else "wrote (the file records no date, commit, kernel or package versions)"
    )
    # The file is named, not linked: it lies outside the documentation site.
    return "\n\n".join(t.markdown() for t in tables) + (
        f"\n\nClass: **not re-run** (cost: {entry.cost}; one run on one host). *Generated by `{SCRIPT}` from "
        f"`{entry.source}`, which `{command}` {when}.*"
    )


def recorded_provenance(entry: Recorded, data: dict) -> tuple[str, str | None]:
    """(the command that wrote the entry's file, its date or None): from the file's ``provenance``, or its top level
    where the file keeps its command there, else the entry's own ``command``."""
    provenance = data.get("provenance", data)
    return provenance.get("command") or entry.command, provenance.get("date")


def unrun_block(entry: Unrun, page: Path) -> str:
    history = os.path.relpath(ROOT / UNRUN_HISTORY, page.parent)
    return (
        f"*Not re-run (cost: {entry.cost}). No result file holds this table yet, so no number of it is printed "
        f"here; `{entry.command}` makes it (class once generated: {entry.klass}). The last hand-recorded "
        f"figures, with the runs that made them, are in the [changelog]({history}).*"
    )


# ------------------------------------------------------------------------------------------------ runs


def git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()


CORPUS = (ROOT.parent / "shared" / "pomdp").resolve()
"""The .pomdp benchmark corpus beside the checkout (where tests/decision read it too); the package ships tiger only."""


def expand(argv: Sequence[str], out: str) -> list[str]:
    return [
        part.replace("{python}", ".venv/bin/python").replace("{out}", out).replace("{corpus}", str(CORPUS))
        for part in argv
    ]


CODE = ("embodied_adhoc", "scripts", "assets", "scenes", "pyproject.toml", "constraints.txt")
"""What a run executes, taken from the commit: a check counts against a published run of that code only."""


def snapshot(revision: str = "HEAD") -> tuple[str, str, Path]:
    """``revision``'s commit, the SHA-256 of its files under ``CODE`` (names and blobs), and a copy of those files.

    A figure runs from the copy (``PYTHONPATH`` first, ahead of the editable install), so its numbers are
    those of the commit it records: uncommitted edits in the checkout, and edits made while it runs, never
    reach it. This renderer is left out of the digest, since it changes the pages, never a number."""
    commit = git("rev-parse", revision)
    listing = git("ls-tree", "-r", commit, "--", *CODE).splitlines()
    code = hashlib.sha256(
        "\n".join(line for line in listing if not line.endswith(SCRIPT)).encode()
    ).hexdigest()
    folder = ROOT / RUN_DIR / f"code-{code[:16]}"
    if not folder.is_dir():
        building = folder.with_name(folder.name + ".partial")
        shutil.rmtree(building, ignore_errors=True)
        building.mkdir(parents=True)
        archive = subprocess.run(
            ["git", "archive", commit, "--", *CODE], cwd=ROOT, capture_output=True, check=True
        )
        subprocess.run(["tar", "-x", "-C", str(building)], input=archive.stdout, check=True)
        building.rename(folder)
    return commit, code, folder


def published_code(figure: Figure, extra: Sequence[str] = ()) -> tuple[str, str, Path] | None:
    """The frozen copy the figure's published run ran from (for a check of some rows, the run that re-made those
    rows, where one did): the one this machine kept, or one made again from the recorded commit when this clone
    has it and its files still give the recorded digest."""
    path = RESULTS / f"{figure.name}.json"
    if not path.exists():
        return None
    published = json.loads(path.read_text())["published"]
    published = next((p for p in published.get("parts", []) if p["extra"] == shlex.join(extra)), published)
    code = published.get("code_sha256", "")
    folder = ROOT / RUN_DIR / f"code-{code[:16]}"
    if code and folder.is_dir():
        return published["commit"], code, folder
    known = subprocess.run(
        ["git", "cat-file", "-e", f"{published['commit']}^{{commit}}"], cwd=ROOT
    ).returncode
    if not code or known != 0:
        return None
    again = snapshot(published["commit"])
    return again if again[1] == code else None


def run_figure(
    figure: Figure, kernel: str | None, keys: Sequence[str] = (), extra: Sequence[str] = ()
) -> dict:
    """Run the commands of ``figure`` (those named in ``keys``, or all) in turn under
    ``OPENBLAS_CORETYPE=kernel`` (None: the host's), each with ``extra`` arguments added.

    A check run (``kernel`` given) runs the published run's frozen code when it is still here, so the two runs
    differ in the kernel only; otherwise it freezes HEAD, and the class shows any difference."""
    label = kernel or "default"
    commit, code, folder = (kernel and published_code(figure, extra)) or snapshot()
    env = dict(os.environ)
    env.pop("OPENBLAS_CORETYPE", None)
    if kernel:
        env["OPENBLAS_CORETYPE"] = kernel
    env["XDG_CACHE_HOME"] = str(ROOT / CACHE_DIR / label)
    env.setdefault("MUJOCO_GL", "egl")  # physics figures render offscreen, headless
    env["PYTHONPATH"] = os.pathsep.join([str(folder), *filter(None, [env.get("PYTHONPATH")])])
    probe = subprocess.run(
        [sys.executable, "-c", PROBE], cwd=folder, env=env, capture_output=True, text=True, check=True
    )
    numerics = json.loads(probe.stdout)
    if Path(numerics["package"]).resolve() != (folder / "embodied_adhoc" / "__init__.py").resolve():
        sys.exit(
            f"{figure.name}: the run would import {numerics['package']}, not the frozen copy in {folder}"
        )
    outputs, commands, lanes = {}, {}, {}
    started, load = dt.datetime.now(dt.UTC), os.getloadavg()[0]
    for key, argv in figure.commands.items():
        if keys and key not in keys:
            continue
        out = f"runs/{figure.name}-{label}-{key}"
        command = expand(argv, out) + list(extra)
        commands[key] = shlex.join(command)
        print(f"[{figure.name} {label}] {commands[key]}", file=sys.stderr, flush=True)
        shutil.rmtree(folder / out, ignore_errors=True)
        for path in figure.files:
            (folder / out).mkdir(parents=True, exist_ok=True)
            (folder / out / Path(path).name).write_text(git("show", f"{commit}:{path}") + "\n")
        executable = [str(ROOT / command[0]) if command[0].startswith(".venv/") else command[0], *command[1:]]
        # the output goes to files, so that lanes running at once never block on a full pipe
        streams = folder / f"{out}.stdout", folder / f"{out}.stderr"
        streams[0].parent.mkdir(parents=True, exist_ok=True)
        with streams[0].open("w") as stdout, streams[1].open("w") as stderr:
            lanes[key] = (
                subprocess.Popen(executable, cwd=folder, env=env, stdout=stdout, stderr=stderr),
                streams,
            )
        if not figure.parallel:
            outputs[key] = finish_lane(figure, commands[key], *lanes.pop(key))
    try:
        for key, lane in lanes.items():
            outputs[key] = finish_lane(figure, commands[key], *lane)
    except SystemExit:
        stop_lanes([process for process, _ in lanes.values()])
        raise
    return {
        "kernel": numerics["kernel"],
        "openblas_coretype": kernel,
        "commit": commit,
        "code_sha256": code,
        "commands": commands,
        "keys": list(keys),
        "extra": shlex.join(extra),
        **(
            {"files": {path: git("rev-parse", f"{commit}:{path}") for path in figure.files}}
            if figure.files
            else {}
        ),
        "versions": {k: v for k, v in numerics["versions"].items() if k != "torch" or figure.torch},
        "python": sys.version.split()[0],
        "started": started.isoformat(timespec="seconds"),
        "finished": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        # the host's 1-minute load average at the start and the end: what a timing figure's seconds ran beside
        "load": [round(load, 2), round(os.getloadavg()[0], 2)],
        "data": figure.extract(outputs),
    }


def stop_lanes(processes: Sequence[subprocess.Popen], grace: float = 10.0) -> None:
    """End the lanes still running once one has failed: the figure cannot be published without it, and lanes
    left behind would hold the cores for hours."""
    for process in processes:
        if process.poll() is None:
            process.terminate()
    for process in processes:
        try:
            process.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def finish_lane(figure: Figure, command: str, process: subprocess.Popen, streams: tuple[Path, Path]) -> str:
    """Wait for one command: its stdout, or exit with its message if it failed."""
    code = process.wait()
    stdout, stderr = (path.read_text() for path in streams)
    if code != 0:
        # a test runner reports its failures on stdout: show that where stderr says nothing
        said = stderr.strip() or stdout
        sys.exit(f"{figure.name}: `{command}` exited {code}:\n{said[-2000:]}")
    return stdout


def write_run(figure: Figure, run: dict, check: bool) -> Path:
    path = RESULTS / f"{figure.name}.json"
    document = {"figure": figure.name, "published": run, "checks": []}
    if (check or run["extra"]) and not path.exists():
        sys.exit(
            f"{path.relative_to(ROOT)}: no published run to add to; run `{SCRIPT} run {figure.name}` first"
        )
    if check:
        document = json.loads(path.read_text())
        # One check per kernel and part: OPENBLAS_CORETYPE=Zen runs Haswell's kernels, so a Zen check of other
        # rows is a second Haswell check, kept beside the first.
        same = (run["kernel"], run["extra"])
        document["checks"] = [c for c in document["checks"] if (c["kernel"], c.get("extra", "")) != same] + [
            run
        ]
    elif run["extra"]:
        document = json.loads(path.read_text())
        document["published"] = replace_rows(document["published"], run)
        # A full check, or one of these rows, checked numbers that are no longer published; a check of other rows
        # still holds for those.
        document["checks"] = [c for c in document["checks"] if c.get("extra") not in ("", run["extra"])]
    RESULTS.mkdir(exist_ok=True)
    path.write_text(json.dumps(document, indent=1, ensure_ascii=False) + "\n")
    return path


# --------------------------------------------------------------------------------------- classes/pages


def replace_rows(published: dict, run: dict) -> dict:
    """The published run with the rows that ``run`` (the same command with ``extra`` arguments, e.g. one domain)
    printed in place of the old ones, and ``run`` recorded as the part of the published run that made them."""
    tables = []
    for ours, theirs in zip(published["data"]["tables"], run["data"]["tables"], strict=True):
        new = {row_label(row): row for row in theirs["rows"]}
        rows = [new.pop(row_label(row), row) for row in ours["rows"]]
        tables.append(
            {
                **ours,
                "caption": merge_caption(ours["caption"], theirs["caption"]),
                "rows": rows + [*new.values()],
            }
        )
    part = {k: v for k, v in run.items() if k != "data"}
    parts = [p for p in published.get("parts", []) if p["extra"] != run["extra"]] + [part]
    return {**published, "data": {**published["data"], "tables": tables}, "parts": parts}


SETTING = re.compile(r"(?P<name>[A-Za-z0-9-]+) (?P<value>\d+)")


def merge_caption(ours: str, theirs: str) -> str:
    """``ours`` with the ``name value`` settings that ``theirs`` lists for its rows (e.g. a domain's stage budget
    in "stages per model at most: gridworld 14, isr 13") taken from ``theirs``."""
    values = {m["name"]: m["value"] for m in SETTING.finditer(theirs.rpartition(": ")[2])}
    head, sep, tail = ours.rpartition(": ")
    if not sep or not values:
        return ours
    tail = SETTING.sub(lambda m: f"{m['name']} {values.get(m['name'], m['value'])}", tail)
    return head + sep + tail


def comparable(data: dict) -> str:
    return json.dumps({k: v for k, v in data.items() if k != "timing"}, sort_keys=True)


def table_data(figure: Figure, data: dict, key: str | None) -> dict:
    """The part of ``data`` that table ``key`` prints (all of it for a figure rendered from JSON)."""
    if key is None or "tables" not in data:
        return data
    keys = [table.key for table in figure.tables(data)]
    return {"tables": [data["tables"][keys.index(key)]]}


def checkable(data: dict) -> bool:
    """Whether a table prints something a second run can be held to (an interval or a verdict)."""
    if "tables" not in data:
        return True
    return any(
        ci_of(cell) or header.lower() in VERDICTS
        for table in data["tables"]
        for row in table["rows"]
        for header, cell in zip(table["headers"], row, strict=True)
    )


def reproducibility(figure: Figure, document: dict, key: str | None = None) -> tuple[str, str]:
    """(class, the sentence that says how it was checked) of table ``key``, from the result file's runs."""
    published = document["published"]
    if figure.compare is None or key in figure.timing_tables:
        return TIMING, "seconds depend on the host and its load: re-measure, never compare across machines"
    others = [c for c in document["checks"] if c["kernel"] != published["kernel"]]
    if not others:
        return "not re-checked", f"run under the {published['kernel']} kernel only"
    codes = {"": published.get("code_sha256")} | {
        p["extra"]: p["code_sha256"] for p in published.get("parts", [])
    }
    stale = [c for c in others if c.get("code_sha256") != codes.get(c.get("extra", ""), codes[""])]
    others = [c for c in others if c not in stale]
    if not others:
        kernels = ", ".join(c["kernel"] for c in stale)
        return "not re-checked", f"the {kernels} run checked other code than the published run's"
    names = list(dict.fromkeys([published["kernel"], *(c["kernel"] for c in others)]))
    kernels = ", ".join(names[:-1]) + " and " + names[-1]
    counts = [c["kernel"] for c in others]

    def label(check: dict) -> str:
        """The check's name in the class sentence (its kernel; with its part where a kernel checked two)."""
        return (
            check["kernel"] if counts.count(check["kernel"]) == 1 else f"{check['kernel']} `{check['extra']}`"
        )

    # A partial check ran some commands or rows only: it is held to the same part of the published data.
    ours = {label(c): table_data(figure, part(published["data"], c), key) for c in others}
    theirs = {label(c): table_data(figure, c["data"], key) for c in others}
    scope = "".join(
        f"; {c['kernel']} ran {len(c['keys'])} of the {len(figure.commands)} commands"
        for c in others
        if c.get("keys")
    )
    scope += "".join(f"; {c['kernel']} ran with `{c['extra']}` only" for c in others if c.get("extra"))
    # Where every check ran a part only, the class holds for that part: the rest is not re-checked.
    partly = " (the part checked)" if all(c.get("keys") or c.get("extra") for c in others) else ""
    differ = [kernel for kernel in theirs if comparable(theirs[kernel]) != comparable(ours[kernel])]
    if not differ:
        return (
            f"exact on any host{partly}",
            f"the same numbers, byte for byte, under the {kernels} OpenBLAS kernels{scope}",
        )
    if not checkable(ours[differ[0]]):
        return "statistical, not checked", (
            f"the numbers differ between the {kernels} kernels and the table prints no interval to hold "
            "them to"
        )
    bad = {
        kernel: problems for kernel in differ if (problems := figure.compare(ours[kernel], theirs[kernel]))
    }
    if bad:
        lines = "; ".join(f"{kernel}: {', '.join(problems[:3])}" for kernel, problems in bad.items())
        return "statistical, CHECK FAILED", f"under {kernels}: {lines}"
    identical = [kernel for kernel in theirs if kernel not in differ]
    same = f"; identical under {', '.join(identical)}" if identical else ""
    return f"{STATISTICAL}{partly}", (
        f"the numbers differ between the {kernels} kernels; {figure.checked}{same}{scope}"
    )


def part(data: dict, check: dict) -> dict:
    """The part of the published ``data`` that a check ran: the commands in its ``keys``, or for a check with
    ``extra`` arguments (e.g. fewer domains) the table rows it printed; all of it for a full check."""
    if check.get("keys"):
        return {"runs": {key: data["runs"][key] for key in check["keys"]}}
    if check.get("extra") and "tables" in data:
        tables = []
        for ours, theirs in zip(data["tables"], check["data"]["tables"], strict=True):
            labels = {row_label(row) for row in theirs["rows"]}
            # The caption says what the run covered (e.g. the settings of its domains only), not a number of it.
            rows = [row for row in ours["rows"] if row_label(row) in labels]
            tables.append({**ours, "caption": theirs["caption"], "rows": rows})
        return {"tables": tables}
    return data


def load(name: str) -> dict:
    return json.loads((RESULTS / f"{name}.json").read_text())


def regenerate(figure: Figure) -> str:
    return f".venv/bin/python {SCRIPT} run {figure.name} && .venv/bin/python {SCRIPT} render"


def class_line(figure: Figure, document: dict, key: str | None) -> str:
    klass, how = reproducibility(figure, document, key)
    return f"Class: **{klass}** ({how})."


def provenance(figure: Figure, document: dict, page: Path) -> str:
    """The line under a figure's tables: its result file, its commands and a link to its full page."""
    run = document["published"]
    commands = "; ".join(f"`{command}`" for command in run["commands"].values())
    if len(run["commands"]) > 3:
        scripts = ", ".join(f"`{name}`" for name in script_of(figure).split(", "))
        commands = f"{len(run['commands'])} commands ({scripts}), listed on the results page"
    link = os.path.relpath(PAGES / f"{figure.name}.md", page.parent)
    parts = "".join(
        f"; the rows of `{p['extra']}` re-made on {p['started'][:10]} at commit {p['commit'][:10]} (OpenBLAS "
        f"{p['kernel']})"
        for p in run.get("parts", [])
    )
    return (
        f"*Generated from `results/{figure.name}.json` ({run['started'][:10]}, commit {run['commit'][:10]}, "
        f"OpenBLAS {run['kernel']}{parts}) by `{SCRIPT}`; made by {commands}. [How it reproduces]({link}).*"
    )


def fragment(figure: Figure, document: dict, key: str | None, page: Path) -> str:
    sentences = figure.prose(document["published"]["data"]) if figure.prose else {}
    if key in sentences:
        table, sentence = sentences[key]
        klass = reproducibility(figure, document, table)[0]
        link = os.path.relpath(PAGES / f"{figure.name}.md", page.parent)
        return f"{sentence} *(Generated from `results/{figure.name}.json` by `{SCRIPT}`; [{klass}]({link}).)*"
    tables = figure.tables(document["published"]["data"])
    chosen = [t for t in tables if key is None or t.key == key]
    if not chosen:
        sys.exit(
            f"{page.relative_to(ROOT)}: marker results:{figure.name}.{key}: the figure has tables "
            f"{', '.join(t.key for t in tables)}"
            + (f" and sentences {', '.join(sentences)}" if sentences else "")
        )
    # The embedding page's own prose introduces the tables, so their captions stay on the figure's page.
    blocks = [
        t.markdown() + "\n\n" + class_line(figure, document, t.key if len(tables) > 1 else None)
        for t in chosen
    ]
    return "\n\n".join(blocks) + "\n\n" + provenance(figure, document, page)


def figure_page(figure: Figure, document: dict) -> str:
    run = document["published"]
    lines = [
        f"# {figure.title}",
        "",
        "<!-- generated by scripts/render_results.py from results/"
        f"{figure.name}.json: edit the result file's script, not this page -->",
        "",
    ]
    tables = figure.tables(run["data"])
    for table in tables:
        lines += [table.caption, ""] if table.caption else []
        lines += [
            table.markdown(),
            "",
            class_line(figure, document, table.key if len(tables) > 1 else None),
            "",
        ]
    if figure.notes:
        lines += [figure.notes, ""]
    lines += [
        "## How it reproduces",
        "",
        "Regenerate the result file and the pages (the figure's commands run one after another; "
        "`--kernel Haswell` adds a check run under `OPENBLAS_CORETYPE=Haswell`):",
        "",
        "```bash",
        regenerate(figure),
        "```",
        "",
        "Commands of the published run:",
        "",
        "```bash",
        *run["commands"].values(),
        *(command for p in run.get("parts", []) for command in p["commands"].values()),
        "```",
        "",
    ]
    lines += [
        "| run | OpenBLAS kernel | commit | code (SHA-256 of its files) | versions | date (UTC) | load (1 min, start "
        "/ end) |",
        "|---|---|---|---|---|---|---|",
    ]
    parts = [(f"published, the rows of `{p['extra']}`", p) for p in run.get("parts", [])]
    for label, each in [("published", run), *parts, *(("check", c) for c in document["checks"])]:
        versions = ", ".join(f"{k} {v}" for k, v in each["versions"].items())
        coretype = f" (OPENBLAS_CORETYPE={each['openblas_coretype']})" if each["openblas_coretype"] else ""
        lines.append(
            f"| {label} | {each['kernel']}{coretype} | {each['commit'][:10]} | "
            f"{each.get('code_sha256', 'not recorded')[:16]} | "
            f"python {each['python']}, {versions} | {each['started'].replace('T', ' ')[:16]} | "
            f"{' / '.join(f'{value:g}' for value in each['load']) if 'load' in each else 'not recorded'} |"
        )
    return "\n".join(lines) + "\n"


def index_page(documents: dict[str, dict]) -> str:
    lines = [
        "# Results",
        "",
        "<!-- generated by scripts/render_results.py -->",
        "",
        "Every table below with a page is rendered from a result file in `results/` by "
        "`scripts/render_results.py`, which also states its reproducibility class and checks it in CI "
        "(`render_results.py --check`). The rows without a page are tables of the user pages that no result file "
        "in `results/` holds: generated from a result file that ships as an asset, or not re-run, with the "
        "command that makes them and what a run costs.",
        "",
        "| figure | class | made by |",
        "|---|---|---|",
    ]
    for name, document in documents.items():
        figure = FIGURES[name]
        tables = figure.tables(document["published"]["data"])
        if len(tables) == 1:
            klass = reproducibility(figure, document)[0]
        else:
            klass = "; ".join(f"{t.key}: {reproducibility(figure, document, t.key)[0]}" for t in tables)
        lines.append(f"| [{figure.title}]({name}.md) | {klass} | `{script_of(figure)}` |")
    for entry in RECORDED.values():
        command = recorded_provenance(entry, json.loads((ROOT / entry.source).read_text()))[0]
        lines.append(
            f"| {entry.title} | not re-run, from `{entry.source}` (cost: {entry.cost}) | `{command}` |"
        )
    for entry in SELF_RENDERED.values():
        data = json.loads((ROOT / entry.source).read_text())
        link = os.path.relpath(ROOT / entry.page, PAGES)
        lines.append(
            f"| [{entry.title}]({link}) | {self_rendered_class(entry, data)}, from `{entry.source}` | "
            f"`{data['command']}` |"
        )
    for entry in UNRUN.values():
        if entry.name not in documents:
            lines.append(f"| {entry.title} | not re-run (cost: {entry.cost}) | `{entry.command}` |")
    return "\n".join(lines) + "\n"


HEADLINE = "headline"
"""The README's summary table: one row per headline figure, each cell taken from that figure's result file."""
HEADLINE_SOURCES = ("hotspot", "sim-vs-physics", "chapter5", "teamster-t5000", "teamster-maps")
NOT_GENERATED = (
    (
        "ATLPO steps to finish on foraging and pursuit, task, team and task+team libraries (chapter 6)",
        "docs/atlpo.md",
    ),
)
"""Headline results whose scripts write no result file yet: (the result, the page with its commands and cost)."""


def table_of(document: dict, key: str) -> Table:
    figure = FIGURES[document["figure"]]
    (table,) = [t for t in figure.tables(document["published"]["data"]) if t.key == key]
    return table


def column(document: dict, key: str, header: str) -> list[str]:
    table = table_of(document, key)
    return [row[table.headers.index(header)] for row in table.rows]


def headline(documents: dict[str, dict], page: Path) -> str:
    """The summary table, from whichever headline figures have result files (each row links its full page)."""
    rows = []

    def link(name: str, key: str | None = None) -> str:
        klass = reproducibility(FIGURES[name], documents[name], key)[0]
        return f"[{klass}]({os.path.relpath(PAGES / f'{name}.md', page.parent)})"

    if "hotspot" in documents:
        doc = documents["hotspot"]
        (row,) = [r for r in table_of(doc, "steps").rows if r[:2] == ["communication", "hotspot"]]
        rows.append(
            [
                "HOTSPOT steps to finish with communication, abstract lab, 32 episodes (Fig. 7.8; ours + 1 "
                "counts as the thesis did)",
                f"{row[2]} ({row[4]})",
                row[8],
                link("hotspot", "steps"),
            ]
        )
    if "sim-vs-physics" in documents:
        data = documents["sim-vs-physics"]["published"]["data"]
        abstract, physics = data["backends"]["abstract"]["hotspot"], data["backends"]["mujoco"]["hotspot"]
        rows.append(
            [
                "HOTSPOT on MuJoCo physics vs the abstract lab (section 7.2)",
                f"{steps_cell(physics)} vs {steps_cell(abstract)} "
                f"(Welch p = {data['welch']['hotspot']['p']:.3g})",
                "12.3 live robot",
                link("sim-vs-physics"),
            ]
        )
    if "chapter5" in documents:
        doc = documents["chapter5"]
        ours = [mean_of(cell) for cell in column(doc, "table5_6", "ATPO (ours)")]
        theirs = [mean_of(cell) for cell in column(doc, "table5_6", "ATPO (thesis)")]
        rows.append(
            [
                f"ATPO normalised score over the {len(ours)} Table 5.6 domains",
                f"{min(ours):.1f} % to {max(ours):.1f} %",
                f"{min(theirs):.1f} % to {max(theirs):.1f} %",
                link("chapter5", "table5_6"),
            ]
        )
    if "teamster-t5000" in documents:
        data = documents["teamster-t5000"]["published"]["data"]
        last = TEAMSTER_TEAMS[-1]

        def three(agent: str) -> str:
            return " / ".join(
                f"{data['agents'][agent]['after'][last][t]['mean']:.1f}" for t in TEAMSTER_TEAMS
            )

        def thesis(agent: str) -> str:
            return " / ".join(f"{mean:.2f}" for mean, _ in THESIS_TABLE_4_4[(last, agent)])

        rows.append(
            [
                "TEAMSTER and PLASTIC-Model on pursuit after learning all three teams, evaluated on each (Table 4.4; "
                "8 trials at T = 5000; ours prey captures per 500 steps, the thesis an accumulated episode reward)",
                f"TEAMSTER {three('teamster')}; PLASTIC-Model {three('plastic-model')}",
                f"TEAMSTER {thesis('teamster')}; PLASTIC-Model {thesis('plastic-model')}",
                link("teamster-t5000", "after"),
            ]
        )
    if "teamster-maps" in documents:
        doc = documents["teamster-maps"]
        ours, thesis = [], []
        for key in TEAMSTER_MAPS:
            table = table_of(doc, key)
            cells = [r for r in table.rows if r[0] == "plastic-model"]
            ended, theirs = table.headers.index("mean of ended"), table.headers.index("thesis")
            ours.append(f"{key} " + " / ".join(r[ended] for r in cells))
            thesis.append(f"{key} " + " / ".join(r[theirs] for r in cells))
        rows.append(
            [
                "PLASTIC-Model knowing the three teams on the navigation maps, per team (Tables 4.5-4.7, the row "
                "after learning the third team; 40 episodes per team; mean reward of the episodes that ended, as the "
                "thesis's final tables count)",
                "; ".join(ours),
                "; ".join(thesis),
                link("teamster-maps", TEAMSTER_MAPS[0]),
            ]
        )
    if "benchmark-heldout" in SELF_RENDERED:
        rows.append(heldout_headline(SELF_RENDERED["benchmark-heldout"], page))
    if "library-free" in SELF_RENDERED:
        rows.append(library_free_headline(SELF_RENDERED["library-free"], page))
    rows.append(speech_headline(page))
    for result, guide in NOT_GENERATED:
        rows.append(
            [result, "not generated", "-", f"[not re-run]({os.path.relpath(ROOT / guide, page.parent)})"]
        )
    table = Table(HEADLINE, "", ["result (thesis figure)", "ours", "thesis", "how it reproduces"], rows)
    sources = ", ".join(
        [f"`results/{name}.json`" for name in HEADLINE_SOURCES if name in documents]
        + [f"`{entry.source}`" for entry in SELF_RENDERED.values()]
        + [f"`{RECORDED[SPEECH_HEADLINE].source}`"]
    )
    return (
        f"{table.markdown()}\n\n*Generated by `{SCRIPT}` from {sources}. The rows marked not generated have no "
        "result file yet: their pages give the commands that make them and what a run costs.*"
    )


SPEECH_HEADLINE, SPEECH_PAGE = "speech-eval", "docs/speech.md"
"""The recorded result file behind the README's speech row, and the page that shows it."""


def speech_headline(page: Path) -> list[str]:
    """The offline speech pipeline's clean-speech accuracies (M4-M6) from its recorded result file, beside the
    thesis's live recogniser."""
    entry = RECORDED[SPEECH_HEADLINE]
    data = json.loads((ROOT / entry.source).read_text())
    clean = next(c for c in data["provenance"]["conditions"] if c["snr_db"] is None)
    accuracies = " / ".join(
        percent(clean[k]) for k in ("transcript_accuracy", "place_accuracy", "node_accuracy")
    )
    return [
        "Offline speech pipeline: transcript / place / node of the human recognised from synthesised clean speech "
        "(thesis M4-M6; the thesis's recogniser ran live)",
        f"{accuracies} (n = {clean['n']})",
        f"{' / '.join(SPEECH_THESIS[1:])} (n = {SPEECH_THESIS[0]})",
        f"[not re-run]({os.path.relpath(ROOT / SPEECH_PAGE, page.parent)})",
    ]


def self_rendered_row(entry: SelfRendered, page: Path, title: str, best) -> list[str]:
    """A headline row of a self-rendered file: ``best(data)`` gives, per domain, the agent, its IQM entry and a
    note; each cell reads "domain agent IQM [interval] note"."""
    data = json.loads((ROOT / entry.source).read_text())
    cells = []
    for domain, agent, value, note in best(data):
        low, high = value["iqm_ci"]
        cells.append(f"{domain} {agent} {value['iqm']:.2f} [{low:.2f}, {high:.2f}]{note}")
    full = self_rendered_class(entry, data)
    klass = full.split(" (")[0] + (" (the part checked)" if "(the part checked" in full else "")
    return [title, "; ".join(cells), "-", f"[{klass}]({os.path.relpath(ROOT / entry.page, page.parent)})"]


def heldout_headline(entry: SelfRendered, page: Path) -> list[str]:
    """Per domain of the held-out suite, the agent with the highest IQM among those that do not see the state."""
    privileged = self_rendered_script(entry).PRIVILEGED

    def best(data: dict):
        for domain, scope in data["suites"]["heldout"].items():
            fair = {agent: v for agent, v in scope["aggregate"].items() if agent not in privileged}
            agent = max(fair, key=lambda name: fair[name]["iqm"])
            # a domain whose bounds are simulated (the grid arenas) has no exact best response to normalise by:
            # its 1 is the better of a trained best response and the original team, per teammate
            simulated = any(row.get("bounds", {}).get("episodes") for row in scope["teammates"])
            yield domain, agent, fair[agent], " (1: a simulated upper bound)" if simulated else ""

    title = (
        "Held-out benchmark: the best agent that does not see the state, per domain, held-out IQM of the "
        "normalised score (0 random ego, 1 exact best response unless the cell says otherwise; no thesis "
        "counterpart)"
    )
    return self_rendered_row(entry, page, title, best)


def library_free_headline(entry: SelfRendered, page: Path) -> list[str]:
    """Per domain, the best library-free agent's held-out IQM with its interval and training env steps."""

    def best(data: dict):
        for domain, part in data["domains"].items():
            kind = max(part["agents"], key=lambda name: part["agents"][name]["iqm"])
            yield (
                domain,
                kind,
                part["agents"][kind],
                f" after {part['training'][kind]['env_steps']:,} env steps",
            )

    title = (
        "Library-free agents (no library; the thesis's future work, section 8.1.2): the best of ppo-generalist, "
        "liam and meliba per domain, held-out IQM of the normalised score"
    )
    return self_rendered_row(entry, page, title, best)


def marked_pages() -> list[Path]:
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    return [p for p in pages if p.exists() and not p.is_relative_to(PAGES)]


def render_markers(page: Path, text: str, documents: dict[str, dict]) -> tuple[str, list[str]]:
    """``text`` with every marked block re-rendered, and the names of the blocks it holds."""
    out, names, lines, index = [], [], text.split("\n"), 0
    while index < len(lines):
        match = MARKER.match(lines[index])
        out.append(lines[index])
        index += 1
        if not match:
            continue
        if match["edge"] != "start":
            sys.exit(f"{page.relative_to(ROOT)}:{index}: results:{match['name']} ends before it starts")
        name, _, key = match["name"].partition(".")
        if name not in (HEADLINE, *UNRUN, *RECORDED, *SELF_RENDERED) and (
            name not in FIGURES or name not in documents
        ):
            known = sorted([*documents, *UNRUN, *RECORDED, *SELF_RENDERED])
            sys.exit(
                f"{page.relative_to(ROOT)}:{index}: results:{name}: no such figure with a result file "
                f"(known: {', '.join(known)}); run `{SCRIPT} run {name}`"
            )
        end = f"<!-- results:{match['name']} end -->"
        try:
            stop = lines.index(end, index)
        except ValueError:
            sys.exit(f"{page.relative_to(ROOT)}:{index}: results:{match['name']} has no `{end}` line")
        if name == HEADLINE:
            block = headline(documents, page)
        elif name in UNRUN and name not in documents:  # a figure defined before its first run
            block = unrun_block(UNRUN[name], page)
        elif name in RECORDED:
            block = recorded_block(RECORDED[name], key or None, page)
        elif name in SELF_RENDERED:
            block = self_rendered_block(SELF_RENDERED[name], page)
        else:
            block = fragment(FIGURES[name], documents[name], key or None, page)
        out += ["", block, "", end]
        names.append(match["name"])
        index = stop + 1
    return "\n".join(out), names


def expected_pages() -> dict[Path, tuple[str, list[str]]]:
    """Every page this script owns or fills in -> (its rendered text, the blocks it holds)."""
    documents = {name: load(name) for name in FIGURES if (RESULTS / f"{name}.json").exists()}
    pages = {
        PAGES / f"{name}.md": (figure_page(FIGURES[name], doc), [name]) for name, doc in documents.items()
    }
    pages[PAGES / "index.md"] = (index_page(documents), list(documents))
    for page in marked_pages():
        text = with_self_rendered_tables(page, page.read_text())
        rendered, names = render_markers(page, text, documents)
        if names:
            pages[page] = (rendered, names)
    return pages


def first_difference(actual: str, expected: str) -> str:
    for number, (a, b) in enumerate(zip(actual.split("\n"), expected.split("\n"), strict=False), start=1):
        if a != b:
            return f"line {number}: {a[:80]!r} (rendered: {b[:80]!r})"
    return "the pages differ in length"


def script_of(figure: Figure) -> str:
    """The script (or CLI command) that produces ``figure``'s numbers."""
    names = [argv[1] if argv[0] == "{python}" else " ".join(argv[:3]) for argv in figure.commands.values()]
    return ", ".join(dict.fromkeys(names))


def check() -> int:
    failures = 0
    for page, (expected, names) in expected_pages().items():
        actual = page.read_text() if page.exists() else None
        if actual == expected:
            continue
        failures += 1
        relative = page.relative_to(ROOT)
        if page == PAGES / "index.md":
            print(
                f"{relative}: the index differs from results/*.json; run `.venv/bin/python {SCRIPT} render`"
            )
            continue
        for name in names:
            ours, theirs = ("" if actual is None else _block(actual, name)), _block(expected, name)
            if name in SELF_RENDERED and actual is not None:
                # the script's own table lies outside the results block: it counts as part of it
                start, end = SELF_RENDERED[name].markers
                ours, theirs = (ours + _between(actual, start, end), theirs + _between(expected, start, end))
            if actual is not None and ours == theirs:
                continue
            where = "the page is missing" if actual is None else first_difference(ours, theirs)
            if name == HEADLINE:
                print(
                    f"{relative}: table {name} differs from "
                    f"{', '.join(f'results/{n}.json' for n in HEADLINE_SOURCES)} ({where}); re-render with "
                    f"`.venv/bin/python {SCRIPT} render`, or re-run the figure whose numbers are stale"
                )
                continue
            if name in SELF_RENDERED:
                entry = SELF_RENDERED[name]
                print(
                    f"{relative}: the table of {entry.script} or its class differs from {entry.source}; "
                    f"re-render with `.venv/bin/python {SCRIPT} render` (or `{entry.script} --render-only`)"
                )
                continue
            base = name.partition(".")[0]
            if base in (*UNRUN, *RECORDED) and not (RESULTS / f"{base}.json").exists():
                print(
                    f"{relative}: block {name} differs from its entry in {SCRIPT}; re-render with `{SCRIPT} render`"
                )
                continue
            figure = FIGURES[name.partition(".")[0]]
            print(
                f"{relative}: table {name} differs from results/{figure.name}.json ({where}); re-render with "
                f"`.venv/bin/python {SCRIPT} render`, or if the results are stale re-run its script "
                f"(`{script_of(figure)}`): `{regenerate(figure)}`"
            )
    return 1 if failures else 0


def _between(text: str, start: str, end: str) -> str:
    return text.split(start, 1)[1].split(end, 1)[0] if start in text else text


def _block(text: str, name: str) -> str:
    """The marked block ``name`` of a page (the whole page when it holds no such marker)."""
    start, end = f"<!-- results:{name} start -->", f"<!-- results:{name} end -->"
    if start not in text:
        return text
    return text.split(start, 1)[1].split(end, 1)[0]


def render() -> None:
    PAGES.mkdir(parents=True, exist_ok=True)
    for page, (text, _) in expected_pages().items():
        if not page.exists() or page.read_text() != text:
            page.write_text(text)
            print(f"wrote {page.relative_to(ROOT)}")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--check", action="store_true", help="exit 1 if a page differs from its result files")
    commands = parser.add_subparsers(dest="action")
    run = commands.add_parser("run", help="run a figure's commands and write results/NAME.json")
    run.add_argument("name", choices=sorted(FIGURES))
    run.add_argument("--kernel", help="OPENBLAS_CORETYPE of a check run (e.g. Haswell, Sandybridge)")
    run.add_argument(
        "--extra",
        default="",
        help="arguments added to the figure's command (e.g. '--domains isr'): with --kernel, a check of the rows "
        "it prints; without, a re-run of those rows, which replace the published ones (the others keep their run)",
    )
    run.add_argument(
        "--keys",
        default="",
        help="a check run of some of a many-command figure's commands only (comma-separated keys, see list)",
    )
    commands.add_parser("render", help="write docs/results/ and the marked blocks of README.md and docs/")
    plot = commands.add_parser("plot", help="draw a figure's plot from its result file")
    plot.add_argument("name", choices=sorted(n for n, f in FIGURES.items() if f.plot))
    commands.add_parser("list", help="the figures and their commands")
    args = parser.parse_args(argv)
    if args.check:
        return check()
    if args.action == "run":
        figure = FIGURES[args.name]
        keys = [key for key in args.keys.split(",") if key]
        extra = shlex.split(args.extra)
        unknown = sorted(set(keys) - set(figure.commands))
        if unknown or (keys and (args.kernel is None or not figure.partial_checks)):
            print(
                f"--keys {args.keys}: a check run (--kernel) of the keys of {figure.name}'s runs "
                f"({', '.join(figure.commands)}); unknown: {', '.join(unknown) or 'none'}",
                file=sys.stderr,
            )
            return 2
        if extra and not figure.markdown:
            print(
                f"--extra: arguments added to a one-command figure whose output is Markdown tables "
                f"({', '.join(n for n, f in FIGURES.items() if f.markdown)})",
                file=sys.stderr,
            )
            return 2
        path = write_run(figure, run_figure(figure, args.kernel, keys, extra), check=args.kernel is not None)
        print(f"wrote {path.relative_to(ROOT)}")
    elif args.action == "render":
        render()
    elif args.action == "plot":
        figure, source = FIGURES[args.name], RESULTS / f"{args.name}.json"
        if not source.exists():
            print(
                f"{source.relative_to(ROOT)}: no result file; run `{SCRIPT} run {args.name}` first",
                file=sys.stderr,
            )
            return 2
        target, draw = figure.plot
        draw(json.loads(source.read_text())["published"]["data"], ROOT / target)
        print(f"wrote {target}")
    elif args.action == "list":
        for figure in FIGURES.values():
            print(
                figure.name,
                *(shlex.join(expand(a, f"{RUN_DIR}/...")) for a in figure.commands.values()),
                sep="\n  ",
            )
    else:
        parser.print_help()
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
