"""The chapter-6 table (thesis section 6.2.5) for ATLPO-MF: three environment sets x two domains, 16 episodes per
environment x 3 training seeds, beside the thesis's numbers; the classifier's accuracy per step; and the
held-out-teammate split (teams no library member saw, scores normalised between random 0 and the original
teammate 1, IQM with bootstrap CIs).

    .venv/bin/python scripts/reproduce_atlpo.py --out runs/atlpo [--domains foraging pursuit] [--seeds 0 1 2]

Per (domain, seed) it trains the ``task+team`` library (six members, 30,000 PPO steps each, the command
``embodied-adhoc train atlpo``'s pipeline), then the ``task`` and ``team`` libraries from the same members (a
member's seed depends on its environment, not its set: ``learning.atlpo.member_seed``), each with its own
classifier. Seed 0's ``task+team`` library is the one shipped in the package when it was made with the same
settings (its ``training.json`` says so), so it is copied, not retrained. Everything is resumable: a folder with
``training.json`` is not retrained, an ``evaluation*.json`` not re-evaluated. ``--train-only`` stops before the
evaluations; run two processes with different ``--domains`` to use two cores. ``--mb`` adds the ATLPO-MB
libraries (and the model-based baseline) of the sets and seeds asked, e.g. one cell:
``--mb --domains foraging --sets task --seeds 0 --no-held-out``.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from embodied_adhoc.experiments.script_args import parse_dataclass_args

# results-to-reproduce.md, chapter 6: (set, domain) -> original, model-free RL, ATLPO-MF, random (the thesis's
# model-free RL column "knows task/team": our ``known``, the library member of the true environment)
THESIS = {
    ("task", "foraging"): (6.72, 7.56, 13.02, 59.05),
    ("task", "pursuit"): (9.36, 11.22, 21.36, 50.66),
    ("team", "foraging"): (9.2, 7.68, 8.85, 53.71),
    ("team", "pursuit"): (14.45, 10.19, 10.71, 58.21),
    ("task+team", "foraging"): (7.89, 7.62, 11.96, 56.52),
    ("task+team", "pursuit"): (11.54, 10.71, 16.75, 54.21),
}
# ... and (set, domain) -> model-based RL ("knows task/team"), ATLPO-MB
THESIS_MB = {
    ("task", "foraging"): (8.13, 15.35),
    ("task", "pursuit"): (9.79, 17.34),
    ("team", "foraging"): (7.31, 10.24),
    ("team", "pursuit"): (10.11, 10.64),
    ("task+team", "foraging"): (7.73, 14.06),
    ("task+team", "pursuit"): (9.95, 15.67),
}
TABLE_AGENTS = ("original", "known", "atlpo-mf", "random")
SETS = ("task", "team", "task+team")


@dataclass(frozen=True)
class Args:
    out: Path = Path("runs/atlpo")
    """folder of the libraries, evaluations and the table (resumable)"""
    domains: tuple[str, ...] = ("foraging", "pursuit")
    sets: tuple[str, ...] = SETS
    seeds: tuple[int, ...] = (0, 1, 2)
    """training seeds (the thesis: 3)"""
    episodes: int = 16
    """episodes per library environment and seed (the thesis: 16)"""
    steps: int = 30_000
    """PPO env steps per library member (the thesis: 30,000)"""
    max_steps: int = 200
    """step cap; an unfinished episode counts it"""
    threads: int = 1
    train_only: bool = False
    """train the libraries and classifiers, evaluate nothing"""
    no_held_out: bool = False
    """skip the held-out-teammate split (evaluated with each seed's task+team library)"""
    team: str = ""
    """held-out split: also a user's team, ``module:callable`` (see learning/atlpo_heldout.py)"""
    report_only: bool = False
    """print the table from what ``--out`` holds, train and evaluate nothing"""
    mb: bool = False
    """also train the ATLPO-MB libraries (``train atlpo --model mb --generalist``: members, the model-based
    baseline and the classifier) of the sets and seeds asked, in ``<set>-mb`` folders, then evaluate them"""


def library_folder(out: Path, domain: str, seed: int, set_name: str) -> Path:
    return out / domain / f"seed{seed}" / set_name.replace("+", "-")


def train(args: Args, domain: str, seed: int) -> None:
    from embodied_adhoc.learning.atlpo import library_set, shipped_library
    from embodied_adhoc.learning.atlpo_train import AtlpoTraining, train_atlpo

    union = library_folder(args.out, domain, seed, "task+team")
    if not (union / "training.json").exists() and seed == 0:
        shipped = shipped_library(domain)
        made = json.loads((shipped / "training.json").read_text())
        if made["steps"] == args.steps and made["seed"] == 0 and made["set"] == "task+team":
            shutil.copytree(shipped, union, dirs_exist_ok=True)
            print(f"{union}: the shipped library (same settings)", flush=True)
    for set_name in ("task+team",) + tuple(s for s in args.sets if s != "task+team"):
        folder = library_folder(args.out, domain, seed, set_name)
        if (folder / "training.json").exists():
            continue
        folder.mkdir(parents=True, exist_ok=True)
        for environment in library_set(set_name):  # the same member (same seed) as in the task+team library
            name = f"{domain}-{environment.name}.safetensors"
            if (union / name).exists() and not (folder / name).exists():
                shutil.copy2(union / name, folder / name)
        report = train_atlpo(
            AtlpoTraining(
                domain, set_name, str(folder), steps=args.steps, seed=seed, threads=args.threads, quiet=True
            )
        )
        print(
            f"{folder}: trained in {report['total_seconds']} s (policies {report['policy_seconds']} s)",
            flush=True,
        )


def train_mb(args: Args, domain: str, seed: int) -> None:
    """ATLPO-MB libraries in ``<set>-mb`` folders; ``task+team`` first when asked, whose members (same seeds)
    the other sets then copy, as for ATLPO-MF."""
    from embodied_adhoc.learning.atlpo import library_set
    from embodied_adhoc.learning.atlpo_train import AtlpoTraining, train_atlpo

    def mb_folder(set_name: str) -> Path:
        folder = library_folder(args.out, domain, seed, set_name)
        return folder.with_name(folder.name + "-mb")

    union = mb_folder("task+team")
    for set_name in sorted(args.sets, key=lambda name: name != "task+team"):
        folder = mb_folder(set_name)
        if (folder / "training.json").exists():
            continue
        folder.mkdir(parents=True, exist_ok=True)
        for environment in library_set(set_name):
            name = f"{domain}-mb-{environment.name}.safetensors"
            if (union / name).exists() and not (folder / name).exists():
                shutil.copy2(union / name, folder / name)
        report = train_atlpo(
            AtlpoTraining(
                domain,
                set_name,
                str(folder),
                steps=args.steps,
                seed=seed,
                threads=args.threads,
                quiet=True,
                model="mb",
                generalist=True,
            )
        )
        print(
            f"{folder}: trained in {report['total_seconds']} s (policies {report['policy_seconds']} s)",
            flush=True,
        )


def evaluate_cell(args: Args, domain: str, seed: int, set_name: str) -> dict:
    from embodied_adhoc.learning.atlpo import load_library
    from embodied_adhoc.learning.atlpo_eval import evaluate

    folder = library_folder(args.out, domain, seed, set_name)
    path = folder / f"evaluation-{args.episodes}x{args.max_steps}.json"
    if path.exists():
        return json.loads(path.read_text())
    library, classifier = load_library(folder)
    results = evaluate(library, classifier, args.episodes, seed, args.max_steps, agents=TABLE_AGENTS)
    path.write_text(json.dumps(results) + "\n")
    return results


def mb_cells(args: Args) -> list[tuple[str, int, str, Path]]:
    """(domain, seed, set, folder) of every ATLPO-MB library under ``--out`` (``<set>-mb`` folders written by
    ``embodied-adhoc train atlpo --model mb [--generalist]``), for the seeds asked."""
    found = []
    for domain in ("foraging", "pursuit"):
        for seed in args.seeds:
            for set_name in SETS:
                folder = library_folder(args.out, domain, seed, set_name).with_name(
                    library_folder(args.out, domain, seed, set_name).name + "-mb"
                )
                if (folder / "training.json").exists():
                    found.append((domain, seed, set_name, folder))
    return found


def evaluate_mb_cell(args: Args, domain: str, seed: int, set_name: str, folder: Path) -> dict:
    """ATLPO-MB and, where trained, the model-based baseline (one MB policy on all the set's environments), on
    the same episodes as the MF cell."""
    from embodied_adhoc.learning.atlpo import generalist_path, load_library, load_policy
    from embodied_adhoc.learning.atlpo_eval import evaluate

    path = folder / f"evaluation-{args.episodes}x{args.max_steps}.json"
    if path.exists():
        return json.loads(path.read_text())
    library, classifier = load_library(folder)
    baseline = generalist_path(folder, domain, set_name, "mb")
    generalist = load_policy(baseline) if baseline.exists() else None
    results = evaluate(
        library,
        classifier,
        args.episodes,
        seed,
        args.max_steps,
        agents=("atlpo-mf", "mf-all"),
        generalist=generalist,
    )
    results = {{"atlpo-mf": "atlpo-mb", "mf-all": "mb-all"}.get(k, k): v for k, v in results.items()}
    path.write_text(json.dumps(results) + "\n")
    return results


def mb_report(args: Args) -> tuple[list[str], dict]:
    """ATLPO-MB rows pooled over the seeds whose ``<set>-mb`` cell is evaluated, like the MF table (one sample of
    16 episodes per environment x seeds); the ``seeds`` column names them, so a partial run says which it has."""
    from embodied_adhoc.experiments.stats import summarise_sample

    evaluated: dict[tuple[str, str], list[tuple[int, dict]]] = {}
    for domain, seed, set_name, folder in mb_cells(args):
        path = folder / f"evaluation-{args.episodes}x{args.max_steps}.json"
        if path.exists():
            evaluated.setdefault((set_name, domain), []).append((seed, json.loads(path.read_text())))
    if not evaluated:
        return [], {}
    lines = [
        "ATLPO-MB and the model-based baseline (where trained; same episodes as the MF cell), pooled over the "
        "seeds listed: mean steps [95 % bootstrap CI] (solved %) | thesis (ATLPO-MB; model-based RL, which "
        "knows task and team)",
        "",
        "| set | domain | seeds | atlpo-mb | mb-all |",
        "|---|---|---|---|---|",
    ]
    table = {}
    for set_name in SETS:
        for domain in ("foraging", "pursuit"):
            if (set_name, domain) not in evaluated:
                continue
            seeds = [seed for seed, _ in evaluated[(set_name, domain)]]
            cells = [results for _, results in evaluated[(set_name, domain)]]
            model_based, atlpo_mb = THESIS_MB[(set_name, domain)]
            row = []
            for agent, thesis in (("atlpo-mb", atlpo_mb), ("mb-all", model_based)):
                if any(agent not in results for results in cells):
                    row.append("not trained for every seed listed")
                    continue
                steps = np.concatenate([results[agent]["steps"] for results in cells]).astype(float)
                solved = float(np.mean(np.concatenate([results[agent]["finished"] for results in cells])))
                summary = summarise_sample(steps)
                row.append(
                    f"{summary.mean:.2f} [{summary.ci_low:.2f}, {summary.ci_high:.2f}] ({100 * solved:.0f} %) "
                    f"\\| {thesis}"
                )
                table.setdefault(f"{set_name}/{domain}", {"seeds": seeds})[agent] = {
                    "mean": summary.mean,
                    "ci": [summary.ci_low, summary.ci_high],
                    "iqm": summary.iqm,
                    "solved": solved,
                    "n": summary.n,
                    "thesis": thesis,
                }
            lines.append(f"| {set_name} | {domain} | {','.join(map(str, seeds))} | {row[0]} | {row[1]} |")
    return lines, table


def held_out_cell(args: Args, domain: str, seed: int) -> dict:
    from embodied_adhoc.learning.atlpo import load_library
    from embodied_adhoc.learning.atlpo_heldout import evaluate_held_out, held_out_teams

    folder = library_folder(args.out, domain, seed, "task+team")
    tag = "" if not args.team else "-" + args.team.replace(":", "_").replace(".", "_")
    path = folder / f"held-out-{args.episodes}x{args.max_steps}{tag}.json"
    if path.exists():
        return json.loads(path.read_text())
    library, classifier = load_library(folder)
    results = evaluate_held_out(
        library, classifier, held_out_teams(domain, args.team or None), args.episodes, seed, args.max_steps
    )
    path.write_text(json.dumps(results) + "\n")
    return results


def classifier_accuracy(args: Args, domain: str, set_name: str) -> list[float]:
    """Mean over the seeds of the classifier's held-out accuracy after steps 1..10 (training.json)."""
    rows = []
    for seed in args.seeds:
        path = library_folder(args.out, domain, seed, set_name) / "training.json"
        if path.exists():
            per_step = json.loads(path.read_text())["per_step"]
            rows.append([row["accuracy"] for row in per_step[1:11]])
    width = min((len(r) for r in rows), default=0)
    return [float(np.mean([r[t] for r in rows])) for t in range(width)]


def report(args: Args) -> str:
    from embodied_adhoc.experiments.stats import summarise_sample

    lines = [
        f"Chapter-6 table: average steps to finish ({args.episodes} episodes per environment x seeds "
        f"{list(args.seeds)}, cap {args.max_steps}; an unfinished episode counts the cap); mean [95 % "
        "bootstrap CI] (solved %) | thesis",
        "",
    ]
    header = (
        f"| set | domain | K | seeds | {' | '.join(TABLE_AGENTS)} "
        "| classifier accuracy after step 1/3/5/7/10 (mean over the trained seeds) |"
    )
    lines += [header, "|" + "---|" * (header.count("|") - 1)]
    table = {}
    for set_name in SETS:
        for domain in ("foraging", "pursuit"):
            cells = []
            for seed in args.seeds:
                path = (
                    library_folder(args.out, domain, seed, set_name)
                    / f"evaluation-{args.episodes}x{args.max_steps}.json"
                )
                if path.exists():
                    cells.append(json.loads(path.read_text()))
            if not cells:
                continue
            k = len(cells[0]["original"]["steps"]) // args.episodes
            row = [set_name, domain, str(k), str(len(cells))]
            table[f"{set_name}/{domain}"] = {}
            for i, agent in enumerate(TABLE_AGENTS):
                steps = np.concatenate([c[agent]["steps"] for c in cells]).astype(float)
                solved = np.mean(np.concatenate([c[agent]["finished"] for c in cells]))
                summary = summarise_sample(steps)
                thesis = THESIS[(set_name, domain)][i]
                row.append(
                    f"{summary.mean:.2f} [{summary.ci_low:.2f}, {summary.ci_high:.2f}] ({100 * solved:.0f} %) "
                    f"\\| {thesis}"
                )
                table[f"{set_name}/{domain}"][agent] = {
                    "mean": summary.mean,
                    "ci": [summary.ci_low, summary.ci_high],
                    "iqm": summary.iqm,
                    "solved": float(solved),
                    "n": summary.n,
                    "thesis": thesis,
                }
            accuracy = classifier_accuracy(args, domain, set_name)
            row.append("/".join(f"{accuracy[t]:.2f}" for t in (0, 2, 4, 6, 9) if t < len(accuracy)))
            lines.append("| " + " | ".join(row) + " |")
    held = held_out_report(args)
    mb, mb_table = mb_report(args)
    (args.out / "table.json").write_text(
        json.dumps({"table": table, "held_out": held[1], "mb": mb_table}, indent=1) + "\n"
    )
    return "\n".join(lines + [""] + held[0] + ([""] + mb if mb else []))


def held_out_report(args: Args) -> tuple[list[str], dict]:
    from embodied_adhoc.experiments.stats import summarise_sample
    from embodied_adhoc.learning.atlpo_heldout import normalised_scores

    lines, data = [], {}
    for domain in ("foraging", "pursuit"):
        cells = []
        for seed in args.seeds:
            folder = library_folder(args.out, domain, seed, "task+team")
            cells += [
                json.loads(p.read_text())
                for p in sorted(folder.glob(f"held-out-{args.episodes}x{args.max_steps}*.json"))
            ]
        if not cells:
            continue
        if not lines:
            lines = [
                "Held-out teammates (task+team library; teams no member saw): normalised score "
                "(random 0, original teammate 1), IQM [95 % bootstrap CI] over episodes; mean steps (solved %)",
                "",
                "| domain | team | episodes | atlpo-mf | known-task | original steps | atlpo-mf steps "
                "| random steps |",
                "|---|---|---|---|---|---|---|---|",
            ]
        for team, scores in normalised_scores(cells, summarise_sample).items():
            data[f"{domain}/{team}"] = scores
            lines.append(
                f"| {domain} | {team} | {scores['episodes']} | {scores['atlpo-mf']['iqm']:.2f} "
                f"[{scores['atlpo-mf']['ci'][0]:.2f}, {scores['atlpo-mf']['ci'][1]:.2f}], mean "
                f"{scores['atlpo-mf']['mean']:.2f} | {scores['known-task']['iqm']:.2f}, mean "
                f"{scores['known-task']['mean']:.2f} | {scores['steps']['original']:.1f} "
                f"({100 * scores['solved']['original']:.0f} %) | {scores['steps']['atlpo-mf']:.1f} "
                f"({100 * scores['solved']['atlpo-mf']:.0f} %) | {scores['steps']['random']:.1f} "
                f"({100 * scores['solved']['random']:.0f} %) |"
            )
    return lines, data


def main(args: Args) -> None:
    import torch

    torch.set_num_threads(args.threads)
    if not args.report_only:
        for domain in args.domains:
            for seed in args.seeds:
                train(args, domain, seed)
                if args.mb:
                    train_mb(args, domain, seed)
        if not args.train_only:
            for domain in args.domains:
                for seed in args.seeds:
                    for set_name in args.sets:
                        evaluate_cell(args, domain, seed, set_name)
                    if not args.no_held_out:
                        held_out_cell(args, domain, seed)
            for domain, seed, set_name, folder in mb_cells(args):
                if domain in args.domains and set_name in args.sets:
                    evaluate_mb_cell(args, domain, seed, set_name, folder)
                    print(f"{domain} seed {seed}: evaluated", flush=True)
    text = report(args)
    (args.out / "table.md").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main(parse_dataclass_args(Args, description=__doc__))
