"""Acoustic adaptation of pocketsphinx's English model: a global MLLR mean transform estimated from speech.

pocketsphinx's en-us model is trained on American speech; our speakers (espeak-ng voices, or a lab's people) sound
different. Maximum-likelihood linear regression (Leggetter & Woodland 1995) moves every Gaussian mean of the model
by one affine transform per feature stream, ``mu' = A mu + b``, chosen to maximise the likelihood of adaptation
utterances whose words are known. pocketsphinx applies such a transform at load time (its ``-mllr`` option), so
the model files are not changed and the transform is a small text file (``assets/speech/synthetic.mllr``).

Estimation, for each utterance (audio + its reference text):

1. pocketsphinx's own front end computes the cepstra (called through the wheel's shared library, with the model's
   ``feat.params``, so the features are exactly the decoder's; a test checks that decoding these cepstra gives the
   same transcript and score as decoding the audio), then batch CMN and the model's delta / delta-delta streams;
2. pocketsphinx's forced alignment gives the senone of every frame (``Decoder.set_align_text``, state level);
3. each frame's posterior over the 128 Gaussians of its phone's codebook (the model is phonetically tied: one
   codebook per base phone, three streams of 13) uses the senone's mixture weights (``sendump``);
4. the MLLR statistics are accumulated and each row of each stream's transform solved in closed form (diagonal
   covariances: ``W_i = G_i^-1 k_i``).

Utterances the aligner cannot fit (no path through the reference) are skipped and counted.
"""

from __future__ import annotations

import ctypes
import functools
import json
import re
import struct
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from embodied_adhoc.atomic import atomic_write_text
from embodied_adhoc.errors import SpeechError

ADAPTATION_FILE = "speech/synthetic.mllr"
"""Asset path of the committed transform (estimated from synthesised speech: ``embodied-adhoc speech adapt``)."""

VARIANCE_FLOOR = 1e-4
"""pocketsphinx's default variance floor (``-varfloor``), applied to the model's variances here too."""

_LOG_BASE = np.log(1.0001)  # pocketsphinx's log base; sendump stores -log(w) in these units >> 10


@dataclass(frozen=True)
class AcousticModel:
    """The parameters of pocketsphinx's phonetically tied en-us model that MLLR needs."""

    means: np.ndarray  # (codebooks, streams, densities, dims)
    variances: np.ndarray  # same shape, floored
    log_weights: np.ndarray  # (streams, densities, senones)
    phones: tuple[str, ...]  # base phones; codebook k belongs to phones[k]


def _read_s3(path: Path) -> np.ndarray:
    data = path.read_bytes()
    try:
        start = data.index(b"endhdr\n") + len(b"endhdr\n")
    except ValueError:
        raise SpeechError(f"{path}: not a Sphinx-3 binary parameter file (no 'endhdr')") from None
    if struct.unpack("<I", data[start : start + 4])[0] != 0x11223344:
        raise SpeechError(f"{path}: unexpected byte order mark")
    n_codebooks, n_streams, n_densities = struct.unpack("<3i", data[start + 4 : start + 16])
    lengths = struct.unpack(f"<{n_streams}i", data[start + 16 : start + 16 + 4 * n_streams])
    if len(set(lengths)) != 1:
        raise SpeechError(f"{path}: streams of different lengths {lengths} are not supported")
    offset = start + 16 + 4 * n_streams
    (count,) = struct.unpack("<i", data[offset : offset + 4])
    values = np.frombuffer(data, dtype="<f4", count=count, offset=offset + 4).astype(np.float64)
    return values.reshape(n_codebooks, n_streams, n_densities, lengths[0])


def _read_sendump(path: Path, n_streams: int) -> np.ndarray:
    data = path.read_bytes()
    offset = 0
    while True:  # header: length-prefixed strings, ended by a zero length
        (length,) = struct.unpack("<i", data[offset : offset + 4])
        offset += 4 + length
        if length == 0:
            break
    n_densities, n_senones = struct.unpack("<ii", data[offset : offset + 8])
    raw = np.frombuffer(data, dtype=np.uint8, offset=offset + 8)
    if raw.size != n_streams * n_densities * n_senones:
        raise SpeechError(f"{path}: expected {n_streams}x{n_densities}x{n_senones} weights, found {raw.size}")
    return -(raw.reshape(n_streams, n_densities, n_senones).astype(np.float64) * 1024.0 * _LOG_BASE)


def _base_phones(mdef: Path, count: int) -> tuple[str, ...]:
    """The model's base phones in codebook order (the binary mdef stores them sorted, fillers first)."""
    data = mdef.read_bytes()
    match = re.search(rb"(?:[A-Z+]+\x00){%d}" % count, data)
    if match is None:
        raise SpeechError(f"{mdef}: could not find the {count} base phone names")
    return tuple(name.decode() for name in match.group(0).split(b"\x00")[:count])


