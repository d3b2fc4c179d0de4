"""Per-step CPU cost of a chapter-4 sequential-teams trial (``run_trial``), split into planning (UCT decisions
while learning), learning (Algorithm 1's lines 10-12: belief update and the Adam steps) and evaluation (decisions
and belief updates with learning paused), for this tree and, in the same run, for a reference tree.

    git archive <commit> embodied_adhoc scenes assets | tar -x -C /tmp/teamster-ref
    .venv/bin/python scripts/bench_teamster.py --reference /tmp/teamster-ref [--steps 300] [--agent teamster]

Each tree runs in its own subprocess (``PYTHONPATH`` set to the tree, so its package shadows the installed one)
with the same protocol settings and seed, one torch and one BLAS thread (``run_trial``'s own limits); the
reference first, then this tree, then the reference again when ``--repeat 2``, so that a change in the load of
a shared machine shows as a spread between the two reference runs. Times are ``time.process_time`` (CPU of that
process), less sensitive to other jobs than wall time, which is printed beside them. ``--steps 5000`` is the
thesis's T: one whole trial (46,500 steps with ``--changed mirror``); the default is a short one.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

CATEGORIES = ("planning", "learning", "evaluation")


def _protocol():
    """``(ProtocolConfig, run_trial)`` wherever the tree keeps the protocol module."""
    try:
        from embodied_adhoc.experiments.domains import teamster_protocol as module
    except ImportError:
        from embodied_adhoc.experiments import teamster_protocol as module
    return module.ProtocolConfig, module.run_trial


def worker(args: argparse.Namespace) -> dict:
    """One trial of ``args.agent`` with the agent's act/observe timed by category."""
    from embodied_adhoc.decision.agents import teamwork

    config_class, run_trial = _protocol()
    cpu = dict.fromkeys(CATEGORIES, 0.0)
    steps = dict.fromkeys(CATEGORIES, 0)
    act, observe = teamwork.ModelBasedAgent.act, teamwork.ModelBasedAgent.observe

    def timed_act(self, state):
        start = time.process_time()
        try:
            return act(self, state)
        finally:
            kind = "planning" if self.learning else "evaluation"
            cpu[kind] += time.process_time() - start
            steps[kind] += 1

    def timed_observe(self, *outcome):
        start = time.process_time()
        try:
            return observe(self, *outcome)
        finally:
            cpu["learning" if self.learning else "evaluation"] += time.process_time() - start
            steps["learning"] += bool(self.learning)

    teamwork.ModelBasedAgent.act, teamwork.ModelBasedAgent.observe = timed_act, timed_observe
    config = config_class(
        steps=args.steps,
        eval_steps=args.eval_steps,
        points=args.points,
        seed=args.seed,
        **({"changed": args.changed} if args.changed else {}),
        **({"wave": args.wave} if args.wave else {}),
    )
    start_cpu, start_wall = time.process_time(), time.perf_counter()
    record = run_trial(args.agent, args.trial, config)
    total_cpu, wall = time.process_time() - start_cpu, time.perf_counter() - start_wall
    finals = {team: curve[-1][1] for team, curve in record["curves"].items()}
    result = {"cpu": cpu, "steps": steps, "total_cpu": total_cpu, "wall": wall, "finals": finals}
    return result | _forward_floor(args.wave or 20)


def _forward_floor(wave: int, calls: int = 300) -> dict:
    """CPU time of one planner call of the transition network (a wave of ``wave`` states x 5 agents) and the
    rate of its products in multiply-adds per second: the part of a decision that no change of the code around
    the networks removes (``iterations / wave x depth`` such calls per decision). The planner's forward is the
    pursuit simulator's (``packed_transition``, contiguous weight copies) where the tree has one, else the
    forward over the parameters' views."""
    import numpy as np
    from threadpoolctl import threadpool_limits

    from embodied_adhoc.domains.pursuit4 import Pursuit4
    from embodied_adhoc.learning.teamster import LearnedEnvironment

    world, rng = Pursuit4(), np.random.default_rng(0)
    environment = LearnedEnvironment(world, rng)
    rows = environment.features.transition(world.sample_states(rng, wave), rng.integers(0, 5, (wave, 4)))
    sizes = [layer.weight.numel() for layer in environment.transition_net if hasattr(layer, "weight")]
    forward = getattr(environment, "packed_transition", environment.transition_forward)
    with threadpool_limits(limits=1, user_api="blas"):
        forward(rows)
        start = time.process_time()
        for _ in range(calls):
            forward(rows)
        seconds = (time.process_time() - start) / calls
    return {"forward_ms": seconds * 1e3, "forward_gmacs": sum(sizes) * rows.shape[0] / seconds / 1e9}


