"""The kinematic human teammate: walks the lab's waypoint paths, picks balls up and drops them into the robot.

:class:`HumanWalker` is plain Python (no mujoco): each tick it advances the current command's motion script and
reports the pose of the two mocap bodies of ``assets/props/human.xml`` (body, hand) and grasp events, which
:class:`~embodied_adhoc.sim.lab_world.LabWorld` applies (mocap poses, weld equalities). A carried ball hangs from
the hand through a weld constraint; releasing it over the container lets it fall physically.

Commands (:class:`HumanCommand`): ``stay``; ``move_to(node)`` walks the layout route at ``speed``;
``pick(ball)`` walks to the ball (it must lie in the human's area), kneels, grasps and stands up;
``drop_into_container(ball)`` requires the held ball and the robot in the same area, steps up to the container,
reaches over it, lets go and steps back to the area's human spot.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator
from dataclasses import dataclass

import numpy as np

from embodied_adhoc.control.reference import wrap_angle
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.sim.lab_layout import LabLayout

SHOULDER = np.array([0.0, -0.25, 1.42])  # right shoulder in the body frame (human.xml site "human_shoulder")
ARM_LENGTH = 0.7  # shoulder to palm (human.xml upper arm + forearm)
HAND_REST = np.array([0.1, -0.3, 0.72])  # relaxed hand in the body frame (arm hanging)
GRIP_OFFSET = 0.085  # ball centre beyond the palm along the arm (scene weld relpose)
BALL_RADIUS = 0.06

COMMAND_KINDS = ("stay", "move_to", "pick", "drop_into_container")


@dataclass(frozen=True)
class HumanCommand:
    """What the human does during one macro step: ``kind`` in COMMAND_KINDS, ``target`` a node or ball id."""

    kind: str = "stay"
    target: int | None = None

    def __post_init__(self) -> None:
        if self.kind not in COMMAND_KINDS:
            raise ConfigError(f"HumanCommand.kind must be one of {COMMAND_KINDS}, got {self.kind!r}")
        if (self.kind == "stay") != (self.target is None):
            raise ConfigError(
                f"HumanCommand {self.kind!r}: target must be {'None' if self.kind == 'stay' else 'an int'}"
            )

    @classmethod
    def stay(cls) -> HumanCommand:
        return cls("stay")

    @classmethod
    def move_to(cls, node: int) -> HumanCommand:
        return cls("move_to", int(node))

    @classmethod
    def pick(cls, ball: int) -> HumanCommand:
        return cls("pick", int(ball))

    @classmethod
    def drop_into_container(cls, ball: int) -> HumanCommand:
        return cls("drop_into_container", int(ball))


@dataclass(frozen=True)
class HumanSenses:
    """What the walker needs to know about the world each tick (true state: the human sees the room)."""

    ball_positions: np.ndarray  # (n_balls, 3)
    container_position: np.ndarray  # (3,) centre of the robot's container (rfid site)
    robot_yaw: float
    robot_node: int | None


class HumanWalker:
    """Motion scripts of the human. ``start(command, senses)`` then ``tick(dt, senses)`` until ``finished``."""

    def __init__(self, layout: LabLayout, speed: float = 1.2, turn_rate: float = 6.0):
        if not speed > 0:
            raise ConfigError(f"human speed must be > 0 m/s, got {speed}")
        self.layout = layout
        self.speed = speed
        self.turn_rate = turn_rate
        self.xy = np.zeros(2)
        self.yaw = 0.0
        self.crouch = 0.0  # how far the body is lowered (m): kneeling to pick, bending to drop
        self.hand = HAND_REST.copy()  # hand position in the body frame
        self.node = 0
        self.holding: int | None = None
        self.finished = True
        self.succeeded = True
        self.status = "idle"
        self.events: list[tuple[str, int]] = []
        self._script: Generator[None, None, None] | None = None
        self._dt = 0.0
        self._senses: HumanSenses | None = None

    # ------------------------------------------------------------------------------------------ interface
    def reset(self, node: int, yaw: float = 0.0) -> None:
        self.node = node
        self.xy = np.array(self.layout.human_spots[node], dtype=float)
        self.yaw = yaw
        self.crouch = 0.0
        self.hand = HAND_REST.copy()
        self.holding = None
        self.finished, self.succeeded, self.status = True, True, "idle"
        self._script = None

    def _face_now(self, target_xy) -> None:
        """Turn instantly to face ``target_xy`` (used when placing the human at reset)."""
        self.yaw = math.atan2(target_xy[1] - self.xy[1], target_xy[0] - self.xy[0])

    def start(self, command: HumanCommand, senses: HumanSenses) -> None:
        """Begin ``command``; an impossible command finishes at once with ``succeeded`` False and a reason."""
        self.finished, self.succeeded, self.status = False, True, f"{command.kind} started"
        self._senses = senses
        scripts: dict[str, Callable[[int], Generator[None, None, None]]] = {
            "move_to": self._move_to,
            "pick": self._pick,
            "drop_into_container": self._drop,
        }
        if command.kind == "stay":
            self._finish(True, "stayed")
            return
        self._script = scripts[command.kind](int(command.target))

    def tick(self, dt: float, senses: HumanSenses) -> list[tuple[str, int]]:
        """Advance ``dt`` seconds; returns grasp events [("grasp"|"release", ball)] to apply this tick."""
        self.events = []
        if self.finished or self._script is None:
            return self.events
        self._dt, self._senses = dt, senses
        try:
            next(self._script)
        except StopIteration:
            self._script = None
            if not self.finished:
                self._finish(True, self.status)
        return self.events

    def body_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """World position and quaternion (w, x, y, z) of the ``human`` mocap body."""
        position = np.array([self.xy[0], self.xy[1], -self.crouch])
        return position, np.array([math.cos(self.yaw / 2), 0.0, 0.0, math.sin(self.yaw / 2)])

    def hand_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """World position and quaternion of the ``human_hand`` mocap body (its z axis points to the shoulder)."""
        hand = self._to_world(self.hand)
        axis = self._to_world(SHOULDER) - hand
        axis /= max(np.linalg.norm(axis), 1e-9)
        return hand, _quat_z_to(axis)

    # ------------------------------------------------------------------------------------------ helpers
    def _finish(self, succeeded: bool, status: str) -> None:
        self.finished, self.succeeded, self.status = True, succeeded, status

    def _to_world(self, local: np.ndarray) -> np.ndarray:
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return np.array(
            [
                self.xy[0] + c * local[0] - s * local[1],
                self.xy[1] + s * local[0] + c * local[1],
                local[2] - self.crouch,
            ]
        )

    def _to_body(self, world: np.ndarray) -> np.ndarray:
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        dx, dy = world[0] - self.xy[0], world[1] - self.xy[1]
        return np.array([c * dx + s * dy, -s * dx + c * dy, world[2] + self.crouch])

    def _walk(self, points: list[np.ndarray]) -> Generator[None, None, None]:
        """Walk through ``points`` at ``speed``; distance left over at a waypoint carries on to the next one, so
        a route takes exactly its length / speed (to one tick)."""
        targets = [np.asarray(p, dtype=float) for p in points]
        while targets:
            budget = self.speed * self._dt
            direction = targets[0] - self.xy
            while targets and budget > 0.0:
                offset = targets[0] - self.xy
                distance = float(np.linalg.norm(offset))
                if distance <= budget:
                    self.xy = targets.pop(0).copy()
                    budget -= distance
                else:
                    self.xy = self.xy + offset / distance * budget
                    budget = 0.0
                if distance > 1e-9:
                    direction = offset
            if np.any(direction):
                heading = math.atan2(direction[1], direction[0])
                limit = self.turn_rate * self._dt
                self.yaw = wrap_angle(
                    self.yaw + float(np.clip(wrap_angle(heading - self.yaw), -limit, limit))
                )
            yield

    def _face(self, target_xy: np.ndarray) -> Generator[None, None, None]:
        heading = math.atan2(target_xy[1] - self.xy[1], target_xy[0] - self.xy[0])
        while abs(wrap_angle(heading - self.yaw)) > 1e-3:
            turn = wrap_angle(heading - self.yaw)
            self.yaw = wrap_angle(
                self.yaw + float(np.clip(turn, -self.turn_rate * self._dt, self.turn_rate * self._dt))
            )
            yield

    def _reach(self, ball_target: np.ndarray | None, duration: float) -> Generator[None, None, None]:
        """Move the hand (and lower the body as needed) so a gripped ball would sit at ``ball_target`` (world);
        ``None`` returns to the relaxed standing pose."""
        start_hand, start_crouch = self.hand.copy(), self.crouch
        if ball_target is None:
            goal_hand, goal_crouch = HAND_REST.copy(), 0.0
        else:
            shoulder = self._to_world(SHOULDER) + np.array([0.0, 0.0, self.crouch])  # standing shoulder
            horizontal = float(np.hypot(*(shoulder[:2] - ball_target[:2])))
            reach = ARM_LENGTH + GRIP_OFFSET
            height = math.sqrt(max(reach**2 - horizontal**2, 0.01))
            goal_crouch = max(0.0, SHOULDER[2] - (ball_target[2] + height))
            shoulder[2] -= goal_crouch
            along = shoulder - ball_target
            hand_world = ball_target + GRIP_OFFSET * along / np.linalg.norm(along)
            goal_hand = self._to_body(hand_world)
            goal_hand[2] = hand_world[2] + goal_crouch  # body frame of the lowered body
        steps = max(1, int(round(duration / max(self._dt, 1e-9))))
        for k in range(1, steps + 1):
            alpha = 0.5 - 0.5 * math.cos(math.pi * k / steps)  # smooth in and out
            self.hand = (1 - alpha) * start_hand + alpha * goal_hand
            self.crouch = (1 - alpha) * start_crouch + alpha * goal_crouch
            yield

    def _wait(self, duration: float) -> Generator[None, None, None]:
        elapsed = 0.0
        while elapsed < duration:
            elapsed += self._dt
            yield

    # ------------------------------------------------------------------------------------------ scripts
    def _move_to(self, node: int) -> Generator[None, None, None]:
        route = self.layout.route(self.node, node, spots="human") or [self.layout.human_spots[node]]
        yield from self._walk([np.asarray(p, dtype=float) for p in route])
        self.node = node
        self.status = f"arrived at node {node}"

    def _pick(self, ball: int) -> Generator[None, None, None]:
        if self.holding is not None:
            self._finish(False, f"already holding ball {self.holding}")
            return
        ball_position = self._senses.ball_positions[ball]
        if self.layout.node_at(ball_position[:2]) != self.node:
            self._finish(False, f"ball {ball} is not in the human's area (node {self.node})")
            return
        # stand so that the ball lies ahead and to the right, under the right hand
        approach = ball_position[:2] - self.xy
        approach /= max(np.linalg.norm(approach), 1e-9)
        right = np.array([approach[1], -approach[0]])
        stand = ball_position[:2] - 0.35 * approach - 0.25 * right
        yield from self._walk([stand])
        yield from self._face(stand + approach)
        yield from self._reach(self._senses.ball_positions[ball].copy(), 0.8)
        self.events.append(("grasp", ball))
        self.holding = ball
        yield from self._wait(0.2)
        yield from self._reach(None, 0.8)
        yield from self._walk([np.asarray(self.layout.human_spots[self.node], dtype=float)])
        self.status = f"picked ball {ball}"

    def _drop(self, ball: int) -> Generator[None, None, None]:
        if self.holding != ball:
            self._finish(False, f"not holding ball {ball} (holding {self.holding})")
            return
        if self._senses.robot_node != self.node:
            self._finish(
                False, f"robot not co-located (robot node {self._senses.robot_node}, human {self.node})"
            )
            return
        container = self._senses.container_position
        yaw = self._senses.robot_yaw
        sides = [np.array([math.cos(yaw + a), math.sin(yaw + a)]) for a in (0.0, math.pi / 2, -math.pi / 2)]
        stands = [container[:2] + 0.5 * side for side in sides]
        stand = min(stands, key=lambda p: float(np.linalg.norm(p - self.xy)))
        yield from self._walk([stand])
        yield from self._face(container[:2] + 0.15 * (container[:2] - stand))
        container = self._senses.container_position  # the robot may have moved meanwhile
        yield from self._reach(container + np.array([0.0, 0.0, 0.22]), 0.8)
        hand_gap = float(np.hypot(*(self._to_world(self.hand)[:2] - self._senses.container_position[:2])))
        if self._senses.robot_node != self.node or hand_gap > 0.12:
            yield from self._reach(None, 0.6)
            self._finish(False, f"the robot left before ball {ball} could be dropped")
            return
        self.events.append(("release", ball))
        self.holding = None
        yield from self._wait(0.5)
        yield from self._reach(None, 0.6)
        yield from self._walk([np.asarray(self.layout.human_spots[self.node], dtype=float)])
        self.status = f"dropped ball {ball} into the container"


def _quat_z_to(axis: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) rotating the z axis onto unit vector ``axis`` (the half-way quaternion)."""
    ax, ay, az = float(axis[0]), float(axis[1]), float(axis[2])
    if az < -0.999999:
        return np.array([0.0, 1.0, 0.0, 0.0])
    w = 1.0 + az  # z . axis; the vector part is z x axis = (-ay, ax, 0)
    norm = math.sqrt(w * w + ax * ax + ay * ay)
    return np.array([w / norm, -ay / norm, ax / norm, 0.0])
