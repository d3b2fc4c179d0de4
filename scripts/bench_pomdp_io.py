"""Benchmark the ``.pomdp`` reader and writer, with references measured in the same run.

For each corpus file: the reader's time (best of ``--repeats``), the time of the least any tokenising reader must
do (read the file and ``str.split()`` it: the "floor"), their ratio, and, unless ``--base ''``, the earlier reader
(the dense one-statement-at-a-time reader of ``--base``, loaded from git) and the speed-up over it. Then a
generated sparse model of the largest chapter-5 size (4,831 states, 5 actions, 81 observations): the time to
format it, to write it, and to read it back (the round trip is checked to give the same model).

SARSOP (AdaCompNUS/sarsop) reads Tag in about 0.03 s on a 2-core machine (a recorded figure,
``SARSOP_TAG_SECONDS``); this reader's goal is to read it in under 0.1 s.

    .venv/bin/python scripts/bench_pomdp_io.py
    .venv/bin/python scripts/bench_pomdp_io.py --files sarsop-TagAvoid.pomdp --repeats 20 --base ''
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.decision.models import POMDP
from embodied_adhoc.decision.pomdp_io import format_pomdp, read_pomdp, write_pomdp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compare_pomdp_parsers import BASE, load_old_reader  # noqa: E402  (a sibling script)

ROOT = Path(__file__).resolve().parents[1]
FILES = (
    "sarsop-TagAvoid.pomdp",
    "hallway2.POMDP",
    "cit.POMDP",
    "sunysb.POMDP",
    "saci-s100-a10-z31.POMDP",
    "aloha.30.POMDP",
    "fourth.POMDP",
)
SARSOP_TAG_SECONDS = 0.03  # recorded, not measured here (pomdpsol has no read-only mode)


def best(function, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def floor_read(path: Path) -> None:
    path.read_text(encoding="utf-8", errors="replace").replace(":", " : ").split()


def generated_model(seed: int = 0, n_states: int = 4831, n_actions: int = 5, n_obs: int = 81) -> POMDP:
    """A seeded sparse POMDP of the largest chapter-5 size (5 successors and 3 observations per row)."""
    rng = np.random.default_rng(seed)

    def stochastic(columns: int, per_row: int) -> sp.csr_matrix:
        spread = columns // per_row
        picked = np.arange(per_row) * spread + rng.integers(0, spread, size=(n_states, per_row))
        values = rng.random((n_states, per_row)) + 0.05
        values /= values.sum(axis=1, keepdims=True)
        indptr = np.arange(0, n_states * per_row + 1, per_row)
        return sp.csr_matrix((values.ravel(), picked.ravel(), indptr), shape=(n_states, columns))

    return POMDP(
        transitions=[stochastic(n_states, 5) for _ in range(n_actions)],
        rewards=rng.normal(size=(n_states, n_actions)),
        discount=0.95,
        observations=[stochastic(n_obs, 3) for _ in range(n_actions)],
        initial_belief=np.full(n_states, 1.0 / n_states),
    )


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--corpus", type=Path, default=ROOT / ".." / "shared" / "pomdp")
    parser.add_argument("--files", nargs="+", default=list(FILES))
    parser.add_argument(
        "--repeats", type=int, default=5, help="timings are the best of this many (default 5)"
    )
    parser.add_argument("--base", default=BASE, help="git revision of the earlier reader ('' to skip it)")
    args = parser.parse_args()
    old = load_old_reader(args.base) if args.base else None
    print(
        "| file | MB | S | reader s | floor s (read + split) | reader / floor | earlier reader s | speed-up |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name in args.files:
        path = args.corpus / name
        model = read_pomdp(path)
        seconds = best(lambda: read_pomdp(path), args.repeats)  # noqa: B023 (called at once)
        floor = best(lambda: floor_read(path), args.repeats)  # noqa: B023
        earlier = (
            best(lambda: old.read_pomdp(path), max(1, args.repeats // 2)) if old else float("nan")  # noqa: B023
        )
        print(
            f"| {name} | {path.stat().st_size / 1e6:.2f} | {model.n_states} | {seconds:.4f} | {floor:.4f} | "
            f"{seconds / floor:.1f}x | {earlier:.4f} | {earlier / seconds:.1f}x |"
        )
        if name == "sarsop-TagAvoid.pomdp":
            print(f"|  (SARSOP, recorded) | | | {SARSOP_TAG_SECONDS:.2f} | | | | |")
    model = generated_model()
    text_seconds = best(lambda: format_pomdp(model), 1)
    with tempfile.TemporaryDirectory() as folder:
        target = Path(folder) / "generated.pomdp"
        write_seconds = best(lambda: write_pomdp(model, target), 1)
        read_seconds = best(lambda: read_pomdp(target), args.repeats)
        floor = best(lambda: floor_read(target), args.repeats)
        again = read_pomdp(target)
        size = target.stat().st_size / 1e6
    same = (
        all((x != y).nnz == 0 for x, y in zip(model.transitions, again.transitions, strict=True))
        and all((x != y).nnz == 0 for x, y in zip(model.observations, again.observations, strict=True))
        and np.array_equal(model.rewards, again.rewards)
        and np.array_equal(model.initial_belief, again.initial_belief)
    )
    print(
        f"\ngenerated 4831 x 5 x 81 sparse model ({size:.1f} MB): format {text_seconds:.3f} s, write "
        f"{write_seconds:.3f} s, read {read_seconds:.3f} s (floor {floor:.3f} s, {read_seconds / floor:.1f}x); "
        f"round trip identical: {same}"
    )
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
