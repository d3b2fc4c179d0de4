"""The shared atomic-write mechanism: complete files only, ordinary permissions, nothing left on failure."""

import os
import stat

import pytest

from embodied_adhoc.atomic import atomic_path, atomic_write_text


def test_written_file_has_ordinary_permissions_and_no_temporary(tmp_path):
    target = atomic_write_text(tmp_path / "sub" / "out.json", "{}\n")
    assert target.read_text() == "{}\n"
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~mask
    assert sorted(p.name for p in target.parent.iterdir()) == ["out.json"]


def test_failure_keeps_the_old_file_and_removes_the_temporary(tmp_path):
    target = tmp_path / "result.csv"
    target.write_text("old\n")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as temporary:
            temporary.write_text("half")
            raise RuntimeError("interrupted")
    assert target.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.csv"]
