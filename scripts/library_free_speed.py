"""Training throughput of the library-free agents: env steps per second end to end (collection with the policy,
GAE and the PPO updates, as ``train`` runs them) on each domain, and collection alone (random actions through
the vector env), with the ratio of each to a reference measured in the same run: ppo-generalist on the foraging
grid with the same settings. ``--batches`` adds the foraging grid's collection per CPU second at each number of
sub-envs: the vector env alone under random actions, and the training loop's rollout (the shipped ppo-generalist
sampling every sub-env's action, then the vector env's step; its short episodes reset sub-envs often), each
with its ratio to the first batch size; then the rollout per wall second over one vector env and over the two
halves of ``train --pipeline`` (one half's policy on a second thread while the other half's env steps), with
their ratio and whether both drew the same actions. ``--baseline REF`` also times the reference training row and every
batch of the sweep with the code of the git commit ``REF`` (exported to a temporary folder and run there in a
subprocess, row by row in turn with the current code's), and prints the current code's ratio to it.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python scripts/library_free_speed.py [--updates 4] [--envs 16]
        [--batches 16,256,1024] [--baseline REF] [--json F]

Timings depend on the machine and its load; on a busy host so do the ratios, as each row is timed once, in turn.
"""

from __future__ import annotations

import argparse
import json
import os
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
    parser.add_argument(
        "--batches",
        default="",
        help="comma-separated sub-env counts of the foraging collection sweep (empty: no sweep)",
    )
    parser.add_argument(
        "--baseline",
        help="a git commit whose code is timed too, row by row, for the ratio to the previous version",
    )
    parser.add_argument("--json", help="also write the figures to this file")
    args = parser.parse_args()
    try:
        args.batches = [int(b) for b in args.batches.split(",") if b]
    except ValueError:
        parser.error(f"--batches {args.batches}: give comma-separated positive integers")
    if any(b < 1 for b in args.batches):
        parser.error(f"--batches {args.batches}: give comma-separated positive integers")
    if args.baseline is not None:
        import subprocess

        found = subprocess.run(
            ["git", "rev-parse", "--verify", "--quiet", f"{args.baseline}^{{commit}}"],
            capture_output=True,
            text=True,
        )
        if found.returncode:
            parser.error(f"--baseline {args.baseline}: not a commit of this repository; give a hash or tag")
        args.baseline = found.stdout.strip()
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


def timed_training(agent: str, domain: str, args) -> tuple[float, float]:
    """:func:`training_rate` and the env steps per CPU second of the same call (env set-up included)."""
    began = time.process_time()
    wall = training_rate(agent, domain, args)
    return wall, args.updates * args.envs * args.rollout / (time.process_time() - began)


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


