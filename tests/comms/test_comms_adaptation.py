"""MLLR adaptation: model parameters, the front end, estimation, the file format, and the CLI on small sets."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from embodied_adhoc.comms import adaptation, synthesis
from embodied_adhoc.comms.phrases import sample_phrases
from embodied_adhoc.comms.recognition import DecoderSettings, Recognizer, pcm16, shared_recognizer


def test_model_parameters_are_read_consistently():
    model = adaptation.acoustic_model()
    assert model.means.shape == model.variances.shape == (42, 3, 128, 13)
    assert model.phones[:3] == ("+NSN+", "+SPN+", "AA") and "SIL" in model.phones and len(model.phones) == 42
    assert model.variances.min() >= adaptation.VARIANCE_FLOOR
    # Each senone's mixture weights (8-bit quantised -log w) sum to about one per stream.
    totals = np.exp(model.log_weights).sum(axis=1)
    assert model.log_weights.shape[:2] == (3, 128) and 0.85 < totals.min() <= totals.max() < 1.01


def test_front_end_gives_the_decoders_own_features():
    """Decoding our cepstra gives the same transcript, score and frame count as decoding the audio itself."""
    audio = synthesis.synthesize("I'm waiting at the robot station", synthesis.Voice("en-gb", 160, 50))
    pcm = pcm16(audio)
    decoder = Recognizer(DecoderSettings(adaptation=None))._decoder
    decoder.start_utt()
    decoder.process_raw(pcm.tobytes(), full_utt=True)
    decoder.end_utt()
    from_audio = (decoder.hyp().hypstr, decoder.hyp().score, decoder.n_frames())
    cepstra = adaptation.FrontEnd().cepstra(pcm)
    decoder.start_utt()
    decoder.process_cep(cepstra.astype(np.float32).tobytes(), full_utt=True)
    decoder.end_utt()
    assert (decoder.hyp().hypstr, decoder.hyp().score, decoder.n_frames()) == from_audio
    assert abs(len(cepstra) - from_audio[2]) <= 1


def test_streams_are_cmn_cepstra_with_deltas():
    cepstra = np.arange(40, dtype=np.float64).reshape(10, 4) ** 1.5
    features = adaptation.streams(cepstra)
    c = cepstra - cepstra.mean(axis=0)
    assert features.shape == (10, 3, 4) and np.allclose(features[:, 0], c)
    assert np.allclose(features[5, 1], c[7] - c[3]) and np.allclose(features[0, 1], c[2] - c[0])
    assert np.allclose(features[5, 2], (c[8] - c[4]) - (c[6] - c[2]))


def test_estimate_writes_a_transform_pocketsphinx_loads(tmp_path):
    pairs = sample_phrases(4, np.random.default_rng(4))
    utterances = [
        (synthesis.synthesize(p.text, synthesis.Voice("en-029", 160, 50)), p.reference) for _, p in pairs
    ]
    result = adaptation.estimate(utterances)
    assert result.utterances == 4 and 1 <= result.aligned <= 4 and result.frames > 100
    assert [a.shape for a, _ in result.transforms] == [(13, 13)] * 3
    path = adaptation.write_transform(result, tmp_path / "t.mllr")
    numbers = path.read_text().split()
    assert numbers[:3] == ["1", "3", "13"] and len(numbers) == 2 + 3 * (1 + 13 * 13 + 13 + 13)
    recognizer = Recognizer(DecoderSettings(adaptation=str(path)))
    assert recognizer.transcribe(utterances[0][0])  # loads and decodes


def test_bad_transform_and_missing_file_are_clear_errors(tmp_path):
    from embodied_adhoc.errors import SpeechError

    with pytest.raises(SpeechError, match="speech adapt"):
        Recognizer(DecoderSettings(adaptation=str(tmp_path / "missing.mllr")))
    with pytest.raises(SpeechError, match="no aligned adaptation frames"):
        adaptation.MllrAccumulator(adaptation.acoustic_model()).solve()


def test_adapt_cli_reads_a_recording_list_and_names_bad_lines(tmp_path):
    pairs = sample_phrases(2, np.random.default_rng(8))
    lines = []
    for index, (_, phrase) in enumerate(pairs):
        synthesis.write_wav(tmp_path / f"u{index}.wav", synthesis.synthesize(phrase.text, synthesis.Voice()))
        lines.append(f"u{index}.wav\t{phrase.text}")
    (tmp_path / "list.tsv").write_text("\n".join(lines) + "\n")
    command = [sys.executable, "-m", "embodied_adhoc.cli", "speech", "adapt", "--recordings"]
    ok = subprocess.run(
        [*command, str(tmp_path / "list.tsv"), "--out", str(tmp_path / "me.mllr")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert ok.returncode == 0, ok.stderr
    assert "2 utterances aligned" in ok.stdout or "of 2 utterances aligned" in ok.stdout
    assert (tmp_path / "me.mllr").read_text().startswith("1\n3\n13\n")
    (tmp_path / "bad.tsv").write_text("u0.wav\tI'm at the door\nno tab here\n")
    bad = subprocess.run([*command, str(tmp_path / "bad.tsv")], capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "bad.tsv:2" in bad.stderr and "Traceback" not in bad.stderr


def test_committed_transform_is_the_default_and_loads():
    assert DecoderSettings().adaptation == adaptation.ADAPTATION_FILE
    assert shared_recognizer().transcribe(synthesis.synthesize("I'm at the door", synthesis.Voice()))


def test_adapt_cli_on_synthesised_speech(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", "speech", "adapt", "--voices", "en-us", "--phrases", "2"]
        + ["--snr", "none,10", "--out", str(tmp_path / "s.mllr")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert "of 4 utterances aligned" in done.stdout and "2 conditions (none,10)" in done.stdout
    assert (tmp_path / "s.mllr").is_file()
