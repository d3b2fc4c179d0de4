"""Measure the offline pipeline: phrases x voices x SNR levels -> metrics 4-6 and the node confusion matrix.

Thesis section 7.1, metrics 4-6: speech-recognition accuracy (exact transcript, ignoring case and punctuation),
named-entity accuracy (the place expression) and node-location accuracy; measured before the trials to build
the observation model of "locate human" (Fig. 7.7). As in the thesis, every speaker reads the same list of
phrases; here a speaker is an espeak-ng voice with a per-utterance speed and pitch, heard clean and at each SNR.

Determinism: every random draw comes from a generator seeded by ``(seed, stream, voice, phrase, level)``, so
results do not depend on the number of worker processes or the order in which utterances are decoded.
"""

from __future__ import annotations

import datetime
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from embodied_adhoc.comms import parsing, synthesis
from embodied_adhoc.comms.phrases import Phrase, PhraseConfig, sample_phrases
from embodied_adhoc.comms.recognition import DecoderSettings, shared_recognizer
from embodied_adhoc.comms.vocabulary import NODE_NAMES
from embodied_adhoc.domains.confusion import ConfusionMatrix, smooth_confusion
from embodied_adhoc.errors import ConfigError

THESIS_ACCURACY = {"transcript_accuracy": 0.5862, "place_accuracy": 0.7777, "node_accuracy": 0.7407}
"""Thesis Fig. 7.10: live accuracies of the original (online) pipeline, metrics 4-6."""

SMOOTHING_FLOOR = 0.03
"""Every confusion entry is raised to at least this, as the thesis's model loading did (docs/hotspot-original.md)."""


@dataclass(frozen=True)
class EvalConfig:
    """What ``embodied-adhoc speech eval`` measures.

    Attributes:
        voices: espeak-ng voices, each reading the same phrase list.
        snr_levels: noise conditions in dB; ``None`` = clean speech.
        phrases: number of phrases in the list (true nodes balanced over the five nodes).
        seed: seed of the phrase list, speeds, pitches and noise.
        noise: ``"babble"`` or ``"white"``.
        phrase_config: share of uninformative replies, fillers and politeness.
        workers: decoding processes (one pocketsphinx decoder each).
        decoder: the recogniser's search settings (saved in the matrix's provenance).
    """

    voices: tuple[str, ...] = synthesis.DEFAULT_VOICES
    snr_levels: tuple[float | None, ...] = (None, 20.0, 10.0, 5.0)
    phrases: int = 60
    seed: int = 0
    noise: str = "babble"
    phrase_config: PhraseConfig = PhraseConfig()
    workers: int = 1
    decoder: DecoderSettings = DecoderSettings()

    def __post_init__(self) -> None:
        if not self.voices:
            raise ConfigError("EvalConfig.voices is empty; pass at least one espeak-ng voice (e.g. en-us)")
        if not self.snr_levels:
            raise ConfigError("EvalConfig.snr_levels is empty; pass at least one level (None = clean)")
        if self.phrases < 1 or self.workers < 1:
            raise ConfigError(
                f"EvalConfig needs phrases >= 1 and workers >= 1 (got {self.phrases}, {self.workers})"
            )
        synthesis.check_noise_kind(self.noise)


@dataclass(frozen=True)
class UtteranceResult:
    """One decoded utterance: its condition, labels, what was recognised, and the decoding cost.

    ``latency_ms`` is wall time of recognition + parsing (it grows when the machine is shared); ``cpu_ms`` is
    the CPU time of the same work, and ``audio_s`` the utterance's duration (with its padding)."""

    voice: str
    snr_db: float | None
    true_node: int
    reference: str
    answer_place: str | None
    answer_node: int | None
    transcript: str
    place: str | None
    node: int | None
    latency_ms: float
    cpu_ms: float
    audio_s: float


def phrase_list(config: EvalConfig) -> list[tuple[int, Phrase]]:
    """The phrases every voice reads: (true node of the speaker, phrase)."""
    return sample_phrases(config.phrases, np.random.default_rng([config.seed, 0]), config.phrase_config)


