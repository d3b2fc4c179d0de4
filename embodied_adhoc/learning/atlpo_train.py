"""The ``embodied-adhoc train atlpo`` pipeline: the ATLPO-MF library of a set (one PPO member per environment,
resumable), optionally the model-free baseline on all its environments, then the recurrent classifier (Eq. 6.2)
on episodes the members play (with ``mixing``, actions from a random member), scored per step on held-out
episodes. Writes the weights, ``library.json`` and ``training.json`` (settings, cost, per-step scores) to ``out``.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

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

ROLLOUT_STEPS = 32


@dataclass(frozen=True)
class AtlpoTraining:
    domain: str
    set_name: str
    out: str
    steps: int = 30_000  # env steps per policy (the thesis: 30,000)
    seed: int = 0
    envs: int = 16
    episodes: int = 256  # classifier training episodes per environment
    episode_steps: int = 30
    iterations: int = 600
    mixing: float = 0.5
    device: str = "auto"
    threads: int = 0  # 0: torch's choice
    generalist: bool = False
    quiet: bool = False
    model: str = (
        "mf"  # "mf": ATLPO-MF; "mb": ATLPO-MB (world model on replayed experience, PPO on its latents)
    )


def train_atlpo(settings: AtlpoTraining) -> dict:
    """Run the pipeline; returns the report written to ``training.json``."""
    if settings.threads:
        torch.set_num_threads(settings.threads)
    batch = settings.envs * ROLLOUT_STEPS
    config = PpoConfig(
        total_steps=settings.steps,
        num_envs=settings.envs,
        rollout_steps=ROLLOUT_STEPS,
        seed=settings.seed,
        device=settings.device,
        minibatches=4 if batch % 4 == 0 else 1,
    )
    out = Path(settings.out)
    members = library_set(settings.set_name)
    started = time.perf_counter()
    policies = len(members) + (1 if settings.generalist else 0)
    with tqdm(
        total=policies * max(1, settings.steps // batch) * batch,
        unit="step",
        desc=f"atlpo {settings.domain} {settings.set_name}",
        disable=settings.quiet,
    ) as bar:

        def progress(member: str, steps: int, row: dict) -> None:
            bar.set_postfix_str(f"{member} episode length {row['mean_episode_length'] or '-'}")
            bar.update(batch)

        library = train_library(
            settings.domain, settings.set_name, config, out, progress=progress, model=settings.model
        )
        if settings.generalist:
            train_generalist(
                settings.domain,
                settings.set_name,
                config,
                out,
                progress=lambda steps, row: progress("all", steps, row),
                model=settings.model,
            )
    policy_seconds = time.perf_counter() - started
    data = collect_trajectories(
        library, settings.episodes, settings.episode_steps, seed=settings.seed, mixing=settings.mixing
    )
    held_out = collect_trajectories(
        library,
        max(8, settings.episodes // 8),
        settings.episode_steps,
        seed=settings.seed + 10**6,
        mixing=settings.mixing,
    )
    classifier = RecurrentBayesianClassifier(
        ClassifierConfig(channels=data.observations.shape[2], environments=len(members))
    )
    device = pick_device(settings.device)
    losses = train_classifier(
        classifier, data, ClassifierTraining(iterations=settings.iterations, seed=settings.seed), device
    )
    classifier.cpu().eval()
    write_manifest(out, library, classifier)
    report = {
        "domain": settings.domain,
        "set": settings.set_name,
        "model": settings.model,
        "members": [m.name for m in members],
        "steps": settings.steps,
        "seed": settings.seed,
        "device": str(device),
        "classifier_episodes": settings.episodes,
        "classifier_iterations": settings.iterations,
        "mixing": settings.mixing,
        "policy_seconds": round(policy_seconds, 1),
        "total_seconds": round(time.perf_counter() - started, 1),
        "classifier_loss": {"first": losses[0], "last": losses[-1]},
        "per_step": per_step_scores(classifier, held_out),
    }
    atomic_write_text(out / "training.json", json.dumps(report, indent=1) + "\n")
    return report
