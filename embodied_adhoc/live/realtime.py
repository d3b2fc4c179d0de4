"""The toxic-waste lab in real time: asynchronous decisions while physics and the human run continuously.

:class:`RealtimeToxicWasteEnv` is ``EmbodiedAdhoc/ToxicWaste-v0`` (same actions, observations, encoding, reward,
reset options, info and frame sink, so the one episode loop, the agents and the recorders run it unchanged) with
a different notion of a step. In the turn-based env a step is a macro step of both teammates: the human's command
is decided at its start and the step lasts until robot *and* human are done. Here:

* the simulation advances control tick by control tick (``LabWorldConfig.control_period``, 20 ms) and is paced
  by a :class:`RealtimeClock`: ``speed`` simulated seconds per wall-clock second (1 = real time, 10 = ten times
  faster, None = as fast as the machine goes: the headless comparison);
* the human is moved by its own driver (``live.humans``) every tick, independently of the robot: the scripted
  cleaner decides whenever its own command is done, a participant walks with the keyboard;
* ``step(action)`` starts the robot's macro action and returns when *that* action completes (the robot reached
  its waypoint or gave up; "stay" after ``min_macro_seconds``; "locate human" when the answer came, or after
  ``reply_timeout`` simulated seconds with no location heard), with the observation gathered meanwhile: the
  localiser's area at completion, any RFID read since the previous decision, the answer heard. The agent then
  decides; under a paced clock the wall time it took to decide passes in the simulation too (the robot stands
  still, the human goes on): :meth:`step` first catches the simulation up to the clock.

Nothing is random beyond the parent env's seeded streams; with ``speed=None`` and the scripted human an episode is
a deterministic function of the seed (tested). Paced runs depend on wall-clock timing by design.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np

from embodied_adhoc import checks
from embodied_adhoc.domains.lab_graph import DISPOSED
from embodied_adhoc.envs import contract
from embodied_adhoc.envs.toxic_waste import ToxicWasteEnv, _area
from embodied_adhoc.errors import EmbodiedAdhocError
from embodied_adhoc.live.humans import ScriptedHuman
from embodied_adhoc.sim.lab_human_mind import BALL_STATUS

__all__ = ["LiveStopped", "RealtimeClock", "RealtimeToxicWasteEnv"]


class LiveStopped(EmbodiedAdhocError):
    """The real-time loop was asked to stop (the server shut down or the participant ended the session)."""


class RealtimeClock:
    """Paces simulated time against ``time.perf_counter``: ``speed`` simulated seconds per wall second.

    ``speed=None`` never waits. When the simulation falls more than ``max_lag`` wall seconds behind (the machine
    cannot keep up), the clock re-anchors instead of racing to catch up and adds the skipped time to ``slipped``.
    """

    def __init__(self, speed: float | None, max_lag: float = 1.0, stop: threading.Event | None = None):
        self.speed = None if speed is None else checks.number("speed", speed, 0.0, low_open=True)
        self.max_lag = float(max_lag)
        self.stop = stop or threading.Event()
        self.slipped = 0.0
        self._wall0 = self._sim0 = 0.0

    def start(self, sim_time: float) -> None:
        self._wall0, self._sim0, self.slipped = time.perf_counter(), float(sim_time), 0.0

    def lag(self, sim_time: float) -> float:
        """Wall seconds by which ``sim_time`` is late (negative: early); 0 when unpaced."""
        if self.speed is None:
            return 0.0
        return time.perf_counter() - (self._wall0 + (sim_time - self._sim0) / self.speed)

    def check(self, sim_time: float) -> float:
        """The lag of ``sim_time`` (wall seconds late; negative: early), after re-anchoring if it exceeds
        ``max_lag``; raise :class:`LiveStopped` if ``stop`` is set."""
        if self.stop.is_set():
            raise LiveStopped("the real-time loop was stopped")
        late = self.lag(sim_time)
        if late > self.max_lag:
            self.slipped += late
            self._wall0 += late
            late = 0.0
        return late

    def wait_for(self, sim_time: float) -> None:
        """Sleep until ``sim_time`` is due (see :meth:`check`)."""
        late = self.check(sim_time)
        if late < 0 and self.stop.wait(-late):
            raise LiveStopped("the real-time loop was stopped")


class RealtimeToxicWasteEnv(ToxicWasteEnv):
    """``ToxicWaste-v0`` with asynchronous decisions (module docstring). Extra arguments:

    | argument | default | meaning |
    |---|---|---|
    | ``human`` | ``ScriptedHuman()`` | the human's driver (``live.humans``) |
    | ``speed`` | 1.0 | simulated seconds per wall second; None = unpaced |
    | ``reply_timeout`` | 20.0 | simulated seconds "locate human" waits for an answer before it hears none |
    | ``tick_listener`` | None | called with the env after every control tick (simulation thread): live frames |
    | ``stop`` | None | a ``threading.Event`` that ends the loop (:class:`LiveStopped`) |
    | ``question_interval`` | 0.0 | simulated seconds after an answer before the robot asks again (it stays meanwhile) |
    | ``question_gate`` | None | called when a question is held back: True (the agent's belief moved) lets it through |

    Contact: a ball the human carries touches nothing (its geoms' collision bits are cleared while its grasp weld
    is active, restored on release), so the kinematic walker cannot push the robot or knock balls out of its
    container; the walker itself has no contacts (``assets/props/human.xml``). A hand-over under way (the walker's
    drop motion) holds the robot still (``LabWorld.tick(drive=False)``: its route waits until the drop has
    succeeded or failed). The robot's action still completes on its own schedule: its agent may decide while the
    ball is on its way (making the action wait for the hand-over deadlocked some scripted episodes).

    Extra ``info`` keys: ``realtime_slip_s`` (wall seconds the clock skipped, 0 when it kept up),
    ``reply_wait_s`` (simulated seconds the robot waited for an answer), ``decision_wait_s`` (simulated seconds
    that passed while the agent decided, robot idle), ``mujoco_warnings`` (raised since the previous decision).
    """

    def __init__(
        self,
        human=None,
        speed: float | None = 1.0,
        reply_timeout: float = 20.0,
        tick_listener: Callable[[RealtimeToxicWasteEnv], None] | None = None,
        stop: threading.Event | None = None,
        question_interval: float = 0.0,
        question_gate: Callable[[], bool] | None = None,
        **kwargs,
    ) -> None:
        super().__init__(**kwargs)
        model = self.world.model
        self._ball_geoms = [
            np.flatnonzero(model.geom_bodyid == body) for body in self.world.ids.ball_bodies.tolist()
        ]
        self._ball_collision = [
            (model.geom_contype[g].copy(), model.geom_conaffinity[g].copy()) for g in self._ball_geoms
        ]
        self._ball_held = [False] * len(self._ball_geoms)
        self.question_interval = checks.number("question_interval", question_interval, 0.0)
        self.question_gate = question_gate
        self.last_answer_time: float | None = None
        self.human_driver = human if human is not None else ScriptedHuman()
        self.clock = RealtimeClock(speed, stop=stop)
        self.reply_timeout = checks.number("reply_timeout", reply_timeout, 0.0, low_open=True)
        self.tick_listener = tick_listener
        self.current_action: int | None = None
        self.question_open = False
        self._warnings_mark = 0

    # ------------------------------------------------------------------ what the human drivers read
    @property
    def task_index(self) -> int:
        return self._task

    @property
    def human_rng(self) -> np.random.Generator:
        return self._human_rng

    @property
    def speech_rng(self) -> np.random.Generator:
        return self._speech_rng

    def true_robot_node(self, truth) -> int:
        return _area(self.layout, truth.robot_pose, truth.robot_node)

    def tick_walker(self, dt: float) -> None:
        """Advance the walker's motion script one tick and apply its grasp/release events and pose; a carried
        ball's collisions are off while it is carried (class docstring)."""
        self.world.tick_human(dt)
        self._sync_ball_contacts()

    def _sync_ball_contacts(self) -> None:
        world = self.world
        held = world.data.eq_active[world.ids.grasp_welds].tolist()
        for ball, now_held in enumerate(held):
            if bool(now_held) == self._ball_held[ball]:
                continue
            geoms, (contype, conaffinity) = self._ball_geoms[ball], self._ball_collision[ball]
            world.model.geom_contype[geoms] = 0 if now_held else contype
            world.model.geom_conaffinity[geoms] = 0 if now_held else conaffinity
            self._ball_held[ball] = bool(now_held)

    @property
    def handover_under_way(self) -> bool:
        """The walker is playing its drop motion (stepping up to the container, reaching, letting go)."""
        walker = self.world.human
        return not walker.finished and walker.status == "drop_into_container started"

    # ------------------------------------------------------------------ gymnasium API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        observation, info = super().reset(seed=seed, options=options)
        self.current_action, self.question_open = None, False
        self.last_answer_time = None
        self._ball_held = [False] * len(self._ball_geoms)
        model = self.world.model
        for geoms, (contype, conaffinity) in zip(self._ball_geoms, self._ball_collision, strict=True):
            model.geom_contype[geoms], model.geom_conaffinity[geoms] = contype, conaffinity
        self._warnings_mark = self.world.warning_count()
        self.human_driver.reset(self)
        self.clock.start(self.world.data.time)
        return observation, info

    def step(self, action):
        self._episode.check()
        action = contract.action(
            action, self.library.n_actions, "see the action table of the env's docstring"
        )
        lib, world, data = self.library, self.world, self.world.data
        reward = float(lib.config.reward.of(np.array(self._status)))
        decided_at = data.time
        while self.clock.check(data.time) > 0:  # the robot stood still while its agent decided
            self._tick(drive=False)
        decision_wait = data.time - decided_at
        target = self.move_target(action)
        self._step_index += 1
        self.current_action = action
        controller = world.controller
        world.start_action(target)
        start = data.time
        kidnaps_before = 0 if world.localiser is None else world.localiser.kidnaps
        asking = self.speech is not None and action == lib.locate_action
        reply = None
        if asking:
            self._hold_question()
            self.question_open = True
            self.human_driver.ask(self, world.ground_truth().human_node)
            reply = self.human_driver.reply(self)
        try:
            while True:
                elapsed = data.time - start
                answered = not asking or reply is not None or elapsed >= self.reply_timeout
                if elapsed >= world.config.macro_timeout or (
                    answered and controller.finished and elapsed >= world.config.min_macro_seconds
                ):
                    break
                self._tick(drive=not self.handover_under_way)
                if asking and reply is None:
                    reply = self.human_driver.reply(self)
                self.clock.wait_for(data.time)
        finally:
            self.current_action, self.question_open = None, False
            data.ctrl[world.ids.wheel_actuators] = 0.0
        if asking and reply is None and hasattr(self.human_driver, "close_question"):
            self.human_driver.close_question()
        if asking:
            self.last_answer_time = data.time
        return self._finish_step(action, target, reward, start, kidnaps_before, asking, reply, decision_wait)

    # ------------------------------------------------------------------ internals
    def _hold_question(self) -> None:
        """Stay (the robot's "locate human" has no route) until ``question_interval`` simulated seconds have
        passed since the previous question closed, unless ``question_gate`` lets the question through."""
        if self.last_answer_time is None or self.question_interval <= 0:
            return
        data = self.world.data
        while data.time - self.last_answer_time < self.question_interval - 1e-9:
            if self.question_gate is not None and self.question_gate():
                return
            self._tick(drive=not self.handover_under_way)
            self.clock.wait_for(data.time)

    def _tick(self, drive: bool) -> None:
        """One control tick of the world (``LabWorld.tick``: the robot's current macro action when ``drive``,
        else standing still while its agent decides) with the human moved by its driver, then the listener."""
        self.world.tick(drive, self._drive_human, self._on_frame if self._frame_sink is not None else None)
        if self.tick_listener is not None:
            self.tick_listener(self)

    def _drive_human(self, dt: float) -> None:
        self.human_driver.tick(self, dt)

    def _finish_step(self, action, target, reward, start, kidnaps_before, asking, reply, decision_wait):
        world, data = self.world, self.world.data
        # the robot's action alone (the human runs on); warnings since the previous decision
        result = world.action_result(start, self._warnings_mark, kidnaps_before, with_human=False)
        self._warnings_mark = world.warning_count()
        events, reading = result.rfid_events, result.robot_node_reading
        truth = world.ground_truth()
        if reading is not None:
            self._robot_believed_node = reading
        elif target is not None:
            self._robot_believed_node = target
        previous = self._status
        self._status = tuple(BALL_STATUS[s] for s in truth.ball_states)
        entered = any(a != DISPOSED and b == DISPOSED for a, b in zip(previous, self._status, strict=True))
        heard, utterances, audio = None, [], None
        if asking:
            if reply is None:
                utterances = ['robot: "Where are you?"', f"(no answer within {self.reply_timeout:g} s)"]
            else:
                heard, utterances, audio = reply.node, list(reply.lines), reply.audio_wav
            if self.speech_failure > 0 and self._failure_rng.random() < self.speech_failure:
                heard = None  # the reply was lost (noise, the human did not answer): no location heard
                utterances = [*utterances, "(reply lost)"]
        observation = self._observation(
            reading, truth.robot_node, truth.human_node, heard, bool(events), action
        )
        self._steps += 1
        terminated = all(s == DISPOSED for s in self._status)
        self._episode.close_if(terminated)
        info = self._info(observation, truth, entered, result, utterances, audio)
        info["human_command"] = world.human.status
        info["realtime_slip_s"] = round(self.clock.slipped, 3)
        info["reply_wait_s"] = round(float(data.time - start), 3) if asking else 0.0
        info["decision_wait_s"] = round(float(decision_wait), 3)
        info["mujoco_warnings"] = result.mujoco_warnings
        return observation.to_vector(), reward, terminated, False, info
