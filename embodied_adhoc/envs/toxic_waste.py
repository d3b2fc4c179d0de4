"""``EmbodiedAdhoc/ToxicWaste-v0``: the HOTSPOT toxic-waste lab on MuJoCo physics (thesis section 7.1)."""

from __future__ import annotations

from collections.abc import Callable

import gymnasium
import numpy as np
from gymnasium import spaces

from embodied_adhoc import checks
from embodied_adhoc.domains.lab import LAB_PARAMETERS, LabConfig, LabObservation, library_from_config
from embodied_adhoc.domains.lab_graph import DEFAULT_GRAPH, DISPOSED, GROUND
from embodied_adhoc.envs import contract
from embodied_adhoc.envs.toxic_waste_speech import SPEECH_KINDS, SpeechTurn, make_speech
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.sim.lab_human_mind import BALL_STATUS, HumanMind

__all__ = ["FAULT_COUNTS", "ToxicWasteEnv"]

FAULT_COUNTS = {
    # info["faults"] key: (a fault event, or an event faults are counted out of; what it counts)
    "rfid_reads": ("event", "balls that entered the container (one RFID read attempt each)"),
    "rfid_misses": ("fault", "of those, reads the RFID reader missed"),
    "replies": ("event", "'locate human' questions asked"),
    "replies_lost": ("fault", "replies lost by speech_failure"),
    "replies_no_location": ("fault", "replies heard as no location (lost, or not recognised)"),
    "lidar_beams": ("event", "lidar beams of the scans the localiser read"),
    "lidar_dropped_beams": ("fault", "of those, beams lost to dropout or a dead lidar"),
    "wheel_slip_m": ("fault", "metres of wheel travel the wheel-radius error added to or took from odometry"),
    "encoder_noise_m": ("fault", "metres of wheel travel the encoder noise added to or took from odometry"),
    "relocalisations": ("fault", "times the localiser declared itself lost and re-seeded globally"),
    "moves": ("event", "macro steps that drove to a neighbour"),
    "blocked_moves": ("fault", "of those, moves that ended blocked"),
    "robot_node_readings": ("event", "robot-node readings observed (the reset's and one per step)"),
    "robot_node_unknown": ("fault", "of those, readings observed as unknown"),
}
"""The per-episode fault and sensor counts of ``info["faults"]``, in this order."""
FrameSink = Callable[[dict], None]


