"""The benchmark's populations: disjoint, versioned splits; members deterministic per seed; the behaviours each
lab human's type label claims, seen in the abstract env; the listing command and the population-file checks."""

import json

import gymnasium
import numpy as np
import pytest

import embodied_adhoc.envs  # noqa: F401  (registers the env ids)
from embodied_adhoc.cli import main
from embodied_adhoc.domains.chapter5 import build_library
from embodied_adhoc.domains.lab import build_lab_library
from embodied_adhoc.domains.lab_graph import GROUND, HELD
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.teammates.lab_members import PopulationHuman
from embodied_adhoc.teammates.populations import (
    BENCH_DOMAINS,
    SPLITS,
    SUITE_VERSION,
    find_member,
    load_population,
    members,
    population,
)

LAB_ID = "EmbodiedAdhoc/ToxicWasteAbstract-v0"


@pytest.mark.parametrize("domain", BENCH_DOMAINS)
def test_splits_are_disjoint_complete_and_versioned(domain):
    specs = population(domain)
    assert {s.split for s in specs} == set(SPLITS)
    names = [s.name for s in specs]
    assert len(names) == len(set(names))
    behaviours = [json.dumps(s.params, sort_keys=True) for s in specs]
    assert len(behaviours) == len(set(behaviours)), "two members with the same policy"
    for split in SPLITS:
        others = {s.name for s in specs if s.split != split}
        assert not others & {s.name for s in members(domain, split)}
    assert members(domain, "heldout") == members(domain, "held-out")
    assert all(s.version == SUITE_VERSION and s.domain == domain for s in specs)
    assert all(find_member(domain, s.name) == s for s in specs)


def _lab_episode(spec, seed: int) -> list:
    env = gymnasium.make(LAB_ID, human=spec.plugin, disable_env_checker=True)
    rng = np.random.default_rng(seed)
    observation, info = env.reset(seed=seed)
    trace = [observation.tolist(), info["state"]]
    for _ in range(60):
        observation, reward, terminated, truncated, info = env.step(int(rng.integers(env.action_space.n)))
        trace += [observation.tolist(), info["state"], reward]
        if terminated or truncated:
            break
    env.close()
    return trace


@pytest.mark.parametrize("spec", population("toxic-waste"), ids=lambda s: s.name)
def test_lab_members_are_deterministic_per_seed(spec):
    assert _lab_episode(spec, 3) == _lab_episode(spec, 3)


@pytest.mark.parametrize("domain", ("pursuit-task", "gridworld"))
def test_chapter5_members_are_deterministic_distributions(domain):
    library = build_library(domain)
    # pursuit's softmax members solve its MMDP (seconds each); gridworld covers that family
    chosen = [s for s in population(domain) if domain == "gridworld" or s.params["family"] != "softmax"]
    for spec in chosen:
        first, again = spec.factory()(library, 1), spec.factory()(library, 1)
        assert np.array_equal(first, again)
        assert first.min() >= 0.0 and np.allclose(first.sum(axis=1), 1.0)


def test_thesis_member_is_the_library_human():
    library = build_lab_library()
    human = find_member("toxic-waste", "thesis").factory()(library, 0)
    for s in np.flatnonzero(library.states.valid[0]):
        _, node, status, _ = library.states.describe(int(s))
        ours = {
            (o.next_node, o.picked_ball): round(o.probability, 12)
            for o in human.policy_outcomes(node, status)
        }
        thesis = {
            (o.next_node, o.picked_ball): round(o.probability, 12)
            for o in library.humans[0].policy_outcomes(node, status)
        }
        assert ours == thesis


def test_order_human_walks_to_its_own_first_ball():
    library = build_lab_library()
    balls = library.tasks[0]  # nodes 0, 1, 2
    human = PopulationHuman(library.graph, balls, {"rule": "order", "order": [2, 1, 0], "slow": 0.0})
    (outcome,) = human.policy_outcomes(balls[0], (GROUND, GROUND, GROUND))
    assert outcome.picked_ball == -1  # standing on ball 0, it leaves for ball 2
    assert library.graph.distances[outcome.next_node, balls[2]] < library.graph.distances[balls[0], balls[2]]
    (pick,) = human.policy_outcomes(balls[2], (GROUND, GROUND, GROUND))
    assert pick.picked_ball == 2


