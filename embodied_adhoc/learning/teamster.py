"""TEAMSTER's learned models (thesis sections 4.0.1-4.0.2 and 4.1.3) on chapter-4 pursuit.

* :class:`LearnedTeam`, a team model ``pi^{-alpha}(A | x) = prod_n pi^n(a^n | x)`` (Eq. 4.2) trained by
  maximum likelihood (Eq. 4.1) on the observed (state, teammates' actions): one Adam step on a minibatch of its
  replay buffer per observed step (the *online* team model, line 12 of Algorithm 1); :meth:`frozen_copy` is
  the library entry stored after the interaction. One network serves the three teammates, told apart by a
  one-hot of the seat (the thesis draws one network per teammate, Fig. 4.6(a); same inputs otherwise).
* :class:`LearnedEnvironment`, the environment model: the factored transition network of Eq. 4.3 (one
  categorical over the five moves per agent, ``P(x' | x, a) = prod_n p_n(s_n' | x, a)``, input the agent's
  one-hot index, its offsets to the other agents and the predators' actions, plus its own action in front)
  and the reward network (offsets prey->predators, sigmoid output ``P(capture)``, evaluated on the next state).
  Table 4.2: transition 2 x 256 ReLU, Adam 0.001; reward 2 x 64 ReLU, Adam 0.01; team 2 x 48 ReLU, Adam 0.001;
  replay buffers of 15,000 samples, minibatches of 32.

Models are evaluated in batches (all leaves of a UCT wave at once, one forward per network per depth) by a
numpy forward over views of the torch parameters (:class:`~embodied_adhoc.learning.blocks.NumpyMlp`): no torch
dispatch and no autograd in the planner, and no weight export after an Adam step (measured in docs/teamster.md);
the pursuit simulator's transition network reads contiguous copies instead, refreshed after each Adam step
(:class:`PackedMlp`: the same products, packed more cheaply by OpenBLAS).
On pursuit the planner's simulator fuses the team model's draw with the environment model's step
(:class:`PursuitSimulator`), and one optimiser steps the transition and reward networks after one backward pass.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from embodied_adhoc.domains.pursuit4 import N_ACTIONS, N_AGENTS, N_PREDATORS, PREY, Pursuit4
from embodied_adhoc.learning.blocks import NumpyMlp, ReplayBuffer, adam_step, mlp, seeded_module, softmax
from embodied_adhoc.learning.weights import load_into, save_weights

CAPACITY = 15_000
BATCH = 32
_OTHERS = np.array([[m for m in range(N_AGENTS) if m != n] for n in range(N_AGENTS)])  # (5, 4)


class Features:
    """One-hot encodings of chapter-4 pursuit states for the networks (batched numpy)."""

    n_agents, n_mates, n_actors = N_AGENTS, 3, N_PREDATORS  # state columns, teammates, agents that act
    step_reward, goal_reward = 0.0, 1.0  # reward = step_reward + goal_reward * P(goal | x') (1 per capture)

    def __init__(self, world: Pursuit4) -> None:
        self.world, self.size = world, world.size
        self.offset_width = 4 * 2 * world.size
        self.team_width = 3 + self.offset_width
        self.transition_width = N_AGENTS + self.offset_width + N_ACTIONS + N_PREDATORS * N_ACTIONS
        self.reward_width = self.agent_width = self.offset_width
        half = world.size // 2
        # (C, C, 2 * size) one-hot of the toroidal offset (rows then columns) from one cell to another
        eye = np.eye(world.size, dtype=np.float32)
        self.offset_code = np.concatenate(
            [eye[world.delta[..., 0] + half], eye[world.delta[..., 1] + half]], -1
        )
        self.pair_code = self.offset_code.reshape(world.cells * world.cells, -1)  # by from * C + to
        cells = np.arange(world.cells)
        moves = np.full((world.cells, world.cells), -1, dtype=np.int64)
        for k in range(N_ACTIONS):
            moves[cells, world.neighbours[:, k]] = k
        self.move_of = moves  # (C, C): the move class taking a cell to another (-1: not one step)

    def offsets(self, states: np.ndarray) -> np.ndarray:
        """(B, 5, 40) each agent's one-hot offsets to the other four (in index order)."""
        others = states[:, _OTHERS]  # (B, 5, 4)
        code = self.offset_code[states[:, :, None], others]  # (B, 5, 4, 2 size)
        return code.reshape(states.shape[0], N_AGENTS, -1)

    def transition(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """(B * 5, 70) Eq. 4.3's inputs: agent one-hot, offsets, own action (zeros for the prey), predators'
        actions."""
        count = states.shape[0]
        eye = np.eye(N_ACTIONS, dtype=np.float32)
        agent = np.broadcast_to(np.eye(N_AGENTS, dtype=np.float32), (count, N_AGENTS, N_AGENTS))
        own = np.concatenate([eye[actions], np.zeros((count, 1, N_ACTIONS), np.float32)], axis=1)
        joint = np.broadcast_to(
            eye[actions].reshape(count, 1, -1), (count, N_AGENTS, N_PREDATORS * N_ACTIONS)
        )
        rows = np.concatenate([agent, self.offsets(states), own, joint], axis=-1)
        return rows.reshape(count * N_AGENTS, -1)

    def reward(self, states: np.ndarray) -> np.ndarray:
        """(B, 40) offsets from the prey to the four predators."""
        return self.offset_code[states[:, PREY][:, None], states[:, :N_PREDATORS]].reshape(
            states.shape[0], -1
        )

    def team(self, states: np.ndarray) -> np.ndarray:
        """(B * 3, 43) per teammate: seat one-hot and its offsets."""
        count = states.shape[0]
        seat = np.broadcast_to(np.eye(3, dtype=np.float32), (count, 3, 3))
        rows = np.concatenate([seat, self.offsets(states)[:, 1:N_PREDATORS]], axis=-1)
        return rows.reshape(count * 3, -1)

    def agent(self, states: np.ndarray) -> np.ndarray:
        """(B, 40) the ad hoc agent's offsets to everyone (the DQN's input)."""
        return self.offsets(states)[:, 0]


class LearnedTeam:
    """A team model learned online by Eq. 4.1 (negative log-likelihood of the observed teammates' actions)."""

    def __init__(
        self,
        world: Pursuit4,
        rng: np.random.Generator,
        hidden: int = 48,
        lr: float = 1e-3,
        name: str = "online",
        features=None,
    ) -> None:
        """``features``: the world's network encodings (default pursuit's :class:`Features`; the navigation
        maps pass theirs, ``learning/teamster_navigation.py``)."""
        self.features = features if features is not None else Features(world)
        self.rng, self.hidden, self.lr, self.name = rng, hidden, lr, name
        self.frozen = False
        self.reset()

    def _network(self) -> nn.Module:
        return mlp(self.features.team_width, self.hidden, 2, N_ACTIONS)

    def reset(self) -> None:
        self.net = seeded_module(self._network, self.rng)
        self.forward = NumpyMlp(self.net)
        self.optimiser = torch.optim.Adam(self.net.parameters(), lr=self.lr, fused=True)
        f = self.features
        self.buffer = ReplayBuffer(
            CAPACITY, {"state": ((f.n_agents,), np.int64), "mates": ((f.n_mates,), np.int64)}
        )
        self.steps = 0

    def probs(self, states: np.ndarray) -> np.ndarray:
        return softmax(self.forward(self.features.team(states))).reshape(
            states.shape[0], self.features.n_mates, N_ACTIONS
        )

    def update(self, state: np.ndarray, mates: np.ndarray) -> float | None:
        """Line 12 of Algorithm 1: store the sample, one Adam step of Eq. 4.1 on a minibatch."""
        if self.frozen:
            return None
        self.buffer.add(state=state, mates=mates)
        self.steps += 1
        batch = self.buffer.sample(BATCH, self.rng)
        logits = self.net(torch.from_numpy(self.features.team(batch["state"])))
        loss = F.cross_entropy(logits, torch.from_numpy(batch["mates"].reshape(-1)))
        return adam_step(self.optimiser, loss)

    def frozen_copy(self, name: str | None = None) -> LearnedTeam:
        copy = LearnedTeam.__new__(LearnedTeam)
        copy.features, copy.rng, copy.hidden, copy.lr = self.features, self.rng, self.hidden, self.lr
        copy.name, copy.frozen, copy.steps = name or self.name, True, self.steps
        copy.net = self._network()
        copy.net.load_state_dict(self.net.state_dict())
        copy.forward = NumpyMlp(copy.net)
        copy.buffer, copy.optimiser = None, None
        return copy

    def save(self, path: str | Path) -> Path:
        return save_weights(
            path,
            self.net,
            {
                "kind": "teamster-team",
                "hidden": self.hidden,
                "name": self.name,
                "size": self.features.size,
                "steps": self.steps,
            },
        )

    def load(self, path: str | Path) -> dict:
        return load_into(self.net, path)


class LearnedEnvironment:
    """TEAMSTER's environment model: factored transition network (Eq. 4.3) and reward network."""

    def __init__(
        self,
        world: Pursuit4,
        rng: np.random.Generator,
        transition_hidden: int = 256,
        reward_hidden: int = 64,
        features=None,
    ) -> None:
        self.world, self.rng = world, rng
        self.features = f = features if features is not None else Features(world)
        self.transition_net = seeded_module(
            lambda: mlp(f.transition_width, transition_hidden, 2, N_ACTIONS), rng
        )
        self.reward_net = seeded_module(lambda: mlp(f.reward_width, reward_hidden, 2, 1), rng)
        self.transition_forward, self.reward_forward = (
            NumpyMlp(self.transition_net),
            NumpyMlp(self.reward_net),
        )
        self.packed_transition = PackedMlp(self.transition_net)  # the pursuit simulator's (PackedMlp)
        # fused: torch's one-kernel CPU Adam, cheaper per step than the per-parameter loop for small networks;
        # one optimiser with a parameter group per network (Table 4.2's rates) steps both in one call
        self.optimiser = torch.optim.Adam(
            [
                {"params": self.transition_net.parameters(), "lr": 1e-3},
                {"params": self.reward_net.parameters(), "lr": 1e-2},
            ],
            fused=True,
        )
        self.buffer = ReplayBuffer(
            CAPACITY,
            {
                "state": ((f.n_agents,), np.int64),
                "action": ((f.n_actors,), np.int64),
                "next": ((f.n_agents,), np.int64),
                "reward": ((), np.float32),
            },
        )
        self.steps = 0
        self.simulator_inputs: dict[
            int, tuple[np.ndarray, np.ndarray]
        ] = {}  # PursuitSimulator's, by batch size

    def transition_probs(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """(B, 5, 5) ``p_n(move | x, a)`` for every agent n (each row sums to 1: Eq. 4.3's factors)."""
        logits = self.transition_forward(self.features.transition(states, actions))
        return softmax(logits).reshape(states.shape[0], self.features.n_agents, N_ACTIONS)

    def capture_probability(self, states: np.ndarray) -> np.ndarray:
        # 1 / (1 + exp(-logit)) in float64, in place; exp(-logit) = inf for logit < -709 gives 1 / inf = 0.0,
        # the exact limit
        weight = np.negative(self.reward_forward(self.features.reward(states))[:, 0], dtype=np.float64)
        with np.errstate(over="ignore"):
            np.exp(weight, out=weight)
        weight += 1.0
        return np.divide(1.0, weight, out=weight)

    def step(self, states: np.ndarray, joint_actions: np.ndarray, rng: np.random.Generator):
        """Sample each agent's move from its factor (:func:`sample_logits`), then the predicted reward
        ``P(capture | x')`` (terminal above 1/2)."""
        logits = self.transition_forward(self.features.transition(states, joint_actions))
        moves = sample_logits(logits.reshape(states.shape[0], self.features.n_agents, N_ACTIONS), rng)
        nxt = self.world.neighbours[states, moves]
        goal = self.capture_probability(nxt).astype(np.float64)
        return nxt, self.features.step_reward + self.features.goal_reward * goal, goal > 0.5

    def simulator(self, team):
        """The planner's simulator with ``team`` drawing the teammates' actions, fused with this model's step
        (:class:`PursuitSimulator`) when both encode pursuit states with the same :class:`Features`; None
        otherwise (the planner then composes ``team.probs`` and :meth:`step`)."""
        features = self.features
        if type(features) is not Features or getattr(team, "features", None) is not features:
            return None
        return PursuitSimulator(self, team)

    def update(self, state, joint_action, reward, next_state, terminal) -> tuple[float, float] | None:
        """Line 11 of Algorithm 1: store the transition, one Adam step of each network on a minibatch."""
        if (self.features.move_of[state, next_state] < 0).any():
            return None  # not one step apart (cannot happen on the true rules; kept out of the data if fed)
        self.buffer.add(state=state, action=joint_action, next=next_state, reward=float(terminal))
        self.steps += 1
        batch = self.buffer.sample(BATCH, self.rng)
        target = torch.from_numpy(self.features.move_of[batch["state"], batch["next"]].reshape(-1))
        logits = self.transition_net(
            torch.from_numpy(self.features.transition(batch["state"], batch["action"]))
        )
        transition_loss = F.cross_entropy(logits, target)
        predicted = self.reward_net(torch.from_numpy(self.features.reward(batch["next"])))[:, 0]
        reward_loss = F.binary_cross_entropy_with_logits(predicted, torch.from_numpy(batch["reward"]))
        # the networks share no parameter, so the sum's gradient is each loss's own: one backward pass
        adam_step(self.optimiser, transition_loss + reward_loss)
        self.packed_transition.refresh()
        return float(transition_loss.detach()), float(reward_loss.detach())

    def save(self, folder: str | Path) -> list[Path]:
        folder = Path(folder)
        meta = {"kind": "teamster-environment", "size": self.world.size, "steps": self.steps}
        return [
            save_weights(folder / "transition.safetensors", self.transition_net, meta),
            save_weights(folder / "reward.safetensors", self.reward_net, meta),
        ]

    def load(self, folder: str | Path) -> None:
        load_into(self.transition_net, Path(folder) / "transition.safetensors")
        load_into(self.reward_net, Path(folder) / "reward.safetensors")
        self.packed_transition.refresh()


class PackedMlp(NumpyMlp):
    """:class:`NumpyMlp` over C-contiguous copies of the weights (the views are the transposes of torch's
    ``(out, in)`` rows): OpenBLAS then packs the right operand of each product without transposing it, which
    is cheaper, and computes the same sums, since only the packing routine differs and the kernel is the same.
    That holds where the product takes OpenBLAS's general path: for pursuit's transition network (five rows per
    state) at every batch size, while some kernels' small-matrix path, taken for fewer than five rows, sums
    in another order (``tests/teamster/test_fast_path.py``). Copies do not follow the torch parameters:
    :meth:`refresh` after each change of them."""

    def __init__(self, module: nn.Sequential) -> None:
        super().__init__(module)
        self.views = self.layers
        self.layers = [(np.ascontiguousarray(weight), bias) for weight, bias in self.views]

    def refresh(self) -> None:
        for (copy, _), (weight, _) in zip(self.layers, self.views, strict=True):
            np.copyto(copy, weight)


class PursuitSimulator:
    """``simulate(states, actions, rng)`` for the planner on pursuit: the team model's draw of the teammates'
    actions, then the environment model's step, as ``team.probs`` + ``sample_rows`` + :meth:`LearnedEnvironment.step`
    compute them (the same inputs, products, uniforms and order of draws; the draws come from the logits by
    :func:`sample_logits`, so they are ``sample_rows``'s on the softmax but for float rounding at a category
    boundary) with fewer numpy calls: the state's offsets are gathered once for both networks and written into
    input arrays whose constant columns (seat, agent index, the prey's zero own action) are kept from call to call."""

    def __init__(self, environment: LearnedEnvironment, team: LearnedTeam) -> None:
        self.environment, self.team, self.features = environment, team, environment.features
        self.buffers = environment.simulator_inputs

    def _inputs(self, count: int) -> tuple[np.ndarray, ...]:
        """(count, 3, 43) team and (count, 5, 70) transition input arrays, constant columns set, with views of
        the transition array's blocks: offsets (count, 5, 4, 2 size), own action (count, 4, 5) and the joint
        action's (count, 5, 20)."""
        inputs = self.buffers.get(count)
        if inputs is None:
            f = self.features
            team = np.zeros((count, 3, f.team_width), dtype=np.float32)
            team[:, :, :3] = np.eye(3, dtype=np.float32)
            transition = np.zeros((count, N_AGENTS, f.transition_width), dtype=np.float32)
            transition[:, :, :N_AGENTS] = np.eye(N_AGENTS, dtype=np.float32)
            own = N_AGENTS + f.offset_width
            offsets = transition[:, :, N_AGENTS:own].reshape(count, N_AGENTS, N_AGENTS - 1, -1)
            inputs = self.buffers[count] = (
                team,
                transition,
                offsets,
                transition[:, :N_PREDATORS, own : own + N_ACTIONS],
                transition[:, :, own + N_ACTIONS :],
            )
        return inputs

    def __call__(self, states: np.ndarray, actions: np.ndarray, rng: np.random.Generator):
        f, env = self.features, self.environment
        count = states.shape[0]
        team_in, transition_in, offsets, own, joint = self._inputs(count)
        # the pairs' offset codes gathered straight into the transition input (mode="clip" writes into the
        # strided view without the bounds-checked copy; the cell indices are in range)
        pairs = states[:, _OTHERS]
        pairs += states[:, :, None] * f.world.cells
        np.take(f.pair_code, pairs, axis=0, out=offsets, mode="clip")
        team_in[:, :, 3:] = transition_in[:, 1:N_PREDATORS, N_AGENTS : N_AGENTS + f.offset_width]
        mates = sample_logits(
            self.team.forward(team_in.reshape(count * 3, -1)).reshape(count, 3, N_ACTIONS), rng
        )
        np.take(_EYE5, actions, axis=0, out=own[:, 0], mode="clip")
        np.take(_EYE5, mates, axis=0, out=own[:, 1:], mode="clip")
        joint[:] = own.reshape(count, 1, -1)
        logits = env.packed_transition(transition_in.reshape(count * N_AGENTS, -1))
        moves = sample_logits(logits.reshape(count, N_AGENTS, N_ACTIONS), rng)
        nxt = f.world.neighbours[states, moves]
        goal = env.capture_probability(nxt)
        return nxt, f.step_reward + f.goal_reward * goal, goal > 0.5


_EYE5 = np.eye(N_ACTIONS, dtype=np.float32)


def sample_logits(logits: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One draw per row of the categorical ``softmax(logits)`` (..., A), by inverse CDF with one uniform per row,
    as :func:`~embodied_adhoc.decision.agents.teamwork.sample_rows` draws from the probabilities: the uniform is
    scaled by the total of the unnormalised weights instead of the weights divided by it, which saves the
    normalisation (two numpy calls per draw, a tenth of a planner step's simulator) and changes a draw only where
    a uniform falls within float rounding of a category boundary.

    The draw is the count of cumulative weights at or below the uniform. The cumulative weights do not decrease,
    so the last one is left out of the count instead of clipping it to ``A - 1`` afterwards; with five categories
    the four comparisons of a row are four bytes, added by one multiplication of their 32-bit word (the top byte
    of ``word * 0x01010101`` is the sum of its bytes), cheaper than numpy's sum over a short axis."""
    weights = np.subtract(logits, np.maximum.reduce(logits, -1, keepdims=True), dtype=np.float64)
    np.exp(weights, out=weights)
    np.add.accumulate(weights, -1, out=weights)
    uniform = rng.random(weights.shape[:-1])
    uniform *= weights[..., -1]
    below = np.greater_equal(uniform[..., None], weights[..., :-1])
    if below.shape[-1] != 4:
        return np.add.reduce(below, -1)
    count = below.view(np.uint32)[..., 0]
    count *= _BYTE_SUM
    count >>= 24
    return count


_BYTE_SUM = np.uint32(0x01010101)
