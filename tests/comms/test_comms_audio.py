"""Synthesis, noise, recognition, channels, evaluation and CLI on a small synthesised set (espeak-ng + pocketsphinx)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import soundfile

from embodied_adhoc.comms import channels, robot_speech, synthesis
from embodied_adhoc.comms import eval as speech_eval
from embodied_adhoc.comms.parsing import parse
from embodied_adhoc.comms.phrases import sample_phrases
from embodied_adhoc.comms.recognition import DecoderSettings, Recognizer, shared_recognizer
from embodied_adhoc.domains.confusion import ConfusionMatrix, load_confusion, save_confusion
from embodied_adhoc.errors import ConfigError, SpeechError


def test_synthesis_is_16khz_mono_padded_and_deterministic():
    voice = synthesis.Voice("en-us", 160, 50)
    audio = synthesis.synthesize("I'm at the door", voice)
    assert audio.dtype == np.float32 and audio.ndim == 1
    pad = int(synthesis.PADDING_S * synthesis.SAMPLE_RATE)
    assert not audio[:pad].any() and np.abs(audio[pad:-pad]).max() > 0.05
    assert 1.0 < len(audio) / synthesis.SAMPLE_RATE < 3.0
    synthesis._synthesize_cached.cache_clear()
    assert np.array_equal(audio, synthesis.synthesize("I'm at the door", voice))


def test_missing_espeak_names_the_bootstrap_script(monkeypatch):
    monkeypatch.setattr(synthesis.shutil, "which", lambda name: None)
    synthesis.require_espeak.cache_clear()
    try:
        with pytest.raises(SpeechError, match="scripts/bootstrap.sh"):
            synthesis.require_espeak()
    finally:
        monkeypatch.undo()
        synthesis.require_espeak.cache_clear()


def test_unknown_voice_is_a_clear_error():
    with pytest.raises(SpeechError, match="voice 'xx-nope'"):
        synthesis.synthesize("hello", synthesis.Voice("xx-nope"))


@pytest.mark.parametrize("kind", ["white", "babble"])
def test_noise_has_the_requested_snr_and_is_seeded(kind):
    clean = synthesis.synthesize("I'm waiting at the robot station", synthesis.Voice())
    noisy = synthesis.add_noise(clean, 10.0, np.random.default_rng(1), kind)
    noise = noisy.astype(np.float64) - clean
    snr = 10 * np.log10(synthesis._speech_power(clean) / np.mean(noise**2))
    assert snr == pytest.approx(10.0, abs=0.01)
    assert np.array_equal(noisy, synthesis.add_noise(clean, 10.0, np.random.default_rng(1), kind))
    assert not np.array_equal(noisy, synthesis.add_noise(clean, 10.0, np.random.default_rng(2), kind))
    with pytest.raises(ConfigError, match="noise kind"):
        synthesis.add_noise(clean, 10.0, np.random.default_rng(1), "pink")


def test_clean_american_speech_is_recognised_to_the_right_node():
    pairs = sample_phrases(10, np.random.default_rng(11))
    recognizer = shared_recognizer()
    transcripts = [
        recognizer.transcribe(synthesis.synthesize(p.text, synthesis.Voice("en-us", 160, 50)))
        for _, p in pairs
    ]
    correct = [parse(t).node == p.node for t, (_, p) in zip(transcripts, pairs, strict=True)]
    assert sum(correct) >= 8, list(zip([p.text for _, p in pairs], transcripts, strict=True))
    # Decoding is independent of what was decoded before: same audio, same transcript, any order.
    again = recognizer.transcribe(synthesis.synthesize(pairs[0][1].text, synthesis.Voice("en-us", 160, 50)))
    assert again == transcripts[0]


def test_accented_speech_regression_with_default_settings():
    """A fixed set of Scottish and Caribbean utterances, decoded three ways. When this was written: the default
    recogniser (accent dictionary, wide beams, MLLR transform) 16 of 16 right; without the transform 13; with
    pocketsphinx's own beams and no transform 10. Deterministic (seeded phrases, fixed voices, a decoder
    independent of order), so this is a regression check of each addition."""
    pairs = sample_phrases(8, np.random.default_rng(3))
    audio = [
        (synthesis.synthesize(p.text, synthesis.Voice(voice, 160, 50)), p.node)
        for voice in ("en-gb-scotland", "en-029")
        for _, p in pairs
    ]

    def correct(settings: DecoderSettings) -> int:
        recognizer = shared_recognizer(settings)
        return sum(parse(recognizer.transcribe(clip)).node == node for clip, node in audio)

    default = correct(DecoderSettings())
    unadapted = correct(DecoderSettings(adaptation=None))
    narrow = correct(DecoderSettings(beam=1e-48, wbeam=7e-29, pbeam=1e-48, adaptation=None))
    assert default >= 15 and default > unadapted > narrow, (default, unadapted, narrow)


def test_decoding_does_not_depend_on_the_previous_utterance():
    """pocketsphinx's noise-removal statistics would carry over between utterances; the recogniser resets its
    front end, so the same audio gets the same transcript and score after anything else."""
    recognizer = Recognizer(DecoderSettings(adaptation=None))
    clean = synthesis.synthesize("hey robot i'm at the charging station", synthesis.Voice("en-gb", 150, 40))
    noisy = synthesis.add_noise(
        synthesis.synthesize("just a second", synthesis.Voice()), 0.0, np.random.default_rng(0), "white"
    )

    def decode(audio):
        transcript = recognizer.transcribe(audio)
        return transcript, recognizer._decoder.hyp().score

    first = decode(clean)
    decode(noisy)
    assert decode(clean) == first


def test_recognizer_rejects_bad_audio():
    with pytest.raises(SpeechError, match="mono"):
        shared_recognizer().transcribe(np.zeros((2, 100)))


def test_perfect_and_matrix_channels():
    rng = np.random.default_rng(0)
    assert channels.PerfectChannel().reply(3, rng) == channels.SpeechReply(3)
    with pytest.raises(ConfigError, match="not a lab node"):
        channels.PerfectChannel().reply(5, rng)
    matrix = np.array([[0.5, 0.1, 0.1, 0.1, 0.1, 0.1]] * 5)
    matrix[4] = [0.0, 0.0, 0.0, 0.0, 0.2, 0.8]
    channel = channels.MatrixChannel(ConfusionMatrix(tuple("abcde"), matrix))
    heard = [channel.reply(4, rng).node for _ in range(4000)]
    assert set(heard) == {4, None}
    assert np.mean([h is None for h in heard]) == pytest.approx(0.8, abs=0.03)
    heard0 = np.array([-1 if (h := channel.reply(0, rng).node) is None else h for _ in range(4000)])
    assert np.mean(heard0 == 0) == pytest.approx(0.5, abs=0.03)
    first = [channel.reply(0, np.random.default_rng(5)).node for _ in range(3)]
    assert first == [channel.reply(0, np.random.default_rng(5)).node for _ in range(3)]


def test_make_channel():
    assert isinstance(channels.make_channel("perfect"), channels.PerfectChannel)
    thesis = channels.make_channel("channel", confusion="thesis")
    assert isinstance(thesis, channels.MatrixChannel) and thesis.confusion.matrix.shape == (5, 6)
    assert isinstance(
        channels.make_channel("channel"), channels.MatrixChannel
    )  # the measured matrix, committed
    with pytest.raises(ConfigError, match="unknown"):
        channels.make_channel("telepathy")
    with pytest.raises(ConfigError, match="only to the 'audio'"):
        channels.make_channel("perfect", snr_db=10)


def test_audio_channel_runs_the_full_pipeline_deterministically():
    channel = channels.make_channel("audio", voices=("en-us",), snr_db=20.0)
    first = channel.reply(2, np.random.default_rng(3))
    second = channel.reply(2, np.random.default_rng(3))
    assert (
        first.phrase == second.phrase and first.transcript == second.transcript and first.node == second.node
    )
    assert np.array_equal(first.audio, second.audio) and first.sample_rate == 16_000
    assert first.node == parse(first.transcript).node


def test_eval_metrics_confusion_and_provenance(tmp_path):
    config = speech_eval.EvalConfig(voices=("en-us",), snr_levels=(None, 10.0), phrases=5, seed=1)
    results = speech_eval.run_eval(config)
    assert len(results) == 10 and [r.snr_db for r in results[:2]] == [None, 10.0]
    clean = speech_eval.condition_metrics(results, None)
    assert clean["n"] == 5 and 0.0 <= clean["transcript_accuracy"] <= clean["place_accuracy"] <= 1.0
    assert clean["place_accuracy"] <= clean["node_accuracy"]
    counts = speech_eval.confusion_counts(results)
    assert counts.sum() == 10 and counts.shape == (5, 6)
    confusion = speech_eval.measured_confusion(results, config, "test")
    # Raised to the floor, then renormalised (as the thesis's .027 entries): no entry below floor / (1 + 6 floor).
    assert confusion.matrix.min() >= 0.03 / 1.18 - 1e-12 and np.allclose(confusion.matrix.sum(axis=1), 1.0)
    assert confusion.provenance["voices"] == ["en-us"] and "pocketsphinx" in confusion.provenance["packages"]
    assert confusion.provenance["decoder"]["beam"] == config.decoder.beam
    loaded = load_confusion(save_confusion(confusion, tmp_path / "m.json"))
    assert np.allclose(loaded.matrix, confusion.matrix, atol=1e-5)
    # Same seed, same results, whatever the number of worker processes (and so the decoding order).
    parallel = speech_eval.run_eval(
        speech_eval.EvalConfig(voices=("en-us",), snr_levels=(None, 10.0), phrases=5, seed=1, workers=2)
    )
    assert [(r.transcript, r.node) for r in parallel] == [(r.transcript, r.node) for r in results]


def test_committed_measured_matrix_is_smoothed_with_provenance():
    measured = load_confusion("measured")
    floor = measured.smoothing_floor
    assert floor == 0.03 and measured.matrix.min() >= floor / (1 + 6 * floor) - 1e-6
    assert {"command", "voices", "snr_db", "packages", "date", "counts", "decoder"} <= set(
        measured.provenance
    )


def test_robot_utterances_as_text_and_wav(tmp_path):
    assert robot_speech.utterance("where") == "Where are you?"
    assert robot_speech.utterance("arrived", 3) == "I'm at the single workbench, you can drop the waste."
    with pytest.raises(ConfigError):
        robot_speech.utterance("arrived")
    text, path = robot_speech.save_utterance(tmp_path / "where.wav", "where")
    audio, rate = soundfile.read(path)
    assert rate == 16_000 and len(audio) > 8000 and text == "Where are you?"


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", "speech", *args], capture_output=True, text=True
    )


def test_cli_try_and_eval_json(tmp_path):
    result = _cli("try", "I'm at the big workbench", "--json")
    assert result.returncode == 0, result.stderr
    reply = json.loads(result.stdout)
    assert set(reply) == {"transcript", "place", "node"}
    assert reply["place"] == "big workbench" and reply["node"] == 4 and "big workbench" in reply["transcript"]
    out = tmp_path / "matrix.json"
    result = _cli("eval", "--json", "--phrases", "2", "--voices", "en-us", "--snr", "10", "--out", str(out))
    assert result.returncode == 0, result.stderr
    document = json.loads(result.stdout)
    assert [c["snr_db"] for c in document["conditions"]] == [None, 10.0]
    assert {"transcript_accuracy", "place_accuracy", "node_accuracy", "n", "latency_ms_mean"} <= set(
        document["conditions"][0]
    )
    assert load_confusion(out).matrix.shape == (5, 6)
    bad = _cli("eval", "--snr", "loud")
    assert bad.returncode == 2 and "--snr" in bad.stderr
