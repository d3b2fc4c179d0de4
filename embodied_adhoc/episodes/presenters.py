"""Per-domain presenters of recorded episodes: what the video's heads-up text, the rerun recording and
``metrics.json`` show of the physics lab (:class:`LabPresenter`), the pursuit arena (:class:`PursuitPresenter`) and
the foraging arena (:class:`ForagingPresenter`). The recorders themselves are domain-free
(:mod:`embodied_adhoc.episodes.recording`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from embodied_adhoc.episodes.loop import EpisodeTrace, StepRecord
from embodied_adhoc.episodes.recording import Presenter, entropy_of

__all__ = [
    "ForagingPresenter",
    "LabPresenter",
    "PursuitPresenter",
    "action_label",
    "describe_observation",
    "describe_pursuit_observation",
    "localisation_events",
    "localisation_fields",
]


# -- the lab ----------------------------------------------------------------------------------------------------
def describe_observation(library, observation_index: int) -> str:
    """The decoded lab observation in words: odometry node, human node heard, RFID."""
    z = library.decode_observation(observation_index)
    names = library.graph.names
    robot = "unknown" if z.robot_node is None else f"{z.robot_node} {names[z.robot_node]}"
    human = "none" if z.human_node is None else f"{z.human_node} {names[z.human_node]}"
    return f"robot at {robot}; human at {human}; rfid {'YES' if z.rfid else 'no'}"


def action_label(library, action: int, target: int | None) -> str:
    """A macro action by what it does: a move by the node it drives to (``env.move_target``), else its name."""
    if target is None:
        return library.action_names[action]
    return f"move to {target} {library.graph.names[target]}"


def localisation_fields(info: dict) -> dict:
    """The localisation outcome of a physics step for ``metrics.json``: errors (m), mode, blocked, kidnaps."""
    return {
        "pose_error_m": round(float(info["pose_error"]), 4),
        "odometry_error_m": round(float(info["odometry_error"]), 4),
        "localisation_mode": info["localisation_mode"],
        "robot_node_reading": info["robot_node_reading"],
        "true_robot_node": info["robot_node"],
        "blocked": bool(info["blocked"]),
        "kidnaps": int(info["kidnaps"]),
    }


def localisation_events(info: dict) -> list[str]:
    """Lines for the recording's event log: a blocked robot, a lost localiser, a lidar that gives nothing."""
    lines = []
    if info.get("blocked"):
        lines.append(
            f"robot blocked: it could not reach its waypoint (pose error {info['pose_error']:.2f} m)"
        )
    if info.get("kidnaps"):
        lines.append(f"localiser lost: re-localised globally {info['kidnaps']} time(s)")
    if info.get("localisation_mode") == "odometry":
        lines.append("no lidar scans: localisation degraded to odometry")
    return lines


