"""Benchmark of the trial runner on the abstract toxic-waste lab against its speed target: 32 trials x 4 agents,
model building and solving included, in under 10 s on a 2-core machine.

Measures, in one run:

1. a cold sweep: 32 episodes x (hotspot, known-task, oracle, random) with every model cache cleared first, so
   building the lab library and solving HOTSPOT's Q*_m / Q*_m,info and the oracle's value iteration are included;
   split into model building + solving and the trials themselves;
2. the same sweep through the CLI in a fresh process (imports included);
3. per-step costs against a reference measured in the same run: the abstract env's ``step`` (Gymnasium API,
   ground-truth info included) vs raw generative sampling from the same task's POMDP (``POMDP.step``: one sparse
   transition row and one observation row), and a whole runner step (agent act + env step + agent observe).

    .venv/bin/python scripts/bench_trials.py [--episodes 32 --steps 20000 --repeats 3]
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time
from dataclasses import dataclass

import numpy as np

from embodied_adhoc.experiments.script_args import parse_dataclass_args

AGENTS = ("hotspot", "known-task", "oracle", "random")


@dataclass(frozen=True)
class Args:
    episodes: int = 32
    """episodes per agent"""
    steps: int = 20000
    """steps per per-step measurement"""
    repeats: int = 3
    """repetitions of each measurement (the median is reported)"""
    seed: int = 7
    """sweep seed"""


def parse_args() -> Args:
    return parse_dataclass_args(Args, __doc__)


def clear_model_caches() -> None:
    from embodied_adhoc.decision.agents.factory import clear_cache
    from embodied_adhoc.domains.lab import library_from_config
    from embodied_adhoc.experiments.executors import close_sessions

    close_sessions()
    clear_cache()
    library_from_config.cache_clear()


def cold_sweep(args: Args) -> dict[str, float]:
    """Wall time of a sweep from empty caches, split into models (build + solve) and trials."""
    from embodied_adhoc.decision.agents.factory import hotspot_plan, mdp_q_values
    from embodied_adhoc.domains.lab import build_lab_library
    from embodied_adhoc.experiments.registry import get_trial_domain
    from embodied_adhoc.experiments.runner import SweepConfig, run_sweep

    options = get_trial_domain("toxic-waste").options()
    config = SweepConfig("toxic-waste", "abstract", options, AGENTS, args.episodes, args.seed)
    clear_model_caches()
    started = time.perf_counter()
    library = build_lab_library(tasks=options["tasks"])
    built = time.perf_counter()
    hotspot_plan(library)
    mdp_q_values(library)
    solved = time.perf_counter()
    result = run_sweep(config)
    finished = time.perf_counter()
    total_steps = sum(r.steps for r in result.records)
    return {
        "build": built - started,
        "solve": solved - built,
        "trials": finished - solved,
        "total": finished - started,
        "steps": total_steps,
    }


def cli_sweep(args: Args) -> float:
    command = [sys.executable, "-m", "embodied_adhoc.cli", "trials", "toxic-waste", "--episodes", str(args.episodes),
               "--seed", str(args.seed), "--json"]  # fmt: skip
    started = time.perf_counter()
    subprocess.run(command, check=True, capture_output=True)
    return time.perf_counter() - started


def per_step_costs(args: Args) -> dict[str, float]:
    """Seconds per step of: raw POMDP sampling, the abstract env, and a full runner step with the hotspot agent."""
    import gymnasium

    import embodied_adhoc.envs  # noqa: F401
    from embodied_adhoc.decision.agents.factory import make_agent
    from embodied_adhoc.domains.lab import build_lab_library

    library = build_lab_library()
    pomdp = library.pomdps[0]
    rng = np.random.default_rng(0)
    actions = rng.integers(pomdp.n_actions, size=args.steps)

    def raw() -> float:
        state = pomdp.sample_initial_state(rng)
        started = time.perf_counter()
        for action in actions:
            state, _, _ = pomdp.step(state, int(action), rng)
        return (time.perf_counter() - started) / args.steps

    env = gymnasium.make("EmbodiedAdhoc/ToxicWasteAbstract-v0", task=0, disable_env_checker=True)

    def env_steps() -> float:
        env.reset(seed=0)
        started = time.perf_counter()
        for action in actions:
            _, _, terminated, truncated, _ = env.step(int(action))
            if terminated or truncated:
                env.reset()
        return (time.perf_counter() - started) / args.steps

    agent = make_agent("hotspot", library)

    def runner_steps() -> float:
        count, started = 0, time.perf_counter()
        episode = 0
        while count < args.steps // 10:
            _, info = env.reset(seed=episode, options={"task": episode % 2})
            agent.reset(np.random.default_rng(episode))
            done = False
            while not done:
                action = agent.act()
                _, _, terminated, truncated, info = env.step(action)
                agent.observe(action, info["observation_index"])
                count += 1
                done = terminated or truncated
            episode += 1
        return (time.perf_counter() - started) / count

    costs = {
        "raw POMDP.step": statistics.median(raw() for _ in range(args.repeats)),
        "abstract env.step": statistics.median(env_steps() for _ in range(args.repeats)),
        "runner step (hotspot act + env.step + observe)": statistics.median(
            runner_steps() for _ in range(args.repeats)
        ),
    }
    env.close()
    return costs


def main() -> None:
    args = parse_args()
    sweeps = [cold_sweep(args) for _ in range(args.repeats)]
    sweep = {key: statistics.median(s[key] for s in sweeps) for key in sweeps[0]}
    cli = statistics.median(cli_sweep(args) for _ in range(args.repeats))
    costs = per_step_costs(args)
    reference = costs["raw POMDP.step"]
    trials = args.episodes * len(AGENTS)
    print(f"cold sweep: {args.episodes} episodes x {len(AGENTS)} agents = {trials} trials, {int(sweep['steps'])} steps "
          f"(median of {args.repeats})")  # fmt: skip
    print(f"  build lab library  {sweep['build']:8.3f} s")
    print(f"  solve models       {sweep['solve']:8.3f} s  (HOTSPOT Q*_m, Q*_m,info; oracle value iteration)")
    print(
        f"  run trials         {sweep['trials']:8.3f} s  ({1e6 * sweep['trials'] / sweep['steps']:.1f} us per step)"
    )
    print(f"  total              {sweep['total']:8.3f} s  (target < 10 s)")
    print(f"CLI in a fresh process (imports included): {cli:.3f} s")
    print(f"per-step cost over {args.steps} steps (median of {args.repeats}), reference = raw POMDP.step:")
    for name, seconds in costs.items():
        print(f"  {name:48s} {1e6 * seconds:8.2f} us  {seconds / reference:6.2f} x reference")


if __name__ == "__main__":
    main()
