"""Shared torch building blocks for agents that learn online from a stream of transitions (thesis chapter 4's
team, transition, reward and DQN networks): a plain MLP, its numpy inference forward (:class:`NumpyMlp`), a
fixed-capacity replay buffer of numpy columns sampled by a seeded ``Generator``, and one Adam step on a loss.

Seeding: :func:`seeded_module` builds a network under ``torch.random.fork_rng`` with a seed drawn from the
caller's numpy ``Generator``, so initial weights depend on that Generator only (not on torch's global state).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from torch import nn

from embodied_adhoc.errors import ConfigError


def mlp(inputs: int, hidden: int, layers: int, outputs: int) -> nn.Sequential:
    """``layers`` hidden ReLU layers of ``hidden`` units and a linear output (Tables 4.2/4.3's networks)."""
    if min(inputs, hidden, layers, outputs) < 1:
        raise ConfigError(f"mlp({inputs}, {hidden}, {layers}, {outputs}): sizes must be positive")
    modules: list[nn.Module] = []
    width = inputs
    for _ in range(layers):
        modules += [nn.Linear(width, hidden), nn.ReLU()]
        width = hidden
    modules.append(nn.Linear(width, outputs))
    return nn.Sequential(*modules)


class NumpyMlp:
    """Inference of an :func:`mlp` in numpy, for planners that evaluate a network thousands of times per second
    on small batches (a UCT wave: about 100 rows), where torch's per-call dispatch costs as much as the maths.

    The layers are numpy *views* of the module's parameters (no copy): torch's optimisers and
    ``load_state_dict`` write parameters in place, so an Adam step is seen by the next call without any export.
    ``module`` must be an :func:`mlp` (Linear and ReLU layers only) of float32 CPU tensors."""

    def __init__(self, module: nn.Sequential) -> None:
        self.layers: list[tuple[np.ndarray, np.ndarray]] = []
        for layer in module:
            if isinstance(layer, nn.Linear):
                self.layers.append((layer.weight.detach().numpy().T, layer.bias.detach().numpy()))
            elif not isinstance(layer, nn.ReLU):
                raise ConfigError(
                    f"NumpyMlp: layer {layer!r} is not Linear or ReLU; give a module built by mlp()"
                )

    def __call__(self, inputs: np.ndarray) -> np.ndarray:
        """(B, inputs) float32 -> (B, outputs) float32 pre-activations of the output layer."""
        hidden = inputs
        last = len(self.layers) - 1
        for i, (weight, bias) in enumerate(self.layers):
            hidden = hidden @ weight
            hidden += bias
            if i < last:
                np.maximum(hidden, 0.0, out=hidden)
        return hidden


def softmax(logits: np.ndarray) -> np.ndarray:
    """Softmax over the last axis in float64 (probabilities that sum to 1 to within 1e-12)."""
    shifted = logits.astype(np.float64) - logits.max(-1, keepdims=True)
    np.exp(shifted, out=shifted)
    shifted /= shifted.sum(-1, keepdims=True)
    return shifted


def one_thread() -> None:
    """Run torch on one thread. The chapter-4 networks are small (batches of 32-160 rows): splitting such a
    product over torch's default thread pool costs more in synchronisation than it saves, and on a machine whose
    cores are busy with other processes the pool's threads spin against them."""
    torch.set_num_threads(1)


def seeded_module(build: Callable[[], nn.Module], rng: np.random.Generator) -> nn.Module:
    """``build()`` with torch's RNG seeded from ``rng`` (and restored afterwards)."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(rng.integers(2**62)))
        return build()


class ReplayBuffer:
    """A ring buffer of named numpy columns (fixed capacity, oldest overwritten), uniform minibatches."""

    def __init__(self, capacity: int, columns: dict[str, tuple[tuple[int, ...], type]]) -> None:
        if capacity < 1:
            raise ConfigError(f"replay capacity={capacity}: give a positive integer")
        self.capacity, self.size, self.cursor = capacity, 0, 0
        self.data = {
            name: np.zeros((capacity, *shape), dtype=dtype) for name, (shape, dtype) in columns.items()
        }

    def add(self, **row) -> None:
        for name, column in self.data.items():
            column[self.cursor] = row[name]
        self.cursor = (self.cursor + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def sample(self, batch: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        index = rng.integers(0, self.size, size=min(batch, self.size))
        return {name: column[index] for name, column in self.data.items()}

    def __len__(self) -> int:
        return self.size


def adam_step(optimiser: torch.optim.Optimizer, loss: torch.Tensor) -> float:
    optimiser.zero_grad(set_to_none=True)
    loss.backward()
    optimiser.step()
    return float(loss.detach())
