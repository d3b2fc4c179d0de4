"""Sparse tabular MDP and POMDP types: the one model representation every solver, agent and simulator uses.

Conventions (Cassandra's, and the thesis's chapter 2):

* ``transitions[a]`` is a CSR ``|S| x |S|`` matrix with ``transitions[a][s, s'] = P(s' | s, a)``.
* ``observations[a]`` is a CSR ``|S| x |Z|`` matrix indexed by the *end* state:
  ``observations[a][s', z] = O(z | s', a)``.
* ``rewards`` is a dense ``|S| x |A|`` array of immediate expected rewards ``R(s, a)``.
* ``initial_belief`` is a dense length-``|S|`` probability vector.

Construction validates everything and raises :class:`~embodied_adhoc.errors.ModelError` naming the array,
the action and the row at fault. Probabilities are never silently renormalised: rows must sum to 1 within
``PROBABILITY_ATOL`` (files such as Cassandra's corpus are rounded to 6 digits).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.errors import ModelError

PROBABILITY_ATOL = 1e-5
"""Tolerance on row sums of stochastic matrices (rounded files sum to 1 only to ~6 digits)."""


def as_csr_stack(matrices: Sequence, shape: tuple[int, int], what: str) -> tuple[sp.csr_matrix, ...]:
    """Convert a sequence of dense/sparse matrices (or a 3-D array) to a tuple of float64 CSR matrices."""
    result = []
    for index, matrix in enumerate(matrices):
        csr = sp.csr_matrix(matrix, dtype=np.float64)
        if csr.shape != shape:
            raise ModelError(f"{what}[{index}] has shape {csr.shape}, expected {shape}")
        csr.eliminate_zeros()
        csr.sort_indices()
        result.append(csr)
    return tuple(result)


def check_stochastic(matrix: sp.csr_matrix, what: str, row_names: Sequence[str] | None = None) -> None:
    """Raise ModelError if ``matrix`` has a negative entry or a row that does not sum to 1."""
    if matrix.nnz and matrix.data.min() < 0.0:
        flat = int(np.argmin(matrix.data))
        row = int(np.searchsorted(matrix.indptr, flat, side="right") - 1)
        raise ModelError(
            f"{what}: row {_row_label(row, row_names)} has a negative entry {matrix.data[flat]:g}"
        )
    sums = np.asarray(matrix.sum(axis=1)).ravel()
    bad = np.flatnonzero(np.abs(sums - 1.0) > PROBABILITY_ATOL)
    if bad.size:
        row = int(bad[0])
        raise ModelError(
            f"{what}: row {_row_label(row, row_names)} sums to {sums[row]:.8g}, expected 1 "
            f"({bad.size} bad row(s) in all); fix the model, rows are never renormalised silently"
        )


def _row_label(row: int, names: Sequence[str] | None) -> str:
    return f"{row} ('{names[row]}')" if names is not None else str(row)


def _names(names: Sequence[str] | None, count: int, what: str) -> tuple[str, ...] | None:
    if names is None:
        return None
    names = tuple(str(n) for n in names)
    if len(names) != count:
        raise ModelError(f"{what}: {len(names)} names given for {count} entries")
    return names


@dataclass(frozen=True, eq=False)
class MDP:
    """A finite discounted MDP ``(S, A, P, R, gamma)`` with sparse per-action transition matrices."""

    transitions: tuple[sp.csr_matrix, ...]
    rewards: np.ndarray
    discount: float
    state_names: tuple[str, ...] | None = None
    action_names: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        rewards = np.asarray(self.rewards, dtype=np.float64)
        if rewards.ndim != 2:
            raise ModelError(f"rewards must be a |S| x |A| array, got shape {rewards.shape}")
        n_states, n_actions = rewards.shape
        if len(self.transitions) != n_actions:
            raise ModelError(
                f"{len(self.transitions)} transition matrices for {n_actions} actions (rewards columns)"
            )
        if not np.all(np.isfinite(rewards)):
            s, a = np.argwhere(~np.isfinite(rewards))[0]
            raise ModelError(f"rewards[{s}, {a}] is not finite")
        if not 0.0 <= float(self.discount) <= 1.0:
            raise ModelError(f"discount must lie in [0, 1], got {self.discount}")
        object.__setattr__(self, "rewards", rewards)
        object.__setattr__(self, "discount", float(self.discount))
        object.__setattr__(self, "state_names", _names(self.state_names, n_states, "state_names"))
        object.__setattr__(self, "action_names", _names(self.action_names, n_actions, "action_names"))
        transitions = as_csr_stack(self.transitions, (n_states, n_states), "transitions")
        for a, matrix in enumerate(transitions):
            check_stochastic(matrix, f"transitions for action {self.action_label(a)}", self.state_names)
        object.__setattr__(self, "transitions", transitions)

    @property
    def n_states(self) -> int:
        return self.rewards.shape[0]

    @property
    def n_actions(self) -> int:
        return self.rewards.shape[1]

    def action_label(self, action: int) -> str:
        return f"{action} ('{self.action_names[action]}')" if self.action_names else str(action)

    def expected_next_values(self, values: np.ndarray) -> np.ndarray:
        """``E[V(s') | s, a]`` for all ``s, a`` as an ``|S| x |A|`` array (one sparse mat-vec per action)."""
        return np.stack([matrix @ values for matrix in self.transitions], axis=1)


@dataclass(frozen=True, eq=False)
class POMDP(MDP):
    """A finite POMDP ``(S, A, Z, P, O, R, gamma, b0)``; see the module docstring for conventions."""

    observations: tuple[sp.csr_matrix, ...] = ()
    initial_belief: np.ndarray = field(default_factory=lambda: np.zeros(0))
    observation_names: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if len(self.observations) != self.n_actions:
            raise ModelError(f"{len(self.observations)} observation matrices for {self.n_actions} actions")
        n_observations = sp.csr_matrix(self.observations[0]).shape[1]
        observations = as_csr_stack(self.observations, (self.n_states, n_observations), "observations")
        for a, matrix in enumerate(observations):
            check_stochastic(matrix, f"observations for action {self.action_label(a)}", self.state_names)
        object.__setattr__(self, "observations", observations)
        object.__setattr__(
            self, "observation_names", _names(self.observation_names, n_observations, "observation_names")
        )
        belief = np.asarray(self.initial_belief, dtype=np.float64)
        if belief.shape != (self.n_states,):
            raise ModelError(f"initial_belief has shape {belief.shape}, expected ({self.n_states},)")
        if belief.min() < 0.0 or abs(belief.sum() - 1.0) > PROBABILITY_ATOL:
            raise ModelError(
                f"initial_belief must be a probability vector (min {belief.min():g}, sum {belief.sum():.8g})"
            )
        object.__setattr__(self, "initial_belief", belief)

    @property
    def n_observations(self) -> int:
        return self.observations[0].shape[1]

    def as_mdp(self) -> MDP:
        """The underlying fully observable MDP (same S, A, P, R, gamma)."""
        return MDP(self.transitions, self.rewards, self.discount, self.state_names, self.action_names)

    # ----------------------------------------------------------------------------------------- beliefs
    def predict(self, belief: np.ndarray, action: int) -> np.ndarray:
        """Prior over the next state, ``sum_s b(s) P(s' | s, a)``."""
        return self.transitions[action].T @ belief

    def observation_likelihood(self, belief: np.ndarray, action: int, observation: int) -> float:
        """``P(z | b, a) = sum_{s'} O(z | s', a) sum_s P(s' | s, a) b(s)``: the normaliser of Eq. 2.3."""
        return float(self._observation_column(action, observation) @ self.predict(belief, action))

    def _observation_column(self, action: int, observation: int) -> np.ndarray:
        """``O(z | ., a)`` as a dense length-|S| vector."""
        return self.observations[action][:, [observation]].toarray().ravel()

    def belief_update(self, belief: np.ndarray, action: int, observation: int) -> tuple[np.ndarray, float]:
        """Bayesian belief update (thesis Eq. 2.3).

        ``b'(s') = O(z | s', a) sum_s P(s' | s, a) b(s) / rho`` with ``rho = P(z | b, a)``.
        Returns ``(b', rho)``. An observation impossible under ``b`` (``rho == 0``) raises ModelError,
        since no posterior exists; callers that expect model mismatch should catch it and reset.
        """
        unnormalised = self._observation_column(action, observation) * self.predict(belief, action)
        likelihood = float(unnormalised.sum())
        if likelihood <= 0.0:
            raise ModelError(
                f"observation {self._observation_label(observation)} has probability 0 after action "
                f"{self.action_label(action)} from this belief: no Bayesian posterior exists"
            )
        return unnormalised / likelihood, likelihood

    def _observation_label(self, observation: int) -> str:
        if self.observation_names:
            return f"{observation} ('{self.observation_names[observation]}')"
        return str(observation)

    # -------------------------------------------------------------------------------------- simulation
    def sample_initial_state(self, rng: np.random.Generator) -> int:
        # Inverse-CDF sampling: files rounded to 6 digits sum to 1 only within PROBABILITY_ATOL, which
        # Generator.choice (tolerance 1e-8) would reject.
        cumulative = np.cumsum(self.initial_belief)
        index = int(np.searchsorted(cumulative, rng.random() * cumulative[-1], side="right"))
        return min(index, self.n_states - 1)

    def step(self, state: int, action: int, rng: np.random.Generator) -> tuple[int, int, float]:
        """Generative model: sample ``s' ~ P(.|s,a)``, ``z ~ O(.|s',a)``; return ``(s', z, R(s, a))``.

        The reward is the expected immediate reward ``R(s, a)`` (for files whose reward depends on ``s'`` and
        ``z`` this is its expectation, which leaves expected returns unchanged).
        """
        next_state = _sample_row(self.transitions[action], state, rng)
        observation = _sample_row(self.observations[action], next_state, rng)
        return next_state, observation, float(self.rewards[state, action])


def _sample_row(matrix: sp.csr_matrix, row: int, rng: np.random.Generator) -> int:
    start, end = matrix.indptr[row], matrix.indptr[row + 1]
    probabilities = matrix.data[start:end]
    choice = int(np.searchsorted(np.cumsum(probabilities), rng.random() * probabilities.sum(), side="right"))
    return int(matrix.indices[start + min(choice, end - start - 1)])
