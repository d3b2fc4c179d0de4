"""Published tables generated from result files, each saying how it reproduces.

Every table of the README and docs/ that this script knows (``FIGURES``) is produced in two steps:

1. ``run NAME`` executes the figure's commands (a ``trials``/``pomdp`` CLI call or a
   ``scripts/reproduce_*.py`` / ``scripts/bench_*.py`` script), one at a time, and writes
   ``results/NAME.json``: the numbers plus their provenance (the git commit it ran, from a copy of that
   commit's code, the exact commands, the OpenBLAS kernel that threadpoolctl reports in the same environment,
   numpy/scipy/mujoco/torch versions, the date). ``run NAME --kernel Haswell`` runs the same commands under
   ``OPENBLAS_CORETYPE=Haswell`` and adds that run to the file as a check of the published one;
2. ``render`` writes one ``docs/results/`` page per figure (``NAME.md`` plus ``docs/results/index.md``) and
   replaces, in README.md and docs/**/*.md, whatever lies between ``<!-- results:NAME start -->`` and
   ``<!-- results:NAME end -->`` (``NAME`` alone: every table of the figure; ``NAME.KEY``: one of them).

Each table states its class, derived from the runs in its result file, never typed:

* *exact on any host*: a second kernel's run gives the same numbers (the data compare equal byte for byte);
* *statistical*: the numbers differ between kernels, and the figure's own check passes (each second-kernel
  mean lies inside the published 95 % interval, every thesis claim keeps its verdict; for a solver value the
  second kernel's lower bound lies in the published [lower, upper] bracket);
* *timing*: seconds and ratios of seconds, which depend on the host and its load; recorded, never compared;
* *not re-checked*: only one kernel has run it.

``--check`` renders in memory and exits 1 when a committed page differs from what the committed result files
render, naming the page, the table and the command to re-run (fast: nothing is solved or simulated)::

    .venv/bin/python scripts/render_results.py run arenas [--kernel Haswell]
    .venv/bin/python scripts/render_results.py render
    .venv/bin/python scripts/render_results.py --check
"""

from __future__ import annotations

import argparse
import datetime as dt
import hashlib
import json
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
VERDICTS = ("holds", "significant", ">= 80 %")
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


def markdown_figure_tables(keys: Sequence[str]) -> Callable[[dict], list[Table]]:
    def tables(data: dict) -> list[Table]:
        return [
            Table(key, table["caption"], table["headers"], table["rows"])
            for key, table in zip(keys, data["tables"], strict=True)
        ]

    return tables


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
            {
                "reproduce": [
                    "{python}",
                    "scripts/reproduce_atpo.py",
                    "--out",
                    "{out}",
                    "--markdown",
                    "--skip-fig59",
                ]
            },
            markdown_extract("reproduce"),
            markdown_figure_tables(("table5_5", "table5_6", "beliefs")),
            compare_markdown_tables,
            ("docs/atpo.md", "README.md"),
            markdown=True,
        ),
    )
}


# ------------------------------------------------------------------------------------------------ runs


def git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()


def expand(argv: Sequence[str], out: str) -> list[str]:
    return [part.replace("{python}", ".venv/bin/python").replace("{out}", out) for part in argv]


CODE = ("embodied_adhoc", "scripts", "assets", "scenes", "pyproject.toml", "constraints.txt")
"""What a run executes, taken from the commit: a check counts against a published run of that code only."""


def snapshot() -> tuple[str, str, Path]:
    """HEAD's commit, the SHA-256 of its files under ``CODE`` (names and blobs), and a copy of those files.

    A figure runs from the copy (``PYTHONPATH`` first, ahead of the editable install), so its numbers are
    those of the commit it records: uncommitted edits in the checkout, and edits made while it runs, never
    reach it. This renderer is left out of the digest, since it changes the pages, never a number."""
    commit = git("rev-parse", "HEAD")
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


def published_code(figure: Figure) -> tuple[str, str, Path] | None:
    """The frozen copy the figure's published run ran from, while this machine still has it."""
    path = RESULTS / f"{figure.name}.json"
    if not path.exists():
        return None
    published = json.loads(path.read_text())["published"]
    code = published.get("code_sha256", "")
    folder = ROOT / RUN_DIR / f"code-{code[:16]}"
    return (published["commit"], code, folder) if code and folder.is_dir() else None


