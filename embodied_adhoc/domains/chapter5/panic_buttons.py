"""Panic Buttons (section 5.1.3, Table 5.1; Brockman et al. 2016): two agents must press two buttons together.

An open ``size`` x ``size`` grid (3, 4 or 5 in Table 5.1); state = both agents' cells (they may share one) plus
the absorbing state: ``size^4 + 1`` states. Moves are deterministic (a move into the border stays). A task is a
button configuration (two cells); the buttons are pressed when the two agents stand on them at the same time:
+100, then the absorbing state; -1 per step otherwise (``library.step_rewards``). Fully observable (BOPA's
setting): ``z = y``. Initial belief: uniform over the states that are not pressed.

Button configurations (the thesis does not give them; ours, fixed): corner pairs top-left + top-right,
bottom-left + bottom-right, top-left + bottom-right. Teammates (one library per teammate, 3 tasks each):

* ``optimal``: knows the task and acts optimally (the MMDP's optimal marginal, ``library.optimal_teammate_policy``);
* ``suboptimal``: the optimal teammate that fails to act (stays) with probability 0.3;
* ``random``: uniform over the 5 actions.
"""

from __future__ import annotations

import numpy as np

from embodied_adhoc.domains.chapter5.grid_maps import ACTION_NAMES, STAY, open_grid
from embodied_adhoc.domains.chapter5.library import (
    ModelLibrary,
    deterministic_matrix,
    joint_mdp,
    optimal_teammate_policy,
    reduce_joint,
    step_rewards,
    task_pomdp,
)
from embodied_adhoc.domains.chapter5.navigation import (
    goal_mask,
    independent_moves_joint,
    pair_states,
    state_table,
)
from embodied_adhoc.errors import ConfigError

__all__ = ["PANIC_TEAMMATES", "build_panic_buttons", "button_configurations"]

PANIC_TEAMMATES = ("optimal", "suboptimal", "random")
SUBOPTIMAL_FAILURE = 0.3


def button_configurations(size: int) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """The three button pairs as ((row, column), (row, column)); see the module docstring."""
    last = size - 1
    return [((0, 0), (0, last)), ((last, 0), (last, last)), ((0, 0), (last, last))]


def build_panic_buttons(size: int = 3, teammate: str = "optimal", horizon: int = 2000) -> ModelLibrary:
    """The 3-task library of one grid size and teammate (a Table 5.1 column)."""
    if size < 2:
        raise ConfigError(f"panic buttons: size must be >= 2, got {size}")
    if teammate not in PANIC_TEAMMATES:
        raise ConfigError(
            f"panic buttons: unknown teammate {teammate!r}; choose from {', '.join(PANIC_TEAMMATES)}"
        )
    grid = open_grid(size, size)
    cell_of = {tuple(int(v) for v in cell): k for k, cell in enumerate(grid.cells)}
    agent, teammate_cells = pair_states(grid.n_cells, True)
    table = state_table(grid.n_cells, agent, teammate_cells)
    absorbing, n_states = len(agent), len(agent) + 1
    names = tuple(
        f"a{grid.cell_name(i)}-t{grid.cell_name(j)}" for i, j in zip(agent, teammate_cells, strict=True)
    )
    names += ("absorbing",)
    observation = deterministic_matrix(np.arange(n_states), n_states)
    pomdps, mmdps, task_names = [], [], []
    for first, second in button_configurations(size):
        pair = (cell_of[first], cell_of[second])
        goal = np.append(goal_mask(agent, teammate_cells, grid.goals, pair), False)
        rewards = step_rewards(goal, absorbing, len(ACTION_NAMES))
        joint = independent_moves_joint(grid, agent, teammate_cells, table, goal, 0.0)
        mmdp = joint_mdp(joint, rewards, ACTION_NAMES)
        if teammate == "random":
            policy = np.full((n_states, len(ACTION_NAMES)), 1.0 / len(ACTION_NAMES))
        else:
            policy = optimal_teammate_policy(mmdp, len(ACTION_NAMES))
            if teammate == "suboptimal":
                policy = (1.0 - SUBOPTIMAL_FAILURE) * policy
                policy[:, STAY] += SUBOPTIMAL_FAILURE
        start = ~goal
        start[absorbing] = False
        transitions = reduce_joint(joint, policy)
        pomdps.append(task_pomdp(transitions, rewards, observation, start, names, ACTION_NAMES, names))
        mmdps.append(mmdp)
        task_names.append(f"{grid.cell_name(pair[0])}+{grid.cell_name(pair[1])}")
    settings = {"size": size, "teammate": teammate}
    return ModelLibrary(
        "panic-buttons",
        tuple(task_names),
        tuple(pomdps),
        tuple(mmdps),
        horizon,
        0.0,
        0,
        absorbing,
        f"panic buttons {size}x{size}, {teammate} teammate, 3 button configurations",
        settings,
    )
