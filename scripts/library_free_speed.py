"""Training throughput of the library-free agents: env steps per second end to end (collection with the policy,
GAE and the PPO updates, as ``train`` runs them) on each domain, and collection alone (random actions through
the vector env), with the ratio of each to a reference measured in the same run: ppo-generalist on the foraging
grid with the same settings.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python scripts/library_free_speed.py [--updates 4] [--envs 16] [--json F]

Timings depend on the machine and its load; on a busy host so do the ratios, as each row is timed once, in turn.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

AGENTS = ("ppo-generalist", "liam", "meliba")
DOMAINS = ("foraging", "toxic-waste", "pursuit-task")
REFERENCE = ("ppo-generalist", "foraging")


def parse() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--updates", type=int, default=4, help="PPO updates timed per agent and domain")
    parser.add_argument("--envs", type=int, default=16)
    parser.add_argument("--rollout", type=int, default=64)
    parser.add_argument(
        "--collect-steps", type=int, default=200, help="vector steps of the collection timing"
    )
    parser.add_argument("--agents", default=",".join(AGENTS))
    parser.add_argument("--domains", default=",".join(DOMAINS))
    parser.add_argument("--json", help="also write the figures to this file")
    args = parser.parse_args()
    for name in ("updates", "envs", "rollout", "collect_steps"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} {getattr(args, name)}: give a positive integer")
    return args


def _settings(agent: str, domain: str, steps: int, envs: int, rollout: int):
    from embodied_adhoc.learning.generalist import GeneralistTraining
    from embodied_adhoc.learning.liam import LiamTraining
    from embodied_adhoc.learning.meliba import MelibaTraining

    kind = {"ppo-generalist": GeneralistTraining, "liam": LiamTraining, "meliba": MelibaTraining}[agent]
    return kind(domain, "", steps=steps, envs=envs, rollout=rollout)


def training_rate(agent: str, domain: str, args) -> float:
    """Env steps per second of ``args.updates`` updates (the loop's own clock, env set-up left out)."""
    from embodied_adhoc.learning.liam import Reconstruction, teammate_count, teammate_views
    from embodied_adhoc.learning.meliba import Belief
    from embodied_adhoc.learning.recurrent_ppo import train_recurrent_ppo

    settings = _settings(agent, domain, args.updates * args.envs * args.rollout, args.envs, args.rollout)
    config, env_kwargs = settings.config(), settings.env_kwargs()
    auxiliary = None
    if agent == "liam":
        auxiliary = Reconstruction(config, teammate_count(domain, env_kwargs), teammate_views(domain))
    elif agent == "meliba":
        auxiliary = Belief(config, teammate_count(domain, env_kwargs))
    result = train_recurrent_ppo(domain, env_kwargs, config, auxiliary=auxiliary)
    return result.steps_per_second


def collection_rate(domain: str, args) -> float:
    """Env steps per second of the vector env alone under uniform random actions."""
    from embodied_adhoc.learning.index_domains import INDEX_DOMAINS, IndexVectorEnv
    from embodied_adhoc.learning.vector_grid import GridVectorEnv

    env = IndexVectorEnv(domain, args.envs) if domain in INDEX_DOMAINS else GridVectorEnv(domain, args.envs)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.integers(0, 5, (args.collect_steps, args.envs))
    env.step(actions[0])  # the lab's envs are made at their first episodes: not timed
    began = time.perf_counter()
    for row in actions:
        env.step(row)
    seconds = time.perf_counter() - began
    env.close()
    return args.collect_steps * args.envs / seconds


def main() -> int:
    import torch

    from embodied_adhoc.experiments.identity import blas_kernel

    args = parse()
    torch.set_num_threads(1)
    agents, domains = args.agents.split(","), args.domains.split(",")
    # a first run pays torch's one-off set-up (lazy imports, first backward); timed after it, the reference is not
    training_rate(*REFERENCE, argparse.Namespace(**{**vars(args), "updates": 1}))
    reference = training_rate(*REFERENCE, args)
    collect_reference = collection_rate(REFERENCE[1], args)
    rows = []
    for domain in domains:
        collected = collection_rate(domain, args)
        for agent in agents:
            rate = reference if (agent, domain) == REFERENCE else training_rate(agent, domain, args)
            rows.append(
                {
                    "agent": agent,
                    "domain": domain,
                    "train_steps_per_s": rate,
                    "collect_steps_per_s": collected,
                }
            )
    print(
        f"reference: {REFERENCE[0]} on {REFERENCE[1]}, {reference:.0f} env steps/s end to end, "
        f"{collect_reference:.0f} collecting (envs {args.envs}, rollout {args.rollout}, {blas_kernel()})"
    )
    print("| agent | domain | end to end (steps/s) | x reference | collection (steps/s) | x reference |")
    print("|---|---|---|---|---|---|")
    for row in rows:
        print(
            f"| {row['agent']} | {row['domain']} | {row['train_steps_per_s']:.0f} | "
            f"{row['train_steps_per_s'] / reference:.2f} | {row['collect_steps_per_s']:.0f} | "
            f"{row['collect_steps_per_s'] / collect_reference:.2f} |"
        )
    if args.json:
        import platform
        import subprocess
        from pathlib import Path

        commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
        document = {
            "command": " ".join([".venv/bin/python", "scripts/library_free_speed.py", *sys.argv[1:]]),
            "commit": commit,
            "kernel": blas_kernel(),
            "python": platform.python_version(),
            "versions": {"numpy": np.__version__, "torch": torch.__version__},
            "reference_agent": REFERENCE[0],
            "reference_domain": REFERENCE[1],
            "reference": {"train_steps_per_s": reference, "collect_steps_per_s": collect_reference},
            "rows": rows,
        }
        Path(args.json).write_text(json.dumps(document, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
