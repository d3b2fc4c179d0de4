"""Per-model state beliefs and the posterior over a library of POMDPs sharing S, A and Z.

One mechanism serves HOTSPOT and ATPO, whose updates are the same mathematics:

* per model ``m``: ``b_m'(y) = O_m(z | y, a) sum_x P_m(y | x, a) b_m(x) / rho_m`` (thesis Eq. 7.1 with the
  teammate-averaged P̄_m; Eq. 5.6 for ATPO), where ``rho_m = P(z | a, T = m, H_t)``;
* the posterior over models: ``p'(m) = rho_m p(m) / sum_k rho_k p(k)`` (Sec. 7.1, "Task inference"; Eq. 5.5,
  whose factor ``pi_t(a | h_t)`` does not depend on the model and cancels in the normalisation);
* the average belief ``b(x) = sum_m p(m) b_m(x)`` (Eq. 7.2).

An observation impossible under model m (``rho_m = 0``) rules m out; its belief becomes the prediction (it no
longer matters). An observation impossible under every model with positive probability (model mismatch) leaves
the posterior unchanged, moves every belief to its prediction and is counted in ``impossible_observations``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.products import dot
from embodied_adhoc.errors import ModelError

__all__ = ["LibraryBeliefs", "LibraryKernels", "check_library", "normalised_entropy"]

_DENSE_LIMIT = 20_000_000


def normalised_entropy(distribution: np.ndarray) -> float:
    """``H̄(b) = -sum_x b(x) log b(x) / log |X|`` (Sec. 7.1, "Decision-theoretic planning"), in [0, 1]."""
    distribution = np.asarray(distribution, dtype=np.float64)
    if distribution.size <= 1:
        return 0.0
    positive = distribution[distribution > 0.0]
    return float(-(positive * np.log(positive)).sum() / np.log(distribution.size))


def check_library(models: Sequence) -> None:
    """Raise ModelError unless every model shares the first one's states, actions (and observations)."""
    if not models:
        raise ModelError("the model library is empty; give at least one model")
    first = models[0]
    for index, model in enumerate(models[1:], start=1):
        if (model.n_states, model.n_actions) != (first.n_states, first.n_actions):
            raise ModelError(
                f"library model {index} has {model.n_states} states and {model.n_actions} actions; model 0 has "
                f"{first.n_states} and {first.n_actions}: library models must share S and A"
            )
        if hasattr(first, "n_observations") and model.n_observations != first.n_observations:
            raise ModelError(
                f"library model {index} has {model.n_observations} observations, model 0 {first.n_observations}"
            )


@dataclass(frozen=True, eq=False)
class LibraryKernels:
    """Precomputed per-model arrays for fast updates: ``P_m[a]^T`` (CSR) and ``O_m[a]`` columns (dense when small)."""

    pomdps: tuple[POMDP, ...]
    transposed: tuple[tuple[sp.csr_matrix, ...], ...]  # [m][a] = P_m[a]^T
    observation_columns: tuple  # [m] = (A, Z, S) dense array, or [m][a] CSC matrix
    stacked: tuple[sp.csr_matrix, ...]  # [a] = block-diagonal of P_m[a]^T: all models in one product
    stacked_columns: np.ndarray | None  # (A, Z, M * S) dense observation columns of all models, when small

    @classmethod
    def build(cls, pomdps: Sequence[POMDP]) -> LibraryKernels:
        pomdps = tuple(pomdps)
        check_library(pomdps)
        transposed = tuple(tuple(matrix.T.tocsr() for matrix in p.transitions) for p in pomdps)
        columns = []
        for p in pomdps:
            if p.n_actions * p.n_states * p.n_observations <= _DENSE_LIMIT:
                columns.append(np.ascontiguousarray(np.stack([m.toarray().T for m in p.observations])))
            else:
                columns.append(tuple(m.tocsc() for m in p.observations))
        stacked = tuple(
            sp.block_diag([transposed[m][a] for m in range(len(pomdps))], format="csr")
            for a in range(pomdps[0].n_actions)
        )
        dense = (
            all(isinstance(c, np.ndarray) for c in columns) and sum(c.size for c in columns) <= _DENSE_LIMIT
        )
        stacked_columns = np.ascontiguousarray(np.concatenate(columns, axis=2)) if dense else None
        return cls(pomdps, transposed, tuple(columns), stacked, stacked_columns)

    @property
    def n_models(self) -> int:
        return len(self.pomdps)

    def column(self, model: int, action: int, observation: int) -> np.ndarray:
        """``O_m(z | ., a)`` as a dense length-|S| vector."""
        columns = self.observation_columns[model]
        if isinstance(columns, np.ndarray):
            return columns[action, observation]
        return columns[action][:, observation].toarray().ravel()


class LibraryBeliefs:
    """Beliefs ``b_m`` (M x S) and posterior ``p`` (M,) over a POMDP library; see the module docstring."""

    def __init__(self, kernels: LibraryKernels, prior: np.ndarray | None = None) -> None:
        self.kernels = kernels
        m = kernels.n_models
        prior = np.full(m, 1.0 / m) if prior is None else np.asarray(prior, dtype=np.float64)
        if prior.shape != (m,) or prior.min() < 0.0 or abs(prior.sum() - 1.0) > 1e-9:
            raise ModelError(f"prior over the {m} library models must be a probability vector, got {prior}")
        self.prior = prior
        self.reset()

    def reset(self) -> None:
        self.beliefs = np.stack([p.initial_belief for p in self.kernels.pomdps])
        self.posterior = self.prior.copy()
        self.impossible_observations = 0

    def update(self, action: int, observation: int) -> np.ndarray:
        """Apply Eq. 7.1 / 5.6 to every model and the posterior update; returns the likelihoods ``rho_m``."""
        kernels = self.kernels
        n_models, n_states = self.beliefs.shape
        predicted = (kernels.stacked[action] @ self.beliefs.ravel()).reshape(n_models, n_states)
        if kernels.stacked_columns is not None:
            columns = kernels.stacked_columns[action, observation].reshape(n_models, n_states)
        else:
            columns = np.stack([kernels.column(m, action, observation) for m in range(n_models)])
        unnormalised = columns * predicted
        likelihoods = unnormalised.sum(axis=1)
        possible = likelihoods > 0.0
        self.beliefs = np.where(
            possible[:, None], unnormalised / np.where(possible, likelihoods, 1.0)[:, None], predicted
        )
        weighted = likelihoods * self.posterior
        total = weighted.sum()
        if total > 0.0:
            self.posterior = weighted / total
        else:
            self.impossible_observations += 1
        return likelihoods

    def average_belief(self) -> np.ndarray:
        """Eq. 7.2: ``b(x) = sum_m p(m) b_m(x)``."""
        return dot(
            self.posterior, self.beliefs
        )  # fixed summation order (products.py): the same bits on any host
