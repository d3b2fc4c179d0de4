"""One recorded Fig. 7.12 pursuit episode on physics: what ``embodied-adhoc run pursuit`` runs.

Seeds, episode draw, agent and loop are the trial runner's (the ``pursuit --pairs`` POMDP domain of
:mod:`embodied_adhoc.experiments.domains.pursuit_pairs` and
:func:`~embodied_adhoc.experiments.episode.run_episode_loop`),
so ``run pursuit --seed S`` replays episode 0 of ``trials pursuit --pairs --backend mujoco --seed S`` for the same
agent. With ``record_dir`` it writes ``episode.mp4`` (overhead view with step, action, observation and task
posterior), ``episode.rrd`` (robot poses, posterior bars, entropy, observations, actions, overhead frames) and
``metrics.json``. Recorders are closed in ``finally``: an interrupted run keeps what it finished.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.arena_recording import ArenaRecording, ArenaVideoConfig, check_video_options
from embodied_adhoc.experiments.episode import StepRecord
from embodied_adhoc.experiments.recorded_episode import EpisodeOutcome, MetricsObserver, play_recorded_episode

__all__ = ["PursuitEpisodeConfig", "describe_pursuit_observation", "run_pursuit_episode"]

ACTION_NAMES = ("up", "down", "left", "right", "stay")
NEIGHBOUR_NAMES = ("NW", "N", "NE", "W", "here", "E", "SW", "S", "SE")
ROBOT_LABELS = ("ad hoc", "teammate", "prey")
ROBOT_COLOURS = ((240, 140, 20), (40, 90, 220), (220, 40, 40))


@dataclass(frozen=True)
class PursuitEpisodeConfig(ArenaVideoConfig):
    """What one ``run pursuit`` episode is (CLI flags map one to one; recording settings: ArenaVideoConfig)."""

    agent: str = "hotspot"
    seed: int = 0
    task: int | None = None  # 1..4 (N+S, W+E, SW+NE, NW+SE); None: drawn
    max_steps: int = 150


def describe_pursuit_observation(observation_index: int) -> str:
    """``z = 9 t + p`` in words: where the teammate and the prey were seen in the 3x3 neighbourhood."""
    if observation_index < 0:
        return "nothing yet"
    mate, prey = divmod(int(observation_index), 9)

    def seen(cell: int) -> str:
        return "unseen" if cell == 4 else NEIGHBOUR_NAMES[cell]

    return f"teammate {seen(mate)}, prey {seen(prey)}"


class _Metrics(MetricsObserver):
    def step_finished(self, record: StepRecord) -> None:
        from embodied_adhoc.decision.agents.task_beliefs import normalised_entropy

        posterior = record.task_posterior
        entropy = None if posterior is None else max(0.0, float(normalised_entropy(posterior)))
        self.metrics.end_step(
            record.action,
            describe_pursuit_observation(record.observation_index),
            record.reward,
            record.info["sim_time"],
            posterior,
            entropy,
        )
        self.metrics.per_step[-1].update(
            cells=record.info["cells"],
            state=int(record.info["state"]),
            intended_state=int(record.info["intended_state"]),
        )


class _Recording(ArenaRecording):
    """Video and rerun (:class:`~embodied_adhoc.experiments.arena_recording.ArenaRecording`) with the pursuit HUD."""

    outcomes = ("captured", "not captured")

    hud_keys = ("action", "observed", "posterior")

    def __init__(self, config: PursuitEpisodeConfig, env, task_names, files: dict[str, Path]):
        self.arena, self.task_names = env.unwrapped.arena, task_names
        super().__init__(
            config,
            self.arena,
            self.arena.backend,
            lambda: self.arena.sim_time,
            ROBOT_LABELS,
            ROBOT_COLOURS,
            f"pursuit {config.agent} seed {config.seed}",
            files,
        )

    def _posterior(self, posterior, info: dict) -> None:
        from embodied_adhoc.decision.agents.task_beliefs import normalised_entropy

        if posterior is None:
            self.hud.pop("posterior", None)
            return
        names = [name.split(":")[-1] for name in self.task_names]
        self.hud["posterior"] = "P(task): " + "  ".join(
            f"{n} {p:.2f}" for n, p in zip(names, posterior, strict=True)
        )
        self.rerun.log_belief(posterior, max(0.0, float(normalised_entropy(posterior))))

    def episode_started(self, info: dict, task_posterior) -> None:
        self.rerun.set_time(0, info["sim_time"])
        self.hud["action"] = f"{self.config.agent} | true task {info['task_name'].split(':')[-1]} | step 0"
        self._posterior(task_posterior, info)
        self.rerun.log_text(
            "events",
            f"start: cells (ad hoc, teammate, prey) {info['cells']}, true task "
            f"{info['task_name']}, library {', '.join(self.task_names)}",
        )
        self._frame(force=True)

    def action_chosen(self, step: int, action: int) -> None:
        self.step = step
        self.hud["action"] = f"{self.config.agent} | step {step}: {ACTION_NAMES[action]}"
        self.rerun.set_time(step, self.arena.sim_time)
        self.rerun.log_text("actions", f"step {step}: {ACTION_NAMES[action]}")

    def step_finished(self, record: StepRecord) -> None:
        description = describe_pursuit_observation(record.observation_index)
        self.rerun.set_time(record.step, record.info["sim_time"])
        self.rerun.log_text(
            "observations", f"step {record.step}: z={record.observation_index} ({description})"
        )
        if record.info["state"] != record.info["intended_state"]:
            self.rerun.log_text(
                "events",
                f"step {record.step}: physics did not execute the drawn move "
                f"(state {record.info['state']}, drawn {record.info['intended_state']})",
                level="WARN",
            )
        self.hud["observed"] = f"observed z={record.observation_index}: {description}"
        self._posterior(record.task_posterior, record.info)
        self._frame(force=True)


def run_pursuit_episode(
    config: PursuitEpisodeConfig, progress: Callable[[int, dict], None] | None = None
) -> EpisodeOutcome:
    """Run (and, with ``config.record_dir``, record) one physics episode; ``progress(step, info)`` per step."""
    import gymnasium

    from embodied_adhoc.experiments import seeding
    from embodied_adhoc.experiments.domains.pursuit_pairs import (
        ENV_IDS,
        POMDP_AGENTS,
        PursuitPairsSession,
        pomdp_options,
    )
    from embodied_adhoc.experiments.registry import agent_plugin, build_agent, get_trial_domain
    from embodied_adhoc.experiments.stats import identify_step
    from embodied_adhoc.record.metrics import EpisodeMetrics

    domain = get_trial_domain("pursuit")
    if (
        config.agent not in POMDP_AGENTS + ("random",)
        and agent_plugin(domain, config.agent, "--agent").builtin
    ):
        raise ConfigError(f"--agent {config.agent}: choose from {', '.join(POMDP_AGENTS + ('random',))}")
    if config.max_steps < 1:
        raise ConfigError(f"--max-steps must be >= 1, got {config.max_steps}")
    check_video_options(config)
    options = pomdp_options(config.task)
    spec = get_trial_domain("pursuit").episode_spec(options, seeding.episode_rng(config.seed, 0))
    session = PursuitPairsSession("mujoco", options)
    recording = config.record_dir is not None
    env = gymnasium.make(
        ENV_IDS["mujoco"],
        max_episode_steps=int(config.max_steps),
        disable_env_checker=True,
        render_mode="rgb_array" if recording else None,
    )
    agent = build_agent(domain, session, config.agent, spec, seeding.agent_seed(config.seed, 0, config.agent))
    metrics = EpisodeMetrics(
        config={
            "command": "run pursuit",
            "agent": config.agent,
            "seed": config.seed,
            "spec": spec,
            "options": options,
            "max_steps": config.max_steps,
            "env": ENV_IDS["mujoco"],
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
        [_Metrics(metrics)],
        (lambda files: _Recording(config, env, session.task_names, files)) if recording else None,
        progress,
    )
    outcome.metrics["physics_mismatches"] = sum(r["state"] != r["intended_state"] for r in metrics.per_step)
    return outcome