def _run_tree(tree: Path | None, argv: list[str]) -> dict:
    env = dict(os.environ)
    if tree is not None:
        env["PYTHONPATH"] = str(tree.resolve()) + os.pathsep + env.get("PYTHONPATH", "")
    out = subprocess.run(
        [sys.executable, __file__, "--worker", *argv],
        env=env,
        cwd=str(tree) if tree is not None else None,
        capture_output=True,
        text=True,
    )
    if out.returncode:
        sys.exit(f"bench_teamster: the worker for {tree or 'this tree'} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _line(name: str, result: dict) -> str:
    per = []
    for kind in CATEGORIES:
        n = result["steps"][kind]
        per.append(f"{kind} {result['cpu'][kind] / n * 1e3 if n else 0.0:6.2f}")
    return (
        f"{name:22s} {'  '.join(per)} ms/step   trial {result['total_cpu']:7.1f} CPU s "
        f"({result['wall']:.1f} s wall)   final evaluations {result['finals']}"
        + (
            f"\n{'':22s} transition forward per planner call {result['forward_ms']:.3f} ms CPU "
            f"({result['forward_gmacs']:.1f} GMAC/s)"
            if "forward_ms" in result
            else ""
        )
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference", type=Path, default=None, help="a tree of the code to compare against")
    parser.add_argument("--agent", default="teamster")
    parser.add_argument("--steps", type=int, default=300, help="T per team (default 300; the thesis: 5000)")
    parser.add_argument("--eval-steps", type=int, default=100)
    parser.add_argument("--points", type=int, default=3)
    parser.add_argument("--changed", default="", help="a changed phase (mirror, fail:P; default none)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--trial", type=int, default=0)
    parser.add_argument(
        "--repeat", type=int, default=1, choices=(1, 2), help="2: the reference again at the end"
    )
    parser.add_argument(
        "--wave",
        type=int,
        default=0,
        help="this tree's UCT wave (default: its planner's; the reference: its own)",
    )
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(worker(args)))
        return
    if args.reference is not None and not (args.reference / "embodied_adhoc").is_dir():
        sys.exit(
            f"bench_teamster: --reference {args.reference}: no embodied_adhoc package there; make one with "
            "git archive <commit> embodied_adhoc scenes assets | tar -x -C DIR"
        )
    argv = [
        f"--agent={args.agent}",
        f"--steps={args.steps}",
        f"--eval-steps={args.eval_steps}",
        f"--points={args.points}",
        f"--changed={args.changed}",
        f"--seed={args.seed}",
        f"--trial={args.trial}",
    ]
    results = []
    if args.reference is not None:
        results.append(("reference", _run_tree(args.reference, argv)))
    results.append(
        (
            "this tree" + (f" (wave {args.wave})" if args.wave else ""),
            _run_tree(None, [*argv, f"--wave={args.wave}"]),
        )
    )
    if args.reference is not None and args.repeat == 2:
        results.append(("reference (again)", _run_tree(args.reference, argv)))
    for name, result in results:
        print(_line(name, result))
    if args.reference is not None:
        ref, now = results[0][1], results[1][1]
        ratios = []
        for kind in CATEGORIES:
            if ref["steps"][kind] and now["steps"][kind] and now["cpu"][kind]:
                before = ref["cpu"][kind] / ref["steps"][kind]
                ratios.append(f"{kind} {before / (now['cpu'][kind] / now['steps'][kind]):.2f}x")
        print(
            f"speed-up (reference / this tree): {', '.join(ratios)}, "
            f"trial {ref['total_cpu'] / now['total_cpu']:.2f}x"
        )


if __name__ == "__main__":
    main()
