"""``EmbodiedAdhoc/ToxicWaste-v0``: the HOTSPOT toxic-waste lab on MuJoCo physics (thesis section 7.1)."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence

import gymnasium
import numpy as np
from gymnasium import spaces

from embodied_adhoc.domains.confusion import DEFAULT_CONFUSION
from embodied_adhoc.domains.lab import DEFAULT_TASKS, LabObservation, build_lab_library
from embodied_adhoc.domains.lab_graph import DISPOSED, GROUND, HELD
from embodied_adhoc.envs.toxic_waste_speech import SPEECH_KINDS, SpeechTurn, make_speech
from embodied_adhoc.errors import ConfigError

__all__ = ["ToxicWasteEnv"]

BALL_STATUS = {"ground": GROUND, "held": HELD, "container": DISPOSED}
FrameSink = Callable[[np.ndarray, dict], None]


class ToxicWasteEnv(gymnasium.Env):
    """A wheeled container robot helps a scripted human put three toxic-waste balls into its container.

    ## Description
    The MuJoCo lab (``scenes/lab.xml``, 10 m x 8 m; ``sim.lab_world.LabWorld``) has five areas: 0 door, 1 open
    space, 2 robot station, 3 single workbench, 4 double workbench, joined by passages 0-1, 1-2, 1-3, 3-4. A task
    places the three balls (default library: nodes [0, 1, 2] and [1, 2, 3]). The human knows the task and follows
    ``teammates.lab_human.LabHuman`` (nearest ball on the ground, pick it up, wait holding it until the robot is in
    the same area and stays or asks; with probability ``human_epsilon`` a move or pick fails). The robot knows
    neither the task nor where the human is: it perceives its wheel-odometry area, the human's spoken reply and
    its container's RFID reader. It is the embodied twin of ``EmbodiedAdhoc/ToxicWasteAbstract-v0``: same actions,
    same observation semantics and encoding, same reward, same ``reset`` options, so an agent (and the trial
    runner) works unchanged in both.

    Each ``step`` is one macro step, turn-based as in the thesis: the human's command is decided from the true
    state at the start of the step, then the robot's waypoint controller (tracking its odometry estimate, not
    ground truth) and the human's motion script run together in physics until both are done (or
    ``macro_timeout`` simulated seconds). The physics step and the env step are synchronous and deterministic: the
    same ``reset(seed=...)`` and actions give the same trajectory.

    ## Action space
    ``Discrete(5)`` (``Discrete(4)`` with ``communication=False``):

    | action | meaning |
    |---|---|
    | 0, 1, 2 | drive to the 1st / 2nd / 3rd lowest-index neighbour of the robot's odometry area (beyond the degree: the lowest) |
    | 3 | stay (the human, if holding a ball in the robot's area, drops it into the container) |
    | 4 | locate human: ask "Where are you?" and hear the reply (also lets the human drop); absent without communication |

    ## Observation space
    ``MultiDiscrete([6, 6, 2])`` = ``[robot node, human node, rfid]`` with 5 = unknown/none, exactly the encoding
    of ``domains.lab_observations.LabObservation``; ``info["observation_index"]`` is its flat index.

    | element | value |
    |---|---|
    | robot node | area containing the wheel-odometry (dead-reckoning) pose; 5 if outside every area |
    | human node | after "locate human": the node recognised from the human's reply through ``speech`` (5 = no location); without communication: the robot's true area when the human is in it; else 5 |
    | rfid | 1 if the container's reader read a ball entering during this step (missed w.p. ``rfid_miss``) |

    ## Rewards
    From the state before the step (``domains.lab.LabReward``): -1 per ball on the ground, -2 per ball held,
    0 per ball in the container.

    ## Episode end
    Terminated when all balls are in the container (physically: inside the RFID site). Truncated after
    ``max_episode_steps`` macro steps (default 100, the thesis's cap).

    ## Arguments (``gymnasium.make`` kwargs)
    | kwarg | default | meaning |
    |---|---|---|
    | ``task`` | None | fixed task index; None = drawn uniformly at each reset |
    | ``tasks`` | [[0,1,2],[1,2,3]] | task library (ball nodes per task) |
    | ``human_epsilon`` | 0.05 | probability that a human move or pick fails |
    | ``communication`` | True | False: no "locate human"; the human is seen only when co-located |
    | ``speech`` | "channel" | "channel" (sample the confusion matrix), "audio" (espeak-ng + pocketsphinx on every query), "perfect" |
    | ``confusion`` | "measured" | confusion matrix of "channel": "thesis", "measured" or a JSON path (also the agents' model) |
    | ``encoder_noise``, ``wheel_slip`` | None | odometry error model (None = ``sim.odometry.OdometryConfig`` defaults) |
    | ``rfid_miss`` | 0.0 | probability that the reader misses a ball entering the container |
    | ``macro_timeout`` | 60.0 | simulated seconds after which an unfinished macro step ends |
    | ``max_episode_steps`` | 100 | truncation |
    | ``render_mode`` | None | "rgb_array": ``render()`` returns the overhead camera image |
    | ``width``, ``height`` | 640, 480 | image size of ``render()`` and of recorded frames |
    | ``render_quality`` | "fast" | "fast" (no shadows, reflections or floor texture: several times faster on CPU) or "high" |
    | ``frame_rate`` | 15.0 | frames per *simulated* second passed to the frame sink (see ``set_frame_sink``) |

    ``reset(seed=..., options={"task": k, "robot_node": i, "human_node": j})`` fixes the episode's start (default:
    task and nodes drawn uniformly, as the abstract env; all balls on the ground).

    ## Info (ground truth, for evaluation and recording only; agents never read it)
    ``state`` (index in the library's shared state space; -1 if physics reached a state outside the model),
    ``observation_index``, ``task``, ``robot_node``/``human_node`` (true areas), ``ball_status`` (0 ground,
    1 held, 2 container), ``rfid_event`` (a ball truly entered the container), ``robot_pose`` and
    ``odometry_pose`` (x, y, yaw), ``odometry_error`` (m), ``human_position``, ``ball_positions``, ``sim_time``
    (s), ``macro_seconds``, ``robot_arrived``, ``timed_out``, ``wall_contact``, ``human_status``,
    ``utterances`` (lines of dialogue this step), ``speech_audio`` (WAV bytes, ``speech="audio"`` only).

    ## Version history
    v0: first version.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 15}

    def __init__(
        self,
        task: int | None = None,
        tasks: Sequence[Sequence[int]] = DEFAULT_TASKS,
        human_epsilon: float = 0.05,
        communication: bool = True,
        speech: str = "channel",
        confusion: str | os.PathLike = DEFAULT_CONFUSION,
        encoder_noise: float | None = None,
        wheel_slip: float | None = None,
        rfid_miss: float = 0.0,
        macro_timeout: float = 60.0,
        max_episode_steps: int = 100,
        render_mode: str | None = None,
        width: int = 640,
        height: int = 480,
        render_quality: str = "fast",
        frame_rate: float = 15.0,
    ) -> None:
        from embodied_adhoc.envs.toxic_waste_world import make_world

        if render_mode not in (None, "rgb_array"):
            raise ConfigError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if speech not in SPEECH_KINDS:
            raise ConfigError(f"speech={speech!r} unknown; use one of {', '.join(SPEECH_KINDS)}")
        if int(max_episode_steps) < 1:
            raise ConfigError(f"max_episode_steps must be >= 1, got {max_episode_steps}")
        self.library = build_lab_library(
            tasks=tasks,
            human_epsilon=human_epsilon,
            communication=communication,
            confusion=confusion,
            rfid_miss=rfid_miss,
        )
        if task is not None and not 0 <= int(task) < self.library.n_tasks:
            raise ConfigError(f"task={task} outside the task library 0..{self.library.n_tasks - 1}")
        self.task, self.render_mode = task, render_mode
        self.max_episode_steps = int(max_episode_steps)
        self.width, self.height, self.render_quality = int(width), int(height), render_quality
        self.world = make_world(
            encoder_noise, wheel_slip, rfid_miss, macro_timeout, frame_rate, width, height, render_quality
        )
        self.layout = self.world.layout
        if (
            self.layout.edges != self.library.graph.edges
            or len(self.layout.nodes) != self.library.graph.n_nodes
        ):
            raise ConfigError(
                "the MuJoCo lab layout and the lab model's graph differ; they must be the same map"
            )
        self.speech: SpeechTurn | None = make_speech(speech, confusion) if communication else None
        n = self.library.graph.n_nodes
        self.action_space = spaces.Discrete(self.library.n_actions)
        self.observation_space = spaces.MultiDiscrete([n + 1, n + 1, 2])
        self._frame_sink: FrameSink | None = None
        self._task = self._steps = 0
        self._status: tuple[int, ...] = ()
        self._robot_believed_node = 0
        self._step_index = 0

    # ----------------------------------------------------------------------------------------------- API
    def set_frame_sink(self, sink: FrameSink | None) -> None:
        """Receive ``(overhead_rgb, snapshot)`` ``frame_rate`` times per simulated second during every step.

        ``snapshot`` has ``step``, ``sim_time``, ``robot_pose``, ``odometry_pose``, ``human_position``,
        ``ball_positions``. Used by ``embodied-adhoc run --record`` for the video and the rerun recording.
        """
        self._frame_sink = sink

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        lib = self.library
        self._task, robot, human = lib.episode_start(options, self.task, self.np_random)
        world_seed, human_seed, speech_seed = self.np_random.integers(0, 2**63 - 1, size=3)
        self._human_rng = np.random.default_rng(int(human_seed))
        self._speech_rng = np.random.default_rng(int(speech_seed))
        self._status = (GROUND,) * len(lib.tasks[self._task])
        self._steps = self._step_index = 0
        self._robot_believed_node = robot
        truth = self.world.reset(int(world_seed), robot, human, lib.tasks[self._task])
        observation = self._observation(
            self.world.odometry_node(), truth.robot_node, truth.human_node, None, False
        )
        return observation.to_vector(), self._info(observation, truth, False, None, [], None)

    def step(self, action):
        from embodied_adhoc.sim.human import HumanCommand

        if (
            not self._status
            or self._steps >= self.max_episode_steps
            or all(s == DISPOSED for s in self._status)
        ):
            raise ConfigError("step() called on a finished episode; call reset() first")
        if not self.action_space.contains(np.int64(action)):
            raise ConfigError(f"action {action!r} outside 0..{self.library.n_actions - 1}")
        action, lib = int(action), self.library
        reward = float(lib.config.reward.of(np.array(self._status)))
        before = self.world.ground_truth()
        robot_node = _area(self.layout, before.robot_pose, before.robot_node)
        if HELD in self._status:
            # The hand-over of domains.lab.apply_step: robot in the human's area, and it stays or asks.
            handover = robot_node == before.human_node and action >= lib.stay_action
            command = (
                HumanCommand.drop_into_container(self._status.index(HELD))
                if handover
                else HumanCommand.stay()
            )
        else:
            outcome = lib.humans[self._task].step(self._human_rng, before.human_node, self._status)
            if outcome.picked_ball >= 0:
                command = HumanCommand.pick(outcome.picked_ball)
            elif outcome.next_node != before.human_node:
                command = HumanCommand.move_to(outcome.next_node)
            else:
                command = HumanCommand.stay()
        target = self.move_target(action)
        self._step_index += 1
        result = self.world.step_macro(target, command, self._on_frame if self._frame_sink else None)
        truth = self.world.ground_truth()
        if result.odometry_node is not None:
            self._robot_believed_node = result.odometry_node
        elif target is not None:
            self._robot_believed_node = target
        previous = self._status
        self._status = tuple(BALL_STATUS[s] for s in truth.ball_states)
        entered = any(a != DISPOSED and b == DISPOSED for a, b in zip(previous, self._status, strict=True))
        utterances: list[str] = []
        heard: int | None = None
        speech_audio = None
        if self.speech is not None and action == lib.locate_action:
            heard, utterances, speech_audio = self.speech.ask(truth.human_node, self._speech_rng)
        observation = self._observation(
            result.odometry_node, truth.robot_node, truth.human_node, heard, bool(result.rfid_events), action
        )
        self._steps += 1
        terminated = all(s == DISPOSED for s in self._status)
        truncated = not terminated and self._steps >= self.max_episode_steps
        info = self._info(observation, truth, entered, result, utterances, speech_audio)
        info["human_command"] = f"{command.kind}" + ("" if command.target is None else f" {command.target}")
        return observation.to_vector(), reward, terminated, truncated, info

    def move_target(self, action: int) -> int | None:
        """The node ``action`` drives to if taken now: that neighbour of the robot's believed (odometry) node,
        exactly as ``step`` maps it (a k beyond the degree: the lowest); None for "stay" and "locate human"."""
        lib = self.library
        if int(action) >= lib.stay_action:
            return None
        return lib.graph.move_target(self._robot_believed_node, int(action))

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        return self.render_camera()

    def close(self) -> None:
        self.world.close()

    # ----------------------------------------------------------------------------------------- internals
    def _observation(self, odometry_node, true_robot, true_human, heard, rfid, action=None) -> LabObservation:
        n = self.library.graph.n_nodes
        if self.speech is not None:
            human = heard if action == self.library.locate_action else None
        else:
            human = true_human if true_robot is not None and true_robot == true_human else None
        return LabObservation(odometry_node, human, bool(rfid), n)

    def _info(self, observation, truth, entered, result, utterances, speech_audio) -> dict:
        robot_node = _area(self.layout, truth.robot_pose, truth.robot_node)
        states = self.library.states
        state = states.fast_index(robot_node, truth.human_node, self._status, entered)
        if state < 0 and entered:
            state = states.fast_index(robot_node, truth.human_node, self._status, False)
        odometry_pose = self.world.odometry_pose()
        return {
            "state": int(state),
            "observation_index": observation.encode(),
            "task": self._task,
            "robot_node": robot_node,
            "human_node": truth.human_node,
            "ball_status": self._status,
            "rfid_event": bool(entered),
            "robot_pose": truth.robot_pose,
            "odometry_pose": odometry_pose,
            "odometry_error": float(
                np.hypot(odometry_pose[0] - truth.robot_pose[0], odometry_pose[1] - truth.robot_pose[1])
            ),
            "human_position": truth.human_pose[:2],
            "ball_positions": np.array(truth.ball_positions),
            "sim_time": truth.time,
            "macro_seconds": 0.0 if result is None else result.sim_seconds,
            "robot_arrived": True if result is None else result.robot_arrived,
            "timed_out": False if result is None else result.timed_out,
            "wall_contact": False if result is None else result.wall_contact,
            "human_status": "" if result is None else result.human_status,
            "utterances": tuple(utterances),
            "speech_audio": speech_audio,
        }

    def render_camera(self, camera: str = "overhead") -> np.ndarray:
        """An RGB image from a named camera of the lab ("overhead", "perspective", "robot") at the env's size."""
        return self.world.render(camera, self.width, self.height)

    def _on_frame(self, world) -> None:
        truth = world.ground_truth()
        snapshot = {
            "step": self._step_index,
            "sim_time": truth.time,
            "robot_pose": truth.robot_pose,
            "odometry_pose": world.odometry_pose(),
            "human_position": truth.human_pose[:2],
            "ball_positions": np.array(truth.ball_positions),
        }
        self._frame_sink(self.render_camera(), snapshot)


def _area(layout, pose, node: int | None) -> int:
    """The true area of a pose; on a border outside every polygon, the nearest node waypoint."""
    return int(node) if node is not None else layout.nearest_node(pose[:2])
