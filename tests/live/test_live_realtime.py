"""The real-time lab: asynchronous decisions, the scripted and the participant human, walking rules, the clock."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from embodied_adhoc.episodes.loop import EpisodeObserver
from embodied_adhoc.experiments.recorded import EpisodeConfig
from embodied_adhoc.live.episode import open_realtime_episode, run_realtime_episode
from embodied_adhoc.live.humans import Participant, Reply, ScriptedHuman, walkable
from embodied_adhoc.live.realtime import LiveStopped, RealtimeClock, RealtimeToxicWasteEnv
from embodied_adhoc.sim.lab_layout import LAB_LAYOUT


class _Trace(EpisodeObserver):
    def __init__(self):
        self.steps = []

    def step_finished(self, record):
        info = record.info
        self.steps.append(
            (record.action, record.observation_index, round(info["sim_time"], 6), info["ball_status"])
        )
        self.warnings = getattr(self, "warnings", 0) + info["mujoco_warnings"]


def _run(seed: int, max_steps: int, **kwargs):
    trace = _Trace()
    episode = open_realtime_episode(EpisodeConfig(seed=seed, max_steps=max_steps), **kwargs)
    outcome = run_realtime_episode(episode, [trace])
    assert trace.warnings == 0  # MuJoCo raised no warning
    return outcome, trace.steps


def test_unpaced_scripted_episode_is_a_function_of_the_seed():
    first, steps_a = _run(1, 8, speed=None)
    again, steps_b = _run(1, 8, speed=None)
    other, steps_c = _run(2, 8, speed=None)
    assert steps_a == steps_b and len(steps_a) == 8
    assert steps_a != steps_c
    assert first.metrics["sim_time_s"] == again.metrics["sim_time_s"]


def test_macro_actions_end_when_the_robot_is_done_not_when_the_human_is():
    """Turn-based steps last until both teammates are done; here a "locate human" or "stay" step lasts the
    minimum (1 s simulated) while the human's own commands run on across steps."""
    _, steps = _run(1, 14, speed=None)
    times = np.diff([0.0] + [t for _, _, t, _ in steps])
    short = [dt for (action, _, _, _), dt in zip(steps, times, strict=True) if action >= 3]
    assert short and all(0.99 <= dt <= 1.1 for dt in short), short


def test_a_full_scripted_episode_finishes():
    outcome, steps = _run(0, 100, speed=None)
    assert outcome.metrics["outcome"] == "success"
    assert steps[-1][3] == (2, 2, 2)


def _env(human, **kwargs) -> RealtimeToxicWasteEnv:
    env = RealtimeToxicWasteEnv(human=human, speed=None, localisation=False, **kwargs)
    env.reset(seed=3, options={"task": 0, "robot_node": 1, "human_node": 1})
    return env


def test_the_participant_walks_with_held_keys_and_a_wall_stops_them():
    person = Participant()
    env = _env(person)
    try:
        start = env.world.human.xy.copy()
        person.keys({"right"}, seq=1)
        for _ in range(50):  # one simulated second
            env._tick(None)
        moved = env.world.human.xy - start
        assert moved[0] == pytest.approx(1.2, abs=0.05) and abs(moved[1]) < 1e-9
        assert person.last_seq == 1 and len(person.log.motion_latency_s) == 1
        person.keys({"up"}, seq=2)  # north of the open space is the wall to the double workbench (no passage)
        for _ in range(250):
            env._tick(None)
        y = env.world.human.xy[1]
        assert 0.5 < y <= 1.0 - 0.25 + 1e-9
        assert env.world.ground_truth().human_node == 1
        with pytest.raises(Exception, match="unknown direction"):
            person.keys({"jump"}, seq=3)
    finally:
        env.close()


