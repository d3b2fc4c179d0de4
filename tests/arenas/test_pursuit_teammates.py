"""The grid arenas' pair teammate 'greedy' and the pursuit POMDP's 'greedy' share a name, not a policy
(teammates/pursuit_teams.py says why each stays with its rules): the arena's walker follows the larger gap four
times in five, the POMDP's is deterministic, columns first."""

import numpy as np

from embodied_adhoc.domains.chapter5 import build_library
from embodied_adhoc.domains.grid_rules import GridRules, GridState, pair_tasks
from embodied_adhoc.domains.grid_rules_team import team_actions
from embodied_adhoc.domains.pursuit import two_predator_config
from embodied_adhoc.teammates.pursuit_teams import PURSUIT_TEAMS

UP, DOWN, LEFT, RIGHT = 0, 1, 2, 3


def test_the_arenas_greedy_teammate_draws_its_axis():
    rules = GridRules(two_predator_config())
    # the teammate (agent 1) at (0, 0), the prey three rows down and two columns right, the robot far away
    state = GridState(np.array([[4, 4], [0, 0]]), np.ones(2, int), np.array([[3, 2]]), np.array([1]))
    moves = [
        int(
            team_actions(
                rules, state, pair_tasks()[0], PURSUIT_TEAMS["greedy"], np.random.default_rng(seed), [1]
            )[0]
        )
        for seed in range(40)
    ]
    assert set(moves) == {DOWN, RIGHT} and moves.count(DOWN) > moves.count(RIGHT)  # mostly the larger gap


def test_the_pomdps_greedy_teammate_is_deterministic_and_goes_columns_first():
    library = build_library("pursuit-teammate")
    policy = library.teammates["greedy"](0)  # pi(b | x) over the model's states
    assert np.all(policy.max(axis=1) == 1.0)  # one action per state
    # state names "t<row>_<col>-p<row>_<col>": the teammate's and the prey's offsets from the robot
    names = library.pomdps[0].state_names
    # its nearest capture cell (N+S task) one row and one column away: a column move, every time
    assert np.argmax(policy[names.index("t-1_0-p1_1")]) == RIGHT
    assert np.argmax(policy[names.index("t1_0-p-1_-1")]) == LEFT