def utterance_audio(
    config: EvalConfig, voice_index: int, phrase_index: int, level_index: int, phrase: Phrase
) -> tuple[synthesis.Voice, np.ndarray]:
    """The speaker and waveform of one (voice, phrase, SNR level) utterance, seeded by those indices."""
    voice_rng = np.random.default_rng([config.seed, 1, voice_index, phrase_index])
    voice = synthesis.sample_voice(voice_rng, config.voices[voice_index : voice_index + 1])
    audio = synthesis.synthesize(phrase.text, voice)
    snr_db = config.snr_levels[level_index]
    if snr_db is not None:
        noise_rng = np.random.default_rng([config.seed, 2, voice_index, phrase_index, level_index])
        audio = synthesis.add_noise(audio, snr_db, noise_rng, config.noise)
    return voice, audio


def _decode_one(task: tuple[EvalConfig, int, int, int, int, Phrase]) -> UtteranceResult:
    config, voice_index, phrase_index, level_index, true_node, phrase = task
    voice, audio = utterance_audio(config, voice_index, phrase_index, level_index, phrase)
    snr_db = config.snr_levels[level_index]
    recognizer = shared_recognizer(config.decoder)
    start, start_cpu = time.perf_counter(), time.process_time()
    transcript = recognizer.transcribe(audio)
    parsed = parsing.parse(transcript)
    latency_ms = 1000.0 * (time.perf_counter() - start)
    cpu_ms = 1000.0 * (time.process_time() - start_cpu)
    return UtteranceResult(
        voice.name,
        snr_db,
        true_node,
        phrase.reference,
        phrase.place,
        phrase.node,
        transcript,
        parsed.place,
        parsed.node,
        latency_ms,
        cpu_ms,
        len(audio) / synthesis.SAMPLE_RATE,
    )


def run_eval(config: EvalConfig, progress: bool = False) -> list[UtteranceResult]:
    """Decode every (voice, phrase, SNR level) utterance; results in a fixed order (voice, phrase, level)."""
    synthesis.require_espeak()
    tasks = [
        (config, v, p, k, node, phrase)
        for v in range(len(config.voices))
        for p, (node, phrase) in enumerate(phrase_list(config))
        for k in range(len(config.snr_levels))
    ]
    if config.workers == 1:
        iterator = map(_decode_one, tasks)
        pool = None
    else:
        import multiprocessing

        pool = multiprocessing.get_context("spawn").Pool(config.workers, initializer=_ignore_interrupts)
        iterator = pool.imap(_decode_one, tasks, chunksize=8)
    if progress:
        from tqdm import tqdm

        iterator = tqdm(iterator, total=len(tasks), desc="speech eval", unit="utt")
    finished = False
    try:
        results = list(iterator)
        finished = True
        return results
    finally:
        if pool is not None:
            # Stopped early (Ctrl-C, SIGTERM under the CLI, an error): kill the workers now rather than let them
            # decode every queued utterance first.
            (pool.close if finished else pool.terminate)()
            pool.join()


