"""``embodied-adhoc train atlpo``: train an ATLPO-MF library (thesis chapter 6) and its classifier.

One PPO policy per environment of the chosen set (task x team), then the recurrent Bayesian classifier (Eq. 6.2)
on episodes each member plays in its own environment, evaluated per step (accuracy, posterior of the true
environment, expected calibration error) on held-out episodes. Everything goes to ``--out``: a safetensors file
per member and for the classifier, ``library.json`` and ``training.json`` (settings, cost, per-step scores).
Interrupted runs resume: members whose weights exist are loaded, not retrained.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from embodied_adhoc.errors import ConfigError


def handle_atlpo(args: argparse.Namespace) -> int:
    import torch
    from tqdm import tqdm

    from embodied_adhoc.atomic import atomic_write_text
    from embodied_adhoc.learning.atlpo import (
        collect_trajectories,
        library_set,
        train_generalist,
        train_library,
        write_manifest,
    )
    from embodied_adhoc.learning.classifier import (
        ClassifierConfig,
        ClassifierTraining,
        RecurrentBayesianClassifier,
        per_step_scores,
        train_classifier,
    )
    from embodied_adhoc.learning.ppo import PpoConfig, pick_device

    for name in ("steps", "envs", "episodes", "episode_steps", "iterations"):
        if getattr(args, name) < 1:
            raise ConfigError(f"--{name.replace('_', '-')} {getattr(args, name)}: give a positive integer")
    if args.threads:
        torch.set_num_threads(args.threads)
    rollout = 32
    config = PpoConfig(total_steps=args.steps, num_envs=args.envs, rollout_steps=rollout, seed=args.seed,
                       device=args.device, minibatches=4 if (args.envs * rollout) % 4 == 0 else 1)
    out = Path(args.out)
    members = library_set(args.set)
    started = time.perf_counter()
    policies = len(members) + (1 if args.generalist else 0)
    with tqdm(total=policies * max(1, args.steps // (args.envs * rollout)) * args.envs * rollout,
              unit="step", desc=f"atlpo {args.domain} {args.set}", disable=args.quiet) as bar:
        def progress(member: str, steps: int, row: dict) -> None:
            bar.set_postfix_str(f"{member} episode length {row['mean_episode_length'] or '-'}")
            bar.update(args.envs * rollout)

        library = train_library(args.domain, args.set, config, out, progress=progress)
        if args.generalist:
            train_generalist(args.domain, args.set, config, out, progress=lambda steps, row: progress("all", steps, row))
    policy_seconds = time.perf_counter() - started
    if not 0.0 <= args.mixing <= 1.0:
        raise ConfigError(f"--mixing {args.mixing}: a probability in [0, 1]")
    data = collect_trajectories(library, args.episodes, args.episode_steps, seed=args.seed, mixing=args.mixing)
    held_out = collect_trajectories(library, max(8, args.episodes // 8), args.episode_steps, seed=args.seed + 10**6,
                                    mixing=args.mixing)
    classifier = RecurrentBayesianClassifier(ClassifierConfig(channels=data.observations.shape[2],
                                                              environments=len(members)))
    device = pick_device(args.device)
    losses = train_classifier(classifier, data, ClassifierTraining(iterations=args.iterations, seed=args.seed), device)
    classifier.cpu().eval()
    write_manifest(out, library, classifier)
    scores = per_step_scores(classifier, held_out)
    report = {"domain": args.domain, "set": args.set, "members": [m.name for m in members], "steps": args.steps,
              "seed": args.seed, "device": str(device), "classifier_episodes": args.episodes,
              "classifier_iterations": args.iterations, "mixing": args.mixing, "policy_seconds": round(policy_seconds, 1),
              "total_seconds": round(time.perf_counter() - started, 1),
              "classifier_loss": {"first": losses[0], "last": losses[-1]}, "per_step": scores}
    atomic_write_text(out / "training.json", json.dumps(report, indent=1) + "\n")
    print(f"library of {len(members)} in {out} ({report['total_seconds']} s, policies {policy_seconds:.1f} s)")
    print("step  accuracy  p(true)  ECE")
    for row in scores[:: max(1, len(scores) // 10)]:
        print(f"{row['step']:4d}  {row['accuracy']:8.2f}  {row['true_posterior']:7.2f}  {row['ece']:.3f}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("train", help="train learned agents (ATLPO-MF library and classifier)",
                                   description=__doc__.split("\n\n")[0])
    kinds = parser.add_subparsers(dest="kind", metavar="KIND")
    parser.set_defaults(_parser=parser)
    atlpo = kinds.add_parser("atlpo", help="one PPO policy per task x team environment, then the classifier",
                             description=__doc__)
    atlpo.add_argument("--domain", choices=("foraging", "pursuit"), required=True)
    atlpo.add_argument("--set", choices=("task", "team", "task+team"), required=True,
                       help="task: tasks 1-4 with tau1; team: tau0-2 on task 1; task+team: both (K=6)")
    atlpo.add_argument("--steps", type=int, default=30_000, help="env steps per policy (default 30000, the thesis's)")
    atlpo.add_argument("--seed", type=int, default=0)
    atlpo.add_argument("--envs", type=int, default=16, help="parallel sub-envs of the vector env (default 16)")
    atlpo.add_argument("--episodes", type=int, default=256, help="classifier training episodes per environment")
    atlpo.add_argument("--episode-steps", type=int, default=30, help="steps kept per classifier episode")
    atlpo.add_argument("--iterations", type=int, default=600, help="classifier training iterations")
    atlpo.add_argument("--mixing", type=float, default=0.5,
                       help="chance per step that a classifier episode takes a random member's action (default 0.5)")
    atlpo.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto")
    atlpo.add_argument("--threads", type=int, default=0, help="torch CPU threads (default: torch's choice)")
    atlpo.add_argument("--generalist", action="store_true",
                       help="also train the model-free baseline on all the set's environments together")
    atlpo.add_argument("--quiet", action="store_true", help="no progress bar")
    atlpo.add_argument("--out", required=True, help="folder for the weights, library.json and training.json")
    atlpo.set_defaults(func=handle_atlpo)
