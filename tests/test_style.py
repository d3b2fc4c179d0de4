"""The tree's style: ``ruff check .`` (E501 at 120 columns included) and ``ruff format --check .`` are clean.

Both run with the venv's ruff (the version pinned in pyproject.toml) and the project's configuration, from the
repository root, so a file that the formatter would change or a line that the linter flags fails here with ruff's
own report. Two further checks feed ruff a bad snippet through stdin under a package path, so that a configuration
that silently checks nothing (a broad exclude, E501 ignored again) fails too.
"""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _ruff(*args: str, stdin: str | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "ruff", *args],
        cwd=ROOT,
        input=stdin,
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_ruff_check_is_clean():
    result = _ruff("check", ".", "--output-format", "concise", "--no-cache")
    assert result.returncode == 0, (
        f"ruff check . found problems (fix them, or `ruff check --fix`):\n{result.stdout}"
    )


def test_ruff_format_check_is_clean():
    result = _ruff("format", "--check", ".", "--no-cache")
    assert result.returncode == 0, (
        f"ruff format --check . would reformat files (run `.venv/bin/ruff format FILE` on yours):\n"
        f"{result.stdout}{result.stderr}"
    )


def test_the_line_length_rule_is_on_at_120_columns():
    path = "embodied_adhoc/_style_probe.py"
    within = f'TEXT = "{"x" * (120 - len("TEXT = " + chr(34) * 2))}"\n'
    beyond = f'TEXT = "{"x" * (121 - len("TEXT = " + chr(34) * 2))}"\n'
    assert len(within) - 1 == 120 and len(beyond) - 1 == 121
    ok = _ruff("check", "--no-cache", "--stdin-filename", path, "-", stdin=within)
    assert ok.returncode == 0, ok.stdout
    flagged = _ruff("check", "--no-cache", "--stdin-filename", path, "-", stdin=beyond)
    assert flagged.returncode == 1 and "E501" in flagged.stdout, flagged.stdout + flagged.stderr


def test_the_format_check_sees_package_files():
    unformatted = "x = {  'a':1 }\n"
    result = _ruff(
        "format",
        "--check",
        "--no-cache",
        "--stdin-filename",
        "embodied_adhoc/_style_probe.py",
        "-",
        stdin=unformatted,
    )
    assert result.returncode == 1, result.stdout + result.stderr
