"""Fault sweep of the physics lab: HOTSPOT in ``EmbodiedAdhoc/ToxicWaste-v0`` under sensor and actuator
faults, with the lidar Monte Carlo localiser on and off (wheel odometry alone), same seeds; and the localiser's
cost per control step against the physics step, measured in the same run (``--no-sweep``: the cost alone).

Per row and mode it prints the success rate, the mean steps (capped episodes count the cap) with the 95 %
percentile-bootstrap interval of the mean, the worst pose error (the pose the controller tracked vs the truth, over
every step of every episode), blocked macro steps and the robot-node readings that were unknown or wrong.
Episodes are those of ``trials toxic-waste --backend mujoco --seed S`` (same episode draw and seeds), so a row can
be replayed with ``run toxic-waste --seed ...``.

With ``--confusion-out PATH`` it also writes the localiser's measured robot-node confusion (true area x reported
area + unknown, pooled over the rows with the localiser on, smoothed with ``--floor``) with its provenance (the
counts per fault setting, seeds, episodes, commit), in the schema of ``domains.confusion``; the lab model reads it
with ``--localisation-model PATH`` (``measured`` = ``assets/data/localisation_confusion_measured.json``). HOTSPOT's
episodes rarely take the robot to every area, so the readings also include ``--tours`` scripted tours per fault
setting (every edge of the lab both ways from the door, a reading after each macro step), which visit all five.

Usage: MUJOCO_GL=egl .venv/bin/python scripts/bench_faults.py [--episodes 16] [--seed 0] [--max-steps 100]
       [--workers 1] [--rows defaults encoder_noise=0.05 ...] [--confusion-out PATH] [--cost-seconds 60]
       [--no-sweep]
"""

from __future__ import annotations

import datetime
import os
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")

from embodied_adhoc.errors import ConfigError  # noqa: E402
from embodied_adhoc.experiments.script_args import parse_dataclass_args  # noqa: E402

ROWS = (
    "defaults",
    "encoder_noise=0.05",
    "wheel_slip=0.005",
    "wheel_slip=0.02",
    "rfid_miss=1.0",
    "lidar_noise=0.05,lidar_dropout=0.3",
    "lidar_dropout=1.0",
    "speech_failure=0.5",
)
AGENT = "hotspot"


@dataclass(frozen=True)
class Args:
    episodes: int = 16
    """episodes per row and mode"""
    seed: int = 0
    """seed of the sweep (as trials --seed)"""
    max_steps: int = 100
    """macro-step cap (the thesis's 100)"""
    workers: int = 1
    """worker processes (results do not depend on it)"""
    rows: tuple[str, ...] = ROWS
    """fault settings: 'defaults' or name=value[,name=value] with the names of --wheel-slip etc."""
    confusion_out: str = ""
    """write the measured robot-node confusion (JSON) here"""
    floor: float = 0.01
    """smoothing floor of the measured confusion"""
    tours: int = 4
    """scripted tours per fault setting added to the measured confusion (seeds 0..N-1)"""
    cost_seconds: float = 60.0
    """simulated seconds of driving for the cost measurement (0: skip)"""
    no_sweep: bool = False
    """skip the fault sweep (with --cost-seconds: measure the localiser's cost only)"""


def parse_row(text: str) -> dict[str, float]:
    from embodied_adhoc.experiments.domains.toxic_waste import FAULTS

    if text == "defaults":
        return {}
    faults = {}
    for part in text.split(","):
        name, _, value = part.partition("=")
        if name not in FAULTS or not value:
            raise ConfigError(
                f"--rows '{text}': use name=value with names {', '.join(FAULTS)}, or 'defaults'"
            )
        faults[name] = float(value)
    return faults


_SESSIONS: dict = {}


