"""Are the sequential-teams protocol's records of two source trees identical (same seed)?

    git archive COMMIT | tar -x -C /tmp/old-tree
    .venv/bin/python scripts/compare_teamster_records.py /tmp/old-tree .

Runs ``run_trial`` (trial 1) of a short pursuit run and a short ntu run for several agents in each tree, each in a
subprocess with that tree first on the path, and compares the JSON records field for field (without the timing).
Each tree's driver is found where it lives (``experiments/domains/teamster_protocol.py``, or in an older tree
``experiments/`` or ``learning/``). Exit 0 when every record is identical, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

CASES = [
    (
        "pursuit",
        {"steps": 40, "eval_steps": 20, "points": 2, "changed": "mirror", "changed_steps": 40},
        ["teamster", "plastic-model", "learns-team", "plastic-policy", "random", "original"],
    ),
    (
        "ntu",
        {"domain": "ntu", "steps": 20, "points": 2, "eval_episodes": 2, "changed": 0.2},
        ["teamster", "plastic-model", "plastic-policy", "random", "original"],
    ),
]
CODE = """
import json, sys
from {module} import ProtocolConfig, run_trial
out = {{}}
for domain, kw, agents in json.loads(sys.argv[1]):
    for agent in agents:
        record = run_trial(agent, 1, ProtocolConfig(**kw))
        record.pop("seconds")
        out[domain + "/" + agent] = record
print(json.dumps(out))
"""


def records(tree: Path) -> dict:
    where = next(
        package
        for package in ("experiments.domains", "experiments", "learning")
        if (tree / "embodied_adhoc" / package.replace(".", "/") / "teamster_protocol.py").is_file()
    )
    env = dict(os.environ, PYTHONPATH=str(tree), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            CODE.format(module=f"embodied_adhoc.{where}.teamster_protocol"),
            json.dumps(CASES),
        ],
        cwd=tree,
        env=env,
        capture_output=True,
        text=True,
    )
    if done.returncode:
        sys.exit(f"{tree}: the protocol failed:\n{done.stderr.strip()}")
    return json.loads(done.stdout)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old", type=Path, help="a source tree (e.g. git archive of a commit)")
    parser.add_argument("new", type=Path, help="another source tree")
    args = parser.parse_args()
    old, new = records(args.old.resolve()), records(args.new.resolve())
    for key in old:
        same = old[key] == new.get(key)
        points = sum(len(curve) for curve in old[key]["curves"].values())
        print(
            f"{key}: {'identical' if same else 'DIFFERENT'} ({points} curve points, after-learning matrix, "
            f"changed phase {old[key].get('changed')})"
        )
    print("ALL IDENTICAL" if old == new else "NOT IDENTICAL")
    return 0 if old == new else 1


if __name__ == "__main__":
    raise SystemExit(main())
