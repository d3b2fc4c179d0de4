"""Recorded physics episodes of the trial domains: what ``run toxic-waste``, ``run pursuit``, ``run foraging`` and
the live mode run.

:func:`prepare_recorded` builds episode 0 of a seed exactly as the trial runner builds it (the domain's episode
draw, session, agent and the seeds of :mod:`embodied_adhoc.experiments.seeding`), so ``run <domain> --seed S``
replays episode 0 of ``trials <domain> --backend mujoco --seed S`` for the same agent and options. The episode then
runs through :func:`embodied_adhoc.episodes.recorded.run_recorded` with the domain's presenter
(:mod:`embodied_adhoc.episodes.presenters`): ``metrics.json`` always, with a record folder also ``episode.mp4``
and ``episode.rrd``. Each domain's config dataclass maps its ``run`` command's flags one to one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from embodied_adhoc.domains.confusion import DEFAULT_CONFUSION
from embodied_adhoc.episodes.recorded import EpisodeOutcome, PreparedEpisode, run_recorded
from embodied_adhoc.episodes.recording import VideoSettings
from embodied_adhoc.errors import ConfigError

__all__ = [
    "ArenaVideoConfig",
    "EpisodeConfig",
    "ForagingEpisodeConfig",
    "PursuitEpisodeConfig",
    "check_recordable",
    "lab_presenter",
    "prepare_lab_episode",
    "prepare_recorded",
    "record_trial_episode",
    "run_episode",
    "run_foraging_episode",
    "run_pursuit_episode",
]

LAB_ENV_ID = "EmbodiedAdhoc/ToxicWaste-v0"
FORAGING_AGENTS = ("atlpo-mf", "original", "random", "ppo-generalist", "liam", "meliba")


def prepare_recorded(
    domain,
    backend: str,
    agent: str,
    seed: int,
    *,
    options: dict,
    max_steps: int,
    command: str,
    make_env: Callable[[Any, dict], Any],
    frames: Callable[[Any], Any],
    spec_overrides: dict | None = None,
    settings: dict | None = None,
    leading: dict | None = None,
) -> PreparedEpisode:
    """Episode 0 of ``seed`` for ``agent`` in trial domain ``domain`` on ``backend`` with ``options``:
    ``make_env(session, spec)`` builds the env, ``frames(env)`` its frame source; ``spec_overrides`` replace
    drawn fields (start nodes); ``metrics.json``'s config names ``command``, the ``leading`` settings, the step cap
    and any further ``settings``."""
    from embodied_adhoc.experiments import seeding
    from embodied_adhoc.experiments.registry import build_agent
    from embodied_adhoc.experiments.stats import identify_step
    from embodied_adhoc.record.metrics import EpisodeMetrics

    spec = domain.episode_spec(options, seeding.episode_rng(seed, 0))
    spec.update({key: int(value) for key, value in (spec_overrides or {}).items() if value is not None})
    session = domain.open_session(backend, options)
    env = make_env(session, spec)
    built = build_agent(domain, session, agent, spec, seeding.agent_seed(seed, 0, agent))
    config = {
        "command": command,
        "agent": agent,
        "seed": seed,
        "spec": spec,
        "options": options,
        **(leading or {}),
    }
    metrics = EpisodeMetrics(
        config={**config, "max_steps": max_steps, **(settings or {})},
        true_task=int(spec["task"]),
        identify=identify_step,
    )
    return PreparedEpisode(
        env=env,
        agent=built,
        env_seed=seeding.env_seed(seed, 0, agent),
        agent_rng=seeding.agent_rng(seed, 0, agent),
        reset_options=session.reset_options(spec),
        max_steps=int(max_steps),
        observation_index=session.observation_index,
        metrics=metrics,
        frames=frames,
        name=f"{domain.name} {agent} seed {seed}",
        spec=spec,
        session=session,
    )


# -- the lab ----------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class EpisodeConfig:
    """What one ``run toxic-waste`` episode is (CLI flags map one to one)."""

    agent: str = "hotspot"
    seed: int = 0
    task: int | None = None
    robot_node: int | None = None
    human_node: int | None = None
    human_epsilon: float = 0.05
    communication: bool = True
    speech: str = "channel"
    confusion: str = DEFAULT_CONFUSION
    max_steps: int = 100
    record_dir: Path | None = None
    # 10 frames per 4 simulated seconds: the robot moves ~20 cm a frame, each macro step's heads-up text stays
    # ~2 s on screen, and recording costs a small multiple of the bare episode (scripts/bench_sim.py)
    video_fps: float = 10.0
    video_speed: float = 4.0  # simulated seconds per second of video (time-lapse keeps rendering affordable)
    video_hold: float = 1.0  # seconds of video that show the final state
    render_quality: str = "fast"
    width: int = 640
    height: int = 480
    rerun_camera_hz: float = 2.0
    video_overlay: bool = True  # heads-up text (step, action, what was heard, task belief) on the video
    env_kwargs: dict = field(default_factory=dict)
    faults: dict = field(default_factory=dict)  # experiments.domains.toxic_waste.FAULTS name -> value
    localisation: bool = True  # False: wheel odometry alone
    localisation_model: str | None = None  # the agent's robot-node model: None (thesis), "measured" or a path
    model_rfid_miss: float | None = None  # the agent's RFID miss model: None = the rfid_miss fault's value

    def video(self) -> VideoSettings:
        return VideoSettings(
            self.width,
            self.height,
            self.video_fps,
            self.video_speed,
            self.video_hold,
            self.video_overlay,
            self.rerun_camera_hz,
        )


def prepare_lab_episode(
    config: EpisodeConfig,
    command: str = "run toxic-waste",
    make_env: Callable[[dict], Any] | None = None,
    options: dict | None = None,
    **settings,
) -> PreparedEpisode:
    """Episode 0 of ``config.seed`` in the physics lab (start nodes overridden by the config); the env renders
    only with a record folder, exactly the frames the video keeps. ``make_env(env_kwargs)`` replaces the
    registered env (the live mode's real-time one); ``options`` (a ``trials toxic-waste`` sweep's) replace the
    config's; ``settings`` go into ``metrics.json``'s config."""
    import gymnasium

    import embodied_adhoc.envs  # noqa: F401  (registers the ids)
    from embodied_adhoc.episodes.frames import LabFrameSource
    from embodied_adhoc.experiments.registry import get_trial_domain

    if not (config.video_fps > 0 and config.video_speed > 0 and config.video_hold >= 0):
        raise ConfigError(
            f"--video-fps ({config.video_fps}) and --video-speed ({config.video_speed}) must be > 0, "
            f"video_hold ({config.video_hold}) >= 0"
        )
    domain = get_trial_domain("toxic-waste")
    options = (
        options
        if options is not None
        else domain.options(
            human_epsilon=config.human_epsilon,
            communication=config.communication,
            task=config.task,
            confusion=config.confusion,
            faults=config.faults,
            localisation=config.localisation,
            localisation_model=config.localisation_model,
            model_rfid_miss=config.model_rfid_miss,
        )
    )

    def lab_env(session, spec):
        env_kwargs = {
            **session.env_kwargs,
            "render_mode": "rgb_array" if config.record_dir is not None else None,
            "width": int(config.width),
            "height": int(config.height),
            "speech": config.speech,
            "render_quality": config.render_quality,
            # the video keeps video_fps frames per video_speed simulated seconds: the env emits exactly those
            "frame_rate": config.video_fps / config.video_speed,
            **config.env_kwargs,
        }
        if make_env is not None:
            return make_env(env_kwargs)
        # the step cap is the registered TimeLimit's, set to --max-steps
        return gymnasium.make(
            LAB_ENV_ID, max_episode_steps=int(config.max_steps), disable_env_checker=True, **env_kwargs
        )

    human = {"human": config.env_kwargs["human"]} if "human" in config.env_kwargs else {}  # a plug-in human
    return prepare_recorded(
        domain,
        "mujoco",
        config.agent,
        config.seed,
        options=options,
        max_steps=config.max_steps,
        command=command,
        make_env=lab_env,
        frames=lambda env: LabFrameSource(env, config.width, config.height),
        spec_overrides={"robot_node": config.robot_node, "human_node": config.human_node},
        leading={"speech": config.speech},
        settings={**human, **settings},
    )


def lab_presenter(episode: PreparedEpisode, agent_name: str):
    """The lab's presenter for a prepared lab episode (``metrics.json`` explains a capped run by its faults)."""
    from embodied_adhoc.episodes.presenters import LabPresenter
    from embodied_adhoc.experiments.domains.toxic_waste import cap_reason

    return LabPresenter(episode.env.unwrapped, episode.session.library, agent_name, episode.spec, cap_reason)


