"""The robot's side of the dialogue (thesis section 7.1, the communication module's acting pipeline).

The decision module's communication actions become text ("order parsing"), which the robot speaks. Here the
text is produced by :func:`utterance` and spoken offline with espeak-ng (:func:`speak`, :func:`save_utterance`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from embodied_adhoc.comms import synthesis
from embodied_adhoc.comms.vocabulary import NODE_NAMES
from embodied_adhoc.errors import ConfigError

ROBOT_VOICE = synthesis.Voice("en-us+m7", speed=150, pitch=40)
"""The robot's own voice: a steady, slightly slow espeak-ng variant, distinct from the human voices."""

ROBOT_UTTERANCES = ("where", "arrived", "ready")
"""Communication acts the robot can speak (see :func:`utterance`)."""

WHERE_ARE_YOU = "Where are you?"


def arrival_confirmation(node: int) -> str:
    """What the robot says when it reaches the human's node to take the waste."""
    return f"I'm at the {_node_name(node)}, you can drop the waste."


def ready_confirmation(node: int) -> str:
    """What the robot says when it waits at a node for the human to come with the waste."""
    return f"I'm waiting at the {_node_name(node)}."


def _node_name(node: int | None) -> str:
    if node is None or not 0 <= int(node) < len(NODE_NAMES):
        raise ConfigError(f"robot utterance needs a lab node 0..{len(NODE_NAMES) - 1}, got {node}")
    return NODE_NAMES[int(node)]


def utterance(act: str, node: int | None = None) -> str:
    """Text of a communication act: ``"where"`` (the "locate human" action), ``"arrived"`` or ``"ready"`` at
    ``node``."""
    if act == "where":
        return WHERE_ARE_YOU
    if act == "arrived":
        return arrival_confirmation(node)
    if act == "ready":
        return ready_confirmation(node)
    raise ConfigError(f"robot utterance {act!r} is unknown; use one of {ROBOT_UTTERANCES}")


def speak(text: str, voice: synthesis.Voice = ROBOT_VOICE) -> np.ndarray:
    """The robot's waveform for ``text`` (mono float32, :data:`synthesis.SAMPLE_RATE`)."""
    return synthesis.synthesize(text, voice)


def save_utterance(
    path: str | os.PathLike, act: str, node: int | None = None, voice: synthesis.Voice = ROBOT_VOICE
) -> tuple[str, Path]:
    """Write the robot's utterance for ``act`` as a 16 kHz WAV at ``path``; returns (text, path)."""
    text = utterance(act, node)
    return text, synthesis.write_wav(path, speak(text, voice))
