"""Cost of one macro step of EmbodiedAdhoc/ToxicWaste-v0, bare and recorded, against the abstract env's step.

Runs the same HOTSPOT episodes (``run toxic-waste`` loop, seeds 0..N-1) three ways and prints wall seconds per
macro step and ratios to the abstract env's step measured in the same run:

    .venv/bin/python scripts/bench_toxic_waste_env.py --episodes 2
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from embodied_adhoc.experiments.script_args import parse_dataclass_args


@dataclass(frozen=True)
class BenchArgs:
    episodes: int = 2
    """episodes per configuration (seeds 0..episodes-1)"""
    width: int = 640
    """recorded video width"""
    height: int = 480
    """recorded video height"""


def abstract_step_seconds(episodes: int) -> float:
    """Mean wall seconds per step of the abstract env under the same agent (the reference)."""
    import gymnasium

    import embodied_adhoc.envs  # noqa: F401
    from embodied_adhoc.episodes.loop import run_episode_loop
    from embodied_adhoc.experiments import seeding
    from embodied_adhoc.experiments.registry import get_trial_domain

    domain = get_trial_domain("toxic-waste")
    options = domain.options()
    session = domain.open_session("abstract", options)
    env = gymnasium.make(
        "EmbodiedAdhoc/ToxicWasteAbstract-v0", disable_env_checker=True, **session.env_kwargs
    )
    steps, started = 0, time.perf_counter()
    for episode in range(episodes * 20):  # many short episodes: the abstract step is microseconds
        spec = domain.episode_spec(options, seeding.episode_rng(0, episode))
        agent = session.make_agent("hotspot", spec, 0)
        trace = run_episode_loop(  # the loop run and trials use
            env,
            agent,
            env_seed=episode,
            agent_rng=seeding.agent_rng(0, episode, "hotspot"),
            reset_options=session.reset_options(spec),
            max_steps=100,
            observation_index=session.observation_index,
        )
        steps += trace.steps
    return (time.perf_counter() - started) / steps


def physics_step_seconds(episodes: int, record: bool, args: BenchArgs) -> tuple[float, float]:
    """Mean wall seconds per macro step and simulated seconds per macro step of ``run toxic-waste``."""
    from embodied_adhoc.experiments.recorded import EpisodeConfig, run_episode

    wall = sim = steps = 0.0
    with tempfile.TemporaryDirectory() as folder:
        for seed in range(episodes):
            config = EpisodeConfig(
                seed=seed,
                record_dir=Path(folder) / str(seed) if record else None,
                width=args.width,
                height=args.height,
            )
            metrics = run_episode(config).metrics
            wall += sum(step["wall_time_s"] for step in metrics["per_step"])
            sim += metrics["sim_time_s"]
            steps += metrics["steps"]
    return wall / steps, sim / steps


def main() -> None:
    args = parse_dataclass_args(BenchArgs, __doc__)
    reference = abstract_step_seconds(args.episodes)
    bare, sim = physics_step_seconds(args.episodes, False, args)
    recorded, _ = physics_step_seconds(args.episodes, True, args)
    print(f"{'configuration':<36} {'s / macro step':>14} {'x abstract':>12}")
    print(f"{'abstract env (reference)':<36} {reference:>14.6f} {1.0:>12.0f}")
    print(f"{'physics, no rendering':<36} {bare:>14.3f} {bare / reference:>12.0f}")
    label = f"physics, recorded {args.width}x{args.height}"
    print(f"{label:<36} {recorded:>14.3f} {recorded / reference:>12.0f}")
    print(
        f"simulated seconds per macro step: {sim:.1f}; real-time factor without rendering: {sim / bare:.1f}"
    )


if __name__ == "__main__":
    main()
