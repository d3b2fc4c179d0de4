"""Sweep results on disk: ``config.json``, an append-only ``trials.csv`` and an append-only ``steps.csv``.

* ``config.json`` (written atomically) holds the run's *identity* (domain, backend, domain options, seed, step cap:
  everything that determines a trial's outcome), the task names, the spec columns and the last request (agents,
  episodes). Re-using a folder with a different identity is a :class:`ConfigError`; the same identity resumes:
  trials already in ``trials.csv`` are skipped, so asking for more agents or episodes extends the run.
* ``trials.csv``: one row per finished trial, appended and flushed (and fsynced) as the trial finishes, in
  completion order. A trial's row is its commit mark: its per-step rows are written to ``steps.csv`` first.
  A session may add columns after the results (its ``trial_columns``, e.g. the physics lab's fault counts).
* ``steps.csv``: one row per step of every trial (step 0 = before acting): action, observation index, reward,
  normalised task entropy and the task posterior (``posterior_<k>`` columns), for Fig. 7.9-style plots.

On resume, rows of a trial that never committed (an interrupt between the two writes) and a torn last line (a
kill mid-write) are dropped by rewriting the files atomically once, before new trials are appended.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from embodied_adhoc.atomic import atomic_write_text
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.trial import TrialResult

FORMAT_VERSION = 1
RESULT_FIELDS = ("success", "steps", "identify_step", "final_entropy", "true_task_probability", "return")


@dataclass(frozen=True)
class TrialRecord:
    """One finished trial as stored (and as read back): what the summary statistics use."""

    agent: str
    episode: int
    spec: dict
    success: bool
    steps: int
    identify_step: int | None
    final_entropy: float
    true_task_probability: float
    total_reward: float
    extras: dict = field(default_factory=dict)  # the session's extra columns (numbers or short codes)


def _format_float(value: float) -> str:
    return "" if value is None or math.isnan(value) else repr(float(value))


def _parse_float(text: str) -> float:
    return math.nan if text == "" else float(text)


def _parse_scalar(text: str):
    for parse in (int, float):
        try:
            return parse(text)
        except ValueError:
            pass
    return text


def trial_row(result: TrialResult, spec_fields: tuple[str, ...]) -> dict[str, str]:
    identified = result.identify_step
    row = {"agent": result.agent, "episode": str(result.episode)}
    row.update({key: str(result.spec[key]) for key in spec_fields})
    row.update(
        success=str(int(result.success)),
        steps=str(result.steps),
        identify_step="" if identified is None else str(identified),
        final_entropy=_format_float(result.final_entropy),
        true_task_probability=_format_float(result.true_task_probability),
    )
    row["return"] = _format_float(result.total_reward)
    row.update({key: _format_extra(value) for key, value in result.extras.items()})
    return row


def _format_extra(value) -> str:
    """An extra column's cell: an int as is, a float as ``repr`` (NaN: empty), a code as its text."""
    if isinstance(value, float):
        return _format_float(value)
    return str(value)


def record_from_row(row: dict[str, str], spec_fields: tuple[str, ...]) -> TrialRecord:
    return TrialRecord(
        agent=row["agent"],
        episode=int(row["episode"]),
        spec={key: _parse_scalar(row[key]) for key in spec_fields},
        success=row["success"] == "1",
        steps=int(row["steps"]),
        identify_step=None if row["identify_step"] == "" else int(row["identify_step"]),
        final_entropy=_parse_float(row["final_entropy"]),
        true_task_probability=_parse_float(row["true_task_probability"]),
        total_reward=_parse_float(row["return"]),
        extras={
            key: _parse_scalar(value)
            for key, value in row.items()
            if key not in spec_fields and key not in ("agent", "episode", *RESULT_FIELDS)
        },
    )


def step_rows(result: TrialResult, n_tasks: int) -> list[dict[str, str]]:
    entropies = result.entropies
    rows = []
    for step in range(result.steps + 1):
        row = {
            "agent": result.agent,
            "episode": str(result.episode),
            "step": str(step),
            "action": "" if step == 0 else str(result.actions[step - 1]),
            "observation": "" if step == 0 else str(result.observations[step - 1]),
            "reward": "" if step == 0 else _format_float(result.rewards[step - 1]),
            "entropy": "" if entropies is None else _format_float(entropies[step]),
        }
        for k in range(n_tasks):
            row[f"posterior_{k}"] = (
                "" if result.posteriors is None else _format_float(result.posteriors[step, k])
            )
        rows.append(row)
    return rows


def _csv_text(fields: Iterable[str], rows: Iterable[dict[str, str]], header: bool) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(fields), lineterminator="\n")
    if header:
        writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue()


