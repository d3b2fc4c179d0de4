"""One recorded level-based-foraging episode in the MuJoCo arena: what ``embodied-adhoc run foraging`` runs.

Seeds, episode draw, agent and loop are the trial runner's (the ``foraging`` grid-arena domain of
:mod:`embodied_adhoc.experiments.domains.foraging` and :func:`~embodied_adhoc.experiments.episode.run_episode_loop`), so
``run foraging --seed S`` replays episode 0 of ``trials foraging --backend mujoco --seed S`` for the same agent
(same ``--team``/``--task``/``--library``). The default agent is ATLPO-MF (thesis chapter 6) with the library
shipped in the package: its observations are the egocentric arrays the arena computes from the robots' physical
positions. With ``record_dir`` it writes ``episode.mp4`` (overhead view with step, action, true task and team,
and the posterior), ``episode.rrd`` (robot poses, the library posterior as bars with its entropy, actions,
events, overhead frames) and ``metrics.json`` (per step also the robots' cells and the library posterior), through
the recorded-episode player shared with ``run toxic-waste`` and ``run pursuit``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.arena_recording import ArenaRecording, ArenaVideoConfig, check_video_options
from embodied_adhoc.experiments.episode import StepRecord
from embodied_adhoc.experiments.recorded_episode import EpisodeOutcome, MetricsObserver, play_recorded_episode

__all__ = ["FORAGING_AGENTS", "ForagingEpisodeConfig", "run_foraging_episode"]

FORAGING_AGENTS = ("atlpo-mf", "original", "random")
ACTION_NAMES = ("up", "down", "left", "right", "forage")
ROBOT_COLOURS = ((240, 140, 20), (40, 90, 220), (40, 160, 90), (150, 60, 200))


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


def _library_posterior(agent) -> np.ndarray | None:
    posterior = getattr(agent, "library_posterior", None)
    return None if posterior is None else np.asarray(posterior, dtype=np.float64)


def _entropy(posterior) -> float | None:
    from embodied_adhoc.decision.agents.task_beliefs import normalised_entropy

    return None if posterior is None else max(0.0, float(normalised_entropy(posterior)))


class _Metrics(MetricsObserver):
    def __init__(self, metrics, agent, backend):
        super().__init__(metrics)
        self.agent, self.backend = agent, backend

    def step_finished(self, record: StepRecord) -> None:
        self.metrics.end_step(
            record.action,
            f"egocentric view, fingerprint {record.observation_index:08x}",
            record.reward,
            float(self.backend.data.time),
            record.task_posterior,
            _entropy(record.task_posterior),
        )
        library = _library_posterior(self.agent)
        self.metrics.per_step[-1].update(
            cells=record.info["state"]["agents"],
            apples_left=int(record.info["remaining"]),
            library_posterior=None if library is None else [round(float(p), 6) for p in library],
        )


class _Recording(ArenaRecording):
    """Video and rerun (:class:`~embodied_adhoc.experiments.arena_recording.ArenaRecording`) with the foraging HUD
    and the library posterior."""

    outcomes = ("apple foraged", "not foraged")

    hud_keys = ("action", "truth", "posterior", "posterior more")

    def __init__(self, config: ForagingEpisodeConfig, env, agent, files: dict[str, Path]):
        backend = env.unwrapped.core.backend
        labels = ["ad hoc"] + [f"teammate {i}" for i in range(1, len(backend.robots))]
        self.agent = agent
        super().__init__(
            config,
            backend,
            backend,
            lambda: float(backend.data.time),
            labels,
            ROBOT_COLOURS[: len(labels)],
            f"foraging {config.agent} seed {config.seed}",
            files,
        )

    @property
    def sim_time(self) -> float:
        return self.clock()

    def _posterior(self) -> None:
        posterior = _library_posterior(self.agent)
        if posterior is None:
            self.hud.pop("posterior", None)
            self.hud.pop("posterior more", None)
            return
        cells = [
            f"{e.task}/{e.team} {p:.2f}"
            for e, p in zip(self.agent.library.environments, posterior, strict=True)
        ]
        self.hud["posterior"] = "P(task/team): " + " ".join(cells[:4])  # four per line fit the video's width
        self.hud["posterior more"] = " ".join(cells[4:])
        self.rerun.log_belief(posterior, _entropy(posterior))

    def episode_started(self, info: dict, task_posterior) -> None:
        self.rerun.set_time(0, self.sim_time)
        self.hud["action"] = f"{self.config.agent} | step 0"
        self.hud["truth"] = (
            f"true task {info['task']} ({info['task_name'].split(':')[-1]}), team {info['team']}"
        )
        self._posterior()
        library = getattr(self.agent, "library", None)
        environments = (
            ""
            if library is None
            else ", library posterior over " + ", ".join(e.name for e in library.environments)
        )
        self.rerun.log_text(
            "events",
            f"start: robots at {info['state']['agents']}, apple at "
            f"{info['state']['targets']}, {self.hud['truth']}{environments}",
        )
        self._frame(force=True)

    def action_chosen(self, step: int, action: int) -> None:
        self.step = step
        self.hud["action"] = f"{self.config.agent} | step {step}: {ACTION_NAMES[action]}"
        self.rerun.set_time(step, self.sim_time)
        self.rerun.log_text("actions", f"step {step}: {ACTION_NAMES[action]}")

    def step_finished(self, record: StepRecord) -> None:
        self.rerun.set_time(record.step, self.sim_time)
        self.rerun.log_text(
            "observations",
            f"step {record.step}: robots at {record.info['state']['agents']}, "
            f"teammates {record.info['teammate_actions']}",
        )
        self._posterior()
        self._frame(force=True)


def run_foraging_episode(
    config: ForagingEpisodeConfig, progress: Callable[[int, dict], None] | None = None
) -> EpisodeOutcome:
    """Run (and, with ``config.record_dir``, record) one physics episode; ``progress(step, info)`` per step."""
    import gymnasium

    from embodied_adhoc.experiments import seeding
    from embodied_adhoc.experiments.domains.foraging import DOMAIN
    from embodied_adhoc.experiments.registry import agent_plugin, build_agent
    from embodied_adhoc.experiments.stats import identify_step
    from embodied_adhoc.record.metrics import EpisodeMetrics

    if config.agent not in FORAGING_AGENTS and agent_plugin(DOMAIN, config.agent, "--agent").builtin:
        raise ConfigError(f"--agent {config.agent}: choose from {', '.join(FORAGING_AGENTS)}")
    if config.max_steps < 1:
        raise ConfigError(f"--max-steps must be >= 1, got {config.max_steps}")
    if config.task is not None and not 1 <= config.task <= 4:
        raise ConfigError(f"--task {config.task}: the task library is 1..4")
    from embodied_adhoc.plugins import names_plugin

    unknown = [
        team for team in config.teams if team not in DOMAIN.team_names and not names_plugin("teammate", team)
    ]
    if unknown or not config.teams:
        raise ConfigError(f"--team {','.join(config.teams)}: choose from {', '.join(DOMAIN.team_names)}")
    check_video_options(config)
    options = config.options()
    spec = DOMAIN.episode_spec(options, seeding.episode_rng(config.seed, 0))
    session = DOMAIN.open_session("mujoco", options)
    agent = build_agent(DOMAIN, session, config.agent, spec, seeding.agent_seed(config.seed, 0, config.agent))
    recording = config.record_dir is not None
    env = gymnasium.make(
        session.env_id,
        max_episode_steps=int(config.max_steps),
        disable_env_checker=True,
        render_mode="rgb_array" if recording else None,
        **session.env_kwargs,
    )
    metrics = EpisodeMetrics(
        config={
            "command": "run foraging",
            "agent": config.agent,
            "seed": config.seed,
            "spec": spec,
            "options": options,
            "max_steps": config.max_steps,
            "env": session.env_id,
            "library": [e.name for e in agent.library.environments] if hasattr(agent, "library") else None,
        },
        true_task=int(spec["task"]),
        identify=identify_step,
    )
    outcome = play_recorded_episode(
        env,
        agent,
        session,
        spec,
        config,
        metrics,
        [_Metrics(metrics, agent, env.unwrapped.core.backend)],
        (lambda files: _Recording(config, env, agent, files)) if recording else None,
        progress,
    )
    outcome.metrics["true_team"] = spec["team"]
    return outcome
