"""Speech channels: how the human's answer to "Where are you?" becomes an observation of their node.

One interface, three fidelities (the embodied lab env's ``speech=`` option):

- :class:`PerfectChannel` (``"perfect"``): always the true node.
- :class:`MatrixChannel` (``"channel"``, the default): samples the confusion-matrix row of the true node
  (thesis section 7.1, Fig. 7.7: the observation model of "locate human"). Fast: one categorical draw.
- :class:`AudioChannel` (``"audio"``): the full offline pipeline, every query: a reply phrase for the true node,
  espeak-ng synthesis with a random voice, speed and pitch, additive noise at a chosen SNR, pocketsphinx
  recognition under the generated grammar, and the transcript -> place -> node parser.

Every channel draws its randomness from the ``numpy.random.Generator`` passed to :meth:`reply`, so the same seed
gives the same replies (audio included).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from embodied_adhoc.comms.phrases import PhraseConfig, sample_phrase
from embodied_adhoc.comms.vocabulary import NODE_NAMES
from embodied_adhoc.domains.confusion import ConfusionMatrix, load_confusion
from embodied_adhoc.errors import ConfigError

CHANNEL_KINDS = ("perfect", "channel", "audio")


@dataclass(frozen=True)
class SpeechReply:
    """What the robot perceives after asking "Where are you?".

    Attributes:
        node: the recognised node of the human, or ``None`` for "no location" (the "failed" column).
        transcript: the recogniser's text (audio channel only).
        audio: the heard waveform, float32 in [-1, 1], mono (audio channel only).
        sample_rate: samples per second of ``audio`` (audio channel only).
        phrase: the text the human said (audio channel only).
    """

    node: int | None
    transcript: str | None = None
    audio: np.ndarray | None = None
    sample_rate: int | None = None
    phrase: str | None = None


@runtime_checkable
class SpeechChannel(Protocol):
    """A channel from the human's true node to what the robot hears."""

    def reply(self, true_human_node: int, rng: np.random.Generator) -> SpeechReply:
        """The robot's perception of the human's answer when the human stands at ``true_human_node``."""
        ...


def _check_node(node: int, n_nodes: int) -> int:
    if not 0 <= int(node) < n_nodes:
        raise ConfigError(f"true_human_node = {node} is not a lab node; use 0..{n_nodes - 1}")
    return int(node)


class PerfectChannel:
    """Always hears the true node (an upper bound on what communication can give)."""

    def __init__(self, n_nodes: int = len(NODE_NAMES)) -> None:
        self.n_nodes = n_nodes

    def reply(self, true_human_node: int, rng: np.random.Generator) -> SpeechReply:
        return SpeechReply(_check_node(true_human_node, self.n_nodes))


class MatrixChannel:
    """Samples the recognised node from the confusion-matrix row of the true node; last column = no location."""

    def __init__(self, confusion: ConfusionMatrix) -> None:
        self.confusion = confusion
        # Cumulative rows: one uniform draw and a search per reply, no per-call normalisation.
        self._cumulative = np.cumsum(confusion.matrix, axis=1)
        self._cumulative[:, -1] = 1.0

    def reply(self, true_human_node: int, rng: np.random.Generator) -> SpeechReply:
        row = self._cumulative[_check_node(true_human_node, self.confusion.n_nodes)]
        column = int(np.searchsorted(row, rng.random(), side="right"))
        return SpeechReply(None if column == self.confusion.failed_column else column)


class AudioChannel:
    """The full offline pipeline on every query: phrase -> espeak-ng -> noise -> pocketsphinx -> parser.

    Args:
        voices: espeak-ng voice names to draw from (e.g. ``"en-us"``, ``"en+f3"``); ``None`` = the default set.
        snr_db: signal-to-noise ratio of the added noise in dB; ``None`` = clean speech.
        noise: ``"babble"`` (speech-shaped, syllable-rate modulated) or ``"white"``.
        phrase_config: how replies are drawn (share of uninformative replies, fillers, politeness).
    """

    def __init__(
        self,
        voices: tuple[str, ...] | None = None,
        snr_db: float | None = 20.0,
        noise: str = "babble",
        phrase_config: PhraseConfig | None = None,
    ) -> None:
        from embodied_adhoc.comms import recognition, synthesis

        self.voices = tuple(voices) if voices else synthesis.DEFAULT_VOICES
        self.snr_db = snr_db
        self.noise = synthesis.check_noise_kind(noise)
        self.phrase_config = phrase_config or PhraseConfig()
        synthesis.require_espeak()
        self._recognizer = recognition.shared_recognizer()

    def reply(self, true_human_node: int, rng: np.random.Generator) -> SpeechReply:
        from embodied_adhoc.comms import parsing, synthesis

        phrase = sample_phrase(_check_node(true_human_node, len(NODE_NAMES)), rng, self.phrase_config)
        voice = synthesis.sample_voice(rng, self.voices)
        audio = synthesis.synthesize(phrase.text, voice)
        if self.snr_db is not None:
            audio = synthesis.add_noise(audio, self.snr_db, rng, self.noise)
        transcript = self._recognizer.transcribe(audio)
        parsed = parsing.parse(transcript)
        return SpeechReply(parsed.node, transcript, audio, synthesis.SAMPLE_RATE, phrase.text)


def make_channel(
    kind: str = "channel", confusion: ConfusionMatrix | str | os.PathLike | None = "measured", **audio_options
) -> SpeechChannel:
    """Build a channel by name: ``"perfect"``, ``"channel"`` (confusion matrix) or ``"audio"`` (full pipeline).

    ``confusion`` (for ``"channel"``) is a :class:`ConfusionMatrix`, ``"measured"`` (ours, the default),
    ``"thesis"`` or a JSON path. ``audio_options`` go to :class:`AudioChannel`.
    """
    if audio_options and kind != "audio":
        raise ConfigError(
            f"options {sorted(audio_options)} apply only to the 'audio' speech channel, not {kind!r}"
        )
    if kind == "perfect":
        return PerfectChannel()
    if kind == "channel":
        matrix = confusion if isinstance(confusion, ConfusionMatrix) else load_confusion(confusion)
        return MatrixChannel(matrix)
    if kind == "audio":
        return AudioChannel(**audio_options)
    raise ConfigError(f"speech channel {kind!r} is unknown; use one of {CHANNEL_KINDS}")
