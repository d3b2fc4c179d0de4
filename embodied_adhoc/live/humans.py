"""Who moves the human in the real-time lab (``live.realtime.RealtimeToxicWasteEnv``), tick by tick.

* :class:`ScriptedHuman` — the lab's scripted cleaner (``domains.lab_human.LabHuman``), run asynchronously: it
  decides its next command whenever the previous one is done (a "stay" lasts ``pause`` seconds), as the physics
  lab's human does (``sim.lab_human_mind.HumanMind``: its policy on the room as it is then, the hand-over when
  the robot's current macro action stays or asks), and answers "Where are you?" at once through the env's speech
  channel.
* :class:`Participant` — a person in the browser: held direction keys walk the human continuously
  (``speed`` m/s, kept inside the lab's areas and passages by :func:`walkable`), one key picks up the nearest ball
  in the area or drops the held one into the robot's container (the walker's own pick/drop motion scripts), and
  replies come typed or spoken (recognised off the simulation thread). Inputs arrive from other threads through a
  queue and are applied at the start of a tick, so the simulation thread alone touches the world.

A driver implements ``reset(env)``, ``tick(env, dt)`` (before the physics of a control tick), ``ask(env, node)``
(the robot asked; ``node`` is the human's true area) and ``reply(env) -> Reply | None`` (polled each tick).
"""

from __future__ import annotations

import math
import queue
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from embodied_adhoc.comms.robot_speech import WHERE_ARE_YOU
from embodied_adhoc.comms.vocabulary import NODE_NAMES
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.sim.human import HumanCommand
from embodied_adhoc.sim.lab_human_mind import HumanMind
from embodied_adhoc.sim.lab_layout import LabLayout

__all__ = ["DIRECTIONS", "Participant", "Reply", "ScriptedHuman", "heard_line", "walkable"]

DIRECTIONS = {"up": (0.0, 1.0), "down": (0.0, -1.0), "left": (-1.0, 0.0), "right": (1.0, 0.0)}
"""Direction keys in the overhead view: up is north (+y), right is east (+x)."""

WALL_MARGIN = 0.25  # m the human's centre keeps from a wall (its shoulders are ~0.25 m from the centre)
REACH = 1.5  # m within which the participant's pick key takes a ball lying in the same area
ROBOT_CLEARANCE = 0.55  # m between the walker's and the robot's centres (chassis half-length + shoulders)


@dataclass(frozen=True)
class Reply:
    """The robot's perception of one answer to "Where are you?": the node heard (None: no location), the lines
    of dialogue for the recording, and the reply's audio as WAV bytes (spoken replies only)."""

    node: int | None
    lines: tuple[str, ...]
    audio_wav: bytes | None = None


def heard_line(node: int | None, how: str) -> str:
    heard = "no location" if node is None else f"{node} {NODE_NAMES[node]}"
    return f"heard node: {heard} ({how})"


def walkable(layout: LabLayout, xy, margin: float = WALL_MARGIN) -> bool:
    """Whether a person can stand at ``xy``: inside an area at least ``margin`` from its borders (every border
    of the lab's areas is a wall), or inside the corridor of a passage (``passage_offset`` either side of its
    wall, ``width / 2 - margin`` along it). Furniture is not an obstacle here (the workbenches sit on the walls)."""
    x, y = float(xy[0]), float(xy[1])
    node = layout.node_at((x, y))
    if node is None:
        return False
    polygon = np.asarray(layout.area_polygons[node], dtype=float)
    starts, ends = polygon, np.roll(polygon, -1, axis=0)
    edge = ends - starts
    t = np.clip(
        ((x - starts[:, 0]) * edge[:, 0] + (y - starts[:, 1]) * edge[:, 1]) / (edge**2).sum(axis=1), 0, 1
    )
    distance = np.hypot(starts[:, 0] + t * edge[:, 0] - x, starts[:, 1] + t * edge[:, 1] - y)
    if float(distance.min()) >= margin:
        return True
    for passage in layout.passages:
        if node not in passage.nodes:
            continue
        dx, dy = x - passage.midpoint[0], y - passage.midpoint[1]
        across = dx * passage.normal[0] + dy * passage.normal[1]
        along = -dx * passage.normal[1] + dy * passage.normal[0]
        if abs(across) <= layout.passage_offset and abs(along) <= passage.width / 2 - margin:
            return True
    return False


def _towards_passage(layout: LabLayout, xy, step: np.ndarray, reach: float = 0.6) -> np.ndarray:
    """A walker pushing into a wall near a passage slides along the wall towards the passage's centre line (as
    games do at doorways), so a person need not line up with the 1.2 m gap by hand. Zero when no passage is
    within ``reach`` of the gap or the step does not point through the wall."""
    length = float(np.hypot(*step))
    for passage in layout.passages:
        normal = np.asarray(passage.normal, dtype=float)
        offset = np.asarray(xy, dtype=float) - passage.midpoint
        across, along = float(offset @ normal), float(offset @ [-normal[1], normal[0]])
        heading = float(step @ normal) / length
        if abs(across) > layout.passage_offset or abs(heading) < 0.5 or across * heading > 0:
            continue  # too far from the wall, walking along it, or already through
        if 1e-9 < abs(along) <= passage.width / 2 + reach:
            return -np.sign(along) * min(length, abs(along)) * np.array([-normal[1], normal[0]])
    return np.zeros(2)


