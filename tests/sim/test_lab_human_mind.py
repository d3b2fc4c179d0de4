"""The physics lab decides and senses for itself: the world's human (sim.lab_human_mind) and the robot's area
sensor (sim.area_sensor), whose dropout is the one parameter the lab model's robot-node factor is built from."""

from dataclasses import dataclass

import numpy as np
import pytest

from embodied_adhoc.domains.lab_human import HumanOutcome
from embodied_adhoc.sim.area_sensor import AreaSensor
from embodied_adhoc.sim.lab_human_mind import HumanMind
from embodied_adhoc.sim.lab_layout import LAB_LAYOUT


@dataclass
class Truth:  # the fields of sim.lab_world.GroundTruth that the human perceives
    human_node: int
    robot_node: int | None
    ball_states: tuple[str, ...]
    robot_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)


class Scripted:
    """A policy of the lab human interface that says what it was asked and answers a fixed outcome."""

    def __init__(self, outcome: HumanOutcome) -> None:
        self.outcome, self.asked = outcome, []

    def step(self, rng, human_node, ball_status):
        self.asked.append((human_node, tuple(ball_status)))
        return self.outcome


STAYS = HumanOutcome(1.0, 1)


def mind(outcome=STAYS):
    return HumanMind(Scripted(outcome), np.random.default_rng(0), LAB_LAYOUT)


def test_the_human_asks_its_policy_with_what_it_perceives_and_carries_the_answer_out():
    move = mind(HumanOutcome(1.0, next_node=3))
    command = move.decide(Truth(1, 2, ("ground", "container", "ground")), robot_stays=False)
    assert (command.kind, command.target) == ("move_to", 3)
    assert move.policy.asked == [(1, (0, 2, 0))]  # its own area and the balls' physical states
    pick = mind(HumanOutcome(1.0, next_node=1, picked_ball=2)).decide(Truth(1, 2, ("ground",) * 3), False)
    assert (pick.kind, pick.target) == ("pick", 2)
    assert mind(HumanOutcome(1.0, next_node=1)).decide(Truth(1, 2, ("ground",) * 3), False).kind == "stay"


@pytest.mark.parametrize(
    ("robot_node", "robot_stays", "expected"),
    [
        (1, True, "drop_into_container"),
        (1, False, "stay"),
        (2, True, "stay"),
        (None, True, "drop_into_container"),
    ],
)
def test_a_human_holding_a_ball_hands_it_over_only_to_a_robot_that_stays_in_its_area(
    robot_node, robot_stays, expected
):
    holding = mind()
    # robot_node None: on a border; the robot's pose is the open space's waypoint, so it counts as there
    pose = (*LAB_LAYOUT.node_waypoints[1], 0.0)
    truth = Truth(1, robot_node, ("container", "held", "ground"), robot_pose=pose)
    command = holding.decide(truth, robot_stays=robot_stays)
    assert command.kind == expected
    if expected == "drop_into_container":
        assert command.target == 1
    assert holding.policy.asked == []  # a human holding a ball makes no draw


def test_the_area_sensor_drops_readings_at_its_rate_from_its_own_stream():
    sensor = AreaSensor(0.75)
    sensor.reset(np.random.default_rng(4))
    readings = [sensor.observe(2) for _ in range(4000)]
    assert set(readings) == {2, None} and abs(readings.count(None) / 4000 - 0.25) < 0.03
    assert all(AreaSensor(1.0).observe(3) == 3 for _ in range(100))
    assert all(AreaSensor(0.0).observe(3) is None for _ in range(100))
    again = AreaSensor(0.75)
    again.reset(np.random.default_rng(4))
    assert [again.observe(2) for _ in range(4000)] == readings


def test_the_physics_lab_senses_with_the_models_own_parameter():
    from embodied_adhoc.envs.toxic_waste import ToxicWasteEnv

    env = ToxicWasteEnv(robot_node_accuracy=0.8)
    try:
        assert env.world.area_sensor.accuracy == env.library.config.robot_node_accuracy == 0.8
        # the model's robot factor is built from the same number
        assert env.library.observation_model.robot(2)[2] == pytest.approx(0.8)
    finally:
        env.close()


class Liar:
    """The library's scripted human, who says it is at the door (``say``) or keeps quiet (``say=None``)."""

    def __init__(self, scripted, say) -> None:
        self.scripted, self.say = scripted, say

    def step(self, rng, human_node, ball_status):
        return self.scripted.step(rng, human_node, ball_status)

    def answer(self, rng, human_node):
        return self.say


@pytest.mark.parametrize(("say", "heard"), [(0, 0), (None, 5)])
def test_the_physics_human_answers_for_itself(say, heard):
    from embodied_adhoc.envs.toxic_waste import ToxicWasteEnv

    env = ToxicWasteEnv(speech="perfect", human=lambda library, task: Liar(library.humans[task], say))
    try:
        env.reset(seed=0, options={"task": 0, "robot_node": 1, "human_node": 3})
        observation, _, _, _, info = env.step(env.library.locate_action)
        assert info["human_node"] != 0  # the human is not at the door, whatever it says
        assert observation[1] == heard  # perfect speech hears what was said; no reply reads as none (5)
    finally:
        env.close()