def run_episode(config: EpisodeConfig, progress: Callable[[int, dict], None] | None = None) -> EpisodeOutcome:
    """Run (and, with ``config.record_dir``, record) one lab episode; ``progress(step, info)`` after each step."""
    episode = prepare_lab_episode(config)
    return run_recorded(
        episode, lab_presenter(episode, config.agent), config.record_dir, config.video(), progress
    )


# -- the grid arenas --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ArenaVideoConfig:
    """The recording settings of a ``run pursuit`` / ``run foraging`` episode (their configs extend it)."""

    record_dir: Path | None = None  # None: no recording
    video_fps: float = 12.0
    video_speed: float = 2.0  # simulated seconds per second of video
    video_hold: float = 1.0  # seconds of video that show the final state
    size: int = 480  # square video, pixels (even)
    video_overlay: bool = True
    rerun_camera_hz: float = 2.0

    def video(self) -> VideoSettings:
        """These settings, refused (one line naming the flags) unless the rates are > 0 and the size even >= 16."""
        if not (self.video_fps > 0 and self.video_speed > 0 and self.size >= 16 and self.size % 2 == 0):
            raise ConfigError(
                f"--video-fps ({self.video_fps}) and --video-speed ({self.video_speed}) must be > 0, "
                f"--size ({self.size}) even and >= 16"
            )
        return VideoSettings(
            self.size,
            self.size,
            self.video_fps,
            self.video_speed,
            self.video_hold,
            self.video_overlay,
            self.rerun_camera_hz,
        )


