"""One real-time toxic-waste episode: ``run toxic-waste``'s episode on :class:`RealtimeToxicWasteEnv`.

Same seeds, episode draw (task, start nodes), agent construction, loop (``episodes.loop.run_episode_loop``)
and observers (``metrics.json``; with a record folder the video and the rerun recording) as
``experiments.recorded.run_episode``, so a real-time episode and a turn-based one of the same seed start
from the same state with the same agent: the comparison of ``scripts/bench_realtime.py``. Extra observers (the
live server's) are attached after the recorders.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence

from embodied_adhoc.episodes.loop import EpisodeObserver
from embodied_adhoc.episodes.recorded import EpisodeOutcome, run_recorded
from embodied_adhoc.experiments.recorded import EpisodeConfig, lab_presenter, prepare_lab_episode
from embodied_adhoc.live.realtime import LiveStopped, RealtimeToxicWasteEnv

__all__ = ["RealtimeEpisode", "open_realtime_episode", "run_realtime_episode"]


class RealtimeEpisode:
    """The pieces of one real-time episode, built before it runs (the live server shows the env while it runs)."""

    def __init__(self, config: EpisodeConfig, prepared):
        self.config, self.prepared = config, prepared
        self.env, self.agent, self.session = prepared.env, prepared.agent, prepared.session
        self.spec, self.metrics = prepared.spec, prepared.metrics


def open_realtime_episode(
    config: EpisodeConfig,
    *,
    human=None,
    speed: float | None = None,
    reply_timeout: float = 20.0,
    tick_listener: Callable | None = None,
    stop: threading.Event | None = None,
    command: str = "live toxic-waste",
) -> RealtimeEpisode:
    """Build env, agent and metrics for ``config`` exactly as ``run toxic-waste`` does (module docstring)."""
    made = []

    def realtime_env(env_kwargs: dict) -> RealtimeToxicWasteEnv:
        env = RealtimeToxicWasteEnv(
            human=human,
            speed=speed,
            reply_timeout=reply_timeout,
            tick_listener=tick_listener,
            stop=stop,
            **env_kwargs,
        )
        made.append(env)
        return env

    prepared = prepare_lab_episode(config, command, realtime_env, speed=speed, reply_timeout=reply_timeout)
    prepared.metrics.config["human"] = type(made[0].human_driver).__name__
    return RealtimeEpisode(config, prepared)


def run_realtime_episode(
    episode: RealtimeEpisode, observers: Sequence[EpisodeObserver] = ()
) -> EpisodeOutcome:
    """Run (and, with a record folder, record) the episode through ``run toxic-waste``'s driver, ``observers``
    after the recorders; a :class:`LiveStopped` ends it as interrupted, with everything finished so far written."""
    config, prepared = episode.config, episode.prepared
    return run_recorded(
        prepared,
        lab_presenter(prepared, config.agent),
        config.record_dir,
        config.video(),
        later=observers,
        interruptions=(LiveStopped,),
    )
