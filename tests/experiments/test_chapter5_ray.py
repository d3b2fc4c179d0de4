"""The Ray executor on a chapter-5 domain: a private single-node Ray gives the returns of the local executor.

Slow (Ray starts in ~10-30 s). Ray is the optional ``ray`` extra (``pip install 'embodied-adhoc[ray]'``), which the
CI's ``.[dev]`` install leaves out: the module is skipped, with that reason, only when the ``ray`` distribution is not
installed. An installed Ray that fails to import is an error, not a skip (the executor's refusal without Ray is
tested in test_experiments_runner.py)."""

from __future__ import annotations

import importlib.metadata

import pytest

from embodied_adhoc.experiments.domains.chapter5 import forget_sessions, sweep_config
from embodied_adhoc.experiments.runner import run_sweep

try:
    importlib.metadata.version("ray")
except importlib.metadata.PackageNotFoundError:
    pytest.skip(
        "the optional 'ray' extra is not installed (pip install 'embodied-adhoc[ray]', Ray 2.60.0)",
        allow_module_level=True,
    )
import ray  # noqa: E402  (installed: an import error here fails the module instead of skipping it)


@pytest.mark.slow
def test_ray_executor_matches_local_on_a_chapter5_domain(tmp_path, monkeypatch):
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))  # passed to Ray's workers (RAY_WORKER_ENV)
    path = tmp_path / "corridor.txt"
    path.write_text("S...G\n#.#.#\nS...G\n")
    config = sweep_config("map", {"map": str(path)}, ("value-iteration", "atpo", "random"), episodes=4, seed=3,
                          beliefs=60)  # fmt: skip
    local = run_sweep(config)
    forget_sessions()
    try:
        remote = run_sweep(config, workers=2, executor="ray")
    finally:
        ray.shutdown()
    key = lambda r: (r.agent, r.episode)  # noqa: E731
    assert [(key(r), r.total_reward, r.steps) for r in sorted(local.records, key=key)] == [
        (key(r), r.total_reward, r.steps) for r in sorted(remote.records, key=key)
    ]
    assert len(list((tmp_path / "xdg").rglob("*.npz"))) == 1  # the workers used the driver's cache folder
