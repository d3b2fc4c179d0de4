"""The process' memory as the solvers' cap reads it: resident memory now, and the default cap from the host.

A solver with a memory cap estimates what its next step allocates and stops before it (keeping the bounds it has)
when resident memory plus that estimate would pass the cap: a solve that stops with a reason instead of being
killed by the kernel's out-of-memory killer, which keeps nothing. Readings come from ``/proc`` (Linux); elsewhere
the peak resident size (``getrusage``) stands in for the current one, which only makes the cap stricter.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import resource
import sys
from pathlib import Path

MB = 1 << 20
DEFAULT_SHARE = 0.8  # of the memory available when the solve starts, beyond what the process holds


def resident_mb() -> float:
    """This process' resident memory now, in MiB (its peak where ``/proc/self/statm`` is missing)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
    except (OSError, IndexError, ValueError):
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return peak / (MB if sys.platform == "darwin" else 1024)  # bytes on macOS, KiB on Linux
    return pages * resource.getpagesize() / MB


def available_mb() -> float | None:
    """The host's available memory in MiB (``MemAvailable`` of ``/proc/meminfo``), None where unknown."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) / 1024
    except (OSError, IndexError, ValueError):
        return None
    return None


def default_cap_mb() -> float | None:
    """The default cap: what the process holds plus ``DEFAULT_SHARE`` of the available memory (None: no cap where
    the available memory is unknown)."""
    available = available_mb()
    return None if available is None else resident_mb() + DEFAULT_SHARE * available


def peak_mb(pid: int | str = "self") -> float | None:
    """The peak resident memory (``VmHWM``) of process ``pid`` in MiB, None where ``/proc`` does not give it.

    Unlike ``getrusage``'s ``ru_maxrss``, which Linux carries over a fork and an exec (a child started by a large
    process reports at least that process's peak), ``VmHWM`` belongs to the memory map the process runs in."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except (OSError, IndexError, ValueError):
        return None
    return None


# Bytes from which a block is mapped on its own and unmapped when freed, and free memory at the heap's top beyond
# which the heap shrinks. Twice the backups' dense blocks (backup.DENSE_BLOCK_BYTES, 2 MiB), which a stage forms and
# frees thousands of times: mapped afresh, each would be faulted in page by page, and the kernel's zeroing of those
# pages would cost as much CPU as the products themselves; reused from the heap, they leave holes of at most their
# own size, so the peak stays near what is live.
_MALLOC_THRESHOLD = 4 << 20
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters


def _glibc() -> ctypes.CDLL | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        return libc if hasattr(libc, "mallopt") and hasattr(libc, "malloc_trim") else None
    except OSError:
        return None


def return_freed_memory() -> None:
    """Make freed memory go back to the system from now on (glibc; elsewhere nothing changes).

    glibc raises its mapping threshold to the size of each large block freed, and the heap's trim threshold to
    twice that, so a solver's transient products would hold the process's resident size (and its peak, the
    figure compared with SARSOP's) at their high-water mark. Fixed thresholds of 4 MiB map the arrays from that
    size on by themselves, returned when freed, and give free memory beyond 4 MiB at the heap's top back; the
    blocks below that size (the backups' 2 MiB blocks above all) are reused from the heap."""
    libc = _glibc()
    if libc is not None:
        libc.mallopt(_M_MMAP_THRESHOLD, _MALLOC_THRESHOLD)
        libc.mallopt(_M_TRIM_THRESHOLD, _MALLOC_THRESHOLD)


def trim() -> None:
    """Collect garbage and give the heap's free memory back to the system (glibc's ``malloc_trim``): after a
    phase such as reading a model file, whose many small objects are gone, so the solve starts from what it holds."""
    gc.collect()
    libc = _glibc()
    if libc is not None:
        libc.malloc_trim(0)
