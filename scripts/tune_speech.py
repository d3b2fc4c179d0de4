"""Recogniser settings on a held-out tuning set: dictionary (CMU only vs CMU + accents) x search beams x MLLR.

The default recogniser (``comms/recognition.py``) uses the multi-accent dictionary (``comms/lexicon.py``), beams
wider than pocketsphinx's, and the MLLR transform of ``assets/speech/synthetic.mllr`` (``comms/adaptation.py``,
estimated from seed-2 phrases). This script measures each choice on phrases drawn with a different seed from the
evaluation's (default ``--seed 1``; ``speech eval`` uses seed 0), clean speech, every default voice, so that the
settings are not chosen on the numbers they are reported with. It prints clean node accuracy (metric 6) pooled
and per voice, transcript accuracy (metric 4), and each configuration's decoding CPU time as a ratio to
pocketsphinx's own settings (CMU dictionary, default beams) measured in the same run.

    .venv/bin/python scripts/tune_speech.py [--seed 1 --phrases 60 --workers 2]

The MLLR rows use the committed transform; `embodied-adhoc speech adapt` re-estimates it.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

from embodied_adhoc.comms import grammar
from embodied_adhoc.comms.eval import EvalConfig, condition_metrics, run_eval, voice_metrics
from embodied_adhoc.comms.recognition import DecoderSettings
from embodied_adhoc.experiments.script_args import parse_dataclass_args

POCKETSPHINX_BEAMS = {"beam": 1e-48, "wbeam": 7e-29, "pbeam": 1e-48}
"""pocketsphinx 5's default search beams (``pocketsphinx.Config()``)."""


@dataclass(frozen=True)
class Args:
    seed: int = 1
    """seed of the tuning phrases, speeds and pitches (the evaluation uses 0)"""
    phrases: int = 60
    """phrases per voice"""
    workers: int = 2
    """decoding processes"""


def configurations(cmu_only_dictionary: Path) -> dict[str, DecoderSettings]:
    cmu = (("dict", str(cmu_only_dictionary)),)
    narrow = DecoderSettings(**POCKETSPHINX_BEAMS, adaptation=None)
    wide = DecoderSettings(adaptation=None)
    return {
        "CMU dictionary, pocketsphinx beams, no MLLR": replace(narrow, extra=cmu),
        "CMU + accents, pocketsphinx beams, no MLLR": narrow,
        "CMU dictionary, wide beams, no MLLR": replace(wide, extra=cmu),
        "CMU + accents, wide beams, no MLLR": wide,
        "CMU + accents, pocketsphinx beams, MLLR": replace(narrow, adaptation=DecoderSettings().adaptation),
        "CMU dictionary, wide beams, MLLR": replace(DecoderSettings(), extra=cmu),
        "CMU + accents, wide beams, MLLR (default)": DecoderSettings(),
    }


def main() -> None:
    args = parse_dataclass_args(Args, __doc__)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        cmu_only = Path(folder) / "cmu-only.dict"
        cmu_only.write_text(grammar.dictionary_text(grammar.cmudict_path(), accents=()))
        for name, settings in configurations(cmu_only).items():
            config = EvalConfig(
                snr_levels=(None,),
                phrases=args.phrases,
                seed=args.seed,
                workers=args.workers,
                decoder=settings,
            )
            start = time.perf_counter()
            results = run_eval(config)
            wall = time.perf_counter() - start
            rows.append((name, condition_metrics(results, None), voice_metrics(results), wall))
            print(f"done: {name} ({wall:.0f} s)", flush=True)
    reference_cpu = rows[0][1]["cpu_ms_mean"]
    voices = list(rows[0][2])
    print(
        f"\nclean speech, seed {args.seed}, {args.phrases} phrases x {len(voices)} voices: node accuracy (metric 6) "
        "pooled and per voice, transcript accuracy (metric 4)\n\n"
        "| dictionary, beams | node (M6) | transcript (M4) | " + " | ".join(voices) + " |"
    )
    print("|---" * (len(voices) + 3) + "|")
    for name, pooled, by_voice, _ in rows:
        print(
            f"| {name} | {100 * pooled['node_accuracy']:.1f} % | {100 * pooled['transcript_accuracy']:.1f} % | "
            + " | ".join(f"{100 * by_voice[v]['node_accuracy']:.1f}" for v in voices)
            + " |"
        )
    print(
        "\ndecoding CPU time per utterance, and its ratio to the first row's (pocketsphinx's own settings) in "
        "this run\n\n| dictionary, beams | CPU ms / utterance | CPU ratio | eval wall s |\n|---|---|---|---|"
    )
    for name, pooled, _, wall in rows:
        print(
            f"| {name} | {pooled['cpu_ms_mean']:.0f} | {pooled['cpu_ms_mean'] / reference_cpu:.2f}x | {wall:.0f} |"
        )


if __name__ == "__main__":
    main()
