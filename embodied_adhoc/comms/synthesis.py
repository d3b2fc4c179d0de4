"""Offline speech synthesis with espeak-ng, and additive noise at a chosen SNR.

Audio everywhere in the communication module is mono float32 in [-1, 1] at :data:`SAMPLE_RATE` (16 kHz, what
the pocketsphinx English model expects). espeak-ng is a Debian package installed by ``scripts/bootstrap.sh``;
it is called as a subprocess (text on stdin, WAV on stdout), so nothing is downloaded and nothing is written.
"""

from __future__ import annotations

import functools
import io
import os
import re
import shutil
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import signal

from embodied_adhoc.atomic import atomic_path
from embodied_adhoc.errors import ConfigError, SpeechError

SAMPLE_RATE = 16_000
"""Samples per second of every waveform in the communication module."""

DEFAULT_VOICES: tuple[str, ...] = (
    "en-us",
    "en-gb",
    "en-us+f3",
    "en-gb-scotland",
    "en-gb-x-rp+f2",
    "en-029+m3",
)
"""espeak-ng voices (language[+variant]) of the evaluation and of the audio channel: six accents/timbres."""

SPEED_RANGE_WPM = (140, 185)
"""Speaking rates drawn by :func:`sample_voice`, words per minute (espeak-ng's default is 175)."""

PITCH_RANGE = (30, 70)
"""Pitches drawn by :func:`sample_voice`, espeak-ng's 0-99 scale (default 50)."""

PADDING_S = 0.3
"""Silence added before and after each utterance (so noise is heard around the speech, as from a microphone)."""

NOISE_KINDS = ("babble", "white")


@dataclass(frozen=True)
class Voice:
    """One espeak-ng speaker: ``name`` (``-v``), ``speed`` in words per minute (``-s``), ``pitch`` 0-99 (``-p``)."""

    name: str = "en-us"
    speed: int = 160
    pitch: int = 50

    def __post_init__(self) -> None:
        if not 80 <= self.speed <= 450:
            raise ConfigError(f"Voice.speed = {self.speed} words/minute is outside espeak-ng's 80..450")
        if not 0 <= self.pitch <= 99:
            raise ConfigError(f"Voice.pitch = {self.pitch} is outside espeak-ng's 0..99")


@functools.cache
def require_espeak() -> str:
    """Path of the ``espeak-ng`` binary, or a :class:`SpeechError` that says how to install it."""
    path = shutil.which("espeak-ng")
    if path is None:
        raise SpeechError(
            "espeak-ng is not installed (offline speech synthesis); run `bash scripts/bootstrap.sh` "
            "or `apt-get install espeak-ng`"
        )
    return path


@functools.cache
def installed_voices() -> tuple[frozenset[str], frozenset[str], tuple[str, ...]]:
    """What espeak-ng's ``-v`` accepts here: (voice spellings in lower case, variant files, the language codes).
    A voice is a language code, a voice name (``Klingon``, ``English (America)``) or a voice file (``gmw/en-US``
    or ``en-US``), in any case; a variant (after ``+``) is a variant file's name, case-sensitive (``f3``,
    ``Alex``): espeak-ng silently ignores anything else there, its display names (``female3``) included."""

    def listing(kind: str) -> list[tuple[str, str, str, list[str]]]:
        """(language, name, file, other languages) per row. Voice files have no spaces and are followed by the
        "(code priority)" groups of the other languages; variant files may contain spaces and end the line."""
        lines = subprocess.run(
            [require_espeak(), f"--voices{kind}"], capture_output=True, text=True, check=False
        ).stdout.splitlines()
        rows = []
        for line in lines[1:]:
            fields = line.split(maxsplit=4)
            if len(fields) == 5:
                rest = fields[4].strip()
                file = re.sub(r"(\s*\([^()]*\))+$", "", rest) if kind else rest.split()[0]
                others = re.findall(r"\(([^\s()]+) \d+\)", rest[len(file) :])
                rows.append((fields[1], fields[3], file, others))
        return rows

    voices, languages = set(), []
    for language, name, file, others in listing(""):
        languages.append(language)
        voices.update((language, name.replace("_", " "), file, file.rsplit("/", 1)[-1], *others))
    variants = {file.rsplit("/", 1)[-1] for _, _, file, _ in listing("=variant")}
    return (
        frozenset(v.lower() for v in voices),
        frozenset(variants),
        tuple(sorted(set(languages))),
    )


def check_voice(name: str, flag: str = "--voice") -> str:
    """``name`` if espeak-ng has that voice (and variant) installed; else a ConfigError listing what it has
    (espeak-ng itself speaks an unknown ``+variant`` with its default one, silently)."""
    voices, variants, languages = installed_voices()
    base, _, variant = name.partition("+")
    if base.lower() not in voices:
        raise ConfigError(
            f"{flag} {name!r}: espeak-ng has no voice {base!r}; installed languages: {', '.join(languages)}"
        )
    if variant and variant not in variants:
        raise ConfigError(
            f"{flag} {name!r}: espeak-ng has no variant {variant!r}; installed variants: "
            f"{', '.join(sorted(variants))}"
        )
    return name


def check_noise_kind(kind: str) -> str:
    if kind not in NOISE_KINDS:
        raise ConfigError(f"noise kind {kind!r} is unknown; use one of {NOISE_KINDS}")
    return kind


