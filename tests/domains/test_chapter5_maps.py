"""Chapter-5 map domains (ntu, isr, mit, pentagon, cit and any map file): sizes, rules, the goal-layout bug."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from embodied_adhoc.domains.chapter5 import build_library
from embodied_adhoc.domains.chapter5.grid_maps import BUILTIN_MAPS, load_map, parse_map
from embodied_adhoc.domains.chapter5.navigation import build_map_library
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.paths import asset

REFERENCE_MAPS = Path(__file__).resolve().parents[3] / "shared" / "reference" / "maps"
TABLE_5_2 = {"ntu": (241, 4), "isr": (1807, 3), "mit": (2163, 3), "pentagon": (2653, 3), "cit": (4831, 3)}


@pytest.mark.parametrize("name", BUILTIN_MAPS)
def test_shipped_maps_match_the_reference(name):
    reference = REFERENCE_MAPS / f"{name}.txt"
    if not reference.is_file():
        pytest.skip("reference maps not available in this checkout")
    assert asset(f"maps/{name}.txt").read_text() == reference.read_text()


@pytest.mark.parametrize("name", BUILTIN_MAPS)
def test_sizes_follow_table_5_2(name):
    library = build_library(name)
    n = load_map(name).n_cells
    states, models = TABLE_5_2[name]
    assert library.n_states == n * (n - 1) + 1 == states
    assert library.n_models == models
    assert (library.n_actions, library.n_observations) == (5, 81)
    for pomdp in library.pomdps:
        for a in range(5):
            np.testing.assert_allclose(pomdp.transitions[a].sum(axis=1), 1.0, atol=1e-12)
            np.testing.assert_allclose(pomdp.observations[a].sum(axis=1), 1.0, atol=1e-12)
        np.testing.assert_allclose(pomdp.initial_belief.sum(), 1.0)


def _state(library, agent: str, teammate: str) -> int:
    return library.state_names.index(f"a{agent}-t{teammate}")


def test_hand_checked_collision_and_observation_on_ntu():
    library = build_map_library("ntu")
    mmdp = library.mmdps[0]
    x = _state(library, "r1c2", "r1c3")
    # agent right into the teammate's cell while the teammate moves left into the agent's: both stay
    joint = 3 * 5 + 2
    assert mmdp.transitions[joint][x, x] == 1.0
    # agent right, teammate right: the teammate frees the cell first, the agent follows
    joint = 3 * 5 + 3
    assert mmdp.transitions[joint][x, _state(library, "r1c3", "r1c4")] == 1.0
    # sensors at r1c2 with the teammate at r1c3: up wall, down wall, left nothing, right teammate
    z = 27 * 1 + 9 * 1 + 3 * 0 + 2
    observation = library.pomdps[0].observations[4]
    assert observation[x, z] == pytest.approx(0.8**3)
    assert observation[x].sum() == pytest.approx(1.0)
    # a misread wall (as nothing) on the up sensor: eps / 2 * 0.8 * 0.8
    assert observation[x, 9 * 1 + 2] == pytest.approx(0.1 * 0.8 * 0.8)


def test_goal_state_pays_100_then_absorbs():
    library = build_map_library("ntu")
    pomdp = library.pomdps[0]  # goals r1c1 + r4c1
    goal = _state(library, "r1c1", "r4c1")
    assert pomdp.rewards[goal, 0] == 100.0
    assert pomdp.transitions[0][goal, library.absorbing_state] == 1.0
    assert pomdp.rewards[library.absorbing_state].tolist() == [0.0] * 5
    assert pomdp.rewards[_state(library, "r1c1", "r4c4"), 0] == -1.0


@pytest.mark.parametrize("name, identical", [("ntu", 6), ("mit", 1)])
def test_goal_layout_bug_is_fixed_and_reproducible(name, identical):
    def identical_pairs(library):
        rewards = [p.rewards for p in library.pomdps]
        return sum(
            np.array_equal(rewards[i], rewards[j])
            for i in range(len(rewards))
            for j in range(i + 1, len(rewards))
        )

    assert identical_pairs(build_map_library(name)) == 0
    assert identical_pairs(build_map_library(name, bug_compatible=True)) == identical


def test_any_map_file_is_accepted(tmp_path):
    path = tmp_path / "corridor.txt"
    path.write_text("S..G\n#..#\nS..G\n")
    library = build_library("map", map=str(path))
    n = 10
    assert library.n_states == n * (n - 1) + 1 and library.n_models == 1


@pytest.mark.parametrize(
    "text, message",
    [
        ("S.G\n.x.\nS.G\n", "bad.txt:2:2: bad character 'x'"),
        ("S.#G\n..#.\nS.#G\n", "bad.txt:1:4: goal 'G' is unreachable"),
        ("S.G\n####\n", "bad.txt:2: the row has 4 cells"),
        ("SG\n##\n", "too small for two agents"),
    ],
)
def test_bad_maps_are_refused_with_their_place(tmp_path, text, message):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message.replace("(", r"\(")):
        load_map(path)


def test_parse_map_names_line_and_column():
    with pytest.raises(ConfigError, match=r"mine:3:5: bad character '\?'"):
        parse_map("S..G\nS..G\n....?\n", "mine")