def run_figure(
    figure: Figure, kernel: str | None, keys: Sequence[str] = (), extra: Sequence[str] = ()
) -> dict:
    """Run the commands of ``figure`` (those named in ``keys``, or all) in turn under
    ``OPENBLAS_CORETYPE=kernel`` (None: the host's), each with ``extra`` arguments added.

    A check run (``kernel`` given) runs the published run's frozen code when it is still here, so the two runs
    differ in the kernel only; otherwise it freezes HEAD, and the class shows any difference."""
    label = kernel or "default"
    commit, code, folder = (kernel and published_code(figure)) or snapshot()
    env = dict(os.environ)
    env.pop("OPENBLAS_CORETYPE", None)
    if kernel:
        env["OPENBLAS_CORETYPE"] = kernel
    env["XDG_CACHE_HOME"] = str(ROOT / CACHE_DIR / label)
    env["PYTHONPATH"] = os.pathsep.join([str(folder), *filter(None, [env.get("PYTHONPATH")])])
    probe = subprocess.run(
        [sys.executable, "-c", PROBE], cwd=folder, env=env, capture_output=True, text=True, check=True
    )
    numerics = json.loads(probe.stdout)
    if Path(numerics["package"]).resolve() != (folder / "embodied_adhoc" / "__init__.py").resolve():
        sys.exit(
            f"{figure.name}: the run would import {numerics['package']}, not the frozen copy in {folder}"
        )
    outputs, commands = {}, {}
    started = dt.datetime.now(dt.UTC)
    for key, argv in figure.commands.items():
        if keys and key not in keys:
            continue
        out = f"runs/{figure.name}-{label}-{key}"
        command = expand(argv, out) + list(extra)
        commands[key] = shlex.join(command)
        print(f"[{figure.name} {label}] {commands[key]}", file=sys.stderr, flush=True)
        shutil.rmtree(folder / out, ignore_errors=True)
        executable = [str(ROOT / command[0]) if command[0].startswith(".venv/") else command[0], *command[1:]]
        done = subprocess.run(executable, cwd=folder, env=env, capture_output=True, text=True)
        if done.returncode != 0:
            sys.exit(f"{figure.name}: `{commands[key]}` exited {done.returncode}:\n{done.stderr[-2000:]}")
        outputs[key] = done.stdout
    return {
        "kernel": numerics["kernel"],
        "openblas_coretype": kernel,
        "commit": commit,
        "code_sha256": code,
        "commands": commands,
        "keys": list(keys),
        "extra": shlex.join(extra),
        "versions": {k: v for k, v in numerics["versions"].items() if k != "torch" or figure.torch},
        "python": sys.version.split()[0],
        "started": started.isoformat(timespec="seconds"),
        "finished": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "data": figure.extract(outputs),
    }


def write_run(figure: Figure, run: dict, check: bool) -> Path:
    path = RESULTS / f"{figure.name}.json"
    document = {"figure": figure.name, "published": run, "checks": []}
    if check:
        if not path.exists():
            sys.exit(
                f"{path.relative_to(ROOT)}: no published run to check; run `{SCRIPT} run {figure.name}` first"
            )
        document = json.loads(path.read_text())
        document["checks"] = [c for c in document["checks"] if c["kernel"] != run["kernel"]] + [run]
    RESULTS.mkdir(exist_ok=True)
    path.write_text(json.dumps(document, indent=1, ensure_ascii=False) + "\n")
    return path


