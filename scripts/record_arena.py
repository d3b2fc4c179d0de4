"""Record one MuJoCo episode of level-based foraging or predator-prey as an mp4 and a rerun ``.rrd``.

The ad hoc robot (orange) runs the team's own policy (the *original teammate*), so the episode shows the team
solving its task. The mp4 shows the overhead camera at ``fps`` frames per simulated second, with the ad hoc
robot's egocentric camera image inset in the top-left corner; the ``.rrd`` holds, per macro step, the overhead
and egocentric frames, the egocentric grid observation (as an image), the joint action and the events.

    .venv/bin/python scripts/record_arena.py --domain foraging --team tau1 --task 1 --out runs/arenas

(Headless: EGL is chosen when there is no display, unless ``MUJOCO_GL`` is set.)
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from embodied_adhoc.experiments.script_args import parse_dataclass_args
from embodied_adhoc.gl import choose_gl_platform

choose_gl_platform()  # before anything imports mujoco


@dataclass(frozen=True)
class Args:
    domain: str = "foraging"
    """foraging or pursuit"""
    team: str = "tau1"
    """team type (tau0, tau1, tau2)"""
    task: int = 1
    """task 1..4"""
    seed: int = 3
    """episode seed (start state, prey moves, tie-breaks)"""
    max_steps: int = 60
    """macro-step cap"""
    fps: float = 20.0
    """video frames per simulated second"""
    size: int = 480
    """overhead frame side (px, even)"""
    out: Path = Path("runs/arenas")
    """output folder"""


def observation_picture(
    observation: np.ndarray, n_agents: int, boundary: int, cell_px: int = 12
) -> np.ndarray:
    """The egocentric channels as one RGB picture: boundary grey, teammates blue, apples/prey green, self orange."""
    view = observation.shape[-1]
    picture = np.full((view, view, 3), 235, dtype=np.uint8)
    picture[observation[boundary] > 0] = 120
    picture[observation[: n_agents - 1].max(axis=0) > 0] = (40, 90, 220)
    picture[observation[n_agents - 1 : boundary].max(axis=0) > 0] = (40, 180, 40)
    picture[view // 2, view // 2] = (240, 140, 20)
    return np.kron(picture, np.ones((cell_px, cell_px, 1), dtype=np.uint8))


def main(args: Args) -> None:
    import gymnasium

    import embodied_adhoc.envs  # noqa: F401
    from embodied_adhoc.record.rerun_recorder import RerunRecorder
    from embodied_adhoc.record.video import VideoWriter

    env_id = {"foraging": "EmbodiedAdhoc/Foraging-v0", "pursuit": "EmbodiedAdhoc/Pursuit-v0"}[args.domain]
    env = gymnasium.make(
        env_id,
        teams=(args.team,),
        tasks=(args.task,),
        obs_mode="image",
        image_size=max(16, args.size // 4),
        render_mode="rgb_array",
    ).unwrapped
    backend, core = env.core.backend, env.core
    args.out.mkdir(parents=True, exist_ok=True)
    stem = args.out / f"{args.domain}_{args.team}_task{args.task}"
    frame_period = 1.0 / args.fps
    clock = {"sim": 0.0, "next_frame": 0.0, "step_start": 0.0}
    n = core.config.n_agents
    boundary = n - 1 + core.config.n_targets  # index of the boundary channel

    with (
        VideoWriter(stem.with_suffix(".mp4"), args.size, args.size, fps=args.fps) as video,
        RerunRecorder(stem.with_suffix(".rrd"), recording_name=stem.name) as recorder,
    ):

        def frame() -> None:
            top = backend.render_top(args.size).copy()
            inset = backend.egocentric_image(0)
            top[8 : 8 + inset.shape[0], 8 : 8 + inset.shape[1]] = inset
            video.write(top)

        def on_tick(t: float) -> None:
            clock["sim"] = clock["step_start"] + t
            while clock["sim"] >= clock["next_frame"]:
                frame()
                clock["next_frame"] += frame_period

        backend.on_tick = on_tick
        _, info = env.reset(seed=args.seed)
        frame()
        for step in range(args.max_steps + 1):
            recorder.set_time(step, clock["sim"])
            recorder.log_camera("overhead", backend.render_top(args.size))
            recorder.log_camera("egocentric", backend.egocentric_image(0))
            recorder.log_camera("grid_observation", observation_picture(core.observe(0), n, boundary))
            recorder.log_text(
                "events",
                f"task {info['task']} ({info['task_name']}), team {info['team']}, state {info['state']}",
            )
            if step == args.max_steps or not core.episode.state.alive.any():
                break
            action = int(core.scripted_actions([0])[0])
            clock["step_start"] = clock["sim"]
            _, reward, terminated, _, info = env.step(action)
            recorder.log_text("actions", f"ad hoc {action}, teammates {info['teammate_actions']}")
            if terminated:
                recorder.log_text("events", f"solved in {info['steps']} steps (reward {reward})")
        for _ in range(int(args.fps)):  # one still second at the end
            frame()
    env.close()
    print(
        f"{stem.with_suffix('.mp4')}  {stem.with_suffix('.rrd')}  ({info['steps']} steps, "
        f"{'solved' if not core.episode.state.alive.any() else 'not solved'})"
    )


if __name__ == "__main__":
    main(parse_dataclass_args(Args, description=__doc__))