class LabPresenter(Presenter):
    """The toxic-waste lab on physics: balls in the container, the action by the node it drives to, what was
    heard, the task belief; rerun gets the lab map, poses, the localiser, utterances, audio and events.
    ``cap_reason(actions, faults, action_names, capped) -> (code, sentence)`` explains a capped episode in
    ``metrics.json``."""

    hud_keys = ("balls", "action", "heard", "belief")
    step_cameras = ("robot",)

    def __init__(self, env, library, agent_name: str, spec: dict, cap_reason: Callable | None = None):
        self.env, self.library, self.agent_name, self.spec = env, library, agent_name, spec
        self.cap_reason = cap_reason

    def open_rerun(self, path: Path, name: str):
        from embodied_adhoc.record.rerun_recorder import RerunRecorder

        rerun = RerunRecorder(path, recording_name=name)
        layout = self.env.layout
        x0, x1, y0, y1 = layout.room_extent
        rerun.log_lab(
            np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]),
            {
                f"{n} {name}": np.asarray(polygon)
                for n, (name, polygon) in enumerate(zip(layout.node_names, layout.area_polygons, strict=True))
            },
            layout.node_waypoints,
            layout.node_names,
            layout.edges,
        )
        return rerun

    def describe(self, observation_index: int) -> str:
        return describe_observation(self.library, observation_index)

    def action_label(self, action: int) -> str:
        return action_label(self.library, action, self.env.move_target(action))

    def _belief_lines(self, posterior, info: dict) -> dict:
        disposed = sum(1 for status in info["ball_status"] if status == 2)
        lines = {"balls": f"{self.agent_name} | balls in container {disposed}/{len(info['ball_status'])}"}
        if posterior is not None:
            beliefs = "  ".join(
                f"{list(task)} {p:.2f}" for task, p in zip(self.library.tasks, posterior, strict=True)
            )
            lines["belief"] = f"P(task): {beliefs}"
        return lines

    def started(self, rerun, info: dict, posterior) -> dict:
        rerun.set_time(0, info["sim_time"])
        rerun.log_poses(
            info["robot_pose"], info["odometry_pose"], info["human_position"], info["ball_positions"]
        )
        if posterior is not None:
            rerun.log_belief(posterior, entropy_of(posterior))
        tasks = ", ".join(f"{k}: balls at {list(t)}" for k, t in enumerate(self.library.tasks))
        rerun.log_text(
            "events",
            f"start: robot at node {self.spec['robot_node']}, human at node {self.spec['human_node']}; "
            f"task library {tasks}",
        )
        return self._belief_lines(posterior, info)

    def log_frame(self, rerun, snapshot: dict, camera_due: bool) -> None:
        rerun.log_poses(
            snapshot["robot_pose"],
            snapshot["odometry_pose"],
            snapshot["human_position"],
            snapshot["ball_positions"],
        )
        if snapshot.get("estimated_pose") is not None:
            rerun.log_localisation(snapshot["estimated_pose"], snapshot["particles"] if camera_due else None)

    def stepped(self, rerun, record: StepRecord, description: str) -> dict:
        step, info, posterior = record.step, record.info, record.task_posterior
        rerun.log_text("observations", f"step {step}: {description}")
        for line in info.get("utterances", ()):
            rerun.log_text("utterances", line)
        if info.get("speech_audio") is not None:
            rerun.log_audio(info["speech_audio"])
        if info.get("rfid_event"):
            rerun.log_text("events", f"step {step}: a ball entered the container")
        for line in localisation_events(info):
            rerun.log_text("events", f"step {step}: {line}", level="WARN")
        if posterior is not None:
            rerun.log_belief(posterior, entropy_of(posterior))
        return {**self._belief_lines(posterior, info), "heard": f"observed: {description}"}

    def metrics_step(self, metrics, record: StepRecord) -> None:
        posterior = record.task_posterior
        metrics.end_step(
            record.action,
            self.describe(record.observation_index),
            record.reward,
            record.info["sim_time"],
            posterior,
            entropy_of(posterior),
            record.info["utterances"],
        )
        if "pose_error" in record.info:
            metrics.per_step[-1].update(localisation_fields(record.info))
        if "faults" in record.info:
            metrics.faults = dict(record.info["faults"])

    def metrics_finished(self, metrics, trace: EpisodeTrace) -> None:
        if metrics.faults is not None and self.cap_reason is not None:
            capped = trace.truncated and not trace.success
            code, detail = self.cap_reason(trace.actions, metrics.faults, self.library.action_names, capped)
            metrics.cap_reason = {"code": code, "detail": detail} if code else None


# -- the grid arenas --------------------------------------------------------------------------------------------
class _ArenaPresenter(Presenter):
    """What both arenas show: the cell grid and every robot's pose (labelled, coloured) in rerun, the agent's name
    and the step's action on the video, and a video frame after every step."""

    frame_each_step = True
    action_names: tuple[str, ...] = ()

    def __init__(
        self, layout, agent_name: str, labels: Sequence[str], colours: Sequence[tuple[int, int, int]]
    ):
        self.layout, self.agent_name = layout, agent_name
        self.labels, self.colours = list(labels), list(colours)

    def open_rerun(self, path: Path, name: str):
        from embodied_adhoc.record.arena_recorder import ArenaRerunRecorder

        rerun = ArenaRerunRecorder(path, recording_name=name)
        rerun.log_cells(self.layout.rows, self.layout.cols, self.layout.cell)
        return rerun

    def action_label(self, action: int) -> str:
        return self.action_names[action]

    def action_line(self, step: int, label: str) -> str:
        return f"{self.agent_name} | step {step}: {label}"

    def finished_line(self, trace: EpisodeTrace, outcome: str) -> dict:
        return {"action": f"{self.agent_name} | done after {trace.steps} steps: {outcome}"}

    def log_frame(self, rerun, snapshot: dict, camera_due: bool) -> None:
        rerun.log_robots(snapshot["poses"], self.labels, self.colours)


PURSUIT_NEIGHBOURS = ("NW", "N", "NE", "W", "here", "E", "SW", "S", "SE")


def describe_pursuit_observation(observation_index: int) -> str:
    """``z = 9 t + p`` in words: where the teammate and the prey were seen in the 3x3 neighbourhood."""
    if observation_index < 0:
        return "nothing yet"
    mate, prey = divmod(int(observation_index), 9)

    def seen(cell: int) -> str:
        return "unseen" if cell == 4 else PURSUIT_NEIGHBOURS[cell]

    return f"teammate {seen(mate)}, prey {seen(prey)}"