def sample_voice(rng: np.random.Generator, voices: Sequence[str] = DEFAULT_VOICES) -> Voice:
    """A random speaker: one of ``voices`` with a random speed and pitch (seeded by ``rng``)."""
    if not voices:
        raise ConfigError("no voices to draw from; pass at least one espeak-ng voice name (e.g. en-us)")
    name = voices[rng.integers(len(voices))]
    speed = int(rng.integers(SPEED_RANGE_WPM[0], SPEED_RANGE_WPM[1] + 1))
    pitch = int(rng.integers(PITCH_RANGE[0], PITCH_RANGE[1] + 1))
    return Voice(name, speed, pitch)


@functools.lru_cache(maxsize=4096)
def _synthesize_cached(text: str, voice: Voice) -> np.ndarray:
    import soundfile

    command = [require_espeak(), "-v", voice.name, "-s", str(voice.speed), "-p", str(voice.pitch), "--stdout"]
    result = subprocess.run(command, input=text.encode(), capture_output=True, check=False)
    stderr = result.stderr.decode(errors="replace").strip()
    if result.returncode != 0 or not result.stdout or stderr:
        raise SpeechError(
            f"espeak-ng failed for voice {voice.name!r} (exit {result.returncode}): {stderr or 'no audio'}; "
            "list the voices with `espeak-ng --voices=en`"
        )
    audio, rate = soundfile.read(io.BytesIO(result.stdout), dtype="float32")
    # 22050 Hz -> 16 kHz with a polyphase filter (exact rational ratio 320/441).
    divisor = np.gcd(SAMPLE_RATE, rate)
    audio = signal.resample_poly(audio, SAMPLE_RATE // divisor, rate // divisor).astype(np.float32)
    pad = np.zeros(int(PADDING_S * SAMPLE_RATE), dtype=np.float32)
    audio = np.concatenate([pad, audio, pad])
    audio.setflags(write=False)  # shared by the cache: callers must copy to change it
    return audio


def synthesize(text: str, voice: Voice = Voice()) -> np.ndarray:
    """Speak ``text`` with ``voice``: mono float32 at 16 kHz, with :data:`PADDING_S` of silence at each end.

    Deterministic: the same text and voice give the same samples (results are cached per process).
    """
    if not text.strip():
        raise ConfigError("cannot synthesise empty text")
    return _synthesize_cached(text, voice)


def _speech_power(audio: np.ndarray) -> float:
    """Mean power over the active samples (20 ms frames within 40 dB of the loudest), the SNR's signal term."""
    frame = SAMPLE_RATE // 50
    usable = audio[: len(audio) // frame * frame].astype(np.float64).reshape(-1, frame)
    energy = (usable**2).mean(axis=1)
    if energy.max() <= 0:
        raise SpeechError(
            "cannot add noise at an SNR to silent audio (the synthesised utterance has no energy)"
        )
    return float(energy[energy >= energy.max() * 1e-4].mean())


def _babble(length: int, rng: np.random.Generator, talkers: int = 6) -> np.ndarray:
    """Babble-like noise: ``talkers`` streams of speech-band noise, each modulated at syllable rate (~4 Hz)."""
    band = signal.butter(2, (150, 3500), btype="bandpass", fs=SAMPLE_RATE, output="sos")
    envelope_filter = signal.butter(2, 4.0, btype="lowpass", fs=SAMPLE_RATE, output="sos")
    carriers = signal.sosfilt(band, rng.standard_normal((talkers, length)), axis=1)
    envelopes = signal.sosfilt(envelope_filter, rng.standard_normal((talkers, length)), axis=1)
    envelopes = np.maximum(envelopes, 0.0)  # on/off like syllables and pauses
    return (carriers * envelopes).sum(axis=0)


def add_noise(audio: np.ndarray, snr_db: float, rng: np.random.Generator, kind: str = "babble") -> np.ndarray:
    """``audio`` plus ``kind`` noise scaled so that speech power / noise power = ``snr_db`` (seeded by ``rng``).

    The speech power is measured over the active part of the utterance (:func:`_speech_power`), the noise power
    over the whole clip. The sum is not clipped: values may exceed 1 at low SNR (the recogniser takes floats).
    """
    check_noise_kind(kind)
    if not np.isfinite(snr_db):
        raise ConfigError(
            f"SNR {snr_db} dB is not a finite number; pass a number of dB, or no noise for clean speech"
        )
    noise = rng.standard_normal(len(audio)) if kind == "white" else _babble(len(audio), rng)
    scale = np.sqrt(_speech_power(audio) / (10.0 ** (snr_db / 10.0)) / np.mean(noise**2))
    return (audio + scale * noise).astype(np.float32)


def write_wav(path: str | os.PathLike, audio: np.ndarray, sample_rate: int = SAMPLE_RATE) -> Path:
    """Write ``audio`` as 16-bit PCM WAV atomically (temp file + rename). Values beyond [-1, 1] are an error."""
    import soundfile

    peak = float(np.max(np.abs(audio))) if len(audio) else 0.0
    if peak > 1.0:
        raise SpeechError(
            f"audio peak {peak:.2f} exceeds full scale 1.0; scale it down before writing {path}"
        )
    with atomic_path(path) as temporary:
        soundfile.write(temporary, audio, sample_rate, subtype="PCM_16", format="WAV")
    return Path(path)


def wav_bytes(audio: np.ndarray, sample_rate: int) -> bytes:
    """16-bit PCM WAV of ``audio`` in memory (the physics env's ``info["speech_audio"]``, the live page's
    sounds). Samples beyond full scale (low-SNR mixtures) saturate at +-1, exactly as the recogniser's 16-bit
    input does (``comms.recognition.Recognizer.transcribe``): the recording is what was heard."""
    import soundfile

    buffer = io.BytesIO()
    soundfile.write(
        buffer, np.asarray(audio, dtype=np.float32), int(sample_rate), format="WAV", subtype="PCM_16"
    )
    return buffer.getvalue()