@functools.cache
def acoustic_model() -> AcousticModel:
    from embodied_adhoc.comms.recognition import asset_path_model

    folder = Path(asset_path_model())
    means = _read_s3(folder / "means")
    variances = np.maximum(_read_s3(folder / "variances"), VARIANCE_FLOOR)
    log_weights = _read_sendump(folder / "sendump", means.shape[1])
    return AcousticModel(means, variances, log_weights, _base_phones(folder / "mdef", means.shape[0]))


class FrontEnd:
    """pocketsphinx's feature front end (``fe_*`` in the wheel's library) with the model's ``feat.params``."""

    def __init__(self) -> None:
        import glob

        import pocketsphinx

        from embodied_adhoc.comms.recognition import asset_path_model

        libraries = glob.glob(str(Path(pocketsphinx.__file__).parent / "_pocketsphinx*.so"))
        if not libraries:
            raise SpeechError("pocketsphinx's shared library was not found; reinstall pocketsphinx")
        lib = ctypes.CDLL(libraries[0])
        lib.ps_config_parse_json.restype = ctypes.c_void_p
        lib.ps_config_parse_json.argtypes = [ctypes.c_void_p, ctypes.c_char_p]
        lib.fe_init_auto_r.restype = ctypes.c_void_p
        lib.fe_init_auto_r.argtypes = [ctypes.c_void_p]
        lib.fe_start_utt.argtypes = [ctypes.c_void_p]
        lib.fe_process_utt.argtypes = [
            ctypes.c_void_p,
            ctypes.c_void_p,
            ctypes.c_size_t,
            ctypes.POINTER(ctypes.POINTER(ctypes.POINTER(ctypes.c_float))),
            ctypes.POINTER(ctypes.c_int32),
        ]
        lib.fe_end_utt.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.POINTER(ctypes.c_int32)]
        params = _feat_params(Path(asset_path_model()) / "feat.params")
        self.ncep = int(params.get("ncep", 13))
        config = lib.ps_config_parse_json(None, json.dumps({"samprate": 16000, **params}).encode())
        self._fe = lib.fe_init_auto_r(config) if config else None
        if not self._fe:
            raise SpeechError("pocketsphinx's front end could not be configured from the model's feat.params")
        self._lib = lib

    def cepstra(self, pcm: np.ndarray) -> np.ndarray:
        """(frames, 13) cepstra of 16-bit ``pcm``, exactly as the decoder computes them."""
        pcm = np.ascontiguousarray(pcm, dtype=np.int16)
        self._lib.fe_start_utt(self._fe)
        block = ctypes.POINTER(ctypes.POINTER(ctypes.c_float))()
        frames = ctypes.c_int32()
        self._lib.fe_process_utt(
            self._fe, pcm.ctypes.data, len(pcm), ctypes.byref(block), ctypes.byref(frames)
        )
        rows = (
            [np.ctypeslib.as_array(block[0], shape=(frames.value, self.ncep)).copy()] if frames.value else []
        )
        last, extra = (ctypes.c_float * self.ncep)(), ctypes.c_int32()
        self._lib.fe_end_utt(self._fe, last, ctypes.byref(extra))
        if extra.value:
            rows.append(np.array(last[:], dtype=np.float32)[None])
        return np.concatenate(rows) if rows else np.zeros((0, self.ncep), dtype=np.float32)


def _feat_params(path: Path) -> dict:
    """Front-end options of the model's feat.params (the ones ``fe`` reads), with pocketsphinx's value types."""
    wanted = {"lowerf": float, "upperf": float, "nfilt": int, "transform": str, "lifter": int, "ncep": int}
    options: dict = {}
    for line in path.read_text().splitlines():
        parts = line.split()
        if len(parts) == 2 and parts[0].lstrip("-") in wanted:
            name = parts[0].lstrip("-")
            options[name] = wanted[name](parts[1])
        elif len(parts) == 2 and parts[0] == "-remove_noise":
            options["remove_noise"] = parts[1] == "yes"
    return options


def streams(cepstra: np.ndarray) -> np.ndarray:
    """(frames, 3, 13): batch-CMN cepstra, deltas c(t+2)-c(t-2) and delta-deltas, the model's 1s_c_d_dd feature
    (edge frames repeated, as pocketsphinx pads)."""
    c = cepstra - cepstra.mean(axis=0)
    index = np.arange(len(c))

    def at(shift: int) -> np.ndarray:
        return c[np.clip(index + shift, 0, len(c) - 1)]

    return np.stack([c, at(2) - at(-2), (at(3) - at(-1)) - (at(1) - at(-3))], axis=1)


