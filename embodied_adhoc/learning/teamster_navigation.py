"""Network encodings of the chapter-4 navigation maps (ntu, isr, pentagon; ``domains/navigation4.py``) for the
learned models of ``learning/teamster.py`` and PLASTIC-Policy's DQN: the same networks as on pursuit (Table
4.2), for N agents.

On a map the walls make absolute position matter (pursuit's torus does not), so an agent's view of the state is
the one-hot of its own cell followed by the one-hot cells of the other agents in seat order (``N * C`` inputs,
C open cells) instead of pursuit's toroidal offsets:

* team model (Eq. 4.1), one row per teammate: its seat one-hot (N - 1) and its view;
* transition model (Eq. 4.3), one row per agent n: its index one-hot (N), its view, its own action and every
  agent's action (one-hot), output a categorical over the five moves (stay also for a blocked move), so
  ``P(x' | x, a) = prod_n p_n(s_n' | x, a)`` for the N agents;
* reward model: every agent's cell (the ad hoc agent's view), output ``P(every agent has left | x')``; the
  planner's reward is ``-1 + 100 P`` (the domain's -1 per step and +100 at the end), terminal above 1/2;
* DQN: the ad hoc agent's view.
"""

from __future__ import annotations

import numpy as np

from embodied_adhoc.domains.navigation4 import N_ACTIONS, Navigation4


class NavigationFeatures:
    """One-hot encodings of navigation states (batched numpy), with the attributes the learned models read."""

    def __init__(self, world: Navigation4) -> None:
        n, cells = world.n_agents, world.cells
        self.world, self.size = world, world.name
        self.n_agents = self.n_actors = n
        self.n_mates = n - 1
        self.step_reward, self.goal_reward = world.step_reward, world.exit_reward
        self.view_width = n * cells
        self.team_width = self.n_mates + self.view_width
        self.transition_width = n + self.view_width + N_ACTIONS + n * N_ACTIONS
        self.reward_width = self.agent_width = self.view_width
        ids = np.arange(cells)
        moves = np.full((cells, cells), -1, dtype=np.int64)
        for k in range(N_ACTIONS):  # stay last: a blocked move is learned as staying
            moves[ids, world.neighbours[:, k]] = k
        self.move_of = moves
        self._order = np.array([[n_] + [m for m in range(n) if m != n_] for n_ in range(n)])  # (N, N)

    def views(self, states: np.ndarray) -> np.ndarray:
        """(B, N, N * C) each agent's own cell one-hot, then the others' in seat order."""
        eye = np.eye(self.world.cells, dtype=np.float32)
        ordered = states[:, self._order]  # (B, N, N)
        return eye[ordered].reshape(states.shape[0], self.n_agents, -1)

    def transition(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """(B * N, transition_width) Eq. 4.3's inputs per agent."""
        count, n = states.shape
        eye = np.eye(N_ACTIONS, dtype=np.float32)
        agent = np.broadcast_to(np.eye(n, dtype=np.float32), (count, n, n))
        own = eye[actions]  # (B, N, 5)
        joint = np.broadcast_to(own.reshape(count, 1, -1), (count, n, n * N_ACTIONS))
        rows = np.concatenate([agent, self.views(states), own, joint], axis=-1)
        return rows.reshape(count * n, -1)

    def reward(self, states: np.ndarray) -> np.ndarray:
        """(B, N * C) every agent's cell."""
        return self.views(states)[:, 0]

    def team(self, states: np.ndarray) -> np.ndarray:
        """(B * (N - 1), team_width) per teammate: seat one-hot and its view."""
        count = states.shape[0]
        seat = np.broadcast_to(np.eye(self.n_mates, dtype=np.float32), (count, self.n_mates, self.n_mates))
        rows = np.concatenate([seat, self.views(states)[:, 1:]], axis=-1)
        return rows.reshape(count * self.n_mates, -1)

    def agent(self, states: np.ndarray) -> np.ndarray:
        """(B, N * C) the ad hoc agent's view (the DQN's input)."""
        return self.views(states)[:, 0]


def features_for(world):
    """The network encodings of a chapter-4 world: pursuit's toroidal offsets or a navigation map's cells."""
    if isinstance(world, Navigation4):
        return NavigationFeatures(world)
    from embodied_adhoc.learning.teamster import Features

    return Features(world)


# Table 4.3's navigation rows: (lr, hidden, epsilon start, epsilon end, initial random steps, target update
# every) and the original implementation's interaction length per team, which scales the random warm-up here
# (10,000 of 100,000 steps on ntu, 15,000 of 100,000 on isr, 15,000 of 125,000 on pentagon).
TABLE_4_3 = {
    "ntu": (0.01, 512, 0.75, 0.05, 10_000, 3, 100_000),
    "isr": (0.001, 512, 0.95, 0.05, 15_000, 4, 100_000),
    "pentagon": (0.001, 512, 0.95, 0.05, 15_000, 4, 125_000),
}


def dqn_config(world, horizon: int):
    """PLASTIC-Policy's DQN for ``world`` (Table 4.3): pursuit's row is :class:`DqnConfig`'s default; on a map
    the initial random steps are the same fraction of ``horizon`` (the interaction per team) as in the original
    (so that a shorter interaction is not all warm-up)."""
    from embodied_adhoc.learning.dqn import DqnConfig

    if not isinstance(world, Navigation4):
        return None
    lr, hidden, start, end, warm, target, original = TABLE_4_3.get(world.name, TABLE_4_3["isr"])
    return DqnConfig(
        hidden=hidden,
        lr=lr,
        epsilon_start=start,
        epsilon_end=end,
        random_steps=round(warm * horizon / original),
        target_every=target,
    )
