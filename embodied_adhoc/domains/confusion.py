"""Speech-channel confusion matrices: rows = the human's true node, columns = the recognised node, then "failed".

One JSON schema, shared by the lab model (which reads it as the observation model of "locate human") and the
communication module (which measures and writes it)::

    {
      "nodes": ["door", "open space", "robot station", "single workbench", "double workbench"],
      "columns": ["door", ..., "double workbench", "failed"],
      "matrix": [[...], ...],              # |nodes| rows of |nodes| + 1 probabilities, each row sums to 1
      "smoothing_floor": 0.03,             # every entry was raised to at least this, then rows renormalised
      "provenance": {"source": "...", ...}
    }

Smoothing (thesis section 7.1, "we smooth the probabilities ... to ensure that no entry has an absolute zero")
is done once, by :func:`smooth_confusion`, when a matrix is *measured*; loading never changes a matrix. Loading
refuses a file over :data:`MAX_FILE_CHARS`, a NaN, infinite or negative entry, and a row not summing to 1, naming
the file, the field and the entry.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from embodied_adhoc import checks, paths
from embodied_adhoc.atomic import atomic_write_text
from embodied_adhoc.errors import ConfigError

THESIS_MATRIX = "data/speech_confusion_thesis.json"
"""The matrix of the original implementation (docs/hotspot-original.md), smoothed with floor 0.03."""
MEASURED_MATRIX = "data/speech_confusion_measured.json"
"""The matrix measured by ``embodied-adhoc speech eval`` (offline espeak-ng + pocketsphinx)."""
MAX_FILE_CHARS = 1 << 20
"""Longest confusion file read, in characters (a 5-node matrix takes about 1 kB)."""
DEFAULT_CONFUSION = "measured"
"""The lab model's default observation matrix for "locate human": the one our offline pipeline measured.
The thesis reproduction pins ``"thesis"`` explicitly (``scripts/reproduce_hotspot.py``)."""


@dataclass(frozen=True)
class ConfusionMatrix:
    nodes: tuple[str, ...]
    matrix: np.ndarray  # (n_nodes, n_nodes + 1): last column = "failed" (no location recognised)
    smoothing_floor: float = 0.0
    provenance: dict = field(default_factory=dict)

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def failed_column(self) -> int:
        return self.n_nodes


def smooth_confusion(counts: np.ndarray, floor: float) -> np.ndarray:
    """Row-normalise ``counts``, raise every entry to at least ``floor`` and renormalise each row."""
    counts = np.asarray(counts, dtype=np.float64)
    totals = counts.sum(axis=1, keepdims=True)
    rows = np.divide(counts, totals, out=np.full_like(counts, 1.0 / counts.shape[1]), where=totals > 0)
    rows = np.maximum(rows, floor)
    return rows / rows.sum(axis=1, keepdims=True)


def load_confusion(source: str | os.PathLike | None = None) -> ConfusionMatrix:
    """Load a matrix: ``"thesis"`` = the original's, ``"measured"`` = ours, ``None`` = ``DEFAULT_CONFUSION``,
    else a JSON path."""
    if source is None:
        source = DEFAULT_CONFUSION
    if source == "thesis":
        path = paths.asset(THESIS_MATRIX)
    elif source == "measured":
        path = paths.asset(MEASURED_MATRIX)
    else:
        path = Path(source)
    if not Path(path).exists():
        raise ConfigError(
            f"confusion matrix file {path} does not exist; pass 'thesis', 'measured' or a JSON path"
        )
    text = checks.read_text(path, MAX_FILE_CHARS, "confusion matrix file")
    try:
        document = json.loads(text)
    except json.JSONDecodeError as error:
        raise ConfigError(f"{path}:{error.lineno}: not valid JSON ({error.msg})") from None
    if not isinstance(document, dict):
        raise ConfigError(
            f"{path}: expected a JSON object (see embodied_adhoc.domains.confusion for the schema)"
        )
    for key in ("nodes", "matrix"):
        if key not in document:
            raise ConfigError(
                f"{path}: missing field '{key}' (see embodied_adhoc.domains.confusion for the schema)"
            )
    if not isinstance(document["nodes"], list) or not all(isinstance(n, str) for n in document["nodes"]):
        raise ConfigError(f"{path}: field 'nodes' must be a list of node names")
    nodes = tuple(document["nodes"])
    # Entries printed to 3 decimals carry up to 0.0005 rounding each: allow exactly that much per row.
    shape = (len(nodes), len(nodes) + 1)
    matrix = checks.probability_rows(
        f"{path}: field 'matrix'", document["matrix"], shape, 0.0005 * shape[1] + 1e-9
    )
    sums = matrix.sum(axis=1)
    # Rows given to 3 decimals (as in the thesis) are exact up to rounding: normalise that rounding only.
    matrix = matrix / sums[:, None]
    return ConfusionMatrix(
        nodes, matrix, float(document.get("smoothing_floor", 0.0)), dict(document.get("provenance", {}))
    )


def save_confusion(confusion: ConfusionMatrix, path: str | os.PathLike) -> Path:
    """Write ``confusion`` as JSON atomically (temp file + rename)."""
    path = Path(path)
    document = {
        "nodes": list(confusion.nodes),
        "columns": [*confusion.nodes, "failed"],
        "matrix": [[round(float(v), 6) for v in row] for row in confusion.matrix],
        "smoothing_floor": confusion.smoothing_floor,
        "provenance": confusion.provenance,
    }
    return atomic_write_text(path, json.dumps(document, indent=2) + "\n")
