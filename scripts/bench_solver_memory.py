"""CPU time, kernel time, page faults and peak memory of fixed solver work under each allocation setting.

The solvers form their reduced products in blocks (``backup._BLOCK_ENTRIES``) and ``pomdp solve`` maps arrays on
their own from a size (``memory._MALLOC_THRESHOLD``, glibc's mapping and trim thresholds). Each setting runs the
same work in a fresh process (Perseus with ``max_iterations``, HSVI with ``max_trials``; the bounds must come out
bit for bit the same, which the table shows), and the table prints each row's CPU seconds (user + system) and
peak resident memory with their ratio to the first setting, measured in the same run:

    OPENBLAS_NUM_THREADS=1 .venv/bin/python scripts/bench_solver_memory.py \\
        --job perseus:../shared/pomdp/sarsop-TagAvoid.pomdp:100 --job hsvi:rocksample:7,8:40 \\
        --setting 1:8 --setting 4:2

A job is ``SOLVER:MODEL:WORK``; MODEL is a ``.pomdp`` path, ``rocksample:N,K`` or ``export:DOMAIN`` (as in
``bench_solvers.py --side-by-side``); a setting is ``THRESHOLD_MIB:BLOCK_MIB`` (``glibc``: glibc's own dynamic
threshold, the current block).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = """
import json, resource, sys
from embodied_adhoc.decision import backup, memory
setting, path, solver, work = sys.argv[1:5]
if setting != "glibc":
    threshold, block = (int(x) for x in setting.split(":"))
    memory._MALLOC_THRESHOLD = threshold << 20
    memory.return_freed_memory()
    backup._BLOCK_ENTRIES = (block << 20) // 8
    backup.DENSE_BLOCK_BYTES = block << 20
from embodied_adhoc.decision.hsvi import HsviConfig, hsvi
from embodied_adhoc.decision.perseus import PerseusConfig, perseus
from embodied_adhoc.decision.pomdp_io import read_pomdp
pomdp = read_pomdp(path)
memory.trim()
before = resource.getrusage(resource.RUSAGE_SELF)
if solver == "perseus":
    config = PerseusConfig(n_beliefs=1000, expand=True, time_limit=1e9, max_iterations=int(work), clock="cpu")
    policy = perseus(pomdp, config)
else:
    policy = hsvi(pomdp, HsviConfig(max_trials=int(work), clock="cpu"))
after = resource.getrusage(resource.RUSAGE_SELF)
system = after.ru_stime - before.ru_stime
print(json.dumps({
    "lower": policy.stats.lower, "upper": policy.stats.upper,
    "cpu": after.ru_utime - before.ru_utime + system, "system": system,
    "faults": after.ru_minflt - before.ru_minflt, "peak_mb": memory.peak_mb(),
}))
"""


def parse() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--job", action="append", required=True, help="SOLVER:MODEL:WORK (repeatable)")
    parser.add_argument("--setting", action="append", required=True, help="THRESHOLD_MIB:BLOCK_MIB or glibc")
    parser.add_argument("--json", help="also write the rows to this file")
    args = parser.parse_args()
    for job in args.job:
        solver, _, rest = job.partition(":")
        model, _, work = rest.rpartition(":")
        if solver not in ("perseus", "hsvi") or not model or not work.isdigit() or int(work) < 1:
            parser.error(f"--job {job}: give SOLVER:MODEL:WORK, e.g. hsvi:rocksample:7,8:40")
    for setting in args.setting:
        parts = setting.split(":")
        if setting != "glibc" and (len(parts) != 2 or not all(p.isdigit() and int(p) > 0 for p in parts)):
            parser.error(f"--setting {setting}: give THRESHOLD_MIB:BLOCK_MIB (positive integers) or glibc")
    return args


def main() -> int:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_solvers import model_path

    args = parse()
    rows = []
    print("| job | setting | CPU s | x first | system s | page faults | peak MB | x first | lower / upper |")
    print("|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as folder:
        for job in args.job:
            solver, _, rest = job.partition(":")
            model, _, work = rest.rpartition(":")
            path = model_path(model, Path(folder))
            first = None
            for setting in args.setting:
                done = subprocess.run(
                    [sys.executable, "-c", CHILD, setting, str(path), solver, work],
                    capture_output=True,
                    text=True,
                    check=False,
                )
                if done.returncode:
                    print(f"{job} {setting}: the solve failed:\n{done.stderr[-2000:]}", file=sys.stderr)
                    return 1
                row = {"job": job, "setting": setting, **json.loads(done.stdout.strip().splitlines()[-1])}
                rows.append(row)
                first = first or row
                print(
                    f"| {job} | {setting} | {row['cpu']:.2f} | {row['cpu'] / first['cpu']:.2f} | "
                    f"{row['system']:.2f} | {row['faults']:,} | {row['peak_mb']:.0f} | "
                    f"{row['peak_mb'] / first['peak_mb']:.2f} | {row['lower']:.6f} / {row['upper']:.6f} |",
                    flush=True,
                )
    if args.json:
        Path(args.json).write_text(json.dumps({"command": " ".join(sys.argv), "rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
