"""Chapter-4 navigation (ntu, isr, pentagon): map sizes, hand-checked rules, the three teams, UCT with the exact
model one step from the exit, Eq. 4.3 for N agents, the protocol and the command."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from embodied_adhoc.cli import main
from embodied_adhoc.decision.agents.teamwork import sample_rows
from embodied_adhoc.decision.uct import BatchedUct, PlainUct, UctConfig
from embodied_adhoc.domains.chapter5.grid_maps import load_map
from embodied_adhoc.domains.navigation4 import TEAMS, Navigation4
from embodied_adhoc.domains.pursuit4 import ExactEnvironment, ExactTeam
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.domains.teamster_protocol import ProtocolConfig, run_trial
from embodied_adhoc.learning.teamster import LearnedEnvironment, LearnedTeam
from embodied_adhoc.learning.teamster_navigation import NavigationFeatures

torch.set_num_threads(1)
UP, DOWN, LEFT, RIGHT, STAY = range(5)
NTU, ISR, PENTAGON = Navigation4("ntu"), Navigation4("isr"), Navigation4("pentagon")


def cells(world: Navigation4, *row_columns: tuple[int, int]) -> np.ndarray:
    index = {tuple(rc): k for k, rc in enumerate(world.grid.cells.tolist())}
    return np.array([index[rc] for rc in row_columns])


@pytest.mark.parametrize(
    "world, agents, n_cells, shape", [(NTU, 4, 16, (6, 6)), (ISR, 3, 43, (10, 9)), (PENTAGON, 3, 52, (9, 11))]
)
def test_sizes_and_the_chapter5_open_cells(world, agents, n_cells, shape):
    assert (world.n_agents, world.cells, world.grid.shape) == (agents, n_cells, shape)
    assert world.exits.size == agents and world.starts.size == agents  # N agents, N exits, N spawn cells
    assert np.array_equal(world.grid.cells, load_map(world.name).cells)  # same facility as chapter 5's file
    states = world.sample_states(np.random.default_rng(0), 50)
    assert all(len(set(row)) == agents for row in states.tolist()) and np.isin(states, world.starts).all()


def test_hand_checked_transition_on_ntu():
    # ntu:  ###G## / #S..S# / G.##.# / #.##.G / #S..S# / ##G###  (exits (0,3), (2,0), (3,5), (5,2))
    rng = np.random.default_rng(0)
    # seat 0 right into (1,2) which seat 1 still holds at its turn: blocked; seat 1 right to (1,3); seat 2 up;
    # seat 3 on the exit (3,5) left: an agent that has left stays
    state = cells(NTU, (1, 1), (1, 2), (4, 1), (3, 5))[None]
    nxt, reward, done = NTU.step(state, np.array([[RIGHT, RIGHT, UP, LEFT]]), rng)
    assert nxt[0].tolist() == cells(NTU, (1, 1), (1, 3), (3, 1), (3, 5)).tolist()
    assert reward[0] == -1.0 and not done[0]
    # seat order: seat 0 leaves (1,3) first, so seat 1 may follow into it (a chain)
    state = cells(NTU, (1, 3), (1, 2), (4, 1), (3, 5))[None]
    nxt, _, _ = NTU.step(state, np.array([[RIGHT, RIGHT, STAY, STAY]]), rng)
    assert nxt[0].tolist() == cells(NTU, (1, 4), (1, 3), (4, 1), (3, 5)).tolist()
    # the last agent steps onto the last free exit: -1 + 100, the episode ends
    state = cells(NTU, (2, 1), (0, 3), (3, 5), (5, 2))[None]
    nxt, reward, done = NTU.step(state, np.array([[LEFT, DOWN, UP, RIGHT]]), rng)
    assert (
        nxt[0].tolist() == cells(NTU, (2, 0), (0, 3), (3, 5), (5, 2)).tolist()
        and reward[0] == 99.0
        and done[0]
    )
    # the changed environment: a move fails with the slip probability
    slipping = Navigation4("ntu", slip=0.5)
    moved = [
        slipping.step(cells(NTU, (1, 1), (0, 3), (3, 5), (5, 2))[None], np.array([[DOWN, 4, 4, 4]]), rng)[0][
            0, 0
        ]
        for _ in range(400)
    ]
    assert 0.4 < np.mean(np.array(moved) == cells(NTU, (2, 1))[0]) < 0.6
    # the mirrored environment: the ad hoc agent's "down" from (1,1) goes up into the wall (stays), its "right"
    # goes left into the wall; its "up" goes down to (2,1); the others' moves are unchanged
    mirrored = Navigation4("ntu", mirror=True)
    state = cells(NTU, (1, 1), (1, 4), (4, 1), (5, 2))[None]
    assert (
        mirrored.step(state, np.array([[UP, DOWN, STAY, STAY]]), rng)[0][0].tolist()
        == cells(NTU, (2, 1), (2, 4), (4, 1), (5, 2)).tolist()
    )
    assert mirrored.step(state, np.array([[DOWN, STAY, STAY, STAY]]), rng)[0][0, 0] == state[0, 0]


def test_teams_act_as_described_on_isr():
    # isr rows 7-9: "........." / "##..#.#.#" / "##G.#####"; exits (0,7), (1,0), (9,2); the ad hoc agent at (3,8)
    state = cells(ISR, (3, 8), (7, 2), (7, 3))[None]
    altruistic = ISR.team_policy("altruistic", state)[0]
    selfish = ISR.team_policy("selfish", state)[0]
    # least total distance (4 + 8 + 3): seat 1 to (1,0) (left, up the west corridor), seat 2 to (9,2) (down)
    assert altruistic[0, LEFT] == 1.0 and altruistic[1, DOWN] == 1.0
    # selfish: both head for their nearest exit (9,2), whoever is nearer
    assert selfish[0, DOWN] == 1.0 and selfish[1, DOWN] == 1.0
    # weighted-altruistic: softmin over the finite assignments (totals 15, 23, 23, 27; seat 0 is walled off
    # from (9,2)): seat 1 goes left in the assignments of 15 and 27, down in the two of 23
    weighted = ISR.team_policy("weighted-altruistic", state)[0]
    z = np.exp(-15) + 2 * np.exp(-23) + np.exp(-27)
    assert np.isclose(weighted[0, LEFT], (np.exp(-15) + np.exp(-27)) / z)
    assert np.isclose(weighted[0, DOWN], 2 * np.exp(-23) / z)
    # once seat 1 has left by (9,2), the selfish seat 2 takes the nearest exit still free: (1,0) west (9 < 11)
    gone = ISR.team_policy("selfish", cells(ISR, (3, 8), (9, 2), (7, 3))[None])[0]
    assert gone[0, STAY] == 1.0 and gone[1, LEFT] == 1.0
    for team in TEAMS:
        probs = ISR.team_policy(team, ISR.sample_states(np.random.default_rng(1), 30), agents=range(3))
        assert probs.shape == (30, 3, 5) and np.allclose(probs.sum(-1), 1.0)
    with pytest.raises(ConfigError, match="team="):
        ISR.team_policy("greedy", state)


@pytest.mark.parametrize(
    "world, team, expected", [(NTU, "altruistic", 98.0), (ISR, "selfish", 94.0), (PENTAGON, "selfish", 88.0)]
)
def test_a_team_on_its_own_scores_the_thesis_original_teammate_row(world, team, expected):
    """Tables 4.5-4.7's "Original Teammate" rows that have no spread (98.0, 94.0, 88.0 with +-0.0)."""
    rng = np.random.default_rng(2)
    for _ in range(6):
        state, total = world.sample_states(rng, 1), 0.0
        for _ in range(100):
            joint = sample_rows(world.team_policy(team, state, agents=range(world.n_agents)), rng)
            state, reward, done = world.step(state, joint, rng)
            total += reward[0]
            if done[0]:
                break
        assert total == expected


