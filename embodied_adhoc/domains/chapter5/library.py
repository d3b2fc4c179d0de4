"""The chapter-5 model library: POMDPs (one per task x teammate model) over one shared state indexing.

Every chapter-5 domain builder returns a :class:`ModelLibrary`. Its ``pomdps`` are what the agents of
:mod:`embodied_adhoc.decision.agents` consume (ATPO's library ``M``, thesis section 5.2); ``mdps`` are the same
models with the state observed (BOPA, section 5.1, and the value-iteration baseline); ``mmdps`` are the joint
(ad hoc agent x teammate) MDPs the teammate policies were derived from.

Shared mechanisms of the builders:

* :func:`optimal_teammate_policy`: the teammate of an MMDP that "knows the task and acts optimally": the marginal,
  over its own action, of the uniform distribution over the MMDP's optimal joint actions (value iteration on the
  MMDP, Eq. 2.2);
* :func:`reduce_joint`: Eq. 2.2 / Fig. 5.2's reduction ``P(y | x, a) = sum_b pi(b | x) P(y | x, a, b)`` (the lab's
  :func:`~embodied_adhoc.domains.lab.average_over_teammate`, applied per ad hoc action);
* :func:`deterministic_matrix`: a CSR transition matrix from a next-state index per state (the builders compute
  next states for all states at once with numpy, never state by state).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.decision.models import MDP, POMDP
from embodied_adhoc.decision.value_iteration import value_iteration
from embodied_adhoc.domains.lab import average_over_teammate

__all__ = [
    "DISCOUNT",
    "ModelLibrary",
    "deterministic_matrix",
    "joint_mdp",
    "optimal_teammate_policy",
    "reduce_joint",
    "step_rewards",
    "task_pomdp",
]

DISCOUNT = 0.95
"""gamma of every chapter-5 domain (Table 5.4)."""

GOAL_REWARD, STEP_REWARD, ABSORBING_REWARD = 100.0, -1.0, 0.0
"""Section 5.2.5: -1 per step, +100 in the step taken from a goal state, 0 in the absorbing state afterwards."""


@dataclass(frozen=True, eq=False)
class ModelLibrary:
    """A chapter-5 library; see the module docstring. ``horizon``, ``noise`` and ``n_beliefs`` are Table 5.2's."""

    domain: str
    task_names: tuple[str, ...]
    pomdps: tuple[POMDP, ...]
    mmdps: tuple[MDP, ...]
    horizon: int
    noise: float
    n_beliefs: int
    absorbing_state: int
    description: str = ""
    settings: dict = field(default_factory=dict)
    # Power plant: the tasks' own state spaces (the ``pomdps`` are padded to one size) and absorbing states.
    native_pomdps: tuple[POMDP, ...] | None = None
    absorbing_states: tuple[int, ...] | None = None
    # The domain's own teammate models by name (pursuit's greedy / aware, overcooked's cooks, gridworld's greedy):
    # ``teammates[name](m)`` is that teammate's ``pi(b | x)`` (S x B) in model m's task, for ``--teammate NAME``
    # (the world's teammate replaced, Fig. 5.2's reduction; ``domains.chapter5.teammates.world_with_teammate``).
    teammates: Mapping[str, Callable[[int], np.ndarray]] = field(default_factory=dict)

    def absorbing(self, model: int) -> int:
        """The absorbing state of ``model`` (where an episode is over)."""
        return self.absorbing_state if self.absorbing_states is None else self.absorbing_states[model]

    @property
    def shares_states(self) -> bool:
        """Whether every model has the same state space (BOPA and ``mdps`` need it)."""
        return self.native_pomdps is None

    @property
    def n_models(self) -> int:
        return len(self.pomdps)

    @property
    def n_states(self) -> int:
        return self.pomdps[0].n_states

    @property
    def n_actions(self) -> int:
        return self.pomdps[0].n_actions

    @property
    def n_observations(self) -> int:
        return self.pomdps[0].n_observations

    @property
    def mdps(self) -> tuple[MDP, ...]:
        """The models with the state observed (BOPA's library, value iteration)."""
        return tuple(p.as_mdp() for p in self.pomdps)

    @property
    def state_names(self) -> tuple[str, ...] | None:
        return self.pomdps[0].state_names

    def start_states(self, model: int) -> np.ndarray:
        """States an episode of ``model`` may start in (the support of its initial belief)."""
        return np.flatnonzero(self.pomdps[model].initial_belief > 0.0)

    def subset(self, models: Sequence[int]) -> ModelLibrary:
        """The library restricted to ``models`` (e.g. Fig. 5.9's growing gridworld libraries)."""
        models = [int(m) for m in models]
        return ModelLibrary(
            self.domain,
            tuple(self.task_names[m] for m in models),
            tuple(self.pomdps[m] for m in models),
            tuple(self.mmdps[m] for m in models),
            self.horizon,
            self.noise,
            self.n_beliefs,
            self.absorbing_state,
            self.description,
            {**self.settings, "models": models},
            None if self.native_pomdps is None else tuple(self.native_pomdps[m] for m in models),
            None if self.absorbing_states is None else tuple(self.absorbing_states[m] for m in models),
            {name: _remapped(policy, models) for name, policy in self.teammates.items()},
        )