def _arena_env(env_id: str, max_steps: int, recording: bool, **env_kwargs):
    import gymnasium

    import embodied_adhoc.envs  # noqa: F401  (registers the ids)

    return gymnasium.make(
        env_id,
        max_episode_steps=int(max_steps),
        disable_env_checker=True,
        render_mode="rgb_array" if recording else None,
        **env_kwargs,
    )


def _check_agent(domain, agent: str, choices: tuple[str, ...], flag: str = "--agent") -> None:
    from embodied_adhoc.experiments.registry import agent_plugin

    if agent not in choices and agent_plugin(domain, agent, flag).builtin:
        raise ConfigError(f"{flag} {agent}: choose from {', '.join(choices)}")


@dataclass(frozen=True)
class PursuitEpisodeConfig(ArenaVideoConfig):
    """What one ``run pursuit`` episode is (CLI flags map one to one; recording settings: ArenaVideoConfig)."""

    agent: str = "hotspot"
    seed: int = 0
    task: int | None = None  # 1..4 (N+S, W+E, SW+NE, NW+SE); None: drawn
    max_steps: int = 150


def run_pursuit_episode(
    config: PursuitEpisodeConfig,
    progress: Callable[[int, dict], None] | None = None,
    options: dict | None = None,
    command: str = "run pursuit",
) -> EpisodeOutcome:
    """One Fig. 7.12 physics episode (episode 0 of ``trials pursuit --pairs --backend mujoco``; ``options``, a
    sweep's, replace the config's), recorded with ``config.record_dir``; ``progress(step, info)`` per step."""
    from embodied_adhoc.episodes.frames import ArenaFrameSource
    from embodied_adhoc.episodes.presenters import PursuitPresenter
    from embodied_adhoc.experiments.domains.pursuit_pairs import ENV_IDS, POMDP_AGENTS, pomdp_options
    from embodied_adhoc.experiments.registry import get_trial_domain

    domain = get_trial_domain("pursuit")
    _check_agent(domain, config.agent, POMDP_AGENTS + ("random",))
    if config.max_steps < 1:
        raise ConfigError(f"--max-steps must be >= 1, got {config.max_steps}")
    video = config.video()
    recording = config.record_dir is not None
    episode = prepare_recorded(
        domain,
        "mujoco",
        config.agent,
        config.seed,
        options=pomdp_options(config.task) if options is None else options,
        max_steps=config.max_steps,
        command=command,
        make_env=lambda session, spec: _arena_env(ENV_IDS["mujoco"], config.max_steps, recording),
        frames=lambda env: ArenaFrameSource(
            env.arena, env.arena.backend, lambda: env.arena.sim_time, config.size, video.frame_period
        ),
        settings={"env": ENV_IDS["mujoco"]},
    )
    arena = episode.env.unwrapped.arena
    presenter = PursuitPresenter(arena.backend.layout, config.agent, episode.session.task_names)
    outcome = run_recorded(episode, presenter, config.record_dir, video, progress)
    per_step = episode.metrics.per_step
    outcome.metrics["physics_mismatches"] = sum(r["state"] != r["intended_state"] for r in per_step)
    return outcome


