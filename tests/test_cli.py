"""CLI smoke tests through a subprocess, as a user would run it."""

import subprocess
import sys


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", *args], capture_output=True, text=True, timeout=120
    )


def test_top_level_help_lists_commands():
    result = run_cli("--help")
    assert result.returncode == 0, result.stderr
    assert "embodied-adhoc" in result.stdout


def test_every_subcommand_has_help():
    from embodied_adhoc.cli import build_parser

    parser = build_parser()
    subparsers = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    for name in subparsers.choices:
        result = run_cli(name, "--help")
        assert result.returncode == 0, (name, result.stderr)
        assert "usage:" in result.stdout
