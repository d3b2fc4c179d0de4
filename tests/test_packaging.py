"""Packaging and documentation pointers: a build leaves the source tree untouched, and every documentation path the
code cites exists in the repository."""

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "embodied_adhoc"


@pytest.mark.slow
def test_wheel_build_writes_nothing_into_the_source_tree(tmp_path):
    # A read-only checkout can be installed only if the build stays out of the tree (no build/, no *.egg-info).
    source = tmp_path / "source"
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout.split(
        b"\0"
    )
    for name in filter(None, files):
        path = ROOT / name.decode()
        if path.is_file():
            (source / name.decode()).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, source / name.decode())
    before = sorted(p.relative_to(source) for p in source.rglob("*"))
    result = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
         "-w", str(tmp_path / "wheels"), str(source)],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "License" not in result.stderr  # the table-form license deprecation warning
    assert sorted(p.relative_to(source) for p in source.rglob("*")) == before
    assert len(list((tmp_path / "wheels").glob("embodied_adhoc-*.whl"))) == 1


def _sources():
    yield from PACKAGE.rglob("*.py")
    yield from (ROOT / "scripts").glob("*.py")
    yield from (ROOT / "assets" / "data").glob("*.json")


def test_every_docs_path_cited_by_the_code_exists():
    cited = {}
    for path in _sources():
        for match in re.finditer(r"docs/[\w./-]+\.md", path.read_text(encoding="utf-8")):
            cited.setdefault(match.group(0), path.relative_to(ROOT))
    assert cited, "no docs/ pointer found: the pattern is wrong"
    missing = {doc: str(where) for doc, where in cited.items() if not (ROOT / doc).is_file()}
    assert not missing


def test_no_pointer_outside_the_repository():
    # Pointers that once led nowhere: a README section that never existed, a file kept outside the repository.
    for path in _sources():
        text = path.read_text(encoding="utf-8")
        for dead in ("docs/architecture", "hotspot-lab.md", "shared/reference"):
            assert dead not in text, f"{path.relative_to(ROOT)} cites {dead}"


def test_every_package_has_a_docstring():
    for init in PACKAGE.rglob("__init__.py"):
        text = init.read_text(encoding="utf-8").lstrip()
        assert text.startswith('"""') and len(text.split('"""')[1].strip()) > 40, init.relative_to(ROOT)