def run_one(task: tuple[str, bool, int, int, int]) -> dict:
    """One episode: (row, localisation on, episode, seed, max_steps) -> outcome and per-step readings."""
    import gymnasium

    from embodied_adhoc.episodes.loop import EpisodeObserver, run_episode_loop
    from embodied_adhoc.experiments import seeding
    from embodied_adhoc.experiments.domains.toxic_waste import DOMAIN

    row, localisation, episode, seed, max_steps = task
    # the sweep's rows name faults the agent's model is not told (its RFID model stays a perfect reader)
    options = DOMAIN.options(faults=parse_row(row), localisation=localisation, model_rfid_miss=0.0)
    key = repr(options)
    if key not in _SESSIONS:
        _SESSIONS[key] = DOMAIN.open_session("mujoco", options)
    session = _SESSIONS[key]
    spec = DOMAIN.episode_spec(options, seeding.episode_rng(seed, episode))
    env = gymnasium.make(
        session.env_id, max_episode_steps=max_steps, disable_env_checker=True, **session.env_kwargs
    )

    class Collect(EpisodeObserver):
        def __init__(self):
            self.pose_errors, self.odometry_errors, self.readings = [], [], []
            self.blocked = self.kidnaps = 0

        def episode_started(self, info, posterior):
            self.readings.append((info["robot_node"], info["robot_node_reading"]))

        def step_finished(self, record):
            info = record.info
            self.pose_errors.append(info["pose_error"])
            self.odometry_errors.append(info["odometry_error"])
            self.readings.append((info["robot_node"], info["robot_node_reading"]))
            self.blocked += int(info["blocked"])
            self.kidnaps += int(info["kidnaps"])

    collect = Collect()
    started = time.perf_counter()
    trace = run_episode_loop(
        env,
        session.make_agent(AGENT, spec, seeding.agent_seed(seed, episode, AGENT)),
        env_seed=seeding.env_seed(seed, episode, AGENT),
        agent_rng=seeding.agent_rng(seed, episode, AGENT),
        reset_options=session.reset_options(spec),
        max_steps=max_steps,
        observation_index=session.observation_index,
        observers=[collect],
    )
    env.close()
    return {
        "row": row,
        "localisation": localisation,
        "episode": episode,
        "success": trace.success,
        "steps": trace.steps,
        "worst_pose_error": max(collect.pose_errors, default=0.0),
        "worst_odometry_error": max(collect.odometry_errors, default=0.0),
        "blocked": collect.blocked,
        "kidnaps": collect.kidnaps,
        "readings": collect.readings,
        "wall_s": time.perf_counter() - started,
    }


TOUR = (1, 2, 1, 3, 4, 3, 1, 0)  # from the door, every edge both ways


def tour_readings(row: str, seed: int) -> list[tuple[int, int | None]]:
    """(true area, reading) after each macro step of one scripted tour under the row's faults (localiser on)."""
    from embodied_adhoc.envs.toxic_waste_world import make_world
    from embodied_adhoc.experiments.domains.toxic_waste import fault_env_kwargs
    from embodied_adhoc.sim.lab_world import HumanCommand

    kwargs = fault_env_kwargs({"faults": parse_row(row)})
    world = make_world(
        kwargs.get("encoder_noise"),
        kwargs.get("wheel_slip"),
        0.0,
        60.0,
        15.0,
        64,
        64,
        localisation=True,
        lidar_noise=kwargs.get("lidar_noise"),
        lidar_dropout=kwargs.get("lidar_dropout"),
    )
    world.reset(seed=seed, robot_node=0, human_node=4, ball_nodes=(0, 1, 2))
    readings = [(0, world.robot_node_reading())]
    for target in TOUR:
        result = world.step_macro(target, HumanCommand.stay())
        true = (
            result.true_robot_node
            if result.true_robot_node is not None
            else world.layout.nearest_node(world.true_robot_pose()[:2])
        )
        readings.append((true, result.robot_node_reading))
    world.close()
    return readings


