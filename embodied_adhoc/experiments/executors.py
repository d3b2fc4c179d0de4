"""Execution backends: run trial jobs in this process, in a local process pool, or on Ray; yield results as they
finish. Results do not depend on the backend or the number of workers (each trial is seeded by its job).

A worker opens a domain session (models built and solved, env created) once per (domain, backend, options) and
reuses it for every trial it runs (:func:`execute_job`).

Signals: pool workers ignore SIGINT (a Ctrl-C reaches the whole terminal process group; only the parent reacts) and
die on SIGTERM. When the parent stops early (Ctrl-C, SIGTERM raised as an exception by the CLI, an error in a
trial) it terminates the workers at once (and kills those still alive :data:`TERMINATE_GRACE_S` later): their
running trials would be discarded anyway, and no worker outlives the command. A further SIGINT or SIGTERM while
it stops is one line on stderr and does not interrupt the stopping; the command then ends with the first signal's
status. A parent that dies without stopping them (SIGKILL, a crash) is noticed by its workers, which exit: on
Linux the kernel signals them (``prctl(PR_SET_PDEATHSIG)``), and everywhere a watchdog thread in each worker
checks every :data:`WATCHDOG_PERIOD_S` seconds that its parent is still the one that started it.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator, Sequence

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.registry import get_trial_domain
from embodied_adhoc.experiments.trial import TrialJob, TrialResult, run_trial

EXECUTORS = ("local", "ray")
RAY_WORKER_ENV = ("XDG_CACHE_HOME", "MUJOCO_GL", "PYTHONPATH")
"""Variables the driver passes to Ray's workers (a node started by ``ray start`` has the environment of that
command, not the driver's): the policy cache location, the rendering backend and the import path."""

TERMINATE_GRACE_S = 3.0
"""Seconds a terminated worker has to exit before it is killed (one that ignores SIGTERM must not hang the parent)."""
WATCHDOG_PERIOD_S = 0.5
"""How often a pool worker checks that its parent still runs (the fallback where PR_SET_PDEATHSIG is missing)."""

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
    env = _env(job.domain, job.backend, job.options, job.max_steps)
    threads = getattr(session, "blas_threads", None)
    if threads is None:
        return run_trial(session, env, job)
    from threadpoolctl import threadpool_limits

    # A session that asks for it runs its trials with that many BLAS threads (chapter 5: one; its per-step
    # products are small, and a multi-threaded BLAS only spins against the other processes on a shared machine).
    with threadpool_limits(limits=threads, user_api="blas"):
        return run_trial(session, env, job)


