"""One real-time toxic-waste episode: ``run toxic-waste``'s episode on :class:`RealtimeToxicWasteEnv`.

Same seeds, episode draw (task, start nodes), agent construction, loop (``experiments.episode.run_episode_loop``)
and observers (``metrics.json``; with a record folder the video and the rerun recording) as
``experiments.recorded_episode.run_episode``, so a real-time episode and a turn-based one of the same seed start
from the same state with the same agent: the comparison of ``scripts/bench_realtime.py``. Extra observers (the
live server's) are attached after the recorders.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence

from embodied_adhoc.experiments.episode import EpisodeObserver
from embodied_adhoc.experiments.recorded_episode import (
    EpisodeConfig,
    EpisodeOutcome,
    _Metrics,
    _Recording,
    episode_metrics,
    play_recorded_episode,
    prepare_episode,
)
from embodied_adhoc.live.realtime import LiveStopped, RealtimeToxicWasteEnv

__all__ = ["RealtimeEpisode", "open_realtime_episode", "run_realtime_episode"]


class RealtimeEpisode:
    """The pieces of one real-time episode, built before it runs (the live server shows the env while it runs)."""

    def __init__(self, config: EpisodeConfig, env, agent, session, spec, metrics):
        self.config, self.env, self.agent, self.session, self.spec, self.metrics = (
            config,
            env,
            agent,
            session,
            spec,
            metrics,
        )


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
    from embodied_adhoc.experiments import seeding

    setup = prepare_episode(config)
    env = RealtimeToxicWasteEnv(
        human=human,
        speed=speed,
        reply_timeout=reply_timeout,
        tick_listener=tick_listener,
        stop=stop,
        **setup.env_kwargs,
    )
    from embodied_adhoc.experiments.domains.toxic_waste import DOMAIN
    from embodied_adhoc.experiments.registry import build_agent

    agent = build_agent(
        DOMAIN, setup.session, config.agent, setup.spec, seeding.agent_seed(config.seed, 0, config.agent)
    )
    metrics = episode_metrics(
        config,
        setup,
        command,
        speed=speed,
        reply_timeout=reply_timeout,
        human=type(env.human_driver).__name__,
    )
    return RealtimeEpisode(config, env, agent, setup.session, setup.spec, metrics)


def run_realtime_episode(
    episode: RealtimeEpisode, observers: Sequence[EpisodeObserver] = ()
) -> EpisodeOutcome:
    """Run (and, with a record folder, record) the episode through ``run toxic-waste``'s player, ``observers``
    after the recorders; a :class:`LiveStopped` ends it as interrupted, with everything finished so far written."""
    config, env, session = episode.config, episode.env, episode.session
    recording = config.record_dir is not None
    return play_recorded_episode(
        env,
        episode.agent,
        session,
        episode.spec,
        config,
        episode.metrics,
        [_Metrics(episode.metrics, session.library)],
        (lambda files: _Recording(config, env, session.library, episode.spec, files)) if recording else None,
        later=observers,
        interruptions=(LiveStopped,),
    )
