"""Time one UCT decision (Table 4.1, pursuit: 100 iterations, depth 5) on chapter-4 pursuit with the exact
environment and the exact teammate-aware team model: the batched search (waves of simulations, one simulator
call per depth) against the plain per-node sequential UCT, both measured in this run on the same states.

    .venv/bin/python scripts/bench_uct.py [--decisions 20] [--wave 20] [--seed 0] [--model exact|learned]

``--model learned`` plans over TEAMSTER's networks instead, first trained on 500 steps of the teammate-aware
team (an untrained reward network ends simulations at random; torch on one thread), and also times a whole
TEAMSTER step (the decision plus the online updates of line 11-12 of Algorithm 1). Prints CPU milliseconds per
decision (``time.process_time``: less sensitive to other jobs on a shared machine than wall time, which is
printed beside it) for both planners and their ratio.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from embodied_adhoc.decision.agents.teamwork import sample_rows
from embodied_adhoc.decision.uct import BatchedUct, PlainUct, UctConfig
from embodied_adhoc.domains.pursuit4 import ExactEnvironment, ExactTeam, Pursuit4


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--decisions", type=int, default=20)
    parser.add_argument("--wave", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--model", choices=("exact", "learned"), default="exact")
    args = parser.parse_args()
    world = Pursuit4()
    team, env = ExactTeam(world, "teammate-aware"), ExactEnvironment(world)
    if args.model == "learned":
        import torch

        from embodied_adhoc.learning.teamster import LearnedEnvironment, LearnedTeam

        torch.set_num_threads(1)
        team = LearnedTeam(world, np.random.default_rng(args.seed))
        env = LearnedEnvironment(world, np.random.default_rng(args.seed + 1))
        rng = np.random.default_rng(args.seed + 2)
        state = world.sample_states(rng, 1)[0]
        for _ in range(500):
            joint = sample_rows(world.team_policy("teammate-aware", state[None], agents=(0, 1, 2, 3))[0], rng)
            nxt, reward, done = world.step(state[None], joint[None], rng)
            env.update(state, joint, float(reward[0]), nxt[0], bool(done[0]))
            team.update(state, joint[1:])
            state = world.sample_states(rng, 1)[0] if done[0] else nxt[0]

    def simulate(states, actions, rng):
        mates = sample_rows(team.probs(states), rng)
        return env.step(states, np.concatenate([actions[:, None], mates], axis=1), rng)

    states = world.sample_states(np.random.default_rng(args.seed), args.decisions)
    rows = []
    for name, planner in (
        ("plain per-node UCT", PlainUct(UctConfig())),
        (f"batched UCT (wave {args.wave})", BatchedUct(UctConfig(wave=args.wave))),
    ):
        rng = np.random.default_rng(args.seed)
        planner.plan(states[0], simulate, rng)  # warm-up
        cpu, wall = time.process_time(), time.perf_counter()
        for state in states:
            planner.plan(state, simulate, rng)
        rows.append(
            (
                name,
                (time.process_time() - cpu) / len(states) * 1e3,
                (time.perf_counter() - wall) / len(states) * 1e3,
            )
        )
    for name, ms, wall_ms in rows:
        print(f"{name:28s} {ms:8.2f} ms CPU/decision  {1e3 / ms:7.1f} decisions/s  ({wall_ms:.2f} ms wall)")
    print(f"speed-up batched / plain: {rows[0][1] / rows[1][1]:.1f}x  (goal: batched < 20 ms)")
    if args.model == "learned":
        planner, rng = BatchedUct(UctConfig(wave=args.wave)), np.random.default_rng(args.seed)
        cpu = time.process_time()
        for state in states:
            joint = np.concatenate(
                [[planner.plan(state, simulate, rng)], sample_rows(team.probs(state[None])[0], rng)]
            )
            nxt, reward, done = world.step(state[None], joint[None], rng)
            env.update(state, joint, float(reward[0]), nxt[0], bool(done[0]))
            team.update(state, joint[1:])
        print(
            f"{'TEAMSTER step (plan + learn)':28s} {(time.process_time() - cpu) / len(states) * 1e3:8.2f} ms CPU/step"
        )


if __name__ == "__main__":
    main()