def _read_complete_rows(path: Path, fields: tuple[str, ...]) -> tuple[list[dict[str, str]], bool]:
    """Rows of a CSV with the expected header; drops a torn last line. Returns (rows, file_was_clean)."""
    if not path.exists():
        return [], False
    with open(path, encoding="utf-8", newline="") as stream:
        text = stream.read()
    reader = csv.reader(io.StringIO(text))
    header = next(reader, None)
    if header is None:
        return [], False
    if tuple(header) != fields:
        raise ConfigError(
            f"{path}: columns {header} differ from the expected {list(fields)}; it was written by another "
            "configuration or version; use a new --out folder"
        )
    rows, clean = [], text.endswith("\n")
    lines = list(reader)
    for index, values in enumerate(lines):
        if len(values) != len(fields):
            if index == len(lines) - 1:  # torn by a kill mid-write: the trial was never committed
                clean = False
                continue
            raise ConfigError(
                f"{path}:{index + 2}: {len(values)} fields, expected {len(fields)}; the file is damaged"
            )
        rows.append(dict(zip(fields, values, strict=True)))
    if not text.endswith("\n") and lines and len(lines[-1]) == len(fields):
        rows.pop()  # a last line without its newline may have been cut inside its final field
    return rows, clean


class ResultStore:
    """The files of one sweep in ``folder`` (see the module docstring)."""

    def __init__(
        self,
        folder: Path,
        identity: dict,
        task_names: tuple[str, ...],
        spec_fields: tuple[str, ...],
        extra_fields: tuple[str, ...] = (),
    ):
        self.folder = Path(folder)
        self.identity = json.loads(json.dumps(identity))
        self.task_names = tuple(task_names)
        self.spec_fields = tuple(spec_fields)
        self.extra_fields = tuple(extra_fields)  # the session's per-trial columns after the results
        clash = set(self.spec_fields) & {"agent", "episode", *RESULT_FIELDS, *self.extra_fields}
        if clash:
            raise ConfigError(
                f"episode spec keys {sorted(clash)} clash with result columns; rename them in the domain"
            )
        self.trial_fields = ("agent", "episode", *self.spec_fields, *RESULT_FIELDS, *self.extra_fields)
        self.step_fields = (
            "agent",
            "episode",
            "step",
            "action",
            "observation",
            "reward",
            "entropy",
            *(f"posterior_{k}" for k in range(len(self.task_names))),
        )
        self.config_path = self.folder / "config.json"
        self.trials_path = self.folder / "trials.csv"
        self.steps_path = self.folder / "steps.csv"

    def open(self, request: dict) -> list[dict[str, str]]:
        """Create or resume the folder; returns the rows of trials already finished."""
        self.folder.mkdir(parents=True, exist_ok=True)
        if self.config_path.exists():
            stored = json.loads(self.config_path.read_text(encoding="utf-8"))
            if stored.get("identity") != self.identity:
                differences = _differences(stored.get("identity", {}), self.identity)
                raise ConfigError(
                    f"{self.folder} holds a different run ({'; '.join(differences)}); resume it with the same "
                    "options or choose another --out folder"
                )
        config = {
            "format": FORMAT_VERSION,
            "identity": self.identity,
            "task_names": list(self.task_names),
            "spec_fields": list(self.spec_fields),
            "request": request,
            "files": {"trials": self.trials_path.name, "steps": self.steps_path.name},
        }
        atomic_write_text(self.config_path, json.dumps(config, indent=2) + "\n")
        trials, trials_clean = _read_complete_rows(self.trials_path, self.trial_fields)
        committed = {(row["agent"], row["episode"]) for row in trials}
        steps, steps_clean = _read_complete_rows(self.steps_path, self.step_fields)
        kept_steps = [row for row in steps if (row["agent"], row["episode"]) in committed]
        if not trials_clean:
            atomic_write_text(self.trials_path, _csv_text(self.trial_fields, trials, header=True))
        if not steps_clean or len(kept_steps) != len(steps):
            atomic_write_text(self.steps_path, _csv_text(self.step_fields, kept_steps, header=True))
        return trials

    def append(self, result: TrialResult) -> dict[str, str]:
        """Append one finished trial (its steps first, then its row) and flush both to disk."""
        row = trial_row(result, self.spec_fields)
        for path, text in (
            (
                self.steps_path,
                _csv_text(self.step_fields, step_rows(result, len(self.task_names)), header=False),
            ),
            (self.trials_path, _csv_text(self.trial_fields, [row], header=False)),
        ):
            with open(path, "a", encoding="utf-8", newline="") as stream:
                stream.write(text)
                stream.flush()
                os.fsync(stream.fileno())
        return row

    def entropy_curves(self) -> dict[tuple[str, int], list[float]]:
        """Normalised task entropy per step of every committed trial that keeps a posterior."""
        rows, _ = _read_complete_rows(self.steps_path, self.step_fields)
        curves: dict[tuple[str, int], list[float]] = {}
        for row in rows:
            if row["entropy"] != "":
                curves.setdefault((row["agent"], int(row["episode"])), []).append(float(row["entropy"]))
        return curves


def _differences(stored: dict, current: dict) -> list[str]:
    keys = sorted(set(stored) | set(current))
    return [
        f"{key}: stored {stored.get(key)!r}, now {current.get(key)!r}"
        for key in keys
        if stored.get(key) != current.get(key)
    ]
