"""The mp4 writer: frame count survives encoding, bad sizes are clear errors, files appear atomically."""

import imageio.v2 as imageio
import numpy as np
import pytest

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.record.video import VideoWriter


def test_mp4_decodes_with_expected_frame_count_and_size(tmp_path):
    path = tmp_path / "clip.mp4"
    with VideoWriter(path, 64, 48, fps=15) as writer:
        for i in range(17):
            frame = np.zeros((48, 64, 3), np.uint8)
            frame[:, 3 * i : 3 * i + 3] = 255
            writer.write(frame)
    reader = imageio.get_reader(path)
    try:
        meta = reader.get_meta_data()
        frames = [frame for frame in reader]
    finally:
        reader.close()
    assert len(frames) == 17
    assert meta["codec"] == "h264" and meta["fps"] == 15.0
    assert frames[0].shape == (48, 64, 3)
    # the moving white bar is still where it was drawn (encoding is lossy, so compare coarsely)
    assert frames[10][:, 30:33].mean() > 150 and frames[10][:, 50:].mean() < 60
    assert not list(tmp_path.glob(".*partial*")), "temporary file left behind"


def test_odd_size_and_wrong_frame_are_rejected(tmp_path):
    with pytest.raises(ConfigError, match="even"):
        VideoWriter(tmp_path / "odd.mp4", 63, 48)
    writer = VideoWriter(tmp_path / "clip.mp4", 64, 48)
    with pytest.raises(ConfigError, match=r"\(48, 64, 3\) uint8"):
        writer.write(np.zeros((48, 64, 3), np.float32))
    assert writer.close() is None  # nothing written: no empty mp4 is published
    assert not (tmp_path / "clip.mp4").exists()