class ScriptedHuman:
    """The lab's scripted human, deciding asynchronously (see the module docstring)."""

    def __init__(self, pause: float = 1.0):
        if not pause > 0:
            raise ConfigError(f"ScriptedHuman pause must be > 0 s, got {pause}")
        self.pause = float(pause)
        self._busy_until = 0.0
        self._reply: Reply | None = None

    def reset(self, env) -> None:
        self._busy_until = env.world.data.time
        self._reply = None

    def tick(self, env, dt: float) -> None:
        world = env.world
        if world.human.finished and world.data.time >= self._busy_until - 1e-9:
            command = self._decide(env)
            world.human.start(command, world.senses())
            if command.kind == "stay":
                self._busy_until = world.data.time + self.pause
        env.tick_walker(dt)

    def _decide(self, env) -> HumanCommand:
        """The next command from the room now, as the physics lab's human decides it per macro step."""
        world, library = env.world, env.library
        mind = HumanMind(library.humans[env.task_index], env.human_rng, world.layout)
        # the hand-over needs the robot to stay or ask; between two decisions it does neither
        action = env.current_action
        return mind.decide(
            world.ground_truth(), robot_stays=action is not None and action >= library.stay_action
        )

    def ask(self, env, true_node: int) -> None:
        node, lines, wav = env.speech.ask(true_node, env.speech_rng)
        self._reply = Reply(node, tuple(lines), wav)

    def reply(self, env) -> Reply | None:
        reply, self._reply = self._reply, None
        return reply


@dataclass
class InputLog:
    """What the participant did, for the study log (``inputs.jsonl``) and the latency figures."""

    entries: list[dict] = field(default_factory=list)
    motion_latency_s: list[float] = field(
        default_factory=list
    )  # key change received -> first tick that moved


