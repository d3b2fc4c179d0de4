"""The shared atomic-write mechanism: complete files only, ordinary permissions, nothing left on failure."""

import os
import stat

import numpy as np
import pytest

from embodied_adhoc.atomic import atomic_open, atomic_path, atomic_write_text, publish, temporary_sibling


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


def test_a_planted_symlink_is_never_followed(tmp_path):
    """The temporary file is created with O_EXCL under an unpredictable name: links planted where the old
    predictable name (.STEM.partial-PID.SUFFIX) was, or anywhere else, are left alone."""
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    planted = tmp_path / f".out.partial-{os.getpid()}.json"
    planted.symlink_to(victim)
    target = atomic_write_text(tmp_path / "out.json", "{}\n")
    assert target.read_text() == "{}\n" and not target.is_symlink()
    assert victim.read_text() == "precious\n" and planted.is_symlink()
    with atomic_path(tmp_path / "out.json") as temporary:
        assert temporary != planted and temporary.is_file() and not temporary.is_symlink()
        assert temporary.parent == tmp_path and temporary.suffix == ".json"
        temporary.write_text("[]\n")
    assert target.read_text() == "[]\n" and victim.read_text() == "precious\n"


def test_temporary_siblings_are_fresh_private_files(tmp_path):
    first, second = temporary_sibling(tmp_path / "video.mp4"), temporary_sibling(tmp_path / "video.mp4")
    assert first != second and first.suffix == second.suffix == ".mp4"
    assert first.stat().st_size == 0 and stat.S_IMODE(first.stat().st_mode) == 0o600
    published = publish(first, tmp_path / "video.mp4")
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(published.stat().st_mode) == 0o666 & ~mask


def test_atomic_open_writes_exactly_the_path_asked(tmp_path):
    """numpy.savez appends '.npz' to a name not ending in it, but not to a stream: p.bin stays p.bin."""
    target = tmp_path / "p.bin"
    with atomic_open(target) as stream:
        np.savez(stream, values=np.arange(3))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.bin"]
    with np.load(target, allow_pickle=False) as data:
        np.testing.assert_array_equal(data["values"], [0, 1, 2])
    with pytest.raises(KeyboardInterrupt):
        with atomic_open(target) as stream:
            stream.write(b"half")
            raise KeyboardInterrupt
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.bin"]