@dataclass(frozen=True)
class ForagingEpisodeConfig(ArenaVideoConfig):
    """What one ``run foraging`` episode is (CLI flags map one to one; recording settings: ArenaVideoConfig)."""

    agent: str = "atlpo-mf"
    seed: int = 0
    task: int | None = None  # 1..4; None: drawn
    teams: tuple[str, ...] = ("tau0", "tau1", "tau2")  # the episode's team is drawn among these
    library: Path | None = None  # None: the shipped task+team library
    max_steps: int = 200

    def options(self) -> dict:
        """The ``trials foraging`` options of this episode (the grid twin's defaults: 5x5 walled, 4 robots)."""
        options = {
            "domain": "foraging",
            "teams": list(self.teams),
            "task": self.task,
            "rows": 5,
            "cols": 5,
            "agents": 4,
            "toroidal": False,
            "pairs": False,
        }
        if self.library is not None:
            from embodied_adhoc.experiments.domains.foraging import library_folder

            options["library"] = library_folder("foraging", self.library)
        return options


def run_foraging_episode(
    config: ForagingEpisodeConfig,
    progress: Callable[[int, dict], None] | None = None,
    options: dict | None = None,
    command: str = "run foraging",
) -> EpisodeOutcome:
    """One level-based-foraging physics episode (episode 0 of ``trials foraging --backend mujoco``; the default
    agent is ATLPO-MF with the shipped library; ``options``, a sweep's, replace the config's), recorded with
    ``config.record_dir``; ``progress(step, info)`` per step."""
    from embodied_adhoc.episodes.frames import ArenaFrameSource
    from embodied_adhoc.episodes.presenters import ForagingPresenter
    from embodied_adhoc.experiments.domains.foraging import DOMAIN
    from embodied_adhoc.plugins import names_plugin

    _check_agent(DOMAIN, config.agent, FORAGING_AGENTS)
    if config.max_steps < 1:
        raise ConfigError(f"--max-steps must be >= 1, got {config.max_steps}")
    if config.task is not None and not 1 <= config.task <= 4:
        raise ConfigError(f"--task {config.task}: the task library is 1..4")
    unknown = [
        team for team in config.teams if team not in DOMAIN.team_names and not names_plugin("teammate", team)
    ]
    if unknown or not config.teams:
        raise ConfigError(f"--team {','.join(config.teams)}: choose from {', '.join(DOMAIN.team_names)}")
    video = config.video()
    recording = config.record_dir is not None

    def clock_of(env) -> Callable[[], float]:
        backend = env.core.backend
        return lambda: float(backend.data.time)

    episode = prepare_recorded(
        DOMAIN,
        "mujoco",
        config.agent,
        config.seed,
        options=config.options() if options is None else options,
        max_steps=config.max_steps,
        command=command,
        make_env=lambda session, spec: _arena_env(
            session.env_id, config.max_steps, recording, **session.env_kwargs
        ),
        frames=lambda env: ArenaFrameSource(
            env.core.backend, env.core.backend, clock_of(env), config.size, video.frame_period
        ),
        settings={"env": None},
    )
    agent, backend = episode.agent, episode.env.unwrapped.core.backend
    episode.metrics.config["env"] = episode.session.env_id
    episode.metrics.config["library"] = (
        [e.name for e in agent.library.environments] if hasattr(agent, "library") else None
    )
    presenter = ForagingPresenter(
        backend.layout, config.agent, agent, len(backend.robots), clock_of(episode.env.unwrapped)
    )
    outcome = run_recorded(episode, presenter, config.record_dir, video, progress)
    outcome.metrics["true_team"] = episode.spec["team"]
    return outcome


