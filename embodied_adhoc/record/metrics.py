"""Episode metrics accumulated step by step and written to ``metrics.json`` (atomically).

``metrics.json`` fields (schema version 1):

=====================  ===============================================================================
field                  meaning
=====================  ===============================================================================
``success``            all balls were disposed before the step cap
``outcome``            ``"success"``, ``"truncated"`` (step cap) or ``"interrupted"`` (Ctrl-C / error)
``steps``              macro steps taken
``identify_step``      thesis Metric 2: first step from which the true task's posterior leads every other by
                       more than 1e-6 to the end (0 = already at the prior; the caller's ``identify``, i.e.
                       ``experiments.stats.identify_step``); null if never, or the agent keeps no posterior
``final_entropy``      normalised entropy of the final task posterior (null without posterior)
``wall_time_s``        wall-clock seconds of the whole episode (rendering and recording included)
``macro_step_time_s``  mean / median / max wall seconds per macro step, and the per-step list
``sim_time_s``         simulated seconds
``per_step``           list of {step, action, observation, reward, entropy, sim_time_s, wall_time_s}, plus
                       ``utterances`` (the "locate human" dialogue: question, reply, transcript, node heard)
                       on steps that had one
``localisation``       physics runs: ``blocked_steps``, ``kidnaps``, ``worst_pose_error_m`` (the pose the
                       controller tracked), ``worst_odometry_error_m``, ``unknown_readings`` and
                       ``wrong_readings`` (robot-node readings unknown / not the true area); per step
                       ``pose_error_m``, ``odometry_error_m``, ``localisation_mode``, ``robot_node_reading``,
                       ``true_robot_node``, ``blocked``, ``kidnaps``. Null for envs without them.
``faults``             physics runs: the episode's fault events (the env's ``info["faults"]``: RFID misses of
                       reads, lost replies, dropped lidar beams, wheel-slip and encoder-noise metres,
                       re-localisations, blocked moves, unknown robot-node readings). Null for envs without them.
``cap_reason``         physics runs that hit the step cap: ``code`` (the observation that stayed uninformative,
                       e.g. ``rfid_missed``) and ``detail`` (e.g. "cap reached: 'locate human' chosen 96/100
                       steps; RFID missed 2 of 3 reads"); null otherwise.
``config``             the run's configuration (agent, seed, task, env kwargs, ...)
=====================  ===============================================================================
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from embodied_adhoc.atomic import atomic_write_text

SCHEMA_VERSION = 1


@dataclass
class EpisodeMetrics:
    """Accumulates one episode's per-step records; :meth:`summary` gives the ``metrics.json`` payload.

    ``identify`` computes thesis Metric 2 from the posterior history (rows: prior, then after each step) and the
    true task: the caller passes the project's one definition (``experiments.stats.identify_step``), so that this
    layer does not import ``experiments/`` (``tests/test_layers.py``); None leaves ``identify_step`` null.
    """

    config: dict[str, Any] = field(default_factory=dict)
    true_task: int | None = None
    identify: Callable[[np.ndarray, int], int | None] | None = None
    per_step: list[dict[str, Any]] = field(default_factory=list)
    task_posteriors: list[np.ndarray] = field(default_factory=list)
    success: bool = False
    outcome: str = "interrupted"
    faults: dict[str, Any] | None = None  # the env's fault counts of the episode, where it keeps them
    cap_reason: dict[str, str] | None = None  # why a capped episode did not finish: code and sentence
    sim_time_s: float = 0.0
    _started: float = field(default_factory=time.perf_counter)
    _step_started: float = field(default_factory=time.perf_counter)

    def start_episode(self, prior: np.ndarray | None) -> None:
        """Record the agent's task prior (row 0 of the posterior history) and restart the wall clock."""
        self._started = time.perf_counter()
        self.task_posteriors = [] if prior is None else [np.asarray(prior, dtype=np.float64).copy()]

    def start_step(self) -> None:
        """Mark the start of a macro step (its wall time runs until :meth:`end_step`)."""
        self._step_started = time.perf_counter()

    def end_step(
        self,
        action: int,
        observation: str,
        reward: float,
        sim_time_s: float,
        task_posterior: np.ndarray | None,
        entropy: float | None,
        utterances: tuple[str, ...] | list[str] = (),
    ) -> float:
        """Record the step just finished; returns its wall time in seconds."""
        elapsed = time.perf_counter() - self._step_started
        self.sim_time_s = float(sim_time_s)
        if task_posterior is not None:
            self.task_posteriors.append(np.asarray(task_posterior, dtype=np.float64).copy())
        self.per_step.append(
            {
                "step": len(self.per_step) + 1,
                "action": int(action),
                "observation": observation,
                "reward": float(reward),
                "entropy": None if entropy is None else float(entropy),
                "sim_time_s": round(float(sim_time_s), 4),
                "wall_time_s": round(elapsed, 4),
            }
        )
        if utterances:
            self.per_step[-1]["utterances"] = list(utterances)
        return elapsed

    def finish(self, success: bool, truncated: bool) -> None:
        """Set the episode's outcome (call once the env reports termination or truncation)."""
        self.success = bool(success)
        self.outcome = "success" if success else ("truncated" if truncated else "failure")

    @property
    def identify_step(self) -> int | None:
        if self.identify is None or self.true_task is None or not self.task_posteriors:
            return None
        return self.identify(np.stack(self.task_posteriors), self.true_task)

    def summary(self) -> dict[str, Any]:
        step_times = np.array([record["wall_time_s"] for record in self.per_step], dtype=np.float64)
        entropies = [record["entropy"] for record in self.per_step if record["entropy"] is not None]
        return {
            "schema_version": SCHEMA_VERSION,
            "success": self.success,
            "outcome": self.outcome,
            "steps": len(self.per_step),
            "identify_step": self.identify_step,
            "final_entropy": entropies[-1] if entropies else None,
            "true_task": self.true_task,
            "wall_time_s": round(time.perf_counter() - self._started, 3),
            "sim_time_s": round(self.sim_time_s, 3),
            "macro_step_time_s": {
                "mean": round(float(step_times.mean()), 4) if len(step_times) else None,
                "median": round(float(np.median(step_times)), 4) if len(step_times) else None,
                "max": round(float(step_times.max()), 4) if len(step_times) else None,
            },
            "localisation": _localisation_summary(self.per_step),
            "faults": self.faults,
            "cap_reason": self.cap_reason,
            "config": self.config,
            "per_step": self.per_step,
        }

    def write(self, path: str | Path) -> Path:
        """Write ``metrics.json`` atomically."""
        return atomic_write_text(path, json.dumps(self.summary(), indent=2, allow_nan=False) + "\n")


def _localisation_summary(per_step: list[dict[str, Any]]) -> dict[str, Any] | None:
    """Failures of the robot's localisation over an episode (see the module docstring); None without them."""
    steps = [record for record in per_step if "pose_error_m" in record]
    if not steps:
        return None
    return {
        "blocked_steps": [record["step"] for record in steps if record["blocked"]],
        "kidnaps": sum(record["kidnaps"] for record in steps),
        "worst_pose_error_m": max(record["pose_error_m"] for record in steps),
        "worst_odometry_error_m": max(record["odometry_error_m"] for record in steps),
        "unknown_readings": sum(record["robot_node_reading"] is None for record in steps),
        "wrong_readings": sum(
            record["robot_node_reading"] is not None
            and record["robot_node_reading"] != record["true_robot_node"]
            for record in steps
        ),
        "modes": sorted({record["localisation_mode"] for record in steps}),
    }
