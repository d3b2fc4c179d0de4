"""Where the benchmark ships the trained best responses to its grid members, and how an agent spec names one.

The trainer (``embodied_adhoc.learning.best_response``, torch) writes them; the bounds (``bench.bounds``) read
them through the trial runner by their agent spec and key their trials by the weights' bytes. Both go through
this module, so neither layer imports the other.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from embodied_adhoc.paths import assets_dir

__all__ = ["KIND", "TRAINER", "agent_spec", "shipped_path", "weights_digest"]

KIND = "best-response"
TRAINER = "embodied_adhoc.learning.best_response"
"""The module whose plug-in factory plays a shipped best response (named as text: this layer imports no torch)."""
FOLDER = "bench/{domain}/best-response/{member}"


def shipped_path(domain: str, member: str) -> Path:
    """Where the package holds the weights of ``member``'s best response (present or not); the file name is the
    library-free weights' ``<domain>-<kind>.safetensors``."""
    return assets_dir() / FOLDER.format(domain=domain, member=member) / f"{domain}-{KIND}.safetensors"


def weights_digest(path: str | Path) -> str:
    """SHA-256 of the weights file's bytes: the content key of what a best response scores."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def agent_spec(domain: str, member: str) -> str:
    """The agent plug-in spec of ``member``'s shipped best response."""
    return f"{TRAINER}:{domain}/{member}"
