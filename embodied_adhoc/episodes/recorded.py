"""The one recorded-run driver: :func:`run_recorded` plays a prepared episode through the one loop with the
``metrics.json`` observer and, given a folder, the video and rerun recorder over the world's frame source.

``run toxic-waste``, ``run pursuit``, ``run foraging`` and the live mode prepare their episode (the trial domain's
draw, seeds and agent for episode 0 of a seed: :mod:`embodied_adhoc.experiments.recorded`) and hand it here with
the domain's :class:`~embodied_adhoc.episodes.recording.Presenter`. The recorder and the env are closed, and
``metrics.json`` written, in ``finally``: an interrupted run keeps what it finished.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from embodied_adhoc.episodes.loop import EpisodeObserver, run_episode_loop
from embodied_adhoc.episodes.recording import (
    MetricsObserver,
    Presenter,
    ProgressObserver,
    Recording,
    VideoSettings,
)

__all__ = ["EpisodeOutcome", "PreparedEpisode", "run_recorded"]


@dataclass
class PreparedEpisode:
    """Everything one episode is, built before it runs: the env and agent, the loop's seeds, reset options, step
    cap and observation index, the episode's ``metrics`` (:class:`~embodied_adhoc.record.metrics.EpisodeMetrics`)
    and ``frames(env)``, the world's :class:`~embodied_adhoc.episodes.frames.FrameSource` for a recording."""

    env: Any
    agent: Any
    env_seed: int
    agent_rng: np.random.Generator
    reset_options: dict
    max_steps: int
    observation_index: Callable[[Any], int]
    metrics: Any
    frames: Callable[[Any], Any]
    name: str  # the rerun recording's name
    spec: dict = field(default_factory=dict)
    session: Any = None


@dataclass
class EpisodeOutcome:
    metrics: dict[str, Any]
    files: dict[str, Path]
    video_frames: int = 0


def run_recorded(
    episode: PreparedEpisode,
    presenter: Presenter,
    out: Path | None,
    video: VideoSettings | None = None,
    progress: Callable[[int, dict], None] | None = None,
    later: Sequence[EpisodeObserver] = (),
    interruptions: tuple[type[BaseException], ...] = (),
) -> EpisodeOutcome:
    """Run ``episode`` with ``presenter``'s metrics; with a folder ``out`` also record it (``video`` settings)
    into ``episode.mp4``, ``episode.rrd`` and ``metrics.json``. ``progress(step, info)`` after each step;
    ``later`` observers after the recorder. An exception of a type in ``interruptions`` ends the episode as
    interrupted (``metrics.json`` says so; the recorders keep what they have) instead of propagating."""
    files: dict[str, Path] = {}
    observers: list[EpisodeObserver] = [MetricsObserver(episode.metrics, presenter)]
    recorder = None
    try:
        if out is not None:
            if video is None:
                raise ValueError("run_recorded: a recorded episode needs its VideoSettings")
            source = episode.frames(episode.env.unwrapped)
            recorder = Recording(source, presenter, video, Path(out), episode.name, files)
            observers.append(recorder)
        if progress is not None:
            observers.append(ProgressObserver(progress))
        run_episode_loop(
            episode.env,
            episode.agent,
            env_seed=episode.env_seed,
            agent_rng=episode.agent_rng,
            reset_options=episode.reset_options,
            max_steps=episode.max_steps,
            observation_index=episode.observation_index,
            observers=[*observers, *later],
        )
    except interruptions:
        pass  # metrics.json says "interrupted"; the recorders keep what they have
    finally:
        try:
            if recorder is not None:
                recorder.close()
        finally:
            episode.env.close()
            if out is not None:
                files["metrics"] = episode.metrics.write(Path(out) / "metrics.json")
    return EpisodeOutcome(
        episode.metrics.summary(), files, 0 if recorder is None else recorder.video.frame_count
    )