class Participant:
    """A person driving the human (see the module docstring). Thread-safe entry points: :meth:`keys`,
    :meth:`act`, :meth:`answer`; everything else runs on the simulation thread."""

    def __init__(self, speed: float = 1.2, turn_rate: float = 8.0):
        if not speed > 0:
            raise ConfigError(f"Participant speed must be > 0 m/s, got {speed}")
        self.speed, self.turn_rate = float(speed), float(turn_rate)
        self._inputs: queue.SimpleQueue = queue.SimpleQueue()
        self.held: frozenset[str] = frozenset()
        self.question_open = False
        self.notice = ""  # last message for the page (why a key did nothing)
        self.log = InputLog()
        self.last_seq = (
            0  # sequence number of the last input applied (the page matches it to its key presses)
        )
        self._pending_motion: tuple[int, float] | None = None  # (seq, wall time received) of a key change
        self._reply: Reply | None = None
        self._motion: tuple[str, int] | None = None  # the pick or drop under way: (kind, ball)
        self.on_event: Callable[[dict], None] | None = None  # question asked, pick/drop outcome (sim thread)

    # ---------------------------------------------------------------- other threads
    def keys(self, held, seq: int) -> None:
        """The set of direction keys now held (a subset of :data:`DIRECTIONS`)."""
        unknown = set(held) - set(DIRECTIONS)
        if unknown:
            raise ConfigError(f"unknown direction key(s) {sorted(unknown)}; use {sorted(DIRECTIONS)}")
        self._inputs.put(("keys", frozenset(held), int(seq), time.perf_counter()))

    def act(self, seq: int) -> None:
        """The pick-up/drop key."""
        self._inputs.put(("act", None, int(seq), time.perf_counter()))

    def answer(self, reply: Reply, seq: int, detail: dict) -> None:
        """A reply to the open question, already recognised and parsed (``detail`` goes to the input log)."""
        self._inputs.put(("reply", (reply, detail), int(seq), time.perf_counter()))

    # ---------------------------------------------------------------- simulation thread
    def reset(self, env) -> None:
        self.held, self.question_open, self._reply, self._motion = frozenset(), False, None, None

    def tick(self, env, dt: float) -> None:
        while True:
            try:
                kind, value, seq, received = self._inputs.get_nowait()
            except queue.Empty:
                break
            self._apply(env, kind, value, seq, received)
        walker = env.world.human
        if not walker.finished:  # a pick or drop motion script is playing: keys wait for it
            env.tick_walker(dt)
            if self._motion is not None and self._motion_done(walker):
                # the outcome counts when the ball changes hands, not when the walker has stepped back: the
                # last drop ends the episode before that
                kind, ball = self._motion
                self._report(env, walker, f"{'picked' if kind == 'pick' else 'dropped'} ball {ball}", True)
            if walker.finished:
                self.notice = walker.status  # "picked ball 2", or why a drop failed
                if self._motion is not None:
                    self._report(env, walker, walker.status, bool(walker.succeeded))
            return
        direction = np.zeros(2)
        for key in self.held:
            direction += DIRECTIONS[key]
        norm = float(np.hypot(*direction))
        if norm == 0:
            return
        step = direction / norm * self.speed * dt
        moved = False
        moves = (
            step,
            np.array([step[0], 0.0]),
            np.array([0.0, step[1]]),
            _towards_passage(env.layout, walker.xy, step),
        )
        robot = np.asarray(env.world.true_robot_pose()[:2])
        for move in moves:  # straight, else slide along the wall, else towards a nearby passage
            if np.any(move) and walkable(env.layout, walker.xy + move) and _clear_of(robot, walker.xy, move):
                walker.xy = walker.xy + move
                moved = True
                break
        heading = math.atan2(direction[1], direction[0])
        turn = (heading - walker.yaw + math.pi) % (2 * math.pi) - math.pi
        limit = self.turn_rate * dt
        walker.yaw = walker.yaw + max(-limit, min(limit, turn))
        node = env.layout.node_at(walker.xy)
        if node is not None:
            walker.node = node
        env.world.apply_human()
        if moved and self._pending_motion is not None:
            self.log.motion_latency_s.append(time.perf_counter() - self._pending_motion[1])
            self._pending_motion = None

    def _motion_done(self, walker) -> bool:
        kind, ball = self._motion
        return walker.holding == ball if kind == "pick" else walker.holding is None

    def _report(self, env, walker, result: str, succeeded: bool) -> None:
        """The outcome of a pick or drop motion, for the log and the page (once per motion)."""
        kind, ball = self._motion
        self._motion = None
        entry = _entry(env, kind, ball=ball, result=result, succeeded=succeeded)
        self.log.entries.append(entry)
        if self.on_event is not None:
            self.on_event(entry)

    def _apply(self, env, kind: str, value, seq: int, received: float) -> None:
        self.last_seq = max(self.last_seq, seq)
        entry = _entry(env, kind, seq=seq)
        if kind == "keys":
            if value - self.held:
                self._pending_motion = (seq, received)
            self.held = value
            entry["held"] = sorted(value)
        elif kind == "act":
            entry["result"] = self._pick_or_drop(env)
        elif kind == "reply":
            reply, detail = value
            entry.update(detail)
            if self.question_open:
                self._reply, self.question_open = reply, False
                entry["result"] = "answered"
            else:
                entry["result"] = "ignored: no open question"
                self.notice = "the robot has not asked anything"
        self.log.entries.append(entry)

    def _pick_or_drop(self, env) -> str:
        world = env.world
        walker = world.human
        if not walker.finished:
            return self._say("busy: finishing the current motion")
        truth = world.ground_truth()
        if walker.holding is not None:
            robot_node = env.true_robot_node(truth)
            if robot_node != walker.node:
                return self._say("the robot must be in your area to drop the ball into its container")
            self._motion = ("drop", walker.holding)
            walker.start(HumanCommand.drop_into_container(walker.holding), world.senses())
            return self._say(f"dropping ball {walker.holding}")
        candidates = [
            (float(np.hypot(p[0] - walker.xy[0], p[1] - walker.xy[1])), ball)
            for ball, (p, state) in enumerate(zip(truth.ball_positions, truth.ball_states, strict=True))
            if state == "ground" and env.layout.node_at(p[:2]) == walker.node
        ]
        if not candidates or min(candidates)[0] > REACH:
            return self._say(f"no ball on the floor within {REACH} m in your area")
        ball = min(candidates)[1]
        self._motion = ("pick", ball)
        walker.start(HumanCommand.pick(ball), world.senses())
        return self._say(f"picking up ball {ball}")

    def _say(self, notice: str) -> str:
        self.notice = notice
        return notice

    def ask(self, env, true_node: int) -> None:
        self.question_open, self._reply = True, None
        entry = _entry(env, "question", text=WHERE_ARE_YOU)
        self.log.entries.append(entry)
        if self.on_event is not None:
            self.on_event(entry)

    def reply(self, env) -> Reply | None:
        reply, self._reply = self._reply, None
        return reply

    def close_question(self) -> None:
        """The robot stopped waiting (timeout): a late answer is ignored."""
        self.question_open = False

    def note(self, env, kind: str, **detail) -> None:
        """An event of the session (a page connected or left) in the input log, at the simulation's time."""
        self.log.entries.append(_entry(env, kind, **detail))


def _entry(env, kind: str, **detail) -> dict:
    """One input-log entry: what happened, at which simulated and wall-clock (Unix, UTC) time."""
    return {
        "kind": kind,
        "sim_time": round(float(env.world.data.time), 3),
        "wall_time": round(time.time(), 3),
        **detail,
    }


def _clear_of(robot: np.ndarray, xy: np.ndarray, move: np.ndarray) -> bool:
    """The walker stops at the robot's footprint: a step may not end within ``ROBOT_CLEARANCE`` of the robot's
    centre unless it leads away from it (so a walker the robot drove up to can always step back)."""
    after = float(np.hypot(*(xy + move - robot)))
    return after >= ROBOT_CLEARANCE or after > float(np.hypot(*(xy - robot)))
