"""The ppo-generalist beside ATLPO-MF, the library member that knows the task, the original teammate and random,
on the train teams (tau0-tau2, what it was trained with) and the held-out teams of the ATLPO split (noisy and mixed
teams it never saw), and the liam and meliba agents where shipped (or ``--liam FILE``, ``--meliba FILE``), with
the held-out protocol of ``embodied_adhoc.learning.atlpo_heldout``: the same episodes
(seeds, tasks cycling 1..4) for every agent, scores normalised between random (0) and the original teammate (1),
IQM and mean with percentile-bootstrap intervals.

    .venv/bin/python scripts/generalist_heldout.py --domain foraging --episodes 16 --out runs/generalist-heldout

Writes ``results.json`` (per team and agent: steps, finished flags, normalised scores; each scored agent's
weights and training budget; the command with ``--out DIR``) and ``table.md``; uses the shipped weights and
library unless ``--weights FILE`` / ``--library DIR`` are given. ``scripts/library_free_bench.py`` renders the
held-out tables of ``results/library_free/<domain>-heldout/results.json`` on docs/library_free.md.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def shown(path) -> str:
    """``path`` relative to the repository when it lies inside it (result files name no machine's folders)."""
    path = Path(path).resolve()
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def command(argv: list[str]) -> str:
    """The command line of this run with its output folder written ``DIR`` (and the BLAS thread count it ran
    with, where one was set)."""
    threads = os.environ.get("OPENBLAS_NUM_THREADS")
    words = [*([f"OPENBLAS_NUM_THREADS={threads}"] if threads else []), ".venv/bin/python"]
    words.append("scripts/generalist_heldout.py")
    rest = iter(argv)
    for word in rest:
        if word == "--out":
            next(rest, None)
            words += ["--out", "DIR"]
        elif word.startswith("--out="):
            words.append("--out=DIR")
        else:
            words.append(word)
    return " ".join(words)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--domain", choices=("foraging", "pursuit"), default="foraging")
    parser.add_argument("--episodes", type=int, default=16, help="episodes per team (default 16)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-steps", type=int, default=200)
    parser.add_argument("--weights", default=None, help="ppo-generalist weights (default: the shipped ones)")
    parser.add_argument("--library", default=None, help="ATLPO library folder (default: the shipped one)")
    parser.add_argument(
        "--liam",
        default=None,
        help="liam weights scored beside it (default: the shipped ones, where shipped)",
    )
    parser.add_argument(
        "--meliba",
        default=None,
        help="meliba weights scored beside it (default: the shipped ones, where shipped)",
    )
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    if args.episodes < 1 or args.max_steps < 1:
        parser.error("--episodes and --max-steps: give positive integers")

    import torch

    from embodied_adhoc.experiments.stats import summarise_sample
    from embodied_adhoc.learning.atlpo import load_library, shipped_library
    from embodied_adhoc.learning.atlpo_heldout import evaluate_held_out, held_out_teams, normalised_scores
    from embodied_adhoc.learning.generalist import (
        GeneralistAgent,
        load_generalist,
        shipped_weights,
        train_teams,
    )

    torch.set_num_threads(1)
    library, classifier = load_library(args.library or shipped_library(args.domain))
    weights_path = args.weights or shipped_weights(args.domain)
    model, metadata = load_generalist(weights_path)
    extra_agents = {"ppo-generalist": lambda: GeneralistAgent(model)}
    training = {"ppo-generalist": (weights_path, metadata)}
    liam_path = args.liam
    if liam_path is None:
        from embodied_adhoc.errors import ConfigError
        from embodied_adhoc.learning.liam import shipped_weights as shipped_liam

        try:
            liam_path = shipped_liam(args.domain)
        except ConfigError:  # none shipped for this domain: the table goes without it
            liam_path = None
    if liam_path is not None:
        liam_model, liam_metadata = load_generalist(liam_path, kind="liam")
        extra_agents["liam"] = lambda: GeneralistAgent(liam_model, name="liam")
        training["liam"] = (liam_path, liam_metadata)
    meliba_path = args.meliba
    if meliba_path is None:
        from embodied_adhoc.errors import ConfigError
        from embodied_adhoc.learning.meliba import shipped_weights as shipped_meliba

        try:
            meliba_path = shipped_meliba(args.domain)
        except ConfigError:  # none shipped for this domain: the table goes without it
            meliba_path = None
    if meliba_path is not None:
        from embodied_adhoc.learning.meliba import load_meliba

        meliba_model, meliba_metadata = load_meliba(meliba_path)
        extra_agents["meliba"] = lambda: GeneralistAgent(meliba_model, name="meliba")
        training["meliba"] = (meliba_path, meliba_metadata)
    started = time.perf_counter()
    results, scores = {}, {}
    for split, teams in (("train", train_teams(args.domain)), ("held-out", held_out_teams(args.domain))):
        cell = evaluate_held_out(
            library,
            classifier,
            teams,
            args.episodes,
            args.seed,
            args.max_steps,
            extra_agents=extra_agents,
        )
        results[split] = cell
        scores[split] = normalised_scores([cell], summarise_sample)
    seconds = time.perf_counter() - started
    agents = (*extra_agents, "atlpo-mf", "known-task")
    lines = [
        f"{args.domain}: normalised score (random 0, original teammate 1), IQM [95 % bootstrap CI] over "
        f"{args.episodes} episodes per team (tasks cycling 1..4, cap {args.max_steps}); mean steps (solved %)",
        "",
        "| split | team | "
        + " | ".join(agents)
        + " | steps: "
        + " / ".join((*agents, "original", "random"))
        + " |",
        "|---|---|" + "---|" * (len(agents) + 1),
    ]
    for split, table in scores.items():
        for team, row in table.items():
            cells = [f"{row[a]['iqm']:.2f} [{row[a]['ci'][0]:.2f}, {row[a]['ci'][1]:.2f}]" for a in agents]
            steps = [
                f"{row['steps'][a]:.1f} ({100 * row['solved'][a]:.0f} %)"
                for a in (*agents, "original", "random")
            ]
            lines.append(f"| {split} | {team} | " + " | ".join(cells) + " | " + " / ".join(steps) + " |")
    lines += [
        "",
        f"ppo-generalist: {metadata['env_steps']} training env steps, {metadata['seconds']} s of training; "
        f"evaluation {seconds:.0f} s",
    ]
    if "liam" in extra_agents:
        lines.insert(
            -1,
            f"liam ({shown(liam_path)}): {liam_metadata['env_steps']} training env steps, "
            f"{liam_metadata['seconds']} s of training",
        )
    if "meliba" in extra_agents:
        lines.insert(
            -1,
            f"meliba ({shown(meliba_path)}): {meliba_metadata['env_steps']} training env steps, "
            f"{meliba_metadata['seconds']} s of training",
        )
    args.out.mkdir(parents=True, exist_ok=True)
    paths = ("weights", "library", "liam", "meliba")
    settings = {
        key: shown(value) if key in paths and value is not None else value
        for key, value in vars(args).items()
        if key != "out"
    }
    budgets = {
        agent: {"weights": shown(path), "env_steps": meta["env_steps"], "train_seconds": meta["seconds"]}
        for agent, (path, meta) in training.items()
    }
    record = {
        "command": command(sys.argv[1:]),
        "settings": settings,
        "training": budgets,
        "evaluation_seconds": round(seconds, 1),
        "results": results,
        "scores": scores,
    }
    (args.out / "results.json").write_text(json.dumps(record) + "\n")
    (args.out / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
