"""A solve is the same computation on any host: the same bytes under every OpenBLAS kernel.

The solver's deciding products sum in one fixed order (decision/products.py; the dense projection's BLAS scores
are rescored in that order where they nearly tie), so the alphas, the plans and the bounds of a solve do not depend
on which kernel OpenBLAS picked for the CPU. Checked directly: the same solves in child processes that force two
other kernels every x86-64 host of this kind runs (OpenBLAS reads ``OPENBLAS_CORETYPE`` when it loads).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

CORPUS = Path(__file__).resolve().parents[2] / ".." / "shared" / "pomdp"

# Tag: sparse observations (support-restricted float32 scores); hallway: dense ones (the BLAS projection with its
# fixed-order rescoring of near-ties); both small enough to take about a second each.
SOLVES = r"""
import hashlib, json, sys
import numpy as np
import threadpoolctl
from embodied_adhoc.decision.backup import blind_policy_vectors
from embodied_adhoc.decision.perseus import PerseusConfig, perseus
from embodied_adhoc.decision.pomdp_io import read_pomdp

def digest(*arrays):
    sha = hashlib.sha256()
    for array in arrays:
        sha.update(np.ascontiguousarray(array).tobytes())
    return sha.hexdigest()

result = {"kernel": threadpoolctl.threadpool_info()[0].get("architecture")}
for name, settings in [
    ("sarsop-TagAvoid.pomdp", dict(n_beliefs=300, max_iterations=12, seed=1, update="perseus")),
    ("sarsop-TagAvoid.pomdp", dict(n_beliefs=300, max_iterations=8, seed=2)),
    ("hallway.POMDP", dict(n_beliefs=200, max_iterations=15, seed=0)),
]:
    pomdp = read_pomdp(sys.argv[1] + "/" + name)
    policy = perseus(pomdp, PerseusConfig(**settings))
    beliefs = np.random.default_rng(5).dirichlet(np.full(pomdp.n_states, 0.05), size=64)
    result[name + repr(sorted(settings.items()))] = [
        digest(policy.alphas, policy.actions),
        digest(blind_policy_vectors(pomdp)),
        digest(policy.actions_of(beliefs), policy.values(beliefs)),
        [policy.stats.iterations, policy.stats.lower, policy.stats.upper],
    ]
print(json.dumps(result))
"""


def _solves(kernel: str | None) -> dict:
    env = dict(os.environ)
    env.pop("OPENBLAS_CORETYPE", None)
    if kernel is not None:
        env["OPENBLAS_CORETYPE"] = kernel
    done = subprocess.run(
        [sys.executable, "-c", SOLVES, str(CORPUS)],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(
    not (CORPUS / "sarsop-TagAvoid.pomdp").is_file(), reason="the shared POMDP corpus is absent"
)
def test_solves_are_the_same_bytes_under_every_openblas_kernel():
    default = _solves(None)
    for kernel in ("Haswell", "Sandybridge"):
        forced = _solves(kernel)
        assert forced.pop("kernel") == kernel, f"OpenBLAS did not load its {kernel} kernel"
        reference = {key: value for key, value in default.items() if key != "kernel"}
        assert forced == reference, f"{kernel} differs from the default kernel ({default['kernel']})"
