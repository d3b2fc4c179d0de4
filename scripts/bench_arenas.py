"""Speed of the foraging/pursuit worlds, as ratios against references measured in the same run.

1. env steps/s of lbforaging 2.0.0's env (5x5, 4 players, 1 food, sight 2, vector observation; random joint
   actions), the reference; against it: our grid twin with random joint actions (PettingZoo env: rules +
   four egocentric observations), the single-agent grid env (scripted teammates plan every step), the
   training vector env (``learning/vector_grid.py``: ``num_envs`` single-agent envs stepped at once, scripted
   teams included; env steps/s counts every sub-env's step; its one-off first step, which builds the grid's move
   table, is timed apart) and the MuJoCo arena (single-agent env, robots
   driven cell to cell physically);
2. physics overhead of one MuJoCo macro step (one grid step executed physically, controllers included) as a
   ratio to one raw ``mj_step`` of the same model, and the number of ``mj_step`` calls it makes.

    MUJOCO_GL=egl .venv/bin/python scripts/bench_arenas.py [--seconds 3 --domain foraging --clock cpu|wall]

Rates are per CPU second of this process by default (``--clock cpu``): on a shared machine other users' load
changes wall-clock rates 2-3x within one run, CPU time much less.

lbforaging is an optional reference (``pip install lbforaging==2.0.0``); without it the lbforaging row is
skipped and our PettingZoo grid env becomes the reference.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from embodied_adhoc.experiments.script_args import parse_dataclass_args


@dataclass(frozen=True)
class Args:
    seconds: float = 3.0
    """wall-clock budget per grid measurement (the MuJoCo one runs a third of it, at least 20 steps)"""
    domain: str = "foraging"
    """foraging or pursuit (lbforaging is compared in either case: it is the only external grid reference)"""
    seed: int = 0
    num_envs: int = 64
    """sub-envs of the vector env row"""
    clock: str = "cpu"
    """cpu: steps per CPU second of this process (fair on a shared, loaded machine; every env here runs on one
    core); wall: per wall-clock second"""


CLOCK = {"cpu": time.process_time, "wall": time.perf_counter}
now = time.process_time


def rate(step, reset, budget: float, minimum: int = 20) -> float:
    """Steps per second of ``step()`` (``reset()`` on episode end) over ``budget`` seconds of the chosen clock."""
    reset()
    steps, start = 0, now()
    while steps < minimum or now() - start < budget:
        if step():
            reset()
        steps += 1
    return steps / (now() - start)


def lbforaging_rate(args: Args) -> float | None:
    try:
        from lbforaging.foraging import ForagingEnv as LbfEnv
    except ImportError:
        return None
    env = LbfEnv(
        players=4,
        min_player_level=1,
        max_player_level=2,
        min_food_level=1,
        max_food_level=None,
        field_size=(5, 5),
        max_num_food=1,
        sight=2,
        max_episode_steps=200,
        force_coop=True,
        grid_observation=False,
    )  # its grid_observation=True fails on gymnasium 1.4 (Box shape bug)
    rng = np.random.default_rng(args.seed)
    seeds = iter(range(10**9))

    def step():
        _, _, done, truncated, _ = env.step(tuple(int(a) for a in rng.integers(0, 6, size=4)))
        return done or truncated

    return rate(step, lambda: env.reset(seed=next(seeds)), args.seconds)


def main(args: Args) -> None:
    global now
    if args.clock not in CLOCK:
        raise SystemExit(f"--clock {args.clock}: use cpu or wall")
    now = CLOCK[args.clock]
    import gymnasium
    import mujoco

    import embodied_adhoc.envs  # noqa: F401
    from embodied_adhoc.envs.multiagent import GridParallelEnv

    rng = np.random.default_rng(args.seed)
    results: list[tuple[str, float]] = []
    lbf = lbforaging_rate(args)
    if lbf is not None:
        results.append(("lbforaging 2.0.0 grid env, random joint actions (reference)", lbf))

    parallel = GridParallelEnv(args.domain)
    seeds = iter(range(10**9))

    def parallel_step():
        actions = dict(zip(parallel.possible_agents, rng.integers(0, 5, size=4).tolist(), strict=True))
        parallel.step(actions)
        return not parallel.agents

    results.append(
        (
            f"{args.domain} grid twin (PettingZoo), random joint actions",
            rate(parallel_step, lambda: parallel.reset(seed=next(seeds)), args.seconds),
        )
    )

    def single_rate(env_id: str, budget: float) -> float:
        env = gymnasium.make(env_id, max_episode_steps=10**6).unwrapped

        def step():
            return env.step(int(rng.integers(5)))[2]

        value = rate(step, lambda: env.reset(seed=next(seeds)), budget)
        env.close()
        return value

    ids = {
        "foraging": ("EmbodiedAdhoc/ForagingGrid-v0", "EmbodiedAdhoc/Foraging-v0"),
        "pursuit": ("EmbodiedAdhoc/PursuitGrid-v0", "EmbodiedAdhoc/Pursuit-v0"),
    }[args.domain]
    results.append((f"{ids[0]}, random ad hoc + scripted team", single_rate(ids[0], args.seconds)))

    from embodied_adhoc.learning.vector_grid import GridVectorEnv

    vector = GridVectorEnv(args.domain, args.num_envs)
    vector.reset(seed=args.seed)
    vector_actions = rng.integers(0, 5, size=(64, args.num_envs))
    setup = now()
    vector.step(vector_actions[0])  # the first step builds the grid's move table once per process (set apart)
    setup = now() - setup
    calls = iter(range(10**12))

    def vector_step():
        vector.step(vector_actions[next(calls) % 64])
        return False  # sub-envs reset themselves (NEXT_STEP autoreset)

    vector_rate = rate(vector_step, lambda: None, args.seconds) * args.num_envs
    results.append(
        (f"GridVectorEnv x{args.num_envs} ({args.domain}), random ad hoc + scripted team", vector_rate)
    )
    notes = [
        f"GridVectorEnv: its first step (the move table, built once per grid and process) took {setup:.2f} s"
    ]

    arena_env = gymnasium.make(ids[1]).unwrapped
    backend = arena_env.core.backend
    arena_env.reset(seed=1)
    before_steps, before_time, macro = backend.physics_steps, now(), 0
    while macro < 20 or now() - before_time < args.seconds / 3:
        if arena_env.step(int(rng.integers(5)))[2]:
            arena_env.reset(seed=next(seeds))
        macro += 1
    macro_time = (now() - before_time) / macro
    mj_steps_per_macro = (backend.physics_steps - before_steps) / macro
    results.append((f"{ids[1]} (MuJoCo), random ad hoc + scripted team", 1.0 / macro_time))
    raw_start, raw_n = now(), 2000
    mujoco.mj_step(backend.model, backend.data, raw_n)
    raw = (now() - raw_start) / raw_n
    arena_env.close()

    reference_name, reference = results[0]
    print(f"{'env':62s} {'steps/s':>10s} {'ratio':>8s}")
    for name, value in results:
        print(f"{name:62s} {value:10.1f} {value / reference:8.3f}")
    print(f"\nratios against: {reference_name}; clock: {args.clock}")
    print(
        f"MuJoCo macro step = {macro_time / raw:.0f} raw mj_step of the same model "
        f"({mj_steps_per_macro:.0f} mj_step calls per macro step, i.e. physics overhead "
        f"{macro_time / (mj_steps_per_macro * raw):.2f}x the physics it runs; "
        f"timestep {backend.model.opt.timestep} s)"
    )
    print("\n".join(notes))
    if args.domain == "pursuit":
        hotspot_pursuit_overhead(args)


def hotspot_pursuit_overhead(args: Args) -> None:
    """Fig. 7.12 in the arena (``EmbodiedAdhoc/PursuitPairPomdp-v0``) driven by HOTSPOT: one macro step (the
    POMDP draw, waypoints, controllers, physics, read-back, observation) against the raw ``mj_step`` calls it
    drives, and the agent's own act + observe, measured in the same run."""
    import gymnasium
    import mujoco

    import embodied_adhoc.envs  # noqa: F401
    from embodied_adhoc.decision.agents.factory import make_agent

    env = gymnasium.make("EmbodiedAdhoc/PursuitPairPomdp-v0", max_episode_steps=10**6).unwrapped
    agent = make_agent("hotspot", env.library)
    seeds = iter(range(10**9))
    env_time = agent_time = 0.0
    macro, before_steps = 0, env.arena.physics_steps

    def start() -> None:
        env.reset(seed=next(seeds))
        agent.reset(np.random.default_rng(macro))

    start()
    while macro < 20 or env_time + agent_time < args.seconds / 3:
        t0 = now()
        action = agent.act()
        t1 = now()
        _, _, terminated, _, info = env.step(action)
        t2 = now()
        agent.observe(action, info["observation_index"])
        agent_time += (t1 - t0) + (now() - t2)
        env_time += t2 - t1
        macro += 1
        if terminated:
            start()
    calls = (env.arena.physics_steps - before_steps) / macro
    backend = env.arena.backend
    raw_start, raw_n = now(), 2000
    mujoco.mj_step(backend.model, backend.data, raw_n)
    raw = (now() - raw_start) / raw_n
    env.close()
    macro_time = env_time / macro
    print(
        f"HOTSPOT in the Fig. 7.12 arena (PursuitPairPomdp-v0), {macro} macro steps: a macro step "
        f"{macro_time * 1e3:.1f} ms = {macro_time / raw:.0f} raw mj_step ({calls:.0f} mj_step calls per macro step: "
        f"{macro_time / (calls * raw):.2f}x the physics it drives); HOTSPOT act + observe "
        f"{agent_time / macro * 1e3:.2f} ms per step ({agent_time / env_time:.3f} of the macro step)"
    )


if __name__ == "__main__":
    main(parse_dataclass_args(Args, description=__doc__))
