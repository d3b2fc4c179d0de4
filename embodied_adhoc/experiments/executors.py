"""Execution backends: run trial jobs in this process, in a local process pool, or on Ray; yield results as they
finish. Results do not depend on the backend or the number of workers (each trial is seeded by its job).

A worker opens a domain session (models built and solved, env created) once per (domain, backend, options) and
reuses it for every trial it runs (:func:`execute_job`).
"""

from __future__ import annotations

import json
import multiprocessing
import os
from collections.abc import Iterator, Sequence

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.registry import get_trial_domain
from embodied_adhoc.experiments.trial import TrialJob, TrialResult, run_trial

EXECUTORS = ("local", "ray")

_SESSIONS: dict[str, object] = {}
_ENVS: dict[tuple[str, int, int], object] = {}


def _key(domain_name: str, backend: str, options: dict) -> str:
    return json.dumps([domain_name, backend, options], sort_keys=True)


def open_session(domain_name: str, backend: str, options: dict):
    """The session of a domain configuration (models built and solved), opened once per process.

    Sessions opened before a fork are inherited by pool workers, so models are built once per sweep.
    """
    key = _key(domain_name, backend, options)
    if key not in _SESSIONS:
        _SESSIONS[key] = get_trial_domain(domain_name).open_session(backend, options)
    return _SESSIONS[key]


def _env(domain_name: str, backend: str, options: dict, max_steps: int):
    # Envs (physics, renderers) are never shared across a fork: one per process.
    key = (_key(domain_name, backend, options), int(max_steps), os.getpid())
    if key not in _ENVS:
        _ENVS[key] = open_session(domain_name, backend, options).make_env(max_steps)
    return _ENVS[key]


def close_sessions() -> None:
    """Close the envs this process opened and forget every session (e.g. to measure model building again)."""
    pid = os.getpid()
    while _ENVS:
        (_, _, owner), env = _ENVS.popitem()
        if owner == pid:
            env.close()
    _SESSIONS.clear()


def execute_job(job: TrialJob) -> TrialResult:
    session = open_session(job.domain, job.backend, job.options)
    return run_trial(session, _env(job.domain, job.backend, job.options, job.max_steps), job)


def resolve_workers(workers: int) -> int:
    if workers < 0:
        raise ConfigError(f"--workers must be >= 0 (0 = one per CPU), got {workers}")
    return workers or (os.cpu_count() or 1)


def execute(jobs: Sequence[TrialJob], workers: int = 1, executor: str = "local") -> Iterator[TrialResult]:
    """Yield the result of every job as it finishes (completion order; order-free content)."""
    if executor not in EXECUTORS:
        raise ConfigError(f"unknown executor '{executor}'; choose one of {', '.join(EXECUTORS)}")
    workers = resolve_workers(workers)
    if not jobs:
        return
    if executor == "ray":
        yield from _execute_ray(jobs, workers)
    elif workers == 1 or len(jobs) == 1:
        for job in jobs:
            yield execute_job(job)
    else:
        yield from _execute_pool(jobs, workers)


def _execute_pool(jobs: Sequence[TrialJob], workers: int) -> Iterator[TrialResult]:
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    # fork keeps domains registered at run time (tests, notebooks); spawn elsewhere needs import-string domains.
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    pool = ProcessPoolExecutor(
        max_workers=min(workers, len(jobs)), mp_context=multiprocessing.get_context(method)
    )
    try:
        pending = {pool.submit(execute_job, job) for job in jobs}
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                yield future.result()
    finally:
        # On an interrupt or error: drop queued trials, let running ones end, keep what was yielded.
        pool.shutdown(wait=True, cancel_futures=True)


def _execute_ray(jobs: Sequence[TrialJob], workers: int) -> Iterator[TrialResult]:
    try:
        import ray
    except ModuleNotFoundError as error:
        raise ConfigError(
            "--executor ray needs Ray, which is not installed; install it with: pip install 'embodied-adhoc[ray]'"
        ) from error
    if not ray.is_initialized():
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    remote = ray.remote(execute_job)
    pending = [remote.remote(job) for job in jobs]
    try:
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for reference in done:
                yield ray.get(reference)
    finally:
        for reference in pending:
            ray.cancel(reference)