def test_walking_into_a_wall_beside_a_passage_slides_through_it():
    person = Participant()
    env = _env(person)
    try:
        env.world.human.xy = np.array(
            [1.5, 1.95]
        )  # double workbench, 0.55 m south of the 3-4 passage's centre line
        env.world.human.node = 4
        person.keys({"left"}, seq=1)
        for _ in range(200):  # four simulated seconds
            env._tick(None)
        assert env.world.human.xy[0] < -0.5 and env.world.ground_truth().human_node == 3
    finally:
        env.close()


def test_the_participant_picks_a_ball_in_reach_and_answers_by_typing():
    person = Participant()
    env = _env(person)
    try:
        # task 0 puts ball 1 in the open space, where the human stands
        ball = np.array(env.world.ground_truth().ball_positions[1][:2])
        env.world.human.xy = ball + [0.6, 0.0]
        person.act(seq=1)
        for _ in range(300):
            env._tick(None)
        assert env.world.human.holding == 1
        assert env.world.ground_truth().ball_states[1] == "held"
        # the robot asks; the typed answer arrives from another thread and the step completes with it
        typed = threading.Timer(
            0.05, person.answer, args=(Reply(1, ("typed",), None), 2, {"text": "open space"})
        )
        typed.start()
        _, _, _, _, info = env.step(env.library.locate_action)
        assert env.library.decode_observation(info["observation_index"]).human_node == 1
        assert info["utterances"] == ("typed",)
        assert [e["kind"] for e in person.log.entries] == ["act", "pick", "question", "reply"]
        assert person.log.entries[1]["succeeded"] and person.log.entries[1]["result"] == "picked ball 1"
        # logged at the grasp, before the walker stood up
        assert person.log.entries[1]["sim_time"] < env.world.data.time - 0.5
    finally:
        env.close()


def test_no_answer_is_heard_as_no_location_after_the_timeout():
    person = Participant()
    env = _env(person, reply_timeout=2.0)
    try:
        _, _, _, _, info = env.step(env.library.locate_action)
        assert info["reply_wait_s"] == pytest.approx(2.0, abs=0.05)
        assert "no answer" in info["utterances"][-1]
        z = env.library.decode_observation(info["observation_index"])
        assert z.human_node is None
        person.answer(Reply(1, ("late",), None), 5, {})
        env._tick(None)
        assert person.log.entries[-1]["result"].startswith("ignored")
    finally:
        env.close()


def test_walkable_areas_and_passages():
    assert walkable(LAB_LAYOUT, (0.5, -0.5))  # open space centre
    assert not walkable(LAB_LAYOUT, (0.5, 0.9))  # against the wall to the double workbench
    assert walkable(LAB_LAYOUT, (1.0, -2.0))  # in the passage 0-1
    assert not walkable(LAB_LAYOUT, (2.5, -2.0))  # in the wall 0-1 beside the passage
    assert not walkable(LAB_LAYOUT, (6.0, 0.0))  # outside the room


def test_clock_stops_and_never_waits_unpaced():
    stop = threading.Event()
    clock = RealtimeClock(None, stop=stop)
    clock.start(0.0)
    assert clock.lag(1e6) == 0.0
    clock.wait_for(1e6)  # returns at once
    stop.set()
    with pytest.raises(LiveStopped):
        clock.wait_for(0.0)
    with pytest.raises(Exception, match="speed"):
        RealtimeClock(0.0)


def test_scripted_human_refuses_a_bad_pause():
    with pytest.raises(Exception, match="pause"):
        ScriptedHuman(pause=0)


def test_a_slow_decision_passes_in_the_simulation_and_a_slow_machine_slips():
    """Paced: the wall time the agent spends deciding passes in the simulation with the robot idle; a clock the
    machine cannot follow re-anchors (``realtime_slip_s``) instead of catching up forever."""
    env = RealtimeToxicWasteEnv(human=ScriptedHuman(), speed=1.0, localisation=False)
    try:
        env.reset(seed=3, options={"task": 0, "robot_node": 1, "human_node": 1})
        env.clock.start(env.world.data.time + 0.5)  # the simulation half a second behind: the agent thought
        robot = env.world.true_robot_pose()
        _, _, _, _, info = env.step(env.library.stay_action)
        assert info["decision_wait_s"] >= 0.5 - 0.02
        assert np.hypot(*np.subtract(env.world.true_robot_pose()[:2], robot[:2])) < 0.05  # it stood still
        env.clock.start(env.world.data.time + 3.0)  # three seconds behind: more than max_lag
        _, _, _, _, info = env.step(env.library.stay_action)
        assert info["realtime_slip_s"] >= 1.0
    finally:
        env.close()