# -- trials --record ----------------------------------------------------------------------------------------------
RECORDABLE = ("toxic-waste", "pursuit", "foraging")


def check_recordable(domain_name: str, backends, options: dict, agents) -> None:
    """``trials --record`` records physics episodes of the domains with a presenter, for the agents their ``run``
    command takes: one line naming the flag and the fix otherwise (before any trial runs)."""
    if domain_name not in RECORDABLE:
        raise ConfigError(
            f"--record: trials {domain_name} has no recorded physics episode; record one of {', '.join(RECORDABLE)}"
        )
    if "mujoco" not in backends:
        raise ConfigError("--record records the physics episodes: add --backend mujoco")
    if domain_name == "pursuit" and not options.get("pairs"):
        raise ConfigError("--record: trials pursuit records the Fig. 7.12 pair variant only: add --pairs")
    from embodied_adhoc.experiments.registry import get_trial_domain

    if domain_name != "toxic-waste":
        from embodied_adhoc.experiments.domains.pursuit_pairs import POMDP_AGENTS

        choices = FORAGING_AGENTS if domain_name == "foraging" else POMDP_AGENTS + ("random",)
        for agent in agents:
            _check_agent(get_trial_domain(domain_name), agent, choices, "--agents")


def record_trial_episode(
    domain_name: str, options: dict, agent: str, seed: int, max_steps: int, out: Path
) -> EpisodeOutcome:
    """Episode 0 of a ``trials DOMAIN --backend mujoco`` sweep's ``seed`` for ``agent`` with the sweep's
    ``options``, recorded into ``out`` (``episode.mp4``, ``episode.rrd``, ``metrics.json``) with the defaults
    of the domain's ``run`` command; the same episode the sweep ran as trial 0."""
    command = f"trials {domain_name} --record"
    if domain_name == "toxic-waste":
        config = EpisodeConfig(agent=agent, seed=seed, max_steps=max_steps, record_dir=out)
        episode = prepare_lab_episode(config, command, options=options)
        return run_recorded(episode, lab_presenter(episode, agent), out, config.video())
    if domain_name == "pursuit":
        pursuit = PursuitEpisodeConfig(agent=agent, seed=seed, max_steps=max_steps, record_dir=out)
        return run_pursuit_episode(pursuit, options=options, command=command)
    foraging = ForagingEpisodeConfig(agent=agent, seed=seed, max_steps=max_steps, record_dir=out)
    return run_foraging_episode(foraging, options=options, command=command)
