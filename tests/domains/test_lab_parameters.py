"""The lab's knowledge written once: LabConfig is the parameter list (with defaults) of build_lab_library and of
both toxic-waste envs; the physics world's own human decides what apply_step says, and the physics env honours
robot_node_accuracy; HOTSPOT's
information reward has one default reward gain."""

import dataclasses
import inspect

import gymnasium
import pytest

import embodied_adhoc.envs  # noqa: F401  (registers the ids)
from embodied_adhoc.decision.agents.hotspot import HotspotConfig, information_reward
from embodied_adhoc.domains.lab import LAB_PARAMETERS, LabConfig, apply_step, build_lab_library
from embodied_adhoc.domains.lab_graph import DISPOSED, GROUND, HELD
from embodied_adhoc.domains.lab_human import HumanOutcome
from embodied_adhoc.envs.toxic_waste import ToxicWasteEnv
from embodied_adhoc.envs.toxic_waste_abstract import ToxicWasteAbstractEnv
from embodied_adhoc.errors import ConfigError


def test_the_parameter_list_and_its_defaults_live_in_lab_config_only():
    assert LAB_PARAMETERS == tuple(f.name for f in dataclasses.fields(LabConfig))
    for function in (build_lab_library, ToxicWasteAbstractEnv.__init__, ToxicWasteEnv.__init__):
        signature = inspect.signature(inspect.unwrap(function))
        repeated = [name for name in LAB_PARAMETERS if name in signature.parameters and name != "graph"]
        assert not repeated, f"{function.__qualname__} repeats {repeated}"
    for env_class in (ToxicWasteAbstractEnv, ToxicWasteEnv):
        assert set(LAB_PARAMETERS) <= set(env_class.__init__.accepted)
    assert build_lab_library().config == LabConfig()
    env = gymnasium.make("EmbodiedAdhoc/ToxicWasteAbstract-v0", rfid_miss=0.25)
    assert env.unwrapped.library.config == LabConfig(rfid_miss=0.25)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"communication": "no"}, "communication"),
        ({"human_epsilon": -0.1}, "human_epsilon"),
        ({"robot_node_accuracy": 1.5}, "robot_node_accuracy"),
        ({"rfid_miss": None}, "rfid_miss"),
        ({"discount": 1.0}, "discount"),
        ({"confusion": 3}, "confusion"),
        ({"tasks": [[0, 9, 1]]}, "node 9"),
    ],
)
def test_every_entry_point_refuses_the_same_bad_parameter_with_the_same_message(kwargs, match):
    messages = set()
    for build in (
        lambda: LabConfig(**kwargs),
        lambda: build_lab_library(**kwargs),
        lambda: ToxicWasteAbstractEnv(**kwargs),
    ):
        with pytest.raises(ConfigError, match=match) as error:
            build()
        messages.add(str(error.value))
    assert len(messages) == 1


@pytest.mark.parametrize(
    "status, robot, human, action, outcome, expected",
    [
        (
            (HELD, GROUND, GROUND),
            2,
            2,
            3,
            None,
            ("drop_into_container", 0),
        ),  # co-located, stays: the hand-over
        (
            (HELD, GROUND, GROUND),
            2,
            2,
            4,
            None,
            ("drop_into_container", 0),
        ),  # co-located, asks: the hand-over too
        ((GROUND, HELD, GROUND), 1, 2, 3, None, ("stay", None)),  # not co-located: the human waits
        ((HELD, GROUND, GROUND), 2, 2, 0, None, ("stay", None)),  # the robot drives away: no hand-over
        ((GROUND, GROUND, GROUND), 0, 1, 0, HumanOutcome(1.0, 1, 1), ("pick", 1)),
        ((DISPOSED, GROUND, GROUND), 0, 0, 3, HumanOutcome(1.0, 1, -1), ("move_to", 1)),
        ((DISPOSED, GROUND, GROUND), 0, 0, 3, HumanOutcome(1.0, 0, -1), ("stay", None)),
    ],
)
def test_the_physics_human_decides_what_the_models_rule_says(status, robot, human, action, outcome, expected):
    from types import SimpleNamespace

    import numpy as np

    from embodied_adhoc.sim.lab_human_mind import BALL_STATUS, HumanMind
    from embodied_adhoc.sim.lab_layout import LAB_LAYOUT

    graph = build_lab_library().graph
    outcome = outcome or HumanOutcome(1.0, human)
    policy = SimpleNamespace(step=lambda rng, node, ball_status: outcome)
    names = {code: name for name, code in BALL_STATUS.items()}
    truth = SimpleNamespace(
        human_node=human,
        robot_node=robot,
        ball_states=tuple(names[s] for s in status),
        robot_pose=(0.0, 0.0, 0.0),
    )
    mind = HumanMind(policy, np.random.default_rng(0), LAB_LAYOUT)
    command = mind.decide(truth, robot_stays=action >= graph.max_degree)  # stay or ask: no move target
    assert (command.kind, command.target) == expected
    # the world's own decision is the transition the abstract model's rule gives
    _, next_human, planned, handed_over = apply_step(graph, robot, human, status, action, outcome)
    assert (command.kind == "drop_into_container") == handed_over
    assert (command.kind == "pick") == any(
        a == GROUND and b == HELD for a, b in zip(status, planned, strict=True)
    )
    assert (command.kind == "move_to") == (next_human != human)


def test_the_physics_env_honours_robot_node_accuracy():
    blind = gymnasium.make("EmbodiedAdhoc/ToxicWaste-v0", robot_node_accuracy=0.0, width=32, height=24)
    sharp = gymnasium.make("EmbodiedAdhoc/ToxicWaste-v0", robot_node_accuracy=1.0, width=32, height=24)
    try:
        start = {"task": 0, "robot_node": 1, "human_node": 3}
        assert blind.reset(seed=0, options=start)[0][0] == 5 and sharp.reset(seed=0, options=start)[0][0] == 1
        assert blind.step(3)[0][0] == 5 and sharp.step(3)[0][0] == 1
        assert blind.unwrapped.library.config.robot_node_accuracy == 0.0  # the agents' model says the same
    finally:
        blind.close()
        sharp.close()


def test_information_reward_defaults_to_hotspots_reward_gain():
    default = inspect.signature(information_reward).parameters["reward_gain"].default
    assert default == HotspotConfig().reward_gain == "conditional"
