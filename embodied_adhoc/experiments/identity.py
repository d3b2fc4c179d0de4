"""A run's inputs by content: the SHA-256 of every input file a domain declares, and the BLAS kernel class.

A stored run (``trials --out DIR``) and a cached policy must not be served to a request whose inputs differ only
in a file's content (a map edited in place, another confusion matrix at the same path) or in the BLAS kernel that
computed it (OpenBLAS picks its kernels per CPU at load time, and a POMDP solve's floating-point sums, hence its
ties and its policy, differ between kernels). This module is the one place that turns those inputs into digests:

* a domain declares its input files with an optional method ``input_files(options) -> {label: path}`` (the label
  is what the user typed the file as, e.g. ``"--map"``; a path may be a folder: its files are hashed by relative
  name and content), and whether its results depend on the BLAS kernel with an optional ``blas_dependent``
  attribute (a bool, or a method of ``options``); :func:`run_inputs` reads both;
* a plug-in (an agent, teammate or human given as ``module:callable``, ``path/to/file.py:callable`` or an entry
  point) is an input too: :func:`plugin_source` names its source file (:mod:`embodied_adhoc.plugins` resolves
  it) for the domain to declare;
* :func:`blas_kernel` is the kernel class, ``"openblas:<architecture>"`` as threadpoolctl reports it (it reflects
  ``OPENBLAS_CORETYPE``, which OpenBLAS honours when it loads); :func:`blas_note` is what ``config.json`` records
  beside it (library version, the variable's value).

Files are read in chunks with a size cap (:data:`MAX_INPUT_BYTES`), so a device or a huge file given as an input
is one clear error, not an unbounded read.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Mapping
from pathlib import Path

from embodied_adhoc.errors import ConfigError

__all__ = ["MAX_INPUT_BYTES", "blas_kernel", "blas_note", "input_digest", "plugin_source", "run_inputs"]

MAX_INPUT_BYTES = 1 << 30
"""Largest input (a file, or a folder's files together) that is hashed: 1 GiB, far above any map, matrix, model
or policy library the domains read."""

_CHUNK = 1 << 20


def _hash_file(path: Path, digest, budget: int, label: str) -> int:
    """Feed ``path``'s bytes to ``digest``; returns the bytes left of ``budget``."""
    try:
        with open(path, "rb") as stream:
            while chunk := stream.read(_CHUNK):
                budget -= len(chunk)
                if budget < 0:
                    raise ConfigError(
                        f"{label} {path}: larger than the {MAX_INPUT_BYTES:,}-byte limit of an input file; "
                        "give a regular file of the expected format"
                    )
                digest.update(chunk)
    except OSError as error:
        raise ConfigError(f"{label} {path}: cannot read it ({error.strerror or error})") from None
    return budget


def input_digest(path: str | os.PathLike, label: str = "input") -> str:
    """SHA-256 (hex) of a file's bytes, or of a folder's files (sorted relative names and contents; hidden
    entries and ``__pycache__`` left out: they do not change what a domain loads)."""
    path = Path(path)
    digest = hashlib.sha256()
    if path.is_dir():
        budget = MAX_INPUT_BYTES
        for file in sorted(p for p in path.rglob("*") if p.is_file()):
            relative = file.relative_to(path)
            if any(part.startswith(".") or part == "__pycache__" for part in relative.parts):
                continue
            inner = hashlib.sha256()
            budget = _hash_file(file, inner, budget, label)
            digest.update(f"{relative.as_posix()}\0{inner.hexdigest()}\n".encode())
        return digest.hexdigest()
    if not path.exists():
        raise ConfigError(f"{label} {path}: no such file")
    _hash_file(path, digest, MAX_INPUT_BYTES, label)
    return digest.hexdigest()


def plugin_source(kind: str, spec: str | None, flag: str | None = None) -> Path | None:
    """The source file of a plug-in of ``kind`` (``"agent"``, ``"teammate"``, ``"human"``) that ``spec`` names
    (``module:callable``, ``path/to/file.py:callable`` or an installed entry point, resolved by
    :mod:`embodied_adhoc.plugins`); None for a built-in name or no spec."""
    if not spec:
        return None
    from embodied_adhoc.plugins import names_plugin, resolve

    if not names_plugin(kind, str(spec)):
        return None
    return resolve(kind, str(spec), flag=flag).source


def _openblas() -> dict | None:
    import numpy  # noqa: F401  (loads the BLAS threadpoolctl inspects)
    from threadpoolctl import threadpool_info

    for entry in threadpool_info():
        if entry.get("user_api") == "blas":
            return entry
    return None


def blas_kernel() -> str:
    """The BLAS kernel class of this process: ``"openblas:SkylakeX"``, ``"openblas:Haswell"``, ...; another BLAS
    is named by its library (``"mkl"``), none found as ``"unknown"``."""
    entry = _openblas()
    if entry is None:
        return "unknown"
    api = str(entry.get("internal_api", "unknown"))
    architecture = entry.get("architecture")
    return f"{api}:{architecture}" if architecture else api


def blas_note() -> dict:
    """What ``config.json`` records about the BLAS beside the kernel class (not part of the identity)."""
    entry = _openblas() or {}
    return {
        "kernel": blas_kernel(),
        "library": entry.get("internal_api"),
        "version": entry.get("version"),
        "threads": entry.get("num_threads"),
        "OPENBLAS_CORETYPE": os.environ.get("OPENBLAS_CORETYPE"),
    }


def _declared(domain, name: str, options: Mapping):
    value = getattr(domain, name, None)
    return value(options) if callable(value) else value


def run_inputs(domain, options: Mapping) -> dict:
    """The content part of a run's identity: ``{"inputs": {label: sha256}}`` for the files ``domain`` declares for
    ``options`` and ``{"blas_kernel": ...}`` where it declares its results BLAS-dependent (keys left out when
    empty, so domains without inputs keep the identity they had)."""
    identity: dict = {}
    files = _declared(domain, "input_files", options) or {}
    digests = {
        str(label): input_digest(path, str(label)) for label, path in files.items() if path is not None
    }
    if digests:
        identity["inputs"] = dict(sorted(digests.items()))
    if _declared(domain, "blas_dependent", options):
        identity["blas_kernel"] = blas_kernel()
    return identity