class PursuitPresenter(_ArenaPresenter):
    """Fig. 7.12's pursuit on physics: the observation in words, the task posterior, and the steps where physics
    did not execute the move the model drew."""

    hud_keys = ("action", "observed", "posterior")
    outcomes = ("captured", "not captured")
    action_names = ("up", "down", "left", "right", "stay")

    def __init__(self, layout, agent_name: str, task_names: Sequence[str]):
        super().__init__(
            layout, agent_name, ("ad hoc", "teammate", "prey"), ((240, 140, 20), (40, 90, 220), (220, 40, 40))
        )
        self.task_names = list(task_names)

    def describe(self, observation_index: int) -> str:
        return describe_pursuit_observation(observation_index)

    def _posterior(self, rerun, posterior) -> dict:
        if posterior is None:
            return {"posterior": None}
        names = [name.split(":")[-1] for name in self.task_names]
        rerun.log_belief(posterior, entropy_of(posterior))
        cells = "  ".join(f"{n} {p:.2f}" for n, p in zip(names, posterior, strict=True))
        return {"posterior": f"P(task): {cells}"}

    def started(self, rerun, info: dict, posterior) -> dict:
        rerun.log_text(
            "events",
            f"start: cells (ad hoc, teammate, prey) {info['cells']}, true task "
            f"{info['task_name']}, library {', '.join(self.task_names)}",
        )
        action = f"{self.agent_name} | true task {info['task_name'].split(':')[-1]} | step 0"
        return {"action": action, **self._posterior(rerun, posterior)}

    def stepped(self, rerun, record: StepRecord, description: str) -> dict:
        info = record.info
        rerun.log_text("observations", f"step {record.step}: z={record.observation_index} ({description})")
        if info["state"] != info["intended_state"]:
            rerun.log_text(
                "events",
                f"step {record.step}: physics did not execute the drawn move "
                f"(state {info['state']}, drawn {info['intended_state']})",
                level="WARN",
            )
        observed = f"observed z={record.observation_index}: {description}"
        return {"observed": observed, **self._posterior(rerun, record.task_posterior)}

    def metrics_step(self, metrics, record: StepRecord) -> None:
        super().metrics_step(metrics, record)
        metrics.per_step[-1].update(
            cells=record.info["cells"],
            state=int(record.info["state"]),
            intended_state=int(record.info["intended_state"]),
        )


class ForagingPresenter(_ArenaPresenter):
    """Level-based foraging on physics (thesis ch. 6): the true task and team, and the ATLPO agent's posterior
    over its library's (task, team) environments where it keeps one."""

    hud_keys = ("action", "truth", "posterior", "posterior more")
    outcomes = ("apple foraged", "not foraged")
    action_names = ("up", "down", "left", "right", "forage")

    def __init__(self, layout, agent_name: str, agent, n_robots: int, clock: Callable[[], float]):
        labels = ["ad hoc"] + [f"teammate {i}" for i in range(1, n_robots)]
        colours = ((240, 140, 20), (40, 90, 220), (40, 160, 90), (150, 60, 200))[:n_robots]
        super().__init__(layout, agent_name, labels, colours)
        self.agent, self.clock = agent, clock

    def describe(self, observation_index: int) -> str:
        return f"egocentric view, fingerprint {observation_index:08x}"

    def library_posterior(self) -> np.ndarray | None:
        posterior = getattr(self.agent, "library_posterior", None)
        return None if posterior is None else np.asarray(posterior, dtype=np.float64)

    def _posterior(self, rerun) -> dict:
        posterior = self.library_posterior()
        if posterior is None:
            return {"posterior": None, "posterior more": None}
        cells = [
            f"{e.task}/{e.team} {p:.2f}"
            for e, p in zip(self.agent.library.environments, posterior, strict=True)
        ]
        rerun.log_belief(posterior, entropy_of(posterior))
        # four per line fit the video's width
        return {"posterior": "P(task/team): " + " ".join(cells[:4]), "posterior more": " ".join(cells[4:])}

    def started(self, rerun, info: dict, posterior) -> dict:
        truth = f"true task {info['task']} ({info['task_name'].split(':')[-1]}), team {info['team']}"
        library = getattr(self.agent, "library", None)
        environments = (
            ""
            if library is None
            else ", library posterior over " + ", ".join(e.name for e in library.environments)
        )
        rerun.log_text(
            "events",
            f"start: robots at {info['state']['agents']}, apple at "
            f"{info['state']['targets']}, {truth}{environments}",
        )
        return {"action": f"{self.agent_name} | step 0", "truth": truth, **self._posterior(rerun)}

    def stepped(self, rerun, record: StepRecord, description: str) -> dict:
        rerun.log_text(
            "observations",
            f"step {record.step}: robots at {record.info['state']['agents']}, "
            f"teammates {record.info['teammate_actions']}",
        )
        return self._posterior(rerun)

    def metrics_step(self, metrics, record: StepRecord) -> None:
        metrics.end_step(
            record.action,
            self.describe(record.observation_index),
            record.reward,
            float(self.clock()),
            record.task_posterior,
            entropy_of(record.task_posterior),
        )
        library = self.library_posterior()
        metrics.per_step[-1].update(
            cells=record.info["state"]["agents"],
            apples_left=int(record.info["remaining"]),
            library_posterior=None if library is None else [round(float(p), 6) for p in library],
        )