def available_cpus() -> int:
    """CPUs this process may run on (its affinity mask where the OS has one, else the machine's count)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0)) or 1
    return os.cpu_count() or 1


def resolve_workers(workers: int) -> int:
    """The number of worker processes for ``--workers``: 0 = one per CPU; more than the CPUs is capped to them
    (extra processes only compete for the same cores; results do not depend on the count). The CLI tells the
    user when it caps (:func:`worker_note`)."""
    if workers < 0:
        raise ConfigError(f"--workers must be >= 0 (0 = one per CPU), got {workers}")
    return min(workers, available_cpus()) if workers else available_cpus()


def worker_note(workers: int) -> str | None:
    """The line to show when ``--workers`` is capped, else None."""
    used = resolve_workers(workers)
    if workers > used:
        return f"--workers {workers}: using {used}, the number of CPUs available (more would only compete for them)"
    return None


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
        max_workers=min(workers, len(jobs)),
        mp_context=multiprocessing.get_context(method),
        initializer=_worker_signals,
        # the kernel's parent-death signal follows the forking thread: asked for only when that is the main thread
        initargs=(os.getpid(), threading.current_thread() is threading.main_thread()),
    )
    finished = False
    queued = iter(jobs)
    try:
        with _signals_at_safe_points() as deliver_pending_signal:
            # At most a few trials per worker in flight: ``wait`` locks every future it is given.
            pending = {pool.submit(execute_job, job) for job in itertools.islice(queued, 4 * workers)}
            while pending:
                done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
                deliver_pending_signal()
                pending |= {pool.submit(execute_job, job) for job in itertools.islice(queued, len(done))}
                for future in done:
                    yield future.result()
        finished = True
    finally:
        # Stopped early (interrupt, SIGTERM, a failed trial, the consumer closed us): what was yielded is kept;
        # queued trials are dropped and running ones killed, so no worker outlives the sweep.
        with _second_signals_noted(stopping=not finished):
            if not finished:
                _terminate_workers(pool)
            pool.shutdown(wait=True, cancel_futures=True)


@contextlib.contextmanager
def _signals_at_safe_points():
    """While the pool runs, SIGINT and SIGTERM only set a flag; the handler they would have run (KeyboardInterrupt,
    the CLI's SIGTERM exception) runs when the loop calls the yielded function, between ``wait`` calls.

    An exception raised inside ``concurrent.futures.wait`` can leave futures' locks held (it acquires them one by
    one), and the pool's shutdown then waits forever for its manager thread, which needs those locks: a SIGTERM
    test hung this way. Outside the main thread (no handlers can be set there) signals are left alone."""
    if threading.current_thread() is not threading.main_thread():
        yield lambda: None
        return
    received: list[tuple[int, object]] = []
    previous = {number: signal.getsignal(number) for number in (signal.SIGINT, signal.SIGTERM)}

    def remember(number, frame):
        received.append((number, frame))

    def deliver():
        if received:
            number, frame = received[0]
            received.clear()
            handler = previous[number]
            if callable(handler):
                handler(number, frame)
            elif handler == signal.SIG_DFL:
                signal.signal(number, signal.SIG_DFL)
                os.kill(os.getpid(), number)

    for number in previous:
        signal.signal(number, remember)
    try:
        yield deliver
    except BaseException:
        # Stopping already (the first signal's exception, or an error): a signal that came meanwhile is noted,
        # not raised over the first.
        for number, _ in received:
            _note_signal_while_stopping(number, None)
        received.clear()
        raise
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
        deliver()


@contextlib.contextmanager
def _second_signals_noted(stopping: bool):
    """While the pool stops after a first signal (or an error), SIGINT and SIGTERM print one line and are otherwise
    ignored: the stopping finishes and the first exception carries on (so the command exits with its status)."""
    if not stopping or threading.current_thread() is not threading.main_thread():
        yield
        return

    previous = {
        number: signal.signal(number, _note_signal_while_stopping)
        for number in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def _note_signal_while_stopping(number, frame) -> None:
    name = signal.Signals(number).name
    print(f"embodied-adhoc: {name} received while stopping; the workers are being stopped", file=sys.stderr)


def _worker_signals(parent: int | None = None, death_signal: bool = True) -> None:
    """Pool initializer: Ctrl-C is the parent's business; SIGTERM kills (a forked worker would otherwise inherit
    the CLI's SIGTERM-as-exception handler and print a traceback); the death of ``parent`` ends the worker."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if parent is None:
        return
    if death_signal:
        _die_with_parent()
    if os.getppid() != parent:  # it died before the request above took effect
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent,), name="parent-watchdog", daemon=True).start()


def _die_with_parent() -> bool:
    """Ask Linux to SIGKILL this process when its parent dies; False where the call is not available."""
    if not sys.platform.startswith("linux"):
        return False
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        pr_set_pdeathsig = 1
        return libc.prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch_parent(parent: int) -> None:
    # Reparenting (to init or a subreaper) changes getppid(): the parent is gone, and its trials with it.
    while os.getppid() == parent:
        time.sleep(WATCHDOG_PERIOD_S)
    os._exit(1)


def _terminate_workers(pool) -> None:
    # Python 3.14 has ProcessPoolExecutor.terminate_workers(); on 3.11 the processes are in ``_processes``.
    processes = list((getattr(pool, "_processes", None) or {}).values())
    terminate = getattr(pool, "terminate_workers", None)
    if terminate is not None:
        terminate()
    else:
        for process in processes:
            if process.is_alive():
                process.terminate()
    deadline = time.monotonic() + TERMINATE_GRACE_S
    for process in processes:
        process.join(max(0.0, deadline - time.monotonic()))
        if process.is_alive():  # it ignores SIGTERM
            process.kill()
            process.join()


def _execute_ray(jobs: Sequence[TrialJob], workers: int) -> Iterator[TrialResult]:
    try:
        import ray
    except ModuleNotFoundError as error:
        raise ConfigError(
            "--executor ray needs Ray, which is not installed; install it with: pip install 'embodied-adhoc[ray]'"
        ) from error
    if not ray.is_initialized():
        # RAY_ADDRESS (Ray's own variable, e.g. 127.0.0.1:6380): join that cluster and use all its CPUs; else a
        # private single-node Ray with --workers CPUs.
        runtime_env = {"env_vars": {name: os.environ[name] for name in RAY_WORKER_ENV if name in os.environ}}
        address = os.environ.get("RAY_ADDRESS")
        try:
            if address:
                ray.init(address=address, log_to_driver=False, runtime_env=runtime_env)
            else:
                ray.init(
                    address="local", num_cpus=workers, include_dashboard=False, log_to_driver=False,
                    runtime_env=runtime_env,
                )  # fmt: skip
        except ConnectionError as error:
            raise ConfigError(
                f"--executor ray: no Ray cluster at RAY_ADDRESS={address} ({error}); start one with "
                "'ray start --head --node-ip-address=127.0.0.1 --port=6380' or unset RAY_ADDRESS"
            ) from None
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
