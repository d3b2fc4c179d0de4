from pathlib import Path

import pytest

from embodied_adhoc import paths


def test_data_folders_resolve():
    assert paths.scenes_dir().is_dir()
    assert paths.assets_dir().is_dir()


def test_missing_scene_is_a_clear_error():
    with pytest.raises(FileNotFoundError, match="no scene 'nope.xml'"):
        paths.scene("nope.xml")


def test_scene_paths_are_absolute():
    assert Path(paths.scenes_dir()).is_absolute()
