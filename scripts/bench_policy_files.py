"""Policy file sizes and load times: each given policy file rewritten in the current format, measured in this run.

    .venv/bin/python scripts/bench_policy_files.py ~/.cache/embodied-adhoc/policies/*.npz --discount 0.95

``--discount`` marks policies whose stats lack one (files written before format 2) as closed Perseus policies of
that discount, so they are stored the way a fresh solve's would be (files whose vectors are float32 already are
left as they are); give it only for such policies (the chapter-5
cache holds infinite-horizon Perseus policies; the pursuit models' discount is 0.95). Prints, per file: vectors x
states, the file's size, the vectors' float64 bytes, the rewritten size and ratio, load CPU seconds of both files,
save CPU seconds, the largest drop of a value and the stored lower bound against the file's. CPU seconds
(``time.process_time``): the machine may be shared.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from embodied_adhoc.decision.policy import AlphaVectorPolicy


def _cpu(function):
    start = time.process_time()
    result = function()
    return result, time.process_time() - start


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("files", nargs="+", type=Path)
    parser.add_argument(
        "--discount", type=float, default=None, help="discount of closed policies without one"
    )
    args = parser.parse_args()
    print(
        "file | K x S | file MB | float64 MB | new MB | ratio | load s old/new | save s | max drop | lower old/new"
    )
    with tempfile.TemporaryDirectory() as folder:
        for path in args.files:
            policy, load_old = _cpu(lambda path=path: AlphaVectorPolicy.load(path))
            stats = policy.stats
            written_before_format_2 = not np.array_equal(policy.alphas.astype(np.float32), policy.alphas)
            if (
                args.discount is not None
                and stats is not None
                and math.isnan(stats.discount)
                and written_before_format_2
            ):
                policy = dataclasses.replace(policy, stats=dataclasses.replace(stats, discount=args.discount))
            target = Path(folder) / "policy.npz"
            _, save = _cpu(lambda policy=policy, target=target: policy.save(target))
            again, load_new = _cpu(lambda target=target: AlphaVectorPolicy.load(target))
            drop = float((policy.alphas - again.alphas).max())
            lowers = "n/a" if stats is None else f"{stats.lower:.6f}/{again.stats.lower:.6f}"
            size, new = path.stat().st_size / 1e6, target.stat().st_size / 1e6
            print(
                f"{path.name[:16]} | {policy.n_vectors} x {policy.n_states} | {size:.1f} | "
                f"{policy.alphas.nbytes / 1e6:.1f} | {new:.1f} | {size / new:.1f}x | {load_old:.2f}/{load_new:.2f} | "
                f"{save:.2f} | {drop:.2e} | {lowers}"
            )


if __name__ == "__main__":
    main()
