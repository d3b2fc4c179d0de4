"""Check that the ``.pomdp`` reader gives the same models as an earlier version of it, on a whole folder.

The earlier reader is taken from git (``git show REV:embodied_adhoc/decision/pomdp_io.py``), so no copy of old
code lives in the tree. For every file (and every ``missing_rows`` choice) both readers parse it; the script
compares sizes, names, discount, start belief and every T and O entry exactly, rewards to 1e-12 (relative to
the largest reward: the sparse collapse of ``R(a, s, s', z)`` adds the same terms in another order), and for
files both refuse, the ``file:line`` of the error. It prints one row per file, the parse times of both, and exits
1 on any difference.

    .venv/bin/python scripts/compare_pomdp_parsers.py                       # ../shared/pomdp, old = af92ccb
    .venv/bin/python scripts/compare_pomdp_parsers.py --folder DIR --base REV
    .venv/bin/python scripts/compare_pomdp_parsers.py --write-fixture tests/decision/data/old_reader_models.npz

``--write-fixture`` saves the earlier reader's models of :data:`FIXTURE_FILES` (sparse T/O entries, rewards,
start belief, discount) for the equivalence test in ``tests/decision/test_pomdp_io.py``.
"""

from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from embodied_adhoc.decision import pomdp_io
from embodied_adhoc.errors import PomdpFormatError

ROOT = Path(__file__).resolve().parents[1]
BASE = "af92ccb"  # the last commit with the dense one-statement-at-a-time reader
FIXTURE_FILES = (  # names, wildcards, row and matrix forms, R on end states and observations, cost, reset
    "saci-s12-a6-z5.95.POMDP",
    "tiger-grid.POMDP",
    "shuttle.95.POMDP",
    "learning.c2.POMDP",
    "bulkhead.A.POMDP",
    "parr95.95.pomdp",
    "mini-hall2.pomdp",  # with missing_rows="absorbing"
)


def load_old_reader(revision: str):
    source = subprocess.run(
        ["git", "show", f"{revision}:embodied_adhoc/decision/pomdp_io.py"],
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    folder = Path(tempfile.mkdtemp(prefix="old-pomdp-io-"))
    path = folder / "old_pomdp_io.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location("old_pomdp_io", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def read(reader, path: Path, missing_rows: str):
    start = time.perf_counter()
    try:
        model = reader.read_pomdp(path, missing_rows=missing_rows)
    except PomdpFormatError as error:
        return str(error), time.perf_counter() - start
    return model, time.perf_counter() - start


def differences(old, new) -> list[str]:
    if isinstance(old, str) or isinstance(new, str):
        if isinstance(old, str) and isinstance(new, str):
            where_old, where_new = old.split(": ", 1)[0], new.split(": ", 1)[0]
            return [] if where_old == where_new else [f"errors at {where_old} (old) and {where_new} (new)"]
        return [
            f"old: {old if isinstance(old, str) else 'a model'}; new: {new if isinstance(new, str) else 'a model'}"
        ]
    found = []
    for field in ("n_states", "n_actions", "n_observations", "discount", "state_names", "action_names",
                  "observation_names"):  # fmt: skip
        if getattr(old, field) != getattr(new, field):
            found.append(f"{field}: {getattr(old, field)} vs {getattr(new, field)}")
    if found:
        return found
    if not np.array_equal(old.initial_belief, new.initial_belief):
        found.append("start belief differs")
    for letter, olds, news in (
        ("T", old.transitions, new.transitions),
        ("O", old.observations, new.observations),
    ):
        for action, (a, b) in enumerate(zip(olds, news, strict=True)):
            if (a != b).nnz:
                found.append(f"{letter} differs for action {action} ({(a != b).nnz} entries)")
    scale = max(1.0, float(np.abs(old.rewards).max()))
    gap = float(np.abs(old.rewards - new.rewards).max())
    if gap > 1e-12 * scale:
        found.append(f"rewards differ by up to {gap:g}")
    return found


def write_fixture(reader, folder: Path, target: Path) -> None:
    arrays: dict[str, np.ndarray] = {}
    for name in FIXTURE_FILES:
        model = reader.read_pomdp(
            folder / name, missing_rows="absorbing" if name == "mini-hall2.pomdp" else "error"
        )
        arrays[f"{name}/discount"] = np.float64(model.discount)
        arrays[f"{name}/start"] = model.initial_belief
        arrays[f"{name}/rewards"] = model.rewards
        for letter, matrices in (("T", model.transitions), ("O", model.observations)):
            for action, matrix in enumerate(matrices):
                coo = matrix.tocoo()
                arrays[f"{name}/{letter}/{action}"] = np.stack([coo.row, coo.col]).astype(np.int64)
                arrays[f"{name}/{letter}/{action}/values"] = coo.data
    target.parent.mkdir(parents=True, exist_ok=True)
    with open(target, "wb") as stream:  # a file object: numpy writes exactly this path
        np.savez_compressed(stream, **arrays)
    print(f"wrote {target} ({len(FIXTURE_FILES)} models of the reader at the base revision)")


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--folder", type=Path, default=ROOT / ".." / "shared" / "pomdp")
    parser.add_argument("--base", default=BASE, help=f"git revision of the earlier reader (default {BASE})")
    parser.add_argument("--write-fixture", type=Path, default=None, metavar="NPZ")
    args = parser.parse_args()
    old_reader = load_old_reader(args.base)
    if args.write_fixture is not None:
        write_fixture(old_reader, args.folder, args.write_fixture)
        return 0
    files = sorted(p for p in args.folder.iterdir() if p.is_file() and p.suffix.lower() == ".pomdp")
    failures = 0
    total_old = total_new = 0.0
    print(f"{'file':<28} {'missing_rows':<12} {'old s':>8} {'new s':>8} {'ratio':>7}  result")
    for path in files:
        for missing_rows in pomdp_io.MISSING_ROWS:
            old, old_seconds = read(old_reader, path, missing_rows)
            new, new_seconds = read(pomdp_io, path, missing_rows)
            found = differences(old, new)
            if missing_rows != "error" and not found and not isinstance(old, str):
                if not isinstance(read(pomdp_io, path, "error")[0], str):
                    continue  # the option changes nothing for a file without missing rows: one row is enough
            total_old += old_seconds
            total_new += new_seconds
            failures += bool(found)
            result = "; ".join(found) if found else ("same error" if isinstance(old, str) else "same model")
            print(
                f"{path.name:<28} {missing_rows:<12} {old_seconds:8.4f} {new_seconds:8.4f} "
                f"{old_seconds / max(new_seconds, 1e-9):6.1f}x  {result}"
            )
    print(
        f"total: old {total_old:.2f} s, new {total_new:.2f} s; {failures} difference(s) in {len(files)} files"
    )
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