def _remapped(policy: Callable[[int], np.ndarray], models: Sequence[int]) -> Callable[[int], np.ndarray]:
    """A teammate factory of the full library as one of its subset (model ``k`` of the subset = ``models[k]``)."""
    return lambda k: policy(models[k])


def deterministic_matrix(next_states: np.ndarray, n_states: int) -> sp.csr_matrix:
    """CSR ``P[x, next_states[x]] = 1``."""
    rows = np.arange(n_states)
    return sp.csr_matrix((np.ones(n_states), (rows, np.asarray(next_states))), shape=(n_states, n_states))


def step_rewards(goal: np.ndarray, absorbing_state: int, n_actions: int) -> np.ndarray:
    """Section 5.2.5's reward ``r(x)`` for every action: +100 on goal states, 0 on the absorbing state, else -1."""
    reward = np.where(goal, GOAL_REWARD, STEP_REWARD)
    reward[absorbing_state] = ABSORBING_REWARD
    return np.repeat(reward[:, None], n_actions, axis=1)


def joint_mdp(
    joint: Sequence[Sequence[sp.csr_matrix]], rewards: np.ndarray, names: Sequence[str] | None = None
) -> MDP:
    """The MMDP as an MDP over joint actions ``a * B + b`` (``joint[a][b]`` = ``P(. | ., a, b)``)."""
    n_teammate = len(joint[0])
    matrices = [matrix for per_action in joint for matrix in per_action]
    joint_rewards = np.repeat(rewards, n_teammate, axis=1)
    joint_names = None
    if names is not None:
        joint_names = tuple(f"{a}-{b}" for a in names for b in names[:n_teammate])
    return MDP(matrices, joint_rewards, DISCOUNT, action_names=joint_names)


def optimal_teammate_policy(mmdp: MDP, n_agent_actions: int, tolerance: float = 1e-9) -> np.ndarray:
    """``pi(b | x)`` (S x B): the teammate's marginal of the uniform policy over the MMDP's optimal joint actions."""
    q = value_iteration(mmdp, tolerance=1e-8).q_values
    best = q.max(axis=1, keepdims=True)
    optimal = q >= best - tolerance * np.maximum(1.0, np.abs(best))
    joint_policy = optimal / optimal.sum(axis=1, keepdims=True)
    n_teammate = mmdp.n_actions // n_agent_actions
    return joint_policy.reshape(-1, n_agent_actions, n_teammate).sum(axis=1)


def reduce_joint(
    joint: Sequence[Sequence[sp.csr_matrix]], teammate_policy: np.ndarray
) -> list[sp.csr_matrix]:
    """Fig. 5.2: the ad hoc agent's transitions with the teammate's policy averaged out, one matrix per action."""
    return [average_over_teammate(list(per_action), teammate_policy) for per_action in joint]


def task_pomdp(
    transitions: Sequence[sp.csr_matrix],
    rewards: np.ndarray,
    observation: sp.csr_matrix,
    start: np.ndarray,
    state_names: Sequence[str],
    action_names: Sequence[str],
    observation_names: Sequence[str],
) -> POMDP:
    """One library model with the same observation matrix after every action and an initial belief uniform over
    the states of the boolean mask ``start``."""
    start = np.asarray(start, dtype=np.float64)
    return POMDP(
        transitions,
        rewards,
        DISCOUNT,
        tuple(state_names),
        tuple(action_names),
        [observation] * len(action_names),
        start / start.sum(),
        tuple(observation_names),
    )
