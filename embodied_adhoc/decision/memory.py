"""The process' memory as the solvers' cap reads it: resident memory now, and the default cap from the host.

A solver with a memory cap estimates what its next step allocates and stops before it (keeping the bounds it has)
when resident memory plus that estimate would pass the cap: a solve that stops with a reason instead of being
killed by the kernel's out-of-memory killer, which keeps nothing. Readings come from ``/proc`` (Linux); elsewhere
the peak resident size (``getrusage``) stands in for the current one, which only makes the cap stricter.
"""

from __future__ import annotations

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
