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
from pathlib import Path

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.episode import EpisodeObserver, run_episode_loop
from embodied_adhoc.experiments.recorded_episode import (
    EpisodeConfig,
    EpisodeOutcome,
    _Metrics,
    _Recording,
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
    from embodied_adhoc.experiments.registry import get_trial_domain
    from embodied_adhoc.experiments.stats import identify_step
    from embodied_adhoc.record.metrics import EpisodeMetrics

    domain = get_trial_domain("toxic-waste")
    options = domain.options(
        human_epsilon=config.human_epsilon,
        communication=config.communication,
        task=config.task,
        confusion=config.confusion,
        faults=config.faults,
        localisation=config.localisation,
        localisation_model=config.localisation_model,
    )
    spec = domain.episode_spec(options, seeding.episode_rng(config.seed, 0))
    for key in ("robot_node", "human_node"):
        if getattr(config, key) is not None:
            spec[key] = int(getattr(config, key))
    session = domain.open_session("mujoco", options)
    recording = config.record_dir is not None
    if not (config.video_fps > 0 and config.video_speed > 0):
        raise ConfigError(
            f"video_fps ({config.video_fps}) and video_speed ({config.video_speed}) must be > 0"
        )
    env = RealtimeToxicWasteEnv(
        human=human,
        speed=speed,
        reply_timeout=reply_timeout,
        tick_listener=tick_listener,
        stop=stop,
        **session.env_kwargs,
        render_mode="rgb_array" if recording else None,
        width=int(config.width),
        height=int(config.height),
        speech=config.speech,
        render_quality=config.render_quality,
        frame_rate=config.video_fps / config.video_speed,
        **config.env_kwargs,
    )
    agent = session.make_agent(config.agent, spec, seeding.agent_seed(config.seed, 0, config.agent))
    metrics = EpisodeMetrics(
        config={
            "command": command,
            "agent": config.agent,
            "seed": config.seed,
            "spec": spec,
            "options": options,
            "speech": config.speech,
            "max_steps": config.max_steps,
            "speed": speed,
            "reply_timeout": reply_timeout,
            "human": type(env.human_driver).__name__,
        },
        true_task=int(spec["task"]),
        identify=identify_step,
    )
    return RealtimeEpisode(config, env, agent, session, spec, metrics)


def run_realtime_episode(
    episode: RealtimeEpisode, observers: Sequence[EpisodeObserver] = ()
) -> EpisodeOutcome:
    """Run (and, with a record folder, record) the episode; a :class:`LiveStopped` ends it as interrupted, with
    everything finished so far written."""
    from embodied_adhoc.experiments import seeding

    config, env, session = episode.config, episode.env, episode.session
    files: dict[str, Path] = {}
    attached: list[EpisodeObserver] = [_Metrics(episode.metrics, session.library)]
    recorder: _Recording | None = None
    try:
        if config.record_dir is not None:
            recorder = _Recording(config, env, session.library, episode.spec, files)
            attached.append(recorder)
        run_episode_loop(
            env,
            episode.agent,
            env_seed=seeding.env_seed(config.seed, 0, config.agent),
            agent_rng=seeding.agent_rng(config.seed, 0, config.agent),
            reset_options=session.reset_options(episode.spec),
            max_steps=config.max_steps,
            observation_index=session.observation_index,
            observers=[*attached, *observers],
        )
    except LiveStopped:
        pass  # metrics.json says "interrupted"; the recorders keep what they have
    finally:
        try:
            if recorder is not None:
                recorder.close()
        finally:
            env.close()
            if config.record_dir is not None:
                files["metrics"] = episode.metrics.write(Path(config.record_dir) / "metrics.json")
    return EpisodeOutcome(
        episode.metrics.summary(), files, 0 if recorder is None else recorder.video.frame_count
    )