def _upright(env) -> float:
    """The z component of the robot base's up axis (1: upright)."""
    body = env.world.model.body("base").id
    return float(env.world.data.xmat[body].reshape(3, 3)[2, 2])


def test_pushing_the_walker_with_a_ball_against_the_robot_moves_nothing():
    """The walker stops at the robot's footprint and a carried ball touches nothing: five seconds of walking
    into the robot leave it upright and in place, and the ball already in its container stays there."""
    from embodied_adhoc.live.humans import ROBOT_CLEARANCE

    person = Participant()
    env = _env(person)
    try:
        world = env.world
        data, ids = world.data, world.ids
        address = ids.ball_qpos[0]  # ball 0 into the container, then let it settle
        data.qpos[address : address + 3] = data.site_xpos[ids.rfid_site] + [0.0, 0.0, 0.05]
        data.qvel[ids.ball_dof[0] : ids.ball_dof[0] + 6] = 0.0
        for _ in range(100):
            env._tick(False)
        assert world.ground_truth().ball_states[0] == "container"
        ball = np.array(world.ground_truth().ball_positions[1][:2])
        world.human.xy = ball + [0.6, 0.0]
        person.act(seq=1)
        for _ in range(300):
            env._tick(False)
        assert world.human.holding == 1
        carried = world.model.geom_bodyid == ids.ball_bodies[1]
        assert not world.model.geom_contype[carried].any() and not world.model.geom_conaffinity[carried].any()
        robot = np.array(world.true_robot_pose()[:2])
        keys = {(1.0, 0.0): "left", (-1.0, 0.0): "right", (0.0, 1.0): "down", (0.0, -1.0): "up"}
        pushed = 0
        for side, key in keys.items():  # from every side the walker can stand on, the ball hand first or not
            for lateral in (-0.3, 0.0, 0.3):
                start = robot + 1.0 * np.array(side) + lateral * np.array(side[::-1])
                if not walkable(env.layout, start):
                    continue
                world.human.xy, pushed = start, pushed + 1
                person.keys({key}, seq=2 * pushed)
                closest = np.inf
                for _ in range(100):  # 2 s of walking into the robot
                    env._tick(False)
                    closest = min(closest, float(np.hypot(*(world.human.xy - robot))))
                    assert world.ground_truth().ball_states[0] == "container"
                    assert _upright(env) > 0.99
                person.keys(set(), seq=2 * pushed + 1)
                env._tick(False)
                assert closest >= ROBOT_CLEARANCE - 0.05
        assert pushed >= 3
        assert float(np.hypot(*(np.array(world.true_robot_pose()[:2]) - robot))) < 0.02
        assert world.ground_truth().ball_states[1] == "held"
    finally:
        env.close()


def test_a_question_waits_for_the_interval_after_an_answer_unless_the_belief_moved():
    gate = {"open": False}
    env = _env(ScriptedHuman(), question_interval=8.0, question_gate=lambda: gate["open"])
    try:
        env.step(env.library.locate_action)
        answered = env.last_answer_time
        env.step(env.library.locate_action)
        assert env.world.data.time - answered >= 8.0 - 1e-6  # the robot stayed until the interval had passed
        gate["open"] = True
        answered = env.last_answer_time
        env.step(env.library.locate_action)
        assert env.world.data.time - answered < 2.0  # the belief moved: asked at once
    finally:
        env.close()
