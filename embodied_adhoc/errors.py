"""Project exception types, one per layer. Messages name the input, the place and the fix."""

from __future__ import annotations


class EmbodiedAdhocError(Exception):
    """Base class: the CLI prints these as one clean line (no traceback) and exits with status 2."""


class ModelError(EmbodiedAdhocError, ValueError):
    """An (PO)MDP whose arrays are inconsistent (shapes, rows not summing to 1, negative entries)."""


class PomdpFormatError(EmbodiedAdhocError, ValueError):
    """A malformed Cassandra ``.pomdp`` file: the message carries ``file:line``, what was found and expected."""


class SolverError(EmbodiedAdhocError, ValueError):
    """A solver asked to do something ill-posed (e.g. discount 1.0 without a finite horizon)."""


class SceneError(EmbodiedAdhocError, ValueError):
    """An MJCF scene or arena that cannot be composed or violates its metadata."""


class ConfigError(EmbodiedAdhocError, ValueError):
    """A bad option value (CLI flag, env kwarg, config field): names the field and the accepted values."""


class SpeechError(EmbodiedAdhocError, RuntimeError):
    """The offline speech pipeline is unavailable or failed (e.g. espeak-ng missing)."""