@pytest.mark.parametrize("planner", [BatchedUct(UctConfig(depth=10)), PlainUct(UctConfig(depth=10))])
def test_uct_with_the_exact_model_steps_onto_the_last_free_exit(planner):
    team, env = ExactTeam(NTU, "altruistic"), ExactEnvironment(NTU)
    state = cells(NTU, (2, 1), (0, 3), (3, 5), (5, 2))  # the teammates have left; (2,0) is one step left

    def simulate(states, actions, rng):
        mates = sample_rows(team.probs(states), rng)
        return env.step(states, np.concatenate([actions[:, None], mates], axis=1), rng)

    for seed in range(3):
        assert planner.plan(state, simulate, np.random.default_rng(seed)) == LEFT


def _selfish_stream(rng, steps):
    """The selfish team in seats 1-3 and uniform actions in seat 0, episodes restarted when they end."""
    state = NTU.sample_states(rng, 1)
    for _ in range(steps):
        joint = sample_rows(NTU.team_policy("selfish", state, agents=range(4)), rng)
        joint[0, 0] = rng.integers(5)
        nxt, reward, done = NTU.step(state, joint, rng)
        yield state[0], joint[0], float(reward[0]), nxt[0], bool(done[0])
        state = NTU.sample_states(rng, 1) if done[0] else nxt


