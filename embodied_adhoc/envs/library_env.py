"""The true chapter-5 model as an episode simulator: :class:`LibraryEnv` (a generative POMDP world with
Gymnasium's ``reset``/``step`` signatures), the world of every ``trials`` domain of chapter 5 and of the pursuit-pair
ablation."""

from __future__ import annotations

import numpy as np

__all__ = ["LibraryEnv"]


class LibraryEnv:
    """The true model as an episode simulator (Gymnasium's ``reset``/``step`` signatures).

    ``reset(seed, options={"task": k, "start": x})``; the observation is the model's observation index (-1 at
    reset: none yet); ``info`` carries ``state`` and ``observation_index`` (ground truth and diagnostics). The
    episode terminates on entering the model's absorbing state; truncation is the runner's cap.
    """

    def __init__(self, library, pomdps=None) -> None:
        self.library = library
        self.pomdps = library.pomdps if pomdps is None else pomdps  # the world's models (a user's teammate)
        self.rng = np.random.default_rng(0)
        self.model, self.state = 0, 0

    def reset(self, seed: int | None = None, options: dict | None = None):
        options = dict(options or {})
        self.rng = np.random.default_rng(seed)
        self.model = int(options["task"])
        self.pomdp = self.pomdps[self.model]
        self.state = int(options["start"])
        return -1, {"state": self.state, "observation_index": -1}  # no observation before the first step

    def step(self, action: int):
        next_state, observation, reward = self.pomdp.step(self.state, int(action), self.rng)
        self.state = next_state
        terminated = next_state == self.library.absorbing(self.model)
        return observation, reward, terminated, False, {"state": next_state, "observation_index": observation}

    def privileged_state(self) -> int:
        """The true state: the channel through which the episode loop gives it to ``observes_state`` agents."""
        return self.state

    def close(self) -> None:
        return None