class MllrAccumulator:
    """Sufficient statistics of a one-class MLLR mean transform per stream, and its solution."""

    def __init__(self, model: AcousticModel) -> None:
        self.model = model
        _, n_streams, _, dims = model.means.shape
        self.g = np.zeros((n_streams, dims, dims + 1, dims + 1))
        self.k = np.zeros((n_streams, dims, dims + 1))
        self.frames = 0

    def add(self, features: np.ndarray, codebooks: np.ndarray, senones: np.ndarray) -> None:
        """Add aligned frames: features (T, streams, dims), each frame's codebook and senone."""
        model = self.model
        for stream in range(features.shape[1]):
            for codebook in np.unique(codebooks):
                chosen = codebooks == codebook
                obs = features[chosen, stream]
                mean, var = model.means[codebook, stream], model.variances[codebook, stream]
                log_lik = -0.5 * (((obs[:, None, :] - mean[None]) ** 2) / var[None]).sum(-1)
                log_lik += -0.5 * np.log(var).sum(-1)[None] + model.log_weights[stream][:, senones[chosen]].T
                posterior = np.exp(log_lik - log_lik.max(axis=1, keepdims=True))
                posterior /= posterior.sum(axis=1, keepdims=True)
                extended = np.hstack([np.ones((len(mean), 1)), mean])  # xi = [1, mu]
                occupancy = posterior.sum(axis=0)[:, None] / var  # (densities, dims)
                self.g[stream] += np.einsum("mi,mj,mk->ijk", occupancy, extended, extended)
                self.k[stream] += np.einsum("mi,mj->ij", (posterior.T @ obs) / var, extended)
        self.frames += len(features)

    def solve(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per stream (A, b) with mu' = A mu + b."""
        if self.frames == 0:
            raise SpeechError("no aligned adaptation frames: every utterance failed forced alignment")
        transforms = []
        for g, k in zip(self.g, self.k, strict=True):
            ridge = 1e-6 * np.eye(g.shape[-1])
            rows = np.stack([np.linalg.solve(g[i] + ridge, k[i]) for i in range(len(g))])
            transforms.append((rows[:, 1:], rows[:, 0]))
        return transforms


def mllr_text(transforms: list[tuple[np.ndarray, np.ndarray]]) -> str:
    """pocketsphinx's MLLR file: classes, streams, then per stream its length, A, b and variance scales (1)."""
    lines = ["1", str(len(transforms))]
    for a, b in transforms:
        lines.append(str(len(b)))
        lines += [" ".join(f"{x:.7g}" for x in row) for row in a]
        lines.append(" ".join(f"{x:.7g}" for x in b))
        lines.append(" ".join("1" for _ in b))
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class AdaptationResult:
    transforms: list
    utterances: int
    aligned: int
    frames: int


def estimate(utterances: Iterable[tuple[np.ndarray, str]]) -> AdaptationResult:
    """MLLR transform from (audio, reference text) pairs (mono float audio at 16 kHz, grammar words)."""
    import pocketsphinx

    from embodied_adhoc.comms.grammar import DICTIONARY_FILE, asset_path
    from embodied_adhoc.comms.recognition import asset_path_model, pcm16
    from embodied_adhoc.comms.vocabulary import normalise

    model = acoustic_model()
    codebook_of = {phone: index for index, phone in enumerate(model.phones)}
    front_end = FrontEnd()
    aligner = pocketsphinx.Decoder(
        hmm=str(asset_path_model()),
        dict=str(asset_path(DICTIONARY_FILE)),
        lm=None,
        cmn="batch",
        loglevel="FATAL",
    )
    accumulator = MllrAccumulator(model)
    total = aligned = 0
    for audio, text in utterances:
        total += 1
        pcm = pcm16(audio)
        raw = pcm.tobytes()
        try:
            aligner.set_align_text(normalise(text))
            for attempt in range(2):  # word alignment, then state alignment within it
                aligner.start_utt()
                aligner.process_raw(raw, full_utt=True)
                aligner.end_utt()
                if attempt == 0:
                    aligner.set_alignment()
            entries = [
                (state.start, state.duration, codebook_of[phone.name], int(state.name))
                for word in aligner.get_alignment()
                for phone in word
                for state in phone
            ]
        except (RuntimeError, KeyError, ValueError):
            continue  # the aligner found no path through the reference: skip the utterance
        features = streams(front_end.cepstra(pcm))
        frames = [(t, cb, sen) for start, n, cb, sen in entries for t in range(start, start + n)]
        frames = [f for f in frames if f[0] < len(features)]
        if not frames:
            continue
        index, codebooks, senones = (np.array(column) for column in zip(*frames, strict=True))
        accumulator.add(features[index], codebooks, senones)
        aligned += 1
    return AdaptationResult(accumulator.solve(), total, aligned, accumulator.frames)


def write_transform(result: AdaptationResult, path: str | Path) -> Path:
    return atomic_write_text(path, mllr_text(result.transforms))
