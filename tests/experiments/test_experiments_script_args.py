"""Dataclass-driven script flags (scripts/reproduce_hotspot.py, scripts/bench_trials.py)."""

from dataclasses import dataclass
from pathlib import Path

import pytest

from embodied_adhoc.experiments.script_args import field_docs, parse_dataclass_args


@dataclass(frozen=True)
class Example:
    out: Path = Path("runs/x")
    """where to write"""
    episodes: int = 32
    rate: float = 0.5
    markdown: bool = False


def test_defaults_and_overrides():
    assert parse_dataclass_args(Example, argv=[]) == Example()
    args = parse_dataclass_args(
        Example, argv=["--out", "y", "--episodes", "4", "--rate", "0.25", "--markdown"]
    )
    assert args == Example(Path("y"), 4, 0.25, True)


def test_field_docs_become_help():
    assert field_docs(Example) == {"out": "where to write"}


def test_bad_value_is_an_argparse_error():
    with pytest.raises(SystemExit):
        parse_dataclass_args(Example, argv=["--episodes", "many"])