def test_learned_transition_factorises_over_n_agents_and_fits_the_rules():
    features = NavigationFeatures(NTU)
    env = LearnedEnvironment(NTU, np.random.default_rng(0), features=features)
    team = LearnedTeam(NTU, np.random.default_rng(1), features=features)
    for row in _selfish_stream(np.random.default_rng(3), 600):
        env.update(*row)
        team.update(row[0], row[1][1:])
    rng = np.random.default_rng(4)
    states = NTU.sample_states(rng, 6)
    actions = rng.integers(0, 5, size=(6, 4))
    factors = env.transition_probs(states, actions)
    assert factors.shape == (6, 4, 5) and np.allclose(factors.sum(-1), 1.0)
    joint = np.einsum("ba,bc,bd,be->bacde", *(factors[:, n] for n in range(4)))
    assert np.allclose(joint.reshape(6, -1).sum(-1), 1.0)  # Eq. 4.3 over all 5**4 move combinations
    # fitted: on fresh steps of the same process each agent's true move is the most likely one
    held_out = list(_selfish_stream(np.random.default_rng(5), 200))
    states, actions, nxt = (np.stack([row[k] for row in held_out]) for k in (0, 1, 3))
    moves = features.move_of[states, nxt]
    assert (env.transition_probs(states, actions).argmax(-1) == moves).mean() > 0.9
    mates = team.probs(states)
    assert mates.shape == (200, 3, 5) and (mates.argmax(-1) == actions[:, 1:]).mean() > 0.9


def test_protocol_on_a_map_same_seed_same_result():
    config = ProtocolConfig(
        domain="ntu", steps=6, points=2, eval_episodes=1, iterations=10, depth=4, changed=0.2
    )
    first, second = run_trial("teamster", 0, config), run_trial("teamster", 0, config)
    first.pop("seconds"), second.pop("seconds")
    assert first == second and set(first["curves"]) == set(TEAMS) and len(first["changed"]) == 3
    assert all(-100.0 <= value <= 98.0 for _, value in first["curves"]["selfish"])
    assert first["config"]["domain"] == "ntu" and "domain" not in ProtocolConfig().as_dict()
    with pytest.raises(ConfigError, match="domain"):
        ProtocolConfig(domain="mit")


def test_command_on_a_map(tmp_path, capsys):
    argv = [
        "teamster",
        "ntu",
        "--agents",
        "original,altruistic",
        "--steps",
        "4",
        "--points",
        "2",
        "--eval-episodes",
        "2",
        "--trials",
        "2",
        "--quiet",
        "--json",
        "--out",
        str(tmp_path),
    ]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["config"]["iterations"] == 100 and summary["config"]["depth"] == 10  # Table 4.1's ntu row
    curve = summary["agents"]["original"]["curves"]["altruistic"]
    assert [p["step"] for p in curve] == [0, 2, 4] and curve[-1]["reward"]["mean"] == 98.0
    assert "after learning" in (tmp_path / "table.md").read_text()
    assert main(["teamster", "ntu", "--agents", "greedy", "--quiet"]) == 2
    assert "--agents 'greedy'" in capsys.readouterr().err
