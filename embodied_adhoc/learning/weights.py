"""Weights on disk as safetensors (tensors plus a JSON header), never pickles.

``save_weights`` writes a module's state dict and a JSON-able ``metadata`` dict (the network sizes, how it was
trained) atomically; ``load_weights`` reads them back. A file that is not safetensors (for instance a
``torch.save`` pickle, which could run code when unpickled) is refused with a :class:`WeightsError` naming the
file: safetensors parses a length-prefixed JSON header and raw tensor bytes, nothing executable.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file

from embodied_adhoc.atomic import atomic_path
from embodied_adhoc.errors import EmbodiedAdhocError

METADATA_KEY = "embodied_adhoc"


class WeightsError(EmbodiedAdhocError, ValueError):
    """A weights file that is missing, not safetensors, or does not fit the network: names the file and fix."""


def save_weights(path: str | Path, module: torch.nn.Module, metadata: dict) -> Path:
    """Write ``module``'s parameters and ``metadata`` (JSON) to ``path`` (a ``.safetensors`` file)."""
    path = Path(path)
    if path.suffix != ".safetensors":
        raise WeightsError(f"{path}: weights are written as .safetensors files; use that suffix")
    tensors = {name: tensor.detach().cpu().contiguous() for name, tensor in module.state_dict().items()}
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        save_file(tensors, str(tmp), metadata={METADATA_KEY: json.dumps(metadata, sort_keys=True)})
    return path


def load_weights(path: str | Path) -> tuple[dict[str, torch.Tensor], dict]:
    """(state dict, metadata) of a file written by :func:`save_weights`."""
    path = Path(path)
    if not path.is_file():
        raise WeightsError(
            f"{path}: no such weights file; train one (embodied_adhoc.learning) or fix the path"
        )
    try:
        tensors = load_file(str(path))
        with open(path, "rb") as handle:
            header_size = int.from_bytes(handle.read(8), "little")
            header = json.loads(handle.read(header_size))
        metadata = json.loads(header.get("__metadata__", {}).get(METADATA_KEY, "null"))
    except (SafetensorError, ValueError, UnicodeDecodeError, OSError) as error:
        raise WeightsError(
            f"{path}: not a safetensors weights file ({error}); pickled weights (torch.save) are "
            "refused, re-save the state dict with save_weights"
        ) from None
    if not isinstance(metadata, dict):
        raise WeightsError(
            f"{path}: safetensors file without embodied_adhoc metadata; write it with save_weights"
        )
    return tensors, metadata


def load_into(module: torch.nn.Module, path: str | Path) -> dict:
    """Load the parameters of ``path`` into ``module`` (all of them, no more, no fewer); returns the metadata."""
    tensors, metadata = load_weights(path)
    try:
        module.load_state_dict(tensors, strict=True)
    except RuntimeError as error:
        raise WeightsError(
            f"{path}: the weights do not fit this network ({str(error).splitlines()[0]}); "
            "check the network sizes in its metadata"
        ) from None
    return metadata
