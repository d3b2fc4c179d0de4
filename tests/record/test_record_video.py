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
    with pytest.raises(ConfigError, match="crf"):
        VideoWriter(tmp_path / "bad.mp4", 64, 48, crf=60)
    writer = VideoWriter(tmp_path / "clip.mp4", 64, 48)
    with pytest.raises(ConfigError, match=r"\(48, 64, 3\) uint8"):
        writer.write(np.zeros((48, 64, 3), np.float32))
    assert writer.close() is None  # nothing written: no empty mp4 is published
    assert not (tmp_path / "clip.mp4").exists()


def test_repeat_holds_a_frame_and_overlay_is_drawn_on_the_writer_thread(tmp_path):
    path = tmp_path / "held.mp4"
    with VideoWriter(path, 320, 240, fps=10) as writer:
        writer.write(np.zeros((240, 320, 3), np.uint8))
        writer.write(np.full((240, 320, 3), 200, np.uint8), overlay=["final state"], repeat=10)
        assert writer.frame_count == 11
    reader = imageio.get_reader(path)
    try:
        frames = [frame for frame in reader]
    finally:
        reader.close()
    assert len(frames) == 11
    assert all(np.abs(frame.astype(int) - frames[-1]).mean() < 2 for frame in frames[1:])
    assert frames[-1][30:, 200:].mean() > 180 and frames[-1][4:20, 4:60].mean() < 150  # dark box top-left


def test_an_encoding_error_is_raised_and_nothing_is_published(tmp_path):
    writer = VideoWriter(tmp_path / "broken.mp4", 320, 240)
    writer.write(np.zeros((240, 320, 3), np.uint8), overlay=[object()])  # fails on the writer thread
    with pytest.raises(RuntimeError, match="video broken.mp4 failed"):
        writer.close()
    assert not (tmp_path / "broken.mp4").exists() and not list(tmp_path.glob(".*partial*"))


def test_recorded_frames_show_the_world_not_the_lidar_rays():
    """The robot's 72 rangefinders are sensors, not scenery: MuJoCo draws their rays unless told not to."""
    from embodied_adhoc.sim.lab_world import LabWorld

    with LabWorld() as world:
        world.reset(seed=0, robot_node=1, human_node=1, ball_nodes=(0, 1, 2))
        image = world.render("overhead", 320, 256).astype(int)
    ray_yellow = (image[..., 0] > 240) & (image[..., 1] > 240) & (image[..., 2] < 60)
    assert ray_yellow.sum() < 20, ray_yellow.sum()