def batch_rates(envs: int, steps: int) -> dict:
    """Foraging collection per CPU second with ``envs`` sub-envs over ``steps`` vector steps (the move table is
    built before the clock starts): random actions through the vector env, and the rollout of the shipped
    ppo-generalist (policy and env timed apart)."""
    import torch

    from embodied_adhoc.learning.generalist import TRAIN_TEAMS, load_generalist, shipped_weights
    from embodied_adhoc.learning.recurrent_ppo import rollout_step
    from embodied_adhoc.learning.vector_grid import GridVectorEnv

    env = GridVectorEnv("foraging", envs, teams=list(TRAIN_TEAMS))
    observation = env.reset(seed=0)[0]
    rng = np.random.default_rng(0)
    actions = rng.integers(0, 5, (steps, envs))
    env.step(actions[0])
    began = time.process_time()
    for row in actions:
        env.step(row)
    random_rate = steps * envs / (time.process_time() - began)
    model = load_generalist(shipped_weights("foraging"))[0]
    torch.manual_seed(0)
    observation = env.reset(seed=1)[0]
    hidden, previous = model.initial_state(envs), torch.full((envs,), model.no_action)
    fresh = torch.ones(envs, dtype=torch.bool)
    policy_seconds = env_seconds = 0.0
    for _ in range(steps):
        began = time.process_time()
        action, _, _, hidden = rollout_step(model, torch.as_tensor(observation), previous, hidden, fresh)
        middle = time.process_time()
        observation, _, terminated, truncated, _ = env.step(action.numpy())
        env_seconds += time.process_time() - middle
        policy_seconds += middle - began
        previous, fresh = action, torch.as_tensor(terminated | truncated)
    env.close()
    return {
        "envs": envs,
        "steps": steps * envs,
        "random_env_steps_per_cpu_s": random_rate,
        "rollout_steps_per_cpu_s": steps * envs / (policy_seconds + env_seconds),
        "rollout_env_share": env_seconds / (policy_seconds + env_seconds),
        # longer than the CPU-time loops: a wall-clock rate needs more steps to settle on a shared host
        **pipeline_rates(model, envs, max(64, 131_072 // envs)),
    }


def pipeline_rates(model, envs: int, steps: int) -> dict:
    """Env steps per wall second of the training loop's rollout (``rollout_pipeline.rollout_steps`` with the
    shipped ppo-generalist's draws) over one vector env and over the two halves of ``train --pipeline``, and
    whether both chose the same actions. Each runs ``steps`` steps after a warm-up of 8, from the same seeds."""
    import torch

    from embodied_adhoc.learning.generalist import TRAIN_TEAMS
    from embodied_adhoc.learning.recurrent_ppo import rollout_step
    from embodied_adhoc.learning.rollout_pipeline import HalvedGridEnv, rollout_steps
    from embodied_adhoc.learning.vector_grid import GridVectorEnv

    def timed(env) -> tuple[float, torch.Tensor]:
        observation = env.reset(seed=1)[0]
        carried = {
            "observation": torch.tensor(observation),
            "previous": torch.full((envs,), model.no_action),
            "hidden": model.initial_state(envs),
            "fresh": torch.ones(envs, dtype=torch.bool),
            "resetting": torch.zeros(envs, dtype=torch.bool),
        }
        actions = torch.zeros((8 + steps, envs), dtype=torch.long)

        def act(t: int, rows: slice, state: dict) -> torch.Tensor:
            action, _, _, hidden = rollout_step(
                model, state["observation"], state["previous"], state["hidden"], state["fresh"]
            )
            state["hidden"][...] = hidden
            actions[t, rows] = action
            return action

        torch.manual_seed(0)
        for _ in rollout_steps(env, act, carried, 8):
            pass
        began = time.perf_counter()
        for _ in rollout_steps(env, lambda t, rows, state: act(8 + t, rows, state), carried, steps):
            pass
        rate = steps * envs / (time.perf_counter() - began)
        env.close()
        return rate, actions

    teams = {"teams": list(TRAIN_TEAMS)}
    single, single_actions = timed(GridVectorEnv("foraging", envs, **teams))
    halved, halved_actions = timed(HalvedGridEnv("foraging", envs, **teams))
    return {
        "rollout_steps_per_s": single,
        "pipelined_steps_per_s": halved,
        "pipelined_same_actions": bool(torch.equal(single_actions, halved_actions)),
    }


def export_commit(commit: str, folder: str) -> str:
    """The tree of ``commit`` written under ``folder`` (its package, scripts and shipped weights)."""
    import subprocess

    archive = subprocess.run(["git", "archive", commit], capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", folder], input=archive, check=True)
    return folder


def baseline_call(tree: str, call: str) -> dict:
    """``call`` (an expression over this script's functions, e.g. ``batch_rates(256, 64)``) evaluated with the
    code of the exported ``tree`` in a fresh interpreter: its package, its copy of this script."""
    import subprocess

    code = (
        "import json, sys, time, torch; torch.set_num_threads(1); sys.path.insert(0, 'scripts'); "
        f"from library_free_speed import *; print(json.dumps({call}))"
    )
    env = {
        **os.environ,
        "PYTHONPATH": tree,
        "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "1"),
    }
    done = subprocess.run([sys.executable, "-c", code], cwd=tree, env=env, capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"--baseline: the baseline's {call} failed:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> int:
    args = parse()
    import torch

    from embodied_adhoc.experiments.identity import blas_kernel

    torch.set_num_threads(1)
    agents, domains = args.agents.split(","), args.domains.split(",")
    # a first run pays torch's one-off set-up (lazy imports, first backward); timed after it, the reference is not
    training_rate(*REFERENCE, argparse.Namespace(**{**vars(args), "updates": 1}))
    reference, reference_cpu = timed_training(*REFERENCE, args)
    collect_reference = collection_rate(REFERENCE[1], args)
    tree = None
    if args.baseline:
        import tempfile

        tree = export_commit(args.baseline, tempfile.mkdtemp(prefix="library-free-speed-"))
        sizes = f"envs={args.envs}, rollout={args.rollout}"
        timed = [f"argparse.Namespace(updates={n}, {sizes})" for n in (1, args.updates)]
        # the same warm-up first, in the baseline's interpreter; then its wall rate and CPU seconds
        timing = f"(lambda b: (training_rate(*REFERENCE, {timed[1]}), time.process_time() - b))"
        baseline_reference, cpu_seconds = baseline_call(
            tree, f"[training_rate(*REFERENCE, {timed[0]}), {timing}(time.process_time())][1]"
        )
        baseline_cpu = args.updates * args.envs * args.rollout / cpu_seconds
    rows = []
    for domain in domains:
        collected = collection_rate(domain, args)
        for agent in agents:
            if (agent, domain) == REFERENCE:
                rate, cpu_rate = reference, reference_cpu
            else:
                rate, cpu_rate = timed_training(agent, domain, args)
            rows.append(
                {
                    "agent": agent,
                    "domain": domain,
                    "train_steps_per_s": rate,
                    "train_steps_per_cpu_s": cpu_rate,
                    "collect_steps_per_s": collected,
                }
            )
    print(
        f"reference: {REFERENCE[0]} on {REFERENCE[1]}, {reference:.0f} env steps/s end to end "
        f"({reference_cpu:.0f} per CPU s), "
        f"{collect_reference:.0f} collecting (envs {args.envs}, rollout {args.rollout}, {blas_kernel()})"
    )
    if tree:
        print(
            f"baseline {args.baseline[:12]}: the reference {baseline_reference:.0f} env steps/s end to end, "
            f"{baseline_cpu:.0f} per CPU s; the current code {reference / baseline_reference:.2f} x and "
            f"{reference_cpu / baseline_cpu:.2f} x"
        )
    print(
        "| agent | domain | end to end (steps/s) | x reference | end to end (steps/CPU s) | "
        "collection (steps/s) | x reference |"
    )
    print("|---|---|---|---|---|---|---|")
    for row in rows:
        print(
            f"| {row['agent']} | {row['domain']} | {row['train_steps_per_s']:.0f} | "
            f"{row['train_steps_per_s'] / reference:.2f} | {row['train_steps_per_cpu_s']:.0f} | "
            f"{row['collect_steps_per_s']:.0f} | "
            f"{row['collect_steps_per_s'] / collect_reference:.2f} |"
        )
    batches = []
    if args.batches:
        print(
            f"uptime: {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f} (load 1/5/15 min)"
        )
        than = " baseline rollout (steps/CPU s) | x baseline |" if tree else ""
        print(
            "| sub-envs | random actions (steps/CPU s) | x first | rollout (steps/CPU s) | x first | env share "
            f"| rollout (steps/s) | pipelined (steps/s) | x rollout | same actions |{than}"
        )
        print("|---|---|---|---|---|---|---|---|---|---|" + ("---|---|" if tree else ""))
        for envs in args.batches:
            steps = max(20, 16_384 // envs)
            if tree:
                previous = baseline_call(tree, f"batch_rates({envs}, {steps})")
            batches.append(batch_rates(envs, steps))
            first, row = batches[0], batches[-1]
            versus = ""
            if tree:
                row["baseline_rollout_steps_per_cpu_s"] = previous["rollout_steps_per_cpu_s"]
                row["baseline_random_env_steps_per_cpu_s"] = previous["random_env_steps_per_cpu_s"]
                ratio = row["rollout_steps_per_cpu_s"] / previous["rollout_steps_per_cpu_s"]
                versus = f" {previous['rollout_steps_per_cpu_s']:.0f} | {ratio:.2f} |"
            print(
                f"| {envs} | {row['random_env_steps_per_cpu_s']:.0f} | "
                f"{row['random_env_steps_per_cpu_s'] / first['random_env_steps_per_cpu_s']:.2f} | "
                f"{row['rollout_steps_per_cpu_s']:.0f} | "
                f"{row['rollout_steps_per_cpu_s'] / first['rollout_steps_per_cpu_s']:.2f} | "
                f"{row['rollout_env_share']:.2f} | {row['rollout_steps_per_s']:.0f} | "
                f"{row['pipelined_steps_per_s']:.0f} | "
                f"{row['pipelined_steps_per_s'] / row['rollout_steps_per_s']:.2f} | "
                f"{'yes' if row['pipelined_same_actions'] else 'no'} |{versus}",
                flush=True,
            )
    if tree:
        import shutil

        shutil.rmtree(tree)
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
            "reference": {
                "train_steps_per_s": reference,
                "train_steps_per_cpu_s": reference_cpu,
                "collect_steps_per_s": collect_reference,
            },
            **(
                {
                    "baseline": {
                        "commit": args.baseline,
                        "train_steps_per_s": baseline_reference,
                        "train_steps_per_cpu_s": baseline_cpu,
                    }
                }
                if tree
                else {}
            ),
            "rows": rows,
            "load_average": list(os.getloadavg()),
        }
        if batches:
            document["batches"] = batches
        Path(args.json).write_text(json.dumps(document, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
