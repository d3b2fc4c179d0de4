"""``embodied-adhoc speech ...``: the offline communication module (espeak-ng + pocketsphinx), see docs/speech.md.

- ``speech eval``: phrases x voices x SNR levels -> metrics 4-6 per condition, latency, and the measured node
  confusion matrix (saved as ``assets/data/speech_confusion_measured.json`` with provenance).
- ``speech try "TEXT"``: synthesise TEXT, recognise it, print transcript, place and node.
- ``speech say ACT``: the robot's utterance ("where", "arrived", "ready") as text and WAV.
- ``speech grammar``: regenerate the recognition grammar and dictionary from the vocabulary.
- ``speech adapt``: estimate the acoustic model's MLLR transform from synthesised speech or from recordings.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys

from embodied_adhoc.commands.arguments import output_file, seed


def _saved_file(text: str):
    """``speech eval --out``: 'none', or a file that can be written (checked before anything is measured)."""
    return "none" if text.lower() == "none" else output_file(text)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "speech",
        help="offline speech: measure the pipeline, try a phrase, robot utterances",
        description="Offline communication module: espeak-ng synthesis, pocketsphinx "
        "recognition under a grammar generated from the lab's place vocabulary.",
    )
    commands = parser.add_subparsers(dest="speech_command", metavar="SUBCOMMAND")
    parser.set_defaults(_parser=parser)

    evaluate = commands.add_parser(
        "eval",
        help="measure accuracies per SNR and the node confusion matrix",
        description="Every voice reads the same phrase list, clean and at each SNR; prints "
        "metrics 4-6 per condition beside the thesis's, and saves the smoothed confusion "
        "matrix (rows = true node, columns = recognised node + failed).",
    )
    evaluate.add_argument(
        "--voices",
        default=None,
        metavar="V,V,...",
        help="espeak-ng voices (default: the six of embodied_adhoc.comms.synthesis.DEFAULT_VOICES)",
    )
    evaluate.add_argument(
        "--snr",
        default="20,10,5",
        metavar="DB,DB,...",
        help="noise levels in dB besides clean speech (default 20,10,5; 'none' = clean only)",
    )
    evaluate.add_argument("--phrases", type=int, default=60, help="phrases per voice (default 60)")
    evaluate.add_argument(
        "--seed", type=seed, default=0, help="seed of phrases, speeds, pitches and noise, >= 0 (default 0)"
    )
    evaluate.add_argument(
        "--noise", choices=("babble", "white"), default="babble", help="noise kind (default babble)"
    )
    evaluate.add_argument("--workers", type=int, default=1, help="decoding processes (default 1)")
    evaluate.add_argument(
        "--out",
        type=_saved_file,
        default=None,
        metavar="PATH",
        help="where to save the confusion matrix JSON "
        "(default assets/data/speech_confusion_measured.json; 'none' = do not save)",
    )
    evaluate.add_argument(
        "--adaptation",
        default=None,
        metavar="PATH|none",
        help="MLLR transform of the acoustic model (default the committed assets/speech/synthetic.mllr; "
        "'none' = the unadapted model)",
    )
    evaluate.add_argument("--json", action="store_true", help="print one JSON document instead of tables")
    evaluate.set_defaults(func=handle_eval)

    attempt = commands.add_parser(
        "try", help="synthesise TEXT, recognise it, print transcript, place and node"
    )
    attempt.add_argument("text", help='what the human says, e.g. "I\'m at the big workbench"')
    attempt.add_argument("--voice", default="en-us", help="espeak-ng voice (default en-us)")
    attempt.add_argument("--speed", type=int, default=160, help="words per minute (default 160)")
    attempt.add_argument("--pitch", type=int, default=50, help="pitch 0-99 (default 50)")
    attempt.add_argument(
        "--snr", type=float, default=None, metavar="DB", help="add noise at this SNR (default clean)"
    )
    attempt.add_argument(
        "--noise", choices=("babble", "white"), default="babble", help="noise kind (default babble)"
    )
    attempt.add_argument("--seed", type=seed, default=0, help="seed of the noise, >= 0 (default 0)")
    attempt.add_argument(
        "--wav",
        type=output_file,
        default=None,
        metavar="PATH",
        help="also write the heard audio as a WAV file",
    )
    attempt.add_argument("--json", action="store_true", help="print JSON")
    attempt.set_defaults(func=handle_try)

    say = commands.add_parser("say", help="the robot's utterance as text (and WAV with --wav)")
    say.add_argument("act", choices=("where", "arrived", "ready"), help="communication act")
    say.add_argument(
        "--node", type=int, default=None, help="node for arrived/ready (0 door .. 4 double workbench)"
    )
    say.add_argument(
        "--wav",
        type=output_file,
        default=None,
        metavar="PATH",
        help="write the spoken utterance as a 16 kHz WAV",
    )
    say.set_defaults(func=handle_say)

    grammar = commands.add_parser("grammar", help="regenerate assets/speech/reply.gram and reply.dict")
    grammar.add_argument(
        "--check", action="store_true", help="only check that the committed files are up to date"
    )
    grammar.set_defaults(func=handle_grammar)

    adapt = commands.add_parser(
        "adapt",
        help="estimate the acoustic model's MLLR transform (speaker adaptation)",
        description="Estimate a global MLLR mean transform of pocketsphinx's English model from utterances "
        "with known words: by default every voice reading --phrases synthesised phrases (seed 2, held out "
        "from `speech eval`'s seed 0), or your own recordings with --recordings.",
    )
    adapt.add_argument(
        "--voices", default=None, metavar="V,V,...", help="espeak-ng voices (default: the six)"
    )
    adapt.add_argument("--phrases", type=int, default=60, help="synthesised phrases per voice (default 60)")
    adapt.add_argument("--seed", type=seed, default=2, help="seed of synthesised phrases, >= 0 (default 2)")
    adapt.add_argument(
        "--snr",
        default="none,20,10",
        metavar="DB,...",
        help="conditions of the synthesised adaptation speech, 'none' = clean (default none,20,10: a transform "
        "estimated on clean speech only helps clean speech and hurts noisy speech)",
    )
    adapt.add_argument(
        "--recordings",
        default=None,
        metavar="LIST",
        help="a text file of 'path.wav<TAB>what was said' lines (16 kHz mono WAV; paths relative to the "
        "list's folder) to adapt to real speakers instead of synthesised ones",
    )
    adapt.add_argument(
        "--out",
        type=output_file,
        default=None,
        metavar="PATH",
        help="where to write the transform (default assets/speech/synthetic.mllr, the recogniser's default)",
    )
    adapt.set_defaults(func=handle_adapt)


def _parse_list(text: str | None, kind: str) -> tuple:
    from embodied_adhoc.errors import ConfigError

    if text is None:
        return ()
    items = tuple(item.strip() for item in text.split(",") if item.strip())
    if kind == "snr":
        try:
            return tuple(None if item.lower() in ("none", "clean") else float(item) for item in items)
        except ValueError:
            raise ConfigError(
                f"--snr {text!r}: expected comma-separated numbers of dB, e.g. 20,10,5"
            ) from None
    return items


def _voices(text: str | None, flag: str) -> tuple[str, ...]:
    """The voices of ``--voices V,V,...`` (each one installed, checked before any synthesis); () when not given."""
    from embodied_adhoc.comms.synthesis import check_voice

    return tuple(check_voice(voice, flag) for voice in _parse_list(text, "voices"))


def _decoder_settings(adaptation: str | None):
    from pathlib import Path

    from embodied_adhoc.comms.recognition import DecoderSettings

    if adaptation is None:
        return DecoderSettings()
    if adaptation.lower() == "none":
        return DecoderSettings(adaptation=None)
    return DecoderSettings(adaptation=str(Path(adaptation).resolve()))


def handle_eval(args: argparse.Namespace) -> int:
    from embodied_adhoc import paths
    from embodied_adhoc.comms import eval as speech_eval
    from embodied_adhoc.comms import synthesis
    from embodied_adhoc.domains.confusion import MEASURED_MATRIX, save_confusion

    levels = (None, *(level for level in _parse_list(args.snr, "snr") if level is not None))
    config = speech_eval.EvalConfig(
        voices=_voices(args.voices, "--voices") or synthesis.DEFAULT_VOICES,
        snr_levels=levels,
        phrases=args.phrases,
        seed=args.seed,
        noise=args.noise,
        workers=args.workers,
        decoder=_decoder_settings(args.adaptation),
    )
    command = (
        "embodied-adhoc " + " ".join(shlex.quote(a) for a in sys.argv[1:])
        if sys.argv[1:2] == ["speech"]
        else f"embodied-adhoc speech eval --phrases {args.phrases} --seed {args.seed} --snr {args.snr}"
    )
    results = speech_eval.run_eval(config, progress=not args.json and sys.stderr.isatty())
    conditions = [speech_eval.condition_metrics(results, level) for level in config.snr_levels]
    confusion = speech_eval.measured_confusion(results, config, command)
    saved = None
    if args.out != "none":
        saved = save_confusion(confusion, args.out or paths.assets_dir() / MEASURED_MATRIX)
    if args.json:
        json.dump(
            {
                "conditions": conditions,
                "thesis": speech_eval.THESIS_ACCURACY,
                "confusion": {
                    "nodes": list(confusion.nodes),
                    "columns": [*confusion.nodes, "failed"],
                    "matrix": confusion.matrix.round(4).tolist(),
                    "counts": confusion.provenance["counts"],
                },
                "clean_by_voice": confusion.provenance["clean_by_voice"],
                "saved": str(saved) if saved else None,
            },
            sys.stdout,
            indent=2,
        )
        print()
        return 0
    print(speech_eval.format_report(conditions, confusion, confusion.provenance["clean_by_voice"]))
    if saved:
        print(f"confusion matrix saved to {saved}")
    return 0


def handle_try(args: argparse.Namespace) -> int:
    import numpy as np

    from embodied_adhoc.comms import parsing, synthesis
    from embodied_adhoc.comms.recognition import shared_recognizer
    from embodied_adhoc.comms.vocabulary import node_name

    voice = synthesis.Voice(synthesis.check_voice(args.voice, "--voice"), args.speed, args.pitch)
    audio = synthesis.synthesize(args.text, voice)
    if args.snr is not None:
        audio = synthesis.add_noise(audio, args.snr, np.random.default_rng(args.seed), args.noise)
    transcript = shared_recognizer().transcribe(audio)
    parsed = parsing.parse(transcript)
    if args.wav:
        peak = float(np.max(np.abs(audio)))
        synthesis.write_wav(args.wav, audio / peak if peak > 1.0 else audio)
    if args.json:
        print(json.dumps({"transcript": transcript, "place": parsed.place, "node": parsed.node}))
    else:
        print(
            f"said:       {args.text}\nheard:      {transcript or '(nothing)'}\n"
            f"place:      {parsed.place or '(none)'}\nnode:       "
            f"{'no location' if parsed.node is None else f'{parsed.node} ({node_name(parsed.node)})'}"
        )
    return 0


def handle_say(args: argparse.Namespace) -> int:
    from embodied_adhoc.comms import robot_speech

    text = robot_speech.utterance(args.act, args.node)
    if args.wav:
        robot_speech.save_utterance(args.wav, args.act, args.node)
        print(f"{text}  -> {args.wav}")
    else:
        print(text)
    return 0


def handle_grammar(args: argparse.Namespace) -> int:
    from embodied_adhoc import paths
    from embodied_adhoc.comms import grammar

    if args.check:
        stale = [
            relative
            for relative, text in grammar.generated_files().items()
            if not (paths.assets_dir() / relative).is_file()
            or (paths.assets_dir() / relative).read_text(encoding="utf-8") != text
        ]
        if stale:
            print(
                f"out of date: {', '.join('assets/' + s for s in stale)}; run `embodied-adhoc speech grammar`"
            )
            return 1
        print("grammar and dictionary are up to date")
        return 0
    for path in grammar.write_generated_files():
        print(f"wrote {path}")
    return 0


def _recordings(list_path: str):
    """(audio, text) pairs from a 'path.wav<TAB>text' list; errors name the file and line."""
    from pathlib import Path

    import soundfile

    from embodied_adhoc.comms.synthesis import SAMPLE_RATE
    from embodied_adhoc.errors import ConfigError

    listing = Path(list_path)
    if not listing.is_file():
        raise ConfigError(f"--recordings {list_path}: no such file")
    for number, line in enumerate(listing.read_text(encoding="utf-8").splitlines(), start=1):
        if not line.strip() or line.startswith("#"):
            continue
        if "\t" not in line:
            raise ConfigError(f"{listing}:{number}: expected 'path.wav<TAB>what was said'")
        name, text = line.split("\t", 1)
        wav = (listing.parent / name.strip()).resolve()
        try:
            audio, rate = soundfile.read(wav, dtype="float32")
        except (OSError, RuntimeError) as error:
            raise ConfigError(f"{listing}:{number}: cannot read {wav} ({error})") from None
        if audio.ndim != 1 or rate != SAMPLE_RATE:
            raise ConfigError(
                f"{listing}:{number}: {wav} is {audio.ndim}-channel at {rate} Hz; "
                f"convert it to mono {SAMPLE_RATE} Hz (e.g. sox in.wav -r 16000 -c 1 out.wav)"
            )
        yield audio, text.strip()


def handle_adapt(args: argparse.Namespace) -> int:
    import time

    from embodied_adhoc import paths
    from embodied_adhoc.comms import adaptation, synthesis
    from embodied_adhoc.comms import eval as speech_eval

    start = time.perf_counter()
    if args.recordings:
        utterances = _recordings(args.recordings)
        source = f"recordings listed in {args.recordings}"
    else:
        voices = _voices(args.voices, "--voices") or synthesis.DEFAULT_VOICES
        levels = _parse_list(args.snr, "snr") or (None,)
        config = speech_eval.EvalConfig(
            voices=voices, snr_levels=levels, phrases=args.phrases, seed=args.seed
        )
        phrases = speech_eval.phrase_list(config)
        utterances = (
            (speech_eval.utterance_audio(config, v, p, k, phrase)[1], phrase.reference)
            for v in range(len(voices))
            for p, (_, phrase) in enumerate(phrases)
            for k in range(len(levels))
        )
        source = (
            f"{len(voices)} voices x {args.phrases} synthesised phrases x {len(levels)} conditions "
            f"({args.snr}), seed {args.seed}"
        )
    result = adaptation.estimate(utterances)
    out = args.out or paths.assets_dir() / adaptation.ADAPTATION_FILE
    written = adaptation.write_transform(result, out)
    print(
        f"MLLR transform from {source}: {result.aligned} of {result.utterances} utterances aligned, "
        f"{result.frames} frames, {time.perf_counter() - start:.0f} s\nwrote {written}"
    )
    return 0
