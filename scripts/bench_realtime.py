"""HOTSPOT turn-based vs real-time, scripted human: steps and seconds to finish the toxic-waste lab.

The same episodes (seeds 0..N-1: same task, start nodes and agent seed as ``run toxic-waste --seed S``) run on
physics three ways:

* **turn-based**: ``EmbodiedAdhoc/ToxicWaste-v0``, one macro step of both teammates per env step (the thesis's
  protocol, the reference of the ratios);
* **real-time, unpaced**: ``live.realtime.RealtimeToxicWasteEnv`` with ``speed=None``: the human decides whenever
  its own command is done, the robot whenever its macro action completes; time spent deciding costs no
  simulated time (deterministic per seed);
* **real-time, paced** at ``--speed`` simulated seconds per wall second (optional, ``--paced-episodes``): the
  wall time the agent takes to decide passes in the simulation too.

"seconds" are simulated seconds until all balls are in the container (the time a participant would spend)::

    .venv/bin/python scripts/bench_realtime.py --episodes 8

``--json`` prints the per-mode summaries as one JSON object instead of the table (what
``scripts/render_results.py`` reads).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass

import numpy as np

from embodied_adhoc.experiments.script_args import parse_dataclass_args


@dataclass(frozen=True)
class BenchArgs:
    episodes: int = 8
    """episodes per mode (seeds 0..episodes-1)"""
    agent: str = "hotspot"
    """agent of every episode"""
    max_steps: int = 100
    """step cap (the registered one)"""
    speed: float = 20.0
    """simulated seconds per wall second of the paced real-time mode"""
    paced_episodes: int = 2
    """episodes of the paced mode (0: skip it)"""
    json: bool = False
    """print the summaries as one JSON object (mode -> success, n, and [mean, 95 % half-width] of steps, simulated
    and wall seconds) instead of the table"""


def run_mode(mode: str, args: BenchArgs, episodes: int) -> list[dict]:
    from embodied_adhoc.experiments.recorded import EpisodeConfig, run_episode
    from embodied_adhoc.live.episode import open_realtime_episode, run_realtime_episode

    rows = []
    for seed in range(episodes):
        config = EpisodeConfig(agent=args.agent, seed=seed, max_steps=args.max_steps)
        started = time.perf_counter()
        if mode == "turn-based":
            metrics = run_episode(config).metrics
        else:
            speed = None if mode == "real-time, unpaced" else args.speed
            metrics = run_realtime_episode(open_realtime_episode(config, speed=speed)).metrics
        rows.append(
            {
                "success": metrics["outcome"] == "success",
                "steps": metrics["steps"],
                "sim_s": metrics["sim_time_s"],
                "wall_s": time.perf_counter() - started,
            }
        )
    return rows


def summary(rows: list[dict]) -> dict:
    def mean_ci(key: str) -> tuple[float, float]:
        values = np.array([row[key] for row in rows], dtype=float)
        half = 1.96 * values.std(ddof=1) / np.sqrt(len(values)) if len(values) > 1 else float("nan")
        return float(values.mean()), float(half)

    return {
        "success": sum(row["success"] for row in rows),
        "n": len(rows),
        "steps": mean_ci("steps"),
        "sim_s": mean_ci("sim_s"),
        "wall_s": mean_ci("wall_s"),
    }


def main() -> None:
    args = parse_dataclass_args(BenchArgs, __doc__)
    modes = [("turn-based", args.episodes), ("real-time, unpaced", args.episodes)]
    if args.paced_episodes > 0:
        modes.append((f"real-time, paced x{args.speed:g}", args.paced_episodes))
    results = {mode: summary(run_mode(mode, args, n)) for mode, n in modes}
    if args.json:
        print(
            json.dumps(
                {"agent": args.agent, "max_steps": args.max_steps, "speed": args.speed, "modes": results}
            )
        )
        return
    reference = results["turn-based"]
    print(f"{args.agent}, scripted human, seeds 0..n-1 (95 % CI half-widths)")
    header = (
        f"{'mode':<26} {'success':>8} {'steps':>14} {'seconds to finish':>19} {'wall s/episode':>15} "
        f"{'steps ratio':>12} {'seconds ratio':>14}"
    )
    print(header)
    print("-" * len(header))
    for mode, result in results.items():
        steps, sim, wall = result["steps"], result["sim_s"], result["wall_s"]
        print(
            f"{mode:<26} {result['success']:>4}/{result['n']:<3} {steps[0]:>7.1f} ± {steps[1]:<4.1f} "
            f"{sim[0]:>10.1f} ± {sim[1]:<6.1f} {wall[0]:>9.1f} ± {wall[1]:<4.1f} "
            f"{steps[0] / reference['steps'][0]:>12.2f} {sim[0] / reference['sim_s'][0]:>14.2f}"
        )


if __name__ == "__main__":
    main()
