"""Offline speech recognition with pocketsphinx, constrained by the generated reply grammar.

The decoder uses the English acoustic model shipped in the pocketsphinx wheel, the generated JSGF grammar and the
small generated dictionary (``assets/speech/``, see :mod:`embodied_adhoc.comms.grammar`): no network, no
downloads, and transcripts are always in-vocabulary. Building a decoder is the expensive part, so one
:class:`Recognizer` per process is shared (:func:`shared_recognizer`).

Each utterance is decoded independently of the previous ones (batch cepstral mean normalisation, and a fixed
dither), so a transcript depends only on the audio: the same audio gives the same transcript in any order and
in any worker process.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from embodied_adhoc.comms.adaptation import ADAPTATION_FILE
from embodied_adhoc.comms.grammar import DICTIONARY_FILE, GRAMMAR_FILE, asset_path, is_complete
from embodied_adhoc.errors import SpeechError

DITHER_LSB = 10.0
"""Standard deviation of the fixed dither added to 16-bit samples. espeak-ng writes exact digital silence
between words; its log-energy features are degenerate and make the decoder drop words, so a tiny, fixed noise
floor (as a real microphone has) is added. Its pattern is the same for every utterance (deterministic)."""


@functools.lru_cache(maxsize=1)
def _dither(length: int) -> np.ndarray:
    return np.random.default_rng(0).standard_normal(length) * DITHER_LSB


def pcm16(audio: np.ndarray) -> np.ndarray:
    """What the decoder hears: ``audio`` (mono float in [-1, 1]) as 16-bit samples with the fixed dither.

    Beyond 16-bit full scale a microphone saturates, so values are clipped there (low-SNR mixtures)."""
    audio = np.asarray(audio, dtype=np.float64)
    if audio.ndim != 1 or len(audio) == 0:
        raise SpeechError(f"audio must be a non-empty mono waveform, got shape {audio.shape}")
    # The first len(audio) values of one seeded stream: the same pattern for every utterance.
    length = 1 << max(14, (len(audio) - 1).bit_length())
    samples = audio * 32767.0 + _dither(length)[: len(audio)]
    return np.clip(np.rint(samples), -32768, 32767).astype(np.int16)


N_BEST = 20
"""How many lattice paths are searched for a complete sentence when the best path is partial."""


@dataclass(frozen=True)
class DecoderSettings:
    """pocketsphinx search settings (its option names). Defaults: pocketsphinx's, with batch CMN and wider beams.

    The beams are wider than pocketsphinx's (1e-48, 7e-29, 1e-48): on a tuning set held out from the evaluation
    (seed 1, six voices, clean) they raise node accuracy from 89.4 to 92.5 % with the accent dictionary (88.1 to
    91.7 % without), mostly for the accents furthest from the American model, at about 3.3 times the decoding
    CPU (``scripts/tune_speech.py``; docs/speech.md).
    ``extra`` holds any other pocketsphinx options as ``(name, value)`` pairs (they override the ones set by
    :class:`Recognizer`, e.g. ``(("dict", "my.dict"),)``); settings are hashable, so decoders can be shared."""

    beam: float = 1e-60
    wbeam: float = 1e-40
    pbeam: float = 1e-60
    wip: float = 0.65
    lw: float = 6.5
    adaptation: str | None = ADAPTATION_FILE
    """MLLR transform applied to the acoustic model (:mod:`embodied_adhoc.comms.adaptation`): an asset path, a
    file path, or None for the unadapted model."""
    extra: tuple[tuple[str, object], ...] = ()


class Recognizer:
    """A pocketsphinx decoder over the reply grammar. ``transcribe(audio)`` -> lower-case transcript ("" = nothing)."""

    def __init__(self, settings: DecoderSettings = DecoderSettings(), sample_rate: int = 16_000) -> None:
        import pocketsphinx

        self.sample_rate = sample_rate
        options = dict(
            hmm=str(asset_path_model()),
            dict=str(asset_path(DICTIONARY_FILE)),
            jsgf=str(asset_path(GRAMMAR_FILE)),
            lm=None,
            samprate=sample_rate,
            cmn="batch",
            loglevel="FATAL",
            beam=settings.beam,
            wbeam=settings.wbeam,
            pbeam=settings.pbeam,
            wip=settings.wip,
            lw=settings.lw,
        )
        if settings.adaptation is not None:
            options["mllr"] = str(_adaptation_path(settings.adaptation))
        options.update(dict(settings.extra))
        try:
            self._decoder = pocketsphinx.Decoder(pocketsphinx.Config(**options))
        except (RuntimeError, KeyError, ValueError) as error:
            raise SpeechError(
                f"pocketsphinx decoder could not be configured ({error}); "
                "regenerate the grammar with `embodied-adhoc speech grammar`"
            ) from None

    def transcribe(self, audio: np.ndarray) -> str:
        """The best grammar path for ``audio`` (mono float at the recogniser's rate), normalised lower-case text."""
        pcm = pcm16(audio).tobytes()
        # A fresh front end per utterance: its noise-removal statistics would otherwise carry over from the previous
        # utterance, making a transcript depend on what was decoded before (and so on worker scheduling).
        self._decoder.reinit_feat()
        self._decoder.start_utt()
        self._decoder.process_raw(pcm, no_search=False, full_utt=True)
        self._decoder.end_utt()
        hypothesis = self._decoder.hyp()
        best = hypothesis.hypstr.strip() if hypothesis is not None else ""
        if best and not is_complete(best):
            # The best path did not reach the end of the grammar (a partial sentence such as "come to the
            # middle"): prefer the best complete sentence among the N-best paths of the lattice, if any.
            for candidate in itertools.islice(self._decoder.nbest(), N_BEST):
                if is_complete(candidate.hypstr):
                    return candidate.hypstr.strip()
        return best


def _adaptation_path(value: str) -> Path:
    path = Path(value)
    if path.is_file():
        return path
    try:
        return asset_path(value)
    except SpeechError:
        raise SpeechError(
            f"MLLR transform {value!r} not found; run `embodied-adhoc speech adapt` or pass adaptation=None"
        ) from None


def asset_path_model():
    """Folder of the English acoustic model inside the pocketsphinx wheel."""
    import pocketsphinx

    path = Path(pocketsphinx.get_model_path()) / "en-us" / "en-us"
    if not path.is_dir():
        raise SpeechError(
            f"pocketsphinx English model not found at {path}; reinstall pocketsphinx (bash scripts/bootstrap.sh)"
        )
    return path


@functools.lru_cache(maxsize=4)
def shared_recognizer(settings: DecoderSettings = DecoderSettings()) -> Recognizer:
    """The process's :class:`Recognizer` for ``settings`` (configuring a decoder is expensive, so it is shared)."""
    return Recognizer(settings)