def _ignore_interrupts() -> None:
    """Pool initializer: Ctrl-C reaches the whole process group, but only the parent should react to it."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def condition_metrics(results: Sequence[UtteranceResult], snr_db: float | None) -> dict:
    """Metrics 4-6, count and mean latency over the utterances of one SNR level."""
    chosen = [r for r in results if r.snr_db == snr_db]
    if not chosen:
        raise ConfigError(f"no utterances at SNR {snr_db}")
    return {
        "snr_db": snr_db,
        "transcript_accuracy": float(np.mean([r.transcript == r.reference for r in chosen])),
        "place_accuracy": float(np.mean([r.place == r.answer_place for r in chosen])),
        "node_accuracy": float(np.mean([r.node == r.answer_node for r in chosen])),
        "n": len(chosen),
        "latency_ms_mean": float(np.mean([r.latency_ms for r in chosen])),
        "cpu_ms_mean": float(np.mean([r.cpu_ms for r in chosen])),
        "real_time_factor": float(sum(r.cpu_ms for r in chosen) / 1000.0 / sum(r.audio_s for r in chosen)),
    }


def voice_metrics(results: Sequence[UtteranceResult], snr_db: float | None = None) -> dict[str, dict]:
    """Metrics 4-6 per voice at one SNR level (default clean): accents differ a lot for an American model."""
    chosen = [r for r in results if r.snr_db == snr_db]
    return {
        voice: condition_metrics([r for r in chosen if r.voice == voice], snr_db)
        for voice in dict.fromkeys(r.voice for r in chosen)
    }


def confusion_counts(results: Sequence[UtteranceResult], n_nodes: int = len(NODE_NAMES)) -> np.ndarray:
    """Counts: rows = the speaker's true node, columns = recognised node, last column = no location ("failed").

    An uninformative reply from a speaker at node k lands in row k's "failed" column when it is (correctly) not
    located: as in the thesis's model, "failed" covers both a person who does not say where they are and a
    recogniser that does not understand them.
    """
    counts = np.zeros((n_nodes, n_nodes + 1), dtype=np.int64)
    for r in results:
        counts[r.true_node, n_nodes if r.node is None else r.node] += 1
    return counts


def measured_confusion(
    results: Sequence[UtteranceResult], config: EvalConfig, command: str
) -> ConfusionMatrix:
    """The smoothed node confusion matrix (all conditions pooled), with its provenance."""
    import importlib.metadata
    import subprocess

    counts = confusion_counts(results)
    espeak = subprocess.run(
        [synthesis.require_espeak(), "--version"], capture_output=True, text=True
    ).stdout.strip()
    provenance = {
        "source": "embodied-adhoc speech eval: offline espeak-ng synthesis + pocketsphinx under the generated grammar",
        "command": command,
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "voices": list(config.voices),
        "snr_db": list(config.snr_levels),
        "noise": config.noise,
        "phrases_per_voice": config.phrases,
        "seed": config.seed,
        "phrase_config": asdict(config.phrase_config),
        "decoder": {**asdict(config.decoder), "extra": dict(config.decoder.extra)},
        "utterances": len(results),
        "pooled_over": "all voices and SNR levels",
        "counts": counts.tolist(),
        "packages": {
            "pocketsphinx": importlib.metadata.version("pocketsphinx"),
            "espeak-ng": espeak,
            "embodied-adhoc": importlib.metadata.version("embodied-adhoc"),
        },
        "conditions": [condition_metrics(results, level) for level in config.snr_levels],
        "clean_by_voice": voice_metrics(results) if None in config.snr_levels else {},
    }
    return ConfusionMatrix(NODE_NAMES, smooth_confusion(counts, SMOOTHING_FLOOR), SMOOTHING_FLOOR, provenance)


def format_report(
    conditions: Sequence[dict], confusion: ConfusionMatrix, by_voice: dict[str, dict] | None = None
) -> str:
    """Human-readable tables: metrics 4-6 per condition beside the thesis's, and the smoothed confusion matrix."""
    lines = [
        "| condition | n | transcript (M4) | place (M5) | node (M6) | latency ms | CPU ms | real-time factor |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for c in conditions:
        name = "clean" if c["snr_db"] is None else f"SNR {c['snr_db']:g} dB"
        lines.append(
            f"| {name} | {c['n']} | {100 * c['transcript_accuracy']:.2f} % | {100 * c['place_accuracy']:.2f} % "
            f"| {100 * c['node_accuracy']:.2f} % | {c['latency_ms_mean']:.0f} | {c['cpu_ms_mean']:.0f} "
            f"| {c['real_time_factor']:.3f} |"
        )
    t = THESIS_ACCURACY
    lines.append(
        f"| thesis (online, live) | 257 | {100 * t['transcript_accuracy']:.2f} % | {100 * t['place_accuracy']:.2f} % "
        f"| {100 * t['node_accuracy']:.2f} % | - | - | - |"
    )
    if by_voice:
        lines += ["", "| clean speech, voice | n | transcript | place | node |", "|---|---|---|---|---|"]
        lines += [
            f"| {voice} | {m['n']} | {100 * m['transcript_accuracy']:.1f} % | {100 * m['place_accuracy']:.1f} % "
            f"| {100 * m['node_accuracy']:.1f} % |"
            for voice, m in by_voice.items()
        ]
    header = "| true \\ heard | " + " | ".join([*(str(i) for i in range(confusion.n_nodes)), "failed"]) + " |"
    lines += [
        "",
        f"node confusion matrix (all conditions pooled, floor {confusion.smoothing_floor}):",
        header,
        "|---" * (confusion.n_nodes + 2) + "|",
    ]
    for node, row in enumerate(confusion.matrix):
        lines.append(f"| {node} {confusion.nodes[node]} | " + " | ".join(f"{v:.3f}" for v in row) + " |")
    return "\n".join(lines)