class ToxicWasteEnv(gymnasium.Env):
    """A wheeled container robot helps a scripted human put three toxic-waste balls into its container.

    ## Description
    The MuJoCo lab (``scenes/lab.xml``, 10 m x 8 m; ``sim.lab_world.LabWorld``) has five areas: 0 door, 1 open
    space, 2 robot station, 3 single workbench, 4 double workbench, joined by passages 0-1, 1-2, 1-3, 3-4. A task
    places the three balls (default library: nodes [0, 1, 2] and [1, 2, 3]). The human knows the task and follows
    ``domains.lab_human.LabHuman`` (nearest ball on the ground, pick it up, wait holding it until the robot is in
    the same area and stays or asks; with probability ``human_epsilon`` a move or pick fails). The robot knows
    neither the task nor where the human is: it perceives its own area (from its lidar Monte Carlo localiser, or
    wheel odometry alone with ``localisation=False``), the human's spoken reply and its container's RFID reader.
    It is the embodied twin of ``EmbodiedAdhoc/ToxicWasteAbstract-v0``: same actions,
    same observation semantics and encoding, same reward, same ``reset`` options, so an agent (and the trial
    runner) works unchanged in both.

    Each ``step`` is one macro step, turn-based as in the thesis: the world's human decides its command from the
    room as it is at the start of the step (``sim.lab_human_mind``: its policy on what it perceives, no rule of
    the abstract model), then the robot's waypoint controller (tracking its pose estimate, not
    ground truth) and the human's motion script run together in physics until both are done (or the robot is
    blocked, ``info["blocked"]``, or ``macro_timeout`` simulated seconds). The physics step and the env step are
    synchronous and deterministic: the
    same ``reset(seed=...)`` and actions give the same trajectory.

    ## Action space
    ``Discrete(5)`` (``Discrete(4)`` with ``communication=False``):

    | action | meaning |
    |---|---|
    | 0, 1, 2 | drive to the 1st / 2nd / 3rd lowest-index neighbour of the odometry area (past its degree: the lowest) |
    | 3 | stay (the human, if holding a ball in the robot's area, drops it into the container) |
    | 4 | locate human: ask "Where are you?" and hear the reply (also lets the human drop); not in ``Discrete(4)`` |

    ## Observation space
    ``MultiDiscrete([6, 6, 2])`` = ``[robot node, human node, rfid]`` with 5 = unknown/none, exactly the encoding
    of ``domains.lab_observations.LabObservation``; ``info["observation_index"]`` is its flat index.

    | element | value |
    |---|---|
    | robot node | the robot's own area reading (below) |
    | human node | after "locate human": the node recognised from the human's reply through ``speech`` (below) |
    | rfid | 1 if the container's reader read a ball entering during this step (missed w.p. ``rfid_miss``) |

    The robot node is the Monte Carlo localiser's area (lidar + odometry against the lab map,
    ``sim.localisation``), 5 (unknown) when its particles span more than one area; with ``localisation=False`` it
    is the wheel-odometry pose's area (5 outside every area). The robot's area sensor (``sim.area_sensor``) reports
    it with probability ``robot_node_accuracy``, else 5: the sensor's dropout, the parameter the model's
    robot-node factor is built from (with a measured ``localisation_model`` the sensor drops nothing). The human
    node is 5 when the reply names no location; without communication it is the robot's true area when the human
    is in it, else 5.

    ## Rewards
    From the state before the step (``domains.lab.LabReward``): -1 per ball on the ground, -2 per ball held,
    0 per ball in the container.

    ## Episode end
    Terminated when all balls are in the container (physically: inside the RFID site). Truncated by the
    registered ``TimeLimit`` after 100 macro steps (the thesis's cap; ``gymnasium.make(id, max_episode_steps=N)``
    changes it). ``step`` after the end raises (``envs.contract``).

    ## Arguments (``gymnasium.make`` kwargs)
    The lab parameters of ``domains.lab.LabConfig``, which holds their defaults, exactly as the abstract env:
    ``tasks``, ``human_epsilon``, ``communication`` (False: no "locate human"; the human is seen only when
    co-located), ``confusion`` (the "channel" speech's matrix and the agents' model), ``robot_node_accuracy``,
    ``rfid_miss`` (also the physical reader's miss rate), ``graph`` (must be the MuJoCo lab's map), ``reward``,
    ``discount``. The physics env's own:

    | kwarg | default | meaning |
    |---|---|---|
    | ``task`` | None | fixed task index; None = drawn uniformly at each reset |
    | ``human`` | "scripted" | the world's human teammate: the scripted cleaner, or a plug-in (``envs.lab_humans``) |
    | ``speech`` | "channel" | "channel" (sample the confusion matrix), "audio" (espeak-ng + pocketsphinx), "perfect" |
    | ``encoder_noise``, ``wheel_slip`` | None | odometry error model (None = ``sim.odometry.OdometryConfig``'s) |
    | ``localisation`` | True | Monte Carlo localisation on the lidar; False: the robot uses wheel odometry alone |
    | ``lidar_noise``, ``lidar_dropout`` | None | lidar range noise (m), per-beam dropout rate (None: 0.015, 0.01) |
    | ``speech_failure`` | 0.0 | probability that the human's reply to "locate human" is lost (heard as no location) |
    | ``reader_miss`` | None | the physical RFID reader's miss probability (None = the model's ``rfid_miss``) |
    | ``macro_timeout`` | 60.0 | simulated seconds after which an unfinished macro step ends |
    | ``render_mode`` | None | "rgb_array": ``render()`` returns the overhead camera image |
    | ``width``, ``height`` | 640, 480 | image size of ``render()`` and of recorded frames |
    | ``render_quality`` | "fast" | "fast" (no shadows, reflections or floor texture: cheap on CPU) or "high" |
    | ``frame_rate`` | 15.0 | frames per *simulated* second passed to the frame sink (see ``set_frame_sink``) |

    A plug-in ``human`` (its interface is in ``envs.lab_humans``), ``speech_failure`` and ``reader_miss`` are faults
    of the world the agents' models are not told about. ``lidar_dropout=1`` is a dead lidar: the localiser falls
    back to odometry and says so.

    ``reset(seed=..., options={"task": k, "robot_node": i, "human_node": j})`` fixes the episode's start (default:
    task and nodes drawn uniformly, as the abstract env; all balls on the ground).

    ## Info (ground truth, for evaluation and recording only; agents never read it)
    ``state`` (index in the library's shared state space; -1 if physics reached a state outside the model),
    ``observation_index``, ``task``, ``robot_node``/``human_node`` (true areas), ``ball_status`` (0 ground,
    1 held, 2 container), ``rfid_event`` (a ball truly entered the container), ``robot_pose`` and
    ``odometry_pose`` (x, y, yaw), ``odometry_error`` (m), ``human_position``, ``ball_positions``, ``sim_time``
    (s), ``macro_seconds``, ``robot_arrived``, ``timed_out``, ``wall_contact``, ``human_status``,
    ``utterances`` (lines of dialogue this step), ``speech_audio`` (WAV bytes, ``speech="audio"`` only);
    localisation: ``estimated_pose`` (the pose the controller tracks), ``pose_error`` (m, estimate vs truth),
    ``pose_covariance`` (3 x 3, None without a localiser), ``localisation_mode`` ("lidar", "odometry": no usable
    scans, "off": no localiser), ``kidnaps`` (times the localiser declared itself lost this step), ``blocked``
    (the robot could not reach its waypoint: stalled or gave up); ``faults``: the episode's fault events so far,
    the counts of ``FAULT_COUNTS`` (RFID misses, lost replies, dropped lidar beams, wheel-slip and encoder-noise
    metres, re-localisations, blocked moves, unknown robot-node readings, each beside what it is counted out of),
    so that a sweep with faults says what they did.

    ## Version history
    v0: first version.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 15}

    @contract.keywords(*LAB_PARAMETERS)
    def __init__(
        self,
        task: int | None = None,
        speech: str = "channel",
        encoder_noise: float | None = None,
        wheel_slip: float | None = None,
        macro_timeout: float = 60.0,
        render_mode: str | None = None,
        width: int = 640,
        height: int = 480,
        render_quality: str = "fast",
        frame_rate: float = 15.0,
        localisation: bool = True,
        lidar_noise: float | None = None,
        lidar_dropout: float | None = None,
        speech_failure: float = 0.0,
        reader_miss: float | None = None,
        human=None,
        **lab,
    ) -> None:
        from embodied_adhoc.envs.lab_humans import lab_humans
        from embodied_adhoc.envs.toxic_waste_world import make_world

        self.render_mode = contract.render_mode(render_mode)
        speech = checks.choice("speech", speech, SPEECH_KINDS)
        config = LabConfig.from_kwargs(type(self).__name__, lab)
        if config.graph != DEFAULT_GRAPH:  # the arena is built from the lab's map (domains.lab_facts)
            raise ConfigError(
                f"{type(self).__name__}: graph= must be the MuJoCo lab's map (domains.lab_facts); a graph of "
                "your own runs on EmbodiedAdhoc/ToxicWasteAbstract-v0"
            )
        self.library = library_from_config(config)
        self._humans = lab_humans(self.library, human)  # the world's human; the agents' models keep theirs
        self.task = None if task is None else checks.integer("task", task, 0, self.library.n_tasks - 1)
        encoder_noise, wheel_slip = (
            None if value is None else checks.number(name, value, 0.0)
            for name, value in (("encoder_noise", encoder_noise), ("wheel_slip", wheel_slip))
        )
        macro_timeout = checks.number("macro_timeout", macro_timeout, 0.0, low_open=True)
        width, height = checks.integer("width", width, 1), checks.integer("height", height, 1)
        render_quality = checks.choice("render_quality", render_quality, ("fast", "high"))
        frame_rate = checks.number("frame_rate", frame_rate, 0.0, low_open=True)
        self.width, self.height, self.render_quality = width, height, render_quality
        localisation = checks.flag("localisation", localisation)
        lidar_noise = None if lidar_noise is None else checks.number("lidar_noise", lidar_noise, 0.0)
        lidar_dropout = (
            None if lidar_dropout is None else checks.number("lidar_dropout", lidar_dropout, 0.0, 1.0)
        )
        self.speech_failure = checks.number("speech_failure", speech_failure, 0.0, 1.0)
        reader_miss = (
            config.rfid_miss if reader_miss is None else checks.number("reader_miss", reader_miss, 0.0, 1.0)
        )
        self.world = make_world(
            encoder_noise,
            wheel_slip,
            reader_miss,
            macro_timeout,
            frame_rate,
            width,
            height,
            render_quality,
            localisation=localisation,
            lidar_noise=lidar_noise,
            lidar_dropout=lidar_dropout,
            # the area sensor's dropout is the model's robot-node factor; a measured localisation model
            # describes the localiser's own errors, and the sensor then drops nothing
            area_accuracy=config.robot_node_accuracy if config.localisation_model is None else 1.0,
        )
        self.layout = self.world.layout
        self.speech: SpeechTurn | None = (
            make_speech(speech, config.confusion) if config.communication else None
        )
        n = self.library.graph.n_nodes
        self.action_space = spaces.Discrete(self.library.n_actions)
        self.observation_space = spaces.MultiDiscrete([n + 1, n + 1, 2])
        self._frame_sink: FrameSink | None = None
        self._task = self._steps = 0
        self._status: tuple[int, ...] = ()
        self._episode = contract.EpisodeGate(type(self).__name__)
        self._robot_believed_node = 0
        self._step_index = 0
        # the env's own counts; LabWorld.fault_counts has the sensors'
        env_counts = ("replies", "replies_lost", "replies_no_location", "moves", "blocked_moves")
        self._counts = dict.fromkeys((*env_counts, "robot_node_readings", "robot_node_unknown"), 0)

    # ----------------------------------------------------------------------------------------------- API
    def set_frame_sink(self, sink: FrameSink | None) -> None:
        """Receive ``snapshot`` ``frame_rate`` times per simulated second during every step (on the simulating
        thread, at that instant; the env renders nothing: a recorder that wants the picture takes it from
        ``self.world``, e.g. ``world.snapshot_renderer()`` to draw it off the simulation thread).

        ``snapshot`` has ``step``, ``sim_time``, ``robot_pose``, ``odometry_pose``, ``estimated_pose``,
        ``particles`` (P x 2 xy of the localiser's particle cloud, None without a localiser), ``human_position``,
        ``ball_positions``. Used by ``embodied-adhoc run --record`` for the video and the rerun recording.
        """
        self._frame_sink = sink

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        lib = self.library
        self._task, robot, human = lib.episode_start(options, self.task, self.np_random)
        world_seed, human_seed, speech_seed, sensor_seed = self.np_random.integers(0, 2**63 - 1, size=4)
        self._human_rng = np.random.default_rng(int(human_seed))
        self._speech_rng = np.random.default_rng(int(speech_seed))
        self._failure_rng = np.random.default_rng((int(speech_seed), 1))  # speech_failure's own stream
        self.world.area_sensor.reset(np.random.default_rng(int(sensor_seed)))
        self._status = (GROUND,) * len(lib.tasks[self._task])
        self._steps = self._step_index = 0
        self._counts = dict.fromkeys(self._counts, 0)
        self._robot_believed_node = robot
        self._episode.open()
        truth = self.world.reset(int(world_seed), robot, human, lib.tasks[self._task])
        self._human = HumanMind(self._humans[self._task], self._human_rng, self.layout)
        observation = self._observation(
            self.world.robot_node_reading(), truth.robot_node, truth.human_node, None, False
        )
        return observation.to_vector(), self._info(observation, truth, False, None, [], None)

    def step(self, action):
        self._episode.check()
        action = contract.action(
            action, self.library.n_actions, "see the action table of the env's docstring"
        )
        lib = self.library
        reward = float(lib.config.reward.of(np.array(self._status)))
        target = self.move_target(action)
        # the world's human decides from the room as it is at the start of the step (sim.lab_human_mind)
        command = self._human.decide(self.world.ground_truth(), robot_stays=target is None)
        self._step_index += 1
        result = self.world.step_macro(target, command, self._on_frame if self._frame_sink else None)
        truth = self.world.ground_truth()
        if result.robot_node_reading is not None:
            self._robot_believed_node = result.robot_node_reading
        elif target is not None:
            self._robot_believed_node = target
        previous = self._status
        self._status = tuple(BALL_STATUS[s] for s in truth.ball_states)
        entered = any(a != DISPOSED and b == DISPOSED for a, b in zip(previous, self._status, strict=True))
        utterances: list[str] = []
        heard: int | None = None
        speech_audio = None
        counts = self._counts
        if self.speech is not None and action == lib.locate_action:
            said = self._human.reply(
                truth.human_node
            )  # the human's own answer (a plug-in may lie or keep quiet)
            if said is None:
                heard, utterances = None, ["(no reply)"]
            else:
                heard, utterances, speech_audio = self.speech.ask(said, self._speech_rng)
                if said != truth.human_node:
                    utterances.append(f"(the human said node {said}; it is at node {truth.human_node})")
            counts["replies"] += 1
            if self.speech_failure > 0 and self._failure_rng.random() < self.speech_failure:
                heard = None  # the reply was lost (noise, the human did not answer): no location heard
                utterances = [*utterances, "(reply lost)"]
                counts["replies_lost"] += 1
            counts["replies_no_location"] += heard is None
        if target is not None:
            counts["moves"] += 1
            counts["blocked_moves"] += bool(result.blocked)
        observation = self._observation(
            result.robot_node_reading,
            truth.robot_node,
            truth.human_node,
            heard,
            bool(result.rfid_events),
            action,
        )
        self._steps += 1
        terminated = all(s == DISPOSED for s in self._status)
        self._episode.close_if(terminated)
        info = self._info(observation, truth, entered, result, utterances, speech_audio)
        info["human_command"] = f"{command.kind}" + ("" if command.target is None else f" {command.target}")
        return observation.to_vector(), reward, terminated, False, info

    def move_target(self, action: int) -> int | None:
        """The node ``action`` drives to if taken now: that neighbour of the robot's believed node (its last reading),
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
    def _observation(self, robot_reading, true_robot, true_human, heard, rfid, action=None) -> LabObservation:
        n = self.library.graph.n_nodes
        robot_reading = self.world.area_sensor.observe(robot_reading)  # the reading as the robot observes it
        if self.speech is not None:
            human = heard if action == self.library.locate_action else None
        else:
            human = true_human if true_robot is not None and true_robot == true_human else None
        self._counts["robot_node_readings"] += 1
        self._counts["robot_node_unknown"] += robot_reading is None
        return LabObservation(robot_reading, human, bool(rfid), n)

    def privileged_state(self) -> int:
        """The true state, as ``info["state"]`` holds it: the one channel through which the episode loop gives it to
        privileged agents (``observes_state``); agents never read ``info``."""
        return self._state_index

    def _info(self, observation, truth, entered, result, utterances, speech_audio) -> dict:
        robot_node = _area(self.layout, truth.robot_pose, truth.robot_node)
        states = self.library.states
        state = states.fast_index(robot_node, truth.human_node, self._status, entered)
        if state < 0 and entered:
            state = states.fast_index(robot_node, truth.human_node, self._status, False)
        odometry_pose = self.world.odometry_pose()
        estimate = self.world.pose_estimate()
        localiser = self.world.localiser
        self._state_index = int(state)
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
            "estimated_pose": estimate,
            "pose_error": float(
                np.hypot(estimate[0] - truth.robot_pose[0], estimate[1] - truth.robot_pose[1])
            ),
            "localisation_mode": "off" if localiser is None else localiser.mode,
            "pose_covariance": None if localiser is None else localiser.covariance,
            "kidnaps": 0 if result is None else result.kidnaps,
            "robot_node_reading": self.world.robot_node_reading()
            if result is None
            else result.robot_node_reading,
            "blocked": False if result is None else result.blocked,
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
            "faults": self.fault_counts(),
        }

    def fault_counts(self) -> dict[str, int | float]:
        """The episode's fault events so far (``info["faults"]``; keys and order of ``FAULT_COUNTS``)."""
        counts = {**self.world.fault_counts(), **self._counts}
        return {key: counts[key] for key in FAULT_COUNTS}

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
            "estimated_pose": world.pose_estimate(),
            "particles": None if world.localiser is None else world.localiser.particles[:, :2].copy(),
            "human_position": truth.human_pose[:2],
            "ball_positions": np.array(truth.ball_positions),
        }
        self._frame_sink(snapshot)


def _area(layout, pose, node: int | None) -> int:
    """The true area of a pose; on a border outside every polygon, the nearest node waypoint."""
    return int(node) if node is not None else layout.nearest_node(pose[:2])
