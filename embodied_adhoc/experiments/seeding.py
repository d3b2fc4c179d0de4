"""Seeds of a sweep: every random source of a trial derives from ``(seed, episode, agent)`` via SeedSequence.

* the episode spec (task, start positions) from ``(seed, episode)``: identical for every agent and independent of
  how many episodes or which agents a run asks for, so a run can be extended or resumed;
* the env's reset seed and the agent's generator from ``(seed, episode, agent, stream)``, where ``agent`` is a
  stable CRC-32 of the agent's name (Python's ``hash`` is salted per process).
"""

from __future__ import annotations

import os
import zlib

import numpy as np

_SPEC, _ENV, _AGENT, _BUILD = 0, 1, 2, 3


def _sequence(seed: int, *key: int) -> np.random.SeedSequence:
    return np.random.SeedSequence(entropy=int(seed), spawn_key=tuple(int(k) for k in key))


def agent_key(name: str) -> int:
    """A stable integer for an agent name (CRC-32 of its UTF-8 bytes).

    A plug-in named by its file (``path/to/file.py:callable``) is keyed by the file's name and the callable, not
    its folder, so the same agent draws the same trials from any working directory or output folder (a run's
    identity hashes the file's content apart from this)."""
    path, sep, target = name.rpartition(":")
    if sep and path.endswith(".py"):
        name = f"{os.path.basename(path)}:{target}"
    return zlib.crc32(name.encode("utf-8"))


def episode_rng(seed: int, episode: int) -> np.random.Generator:
    """The generator that draws episode ``episode``'s spec (shared by all agents)."""
    return np.random.default_rng(_sequence(seed, _SPEC, episode))


def env_seed(seed: int, episode: int, agent: str) -> int:
    """The integer passed to ``env.reset(seed=...)`` for one trial."""
    return int(_sequence(seed, _ENV, episode, agent_key(agent)).generate_state(1, dtype=np.uint32)[0])


def agent_rng(seed: int, episode: int, agent: str) -> np.random.Generator:
    """The generator handed to ``agent.reset(rng)`` for one trial."""
    return np.random.default_rng(_sequence(seed, _AGENT, episode, agent_key(agent)))


def agent_seed(seed: int, episode: int, agent: str) -> int:
    """An integer seed for building the agent (e.g. a randomised solver); a stream apart from agent_rng's."""
    return int(_sequence(seed, _BUILD, episode, agent_key(agent)).generate_state(1, dtype=np.uint32)[0])