def test_switching_human_changes_plan_after_a_ball():
    library = build_lab_library()
    spec = find_member("toxic-waste", "order-201-switch-1")
    human = spec.factory()(library, 0)
    before = human._targets(0, (GROUND, GROUND, GROUND))
    after = human._targets(0, (2, GROUND, GROUND))  # ball 0 in the container: nearest-first now
    assert before == [2] and after == [1]


def _answers(name: str, asks: int = 200) -> list:
    env = gymnasium.make(LAB_ID, human=find_member("toxic-waste", name).plugin, disable_env_checker=True)
    library = env.unwrapped.library
    _, info = env.reset(seed=1)
    heard = []
    for _ in range(asks):
        observation, _, terminated, truncated, info = env.step(library.locate_action)
        heard.append((int(observation[1]), info["human_node"]))
        if terminated or truncated:
            _, info = env.reset()
    env.close()
    return heard


def test_quiet_human_never_answers_and_misleading_human_names_other_nodes():
    none = 5  # the lab's "no human reading"
    assert all(reading == none for reading, _ in _answers("quiet-p100"))
    honest = _answers("thesis")
    misled = _answers("mislead-p50")
    wrong = lambda heard: np.mean([r != n for r, n in heard if r != none])  # noqa: E731
    assert wrong(misled) > wrong(honest) + 0.2


def test_dropping_human_puts_the_ball_back_on_the_ground():
    library = build_lab_library()
    human = find_member("toxic-waste", "drop-p30").factory()(library, 0)
    outcomes = human.policy_outcomes(library.tasks[0][0], (HELD, GROUND, GROUND))
    assert {o.dropped: o.probability for o in outcomes} == pytest.approx({True: 0.3, False: 0.7})
    env = gymnasium.make(
        LAB_ID, human=find_member("toxic-waste", "drop-p30").plugin, disable_env_checker=True
    )
    env.reset(seed=0, options={"task": 0, "robot_node": 4, "human_node": 0})
    statuses = []
    for _ in range(40):  # the robot stays away: a picked ball is held, then dropped, then picked again
        _, _, _, _, info = env.step(library.stay_action)
        statuses.append(info["ball_status"][0])
    assert any(a == HELD and b == GROUND for a, b in zip(statuses, statuses[1:], strict=False))


def test_teammates_command_lists_every_member(capsys):
    assert main(["bench", "teammates", "--domain", "gridworld", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert listed["version"] == SUITE_VERSION
    assert [m["name"] for m in listed["members"]] == [s.name for s in population("gridworld")]
    assert main(["bench", "teammates", "--domain", "toxic-waste"]) == 0
    assert "held-out    quiet-p100" in capsys.readouterr().out
    assert main(["bench", "teammates", "--domain", "pursuit", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)["members"]
    assert [m["name"] for m in listed] == [s.name for s in population("pursuit")]
    assert {m["split"] for m in listed} == set(SPLITS)
    assert {m["params"]["family"] for m in listed} == {"named", "seats", "sticky", "spec", "learned"}
    assert main(["bench", "teammates", "--domain", "nowhere"]) == 2
    assert "--domain 'nowhere': no benchmark population" in capsys.readouterr().err


def test_population_file_is_checked_with_its_place(tmp_path):
    good = tmp_path / "mine.json"
    good.write_text(
        json.dumps(
            {
                "name": "mine",
                "members": [
                    {
                        "name": "careful",
                        "domain": "gridworld",
                        "type": "lazy",
                        "params": {"family": "lazy", "p": 0.9},
                    }
                ],
            }
        )
    )
    name, version, specs = load_population(good)
    assert (name, version, specs[0].split, specs[0].params["p"]) == ("mine", "1", "mine", 0.9)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"members": [{"name": "x", "domain": "gridworld", "plugin": "no_colon"}]}))
    with pytest.raises(ConfigError, match=r"bad.json: members\[0\]\.plugin 'no_colon'"):
        load_population(bad)
    bad.write_text(
        json.dumps({"members": [{"name": "x", "domain": "gridworld", "params": {"family": "odd"}}]})
    )
    with pytest.raises(ConfigError, match=r"members\[0\]: benchmark teammate x: family 'odd'"):
        load_population(bad)
    bad.write_text("{\n  oops")
    with pytest.raises(ConfigError, match=r"bad.json:2: not JSON"):
        load_population(bad)