# --------------------------------------------------------------------------------------- classes/pages


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
    if figure.compare is None:
        return TIMING, "seconds depend on the host and its load: re-measure, never compare across machines"
    others = [c for c in document["checks"] if c["kernel"] != published["kernel"]]
    if not others:
        return "not re-checked", f"run under the {published['kernel']} kernel only"
    stale = [c for c in others if c.get("code_sha256") != published.get("code_sha256")]
    others = [c for c in others if c not in stale]
    if not others:
        kernels = ", ".join(c["kernel"] for c in stale)
        return "not re-checked", f"the {kernels} run checked other code than the published run's"
    names = [published["kernel"], *(c["kernel"] for c in others)]
    kernels = ", ".join(names[:-1]) + " and " + names[-1]
    # A partial check ran some commands or rows only: it is held to the same part of the published data.
    ours = {c["kernel"]: table_data(figure, part(published["data"], c), key) for c in others}
    theirs = {c["kernel"]: table_data(figure, c["data"], key) for c in others}
    scope = "".join(
        f"; {c['kernel']} ran {len(c['keys'])} of the {len(figure.commands)} commands"
        for c in others
        if c.get("keys")
    )
    scope += "".join(f"; {c['kernel']} ran with `{c['extra']}` only" for c in others if c.get("extra"))
    differ = [kernel for kernel in theirs if comparable(theirs[kernel]) != comparable(ours[kernel])]
    if not differ:
        return (
            "exact on any host",
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
    return STATISTICAL, f"the numbers differ between the {kernels} kernels; {figure.checked}{same}{scope}"


def part(data: dict, check: dict) -> dict:
    """The part of the published ``data`` that a check ran: the commands in its ``keys``, or for a check with
    ``extra`` arguments (e.g. fewer domains) the table rows it printed; all of it for a full check."""
    if check.get("keys"):
        return {"runs": {key: data["runs"][key] for key in check["keys"]}}
    if check.get("extra") and "tables" in data:
        tables = []
        for ours, theirs in zip(data["tables"], check["data"]["tables"], strict=True):
            labels = {row_label(row) for row in theirs["rows"]}
            tables.append({**ours, "rows": [row for row in ours["rows"] if row_label(row) in labels]})
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
    return (
        f"*Generated from `results/{figure.name}.json` ({run['started'][:10]}, commit {run['commit'][:10]}, "
        f"OpenBLAS {run['kernel']}) by `{SCRIPT}`; made by {commands}. [How it reproduces]({link}).*"
    )


def fragment(figure: Figure, document: dict, key: str | None, page: Path) -> str:
    tables = figure.tables(document["published"]["data"])
    chosen = [t for t in tables if key is None or t.key == key]
    if not chosen:
        sys.exit(
            f"{page.relative_to(ROOT)}: marker results:{figure.name}.{key}: the figure has tables "
            f"{', '.join(t.key for t in tables)}"
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
        "```",
        "",
    ]
    lines += [
        "| run | OpenBLAS kernel | commit | code (SHA-256 of its files) | versions | date (UTC) |",
        "|---|---|---|---|---|---|",
    ]
    for label, each in [("published", run), *(("check", c) for c in document["checks"])]:
        versions = ", ".join(f"{k} {v}" for k, v in each["versions"].items())
        coretype = f" (OPENBLAS_CORETYPE={each['openblas_coretype']})" if each["openblas_coretype"] else ""
        lines.append(
            f"| {label} | {each['kernel']}{coretype} | {each['commit'][:10]} | "
            f"{each.get('code_sha256', 'not recorded')[:16]} | "
            f"python {each['python']}, {versions} | {each['started'].replace('T', ' ')[:16]} |"
        )
    return "\n".join(lines) + "\n"


def index_page(documents: dict[str, dict]) -> str:
    lines = [
        "# Results",
        "",
        "<!-- generated by scripts/render_results.py -->",
        "",
        "Every table below is rendered from a result file in `results/` by `scripts/render_results.py`, "
        "which "
        "also states its reproducibility class and checks it in CI (`render_results.py --check`).",
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
    return "\n".join(lines) + "\n"


HEADLINE = "headline"
"""The README's summary table: one row per headline figure, each cell taken from that figure's result file."""
HEADLINE_SOURCES = ("hotspot", "sim-vs-physics", "chapter5")
NOT_GENERATED = "the offline speech pipeline, ATLPO and TEAMSTER"
"""Headline results whose scripts do not write result files yet; their pages give the figures and commands."""


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
    table = Table(HEADLINE, "", ["result (thesis figure)", "ours", "thesis", "how it reproduces"], rows)
    sources = ", ".join(f"`results/{name}.json`" for name in HEADLINE_SOURCES if name in documents)
    return (
        f"{table.markdown()}\n\n*Generated by `{SCRIPT}` from {sources}. Not generated from result files yet "
        f"(their pages give the figures and the commands that made them): {NOT_GENERATED}.*"
    )


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
        if name == HEADLINE:
            end = f"<!-- results:{name} end -->"
            stop = lines.index(end, index) if end in lines[index:] else None
            if stop is None:
                sys.exit(f"{page.relative_to(ROOT)}:{index}: results:{name} has no `{end}` line")
            out += ["", headline(documents, page), "", end]
            names.append(name)
            index = stop + 1
            continue
        if name not in FIGURES or name not in documents:
            sys.exit(
                f"{page.relative_to(ROOT)}:{index}: results:{name}: no such figure with a result file "
                f"(known: {', '.join(sorted(documents))}); run `{SCRIPT} run {name}`"
            )
        end = f"<!-- results:{match['name']} end -->"
        try:
            stop = lines.index(end, index)
        except ValueError:
            sys.exit(f"{page.relative_to(ROOT)}:{index}: results:{match['name']} has no `{end}` line")
        out += ["", fragment(FIGURES[name], documents[name], key or None, page), "", end]
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
        text = page.read_text()
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
            figure = FIGURES[name.partition(".")[0]]
            print(
                f"{relative}: table {name} differs from results/{figure.name}.json ({where}); re-render with "
                f"`.venv/bin/python {SCRIPT} render`, or if the results are stale re-run its script "
                f"(`{script_of(figure)}`): `{regenerate(figure)}`"
            )
    return 1 if failures else 0


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
        help="a check run with these arguments added to the figure's command (e.g. '--domains gridworld')",
    )
    run.add_argument(
        "--keys",
        default="",
        help="a check run of some of a many-command figure's commands only (comma-separated keys, see list)",
    )
    commands.add_parser("render", help="write docs/results/ and the marked blocks of README.md and docs/")
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
        if extra and (args.kernel is None or not figure.markdown):
            print(
                f"--extra: a check run (--kernel) of a one-command figure whose output is Markdown tables "
                f"({', '.join(n for n, f in FIGURES.items() if f.markdown)})",
                file=sys.stderr,
            )
            return 2
        path = write_run(figure, run_figure(figure, args.kernel, keys, extra), check=args.kernel is not None)
        print(f"wrote {path.relative_to(ROOT)}")
    elif args.action == "render":
        render()
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
