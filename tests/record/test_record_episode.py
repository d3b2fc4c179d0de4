"""A recorded physics episode: mp4 frame count, rerun entities (read back) and `rerun rrd verify`, metrics.json."""

import json
import subprocess
import sys

import imageio.v2 as imageio
import numpy as np

from embodied_adhoc.experiments.recorded import EpisodeConfig, run_episode
from embodied_adhoc.record.rerun_recorder import ENTITY_PATHS


def test_recorded_episode_files(tmp_path):
    from test_record_rerun import recorded_entities, rerun_binary

    config = EpisodeConfig(
        agent="hotspot",
        seed=2,
        task=0,
        robot_node=1,
        human_node=1,
        max_steps=3,
        record_dir=tmp_path,
        width=64,
        height=48,
        video_fps=10.0,
        video_speed=5.0,
    )
    outcome = run_episode(config)
    metrics = outcome.metrics
    assert metrics["steps"] == 3 and metrics["outcome"] in ("success", "truncated")
    reader = imageio.get_reader(tmp_path / "episode.mp4")
    try:
        frames = [frame for frame in reader]
    finally:
        reader.close()
    assert len(frames) == outcome.video_frames > 0
    assert frames[0].shape == (48, 64, 3)
    simulated = metrics["sim_time_s"] - 0.3  # the world settles for 0.3 s before the first frame
    hold = 10  # the final state, held for video_hold = 1 s at 10 fps
    assert abs(len(frames) - (simulated * 10.0 / 5.0 + hold)) <= 2
    # the video ends on the final state, rendered after the last step: the held frames are one image
    assert all(np.abs(frame.astype(int) - frames[-1]).mean() < 2 for frame in frames[-hold:])
    entities = recorded_entities(tmp_path / "episode.rrd")
    expected = [e for e in ENTITY_PATHS if e != "speech/audio"]  # audio only with --speech audio
    missing = [e for e in expected if not any(n == e or n.startswith(e + "/") for n in entities)]
    assert not missing, missing
    result = subprocess.run(
        [rerun_binary(), "rrd", "verify", str(tmp_path / "episode.rrd")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 0, result.stderr
    written = json.loads((tmp_path / "metrics.json").read_text())
    assert written["steps"] == 3 and written["config"]["spec"]["task"] == 0
    assert {"success", "steps", "identify_step", "wall_time_s", "macro_step_time_s"} <= set(written)


def test_run_command_smoke(tmp_path):
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "embodied_adhoc.cli",
            "run",
            "toxic-waste",
            "--seed",
            "1",
            "--max-steps",
            "1",
            "--task",
            "0",
            "--robot-node",
            "0",
            "--human-node",
            "0",
            "--json",
            "--no-progress",
            "--record",
            str(tmp_path / "out"),
            "--width",
            "32",
            "--height",
            "24",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["steps"] == 1 and set(summary["files"]) == {"video", "rerun", "metrics"}
    assert (tmp_path / "out" / "episode.mp4").exists()


def test_run_command_rejects_odd_video_size(tmp_path):
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "embodied_adhoc.cli",
            "run",
            "toxic-waste",
            "--max-steps",
            "1",
            "--no-progress",
            "--record",
            str(tmp_path),
            "--width",
            "33",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 2 and "even" in result.stderr


def test_interrupted_run_keeps_finished_work(tmp_path):
    import pytest

    def interrupt(step, info):
        raise KeyboardInterrupt

    config = EpisodeConfig(
        seed=0, task=0, robot_node=0, human_node=0, max_steps=5, record_dir=tmp_path, width=32, height=24
    )
    with pytest.raises(KeyboardInterrupt):
        run_episode(config, progress=interrupt)
    written = json.loads((tmp_path / "metrics.json").read_text())
    assert written["outcome"] == "interrupted" and written["steps"] == 1 and not written["success"]
    assert (tmp_path / "episode.mp4").stat().st_size > 0 and (tmp_path / "episode.rrd").stat().st_size > 0
    assert not list(tmp_path.glob(".*partial*"))


def test_progress_bar_closes_as_done_when_the_episode_succeeds_early():
    import io

    from tqdm import tqdm

    from embodied_adhoc.commands.run import finish_progress

    stream = io.StringIO()
    bar = tqdm(total=100, file=stream, ascii=True)
    bar.update(12)
    finish_progress(bar)
    bar.close()
    last = stream.getvalue().replace("\r", "\n").strip().splitlines()[-1]
    assert "12/12" in last and "100%" in last and "?" not in last, last


def test_move_actions_are_labelled_by_the_node_the_env_drives_to():
    """At the door (one neighbour) every move action drives to node 1: the label says so, and the step agrees."""
    import gymnasium

    import embodied_adhoc.envs  # noqa: F401
    from embodied_adhoc.episodes.presenters import action_label

    env = gymnasium.make("EmbodiedAdhoc/ToxicWaste-v0", disable_env_checker=True)
    try:
        env.reset(seed=0, options={"task": 0, "robot_node": 0, "human_node": 4})
        lab = env.unwrapped
        labels = [action_label(lab.library, action, lab.move_target(action)) for action in range(5)]
        assert labels[:3] == ["move to 1 open space"] * 3, labels
        assert lab.move_target(3) is None and labels[3] == lab.library.action_names[3]
        *_, info = env.step(2)  # "move to neighbour 3" of a node with one neighbour
        assert info["robot_node"] == 1
    finally:
        env.close()