def localiser_cost(seconds: float) -> dict[str, float]:
    """CPU time of this process per control step (other processes' load changes it less than wall time) of: the
    physics (its substeps: ``mj_step`` on the world's model and data, as :meth:`LabWorld.tick` runs it), the
    localiser (lidar scan + filter: :meth:`LabWorld.sense` less its odometry), the odometry (``sense`` with the
    localiser detached), and the physics step of the same scene without the lidar's rangefinders; one scripted
    drive."""
    import mujoco

    from embodied_adhoc import paths
    from embodied_adhoc.sim.lab_world import LabWorld

    world = LabWorld()
    world.reset(seed=0, robot_node=1, human_node=4, ball_nodes=(0, 1, 2))
    ticks = int(seconds / world.config.control_period)
    physics = sensing = 0.0
    wheels = [(4.0, 4.0), (3.0, -3.0), (4.0, 3.0), (-2.0, 2.0)]
    for tick in range(ticks):
        world.data.ctrl[world.ids.wheel_actuators] = wheels[(tick // 100) % len(wheels)]
        if tick % 200 == 150:  # keep clear of the walls: back to the open space now and then
            q = world.ids.root_qpos
            world.data.qpos[q : q + 2] = (0.5, -0.5)
            world.localiser.reset(
                world.localiser.rng, world.odometry.pose, world.true_robot_pose(), time=world.data.time
            )
        start = time.process_time()
        mujoco.mj_step(world.model, world.data, nstep=world.substeps)
        middle = time.process_time()
        world.sense()
        end = time.process_time()
        physics += middle - start
        sensing += end - middle
    # odometry alone (the sensing without the localiser) on the same world
    localiser, world.localiser = world.localiser, None
    odometry = 0.0
    for _ in range(ticks):
        start = time.process_time()
        world.sense()
        odometry += time.process_time() - start
    world.localiser = localiser
    # the scene without the lidar's rangefinders: what the physics step cost before the lidar
    spec = mujoco.MjSpec.from_file(str(paths.scene("lab.xml")))
    for sensor in list(spec.sensors):
        if sensor.name.startswith("lidar_"):
            spec.delete(sensor)
    model = spec.compile()
    model.opt.timestep = world.config.timestep
    data = mujoco.MjData(model)
    data.ctrl[:2] = 4.0
    start = time.process_time()
    for _ in range(ticks):
        mujoco.mj_step(model, data, nstep=world.substeps)
    bare = time.process_time() - start
    world.close()
    return {
        "control_steps": ticks,
        "physics_ms": 1e3 * physics / ticks,
        "physics_without_lidar_ms": 1e3 * bare / ticks,
        "localiser_ms": 1e3 * (sensing - odometry) / ticks,
        "odometry_ms": 1e3 * odometry / ticks,
    }


def write_confusion(path: Path, results: list[dict], args: Args) -> None:
    from embodied_adhoc.domains.confusion import ConfusionMatrix, save_confusion, smooth_confusion
    from embodied_adhoc.sim.lab_layout import LAB_LAYOUT

    n = len(LAB_LAYOUT.nodes)
    per_row: dict[str, np.ndarray] = {}
    for result in results:
        if not result["localisation"]:
            continue
        counts = per_row.setdefault(result["row"], np.zeros((n, n + 1), dtype=np.int64))
        for true, reading in result["readings"]:
            counts[true, n if reading is None else reading] += 1
    for row in list(per_row):
        for seed in range(args.tours):
            for true, reading in tour_readings(row, seed):
                per_row[row][true, n if reading is None else reading] += 1
    if not per_row:
        raise ConfigError("--confusion-out needs rows run with the localiser on")
    pooled = sum(per_row.values())
    empty = [LAB_LAYOUT.node_names[i] for i in np.flatnonzero(pooled.sum(axis=1) == 0)]
    if empty:
        raise ConfigError(f"--confusion-out: no reading in area(s) {empty}; raise --tours or --episodes")
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit = "unknown"
    provenance = {
        "source": "scripts/bench_faults.py: robot-node readings of the physics lab's Monte Carlo localiser "
        "(sim/localisation.py) after every reset and macro step of HOTSPOT episodes and of scripted tours "
        "(every edge both ways from the door); rows = true area, columns = reported area, last = unknown",
        "tours_per_row": args.tours,
        "columns_note": "the last column (named 'failed' by the shared schema) is 'unknown'",
        "agent": AGENT,
        "episodes_per_row": args.episodes,
        "seed": args.seed,
        "max_steps": args.max_steps,
        "rows": {row: counts.tolist() for row, counts in per_row.items()},
        "pooled_counts": pooled.tolist(),
        "commit": commit,
        "date": datetime.date.today().isoformat(),
    }
    matrix = ConfusionMatrix(
        LAB_LAYOUT.node_names, smooth_confusion(pooled, args.floor), args.floor, provenance
    )
    save_confusion(matrix, path)
    print(f"wrote {path} (pooled over {len(per_row)} fault settings, {int(pooled.sum())} readings)")


def table_line(row: str, localisation: bool, chosen: list[dict]) -> str:
    from embodied_adhoc.experiments.stats import bootstrap_interval

    readings = [reading for r in chosen for reading in r["readings"]]
    low, high = bootstrap_interval([r["steps"] for r in chosen], lambda block: block.mean(axis=1))
    unknown = sum(reading is None for _, reading in readings)
    wrong = sum(reading is not None and reading != true for true, reading in readings)
    return (
        f"| {row} | {'on' if localisation else 'off'} | {sum(r['success'] for r in chosen)}/{len(chosen)} "
        f"| {np.mean([r['steps'] for r in chosen]):.1f} | [{low:.1f}, {high:.1f}] "
        f"| {max(r['worst_pose_error'] for r in chosen):.2f} m "
        f"| {sum(r['blocked'] for r in chosen)} "
        f"| {sum(r['kidnaps'] for r in chosen)} "
        f"| {unknown} / {wrong} of {len(readings)} "
        f"| {np.mean([r['wall_s'] for r in chosen]):.1f} |"
    )


def refuse(message: str) -> None:
    print(f"bench_faults: {message}", file=sys.stderr)
    raise SystemExit(2)


def sweep(args: Args) -> list[dict]:
    """The fault sweep: every row with the localiser on and off, its table printed row by row."""
    print(
        f"HOTSPOT, {args.episodes} episodes per row and mode, seed {args.seed}, cap {args.max_steps}; "
        f"localiser on = lidar MCL, off = wheel odometry alone; {args.workers} worker(s)\n"
    )
    header = (
        "| fault | localiser | success | mean steps | steps 95% CI (bootstrap) | worst pose error | blocked steps "
        "| re-localisations | unknown / wrong readings | wall s/episode |"
    )
    print(header)
    print("|---|---|---|---|---|---|---|---|---|---|", flush=True)
    pool = ProcessPoolExecutor(args.workers) if args.workers > 1 else None
    results: list[dict] = []
    started = time.perf_counter()
    try:
        for row in args.rows:  # rows one after the other, so a long sweep shows its table as it goes
            tasks = [
                (row, localisation, episode, args.seed, args.max_steps)
                for localisation in (True, False)
                for episode in range(args.episodes)
            ]
            done = list(pool.map(run_one, tasks)) if pool is not None else [run_one(task) for task in tasks]
            results.extend(done)
            for localisation in (True, False):
                print(
                    table_line(row, localisation, [r for r in done if r["localisation"] == localisation]),
                    flush=True,
                )
    finally:
        if pool is not None:
            pool.shutdown()
    print(f"\n{time.perf_counter() - started:.0f} s wall for the sweep")
    return results


def main() -> None:
    args = parse_dataclass_args(Args, __doc__)
    if args.episodes < 1 or args.workers < 1:
        refuse("--episodes and --workers must be >= 1")
    if args.no_sweep and (args.confusion_out or args.cost_seconds <= 0):
        refuse("--no-sweep measures the cost only: give --cost-seconds N > 0 and no --confusion-out")
    for row in args.rows:
        parse_row(row)
    if not args.no_sweep:
        results = sweep(args)
        if args.confusion_out:
            write_confusion(Path(args.confusion_out), results, args)
    if args.cost_seconds > 0:
        cost = localiser_cost(args.cost_seconds)
        print(
            f"\ncost per control step ({cost['control_steps']} steps of 20 ms, this process, CPU time): physics "
            f"{cost['physics_ms']:.3f} ms (the same scene without the lidar's rangefinders: "
            f"{cost['physics_without_lidar_ms']:.3f} ms), localiser {cost['localiser_ms']:.3f} ms "
            f"({cost['localiser_ms'] / cost['physics_ms']:.2f}x the physics), odometry {cost['odometry_ms']:.3f} ms"
        )


if __name__ == "__main__":
    main()
