"""Sweep results on disk: ``config.json``, an append-only ``trials.csv`` and an append-only ``steps.csv``.

* ``config.json`` (written atomically) holds the run's *identity* (domain, backend, domain options, seed, step cap,
  the SHA-256 of every input file the domain declares and, for domains that solve POMDPs, the BLAS kernel class:
  everything that determines a trial's outcome, see :mod:`embodied_adhoc.experiments.identity`), the task names,
  the spec columns, the last request (agents, episodes) and a note on the BLAS. Re-using a folder with a different
  identity is a :class:`ConfigError` naming the first differing field or file; the same identity resumes: trials
  already in ``trials.csv`` are skipped, so asking for more agents or episodes extends the run.
* ``trials.csv``: one row per finished trial, appended and flushed (and fsynced) as the trial finishes, in
  completion order. A trial's row is its commit mark: its per-step rows are written to ``steps.csv`` first. Its
  A session may add columns after the results (its ``trial_columns``, e.g. the physics lab's fault counts). The
  last column, ``check``, is a checksum of the row's other values and of the exact bytes of its ``steps.csv`` rows.
* ``steps.csv``: one row per step of every trial (step 0 = before acting): action, observation index, reward,
  normalised task entropy and the task posterior (``posterior_<k>`` columns), for Fig. 7.9-style plots.
* ``run.lock``: held (``flock``) by the one process writing the folder, with its PID and host inside. A second
  process is refused with the owner named; a lock file left by a process that died is taken over with a note.

On resume every line is checked before any trial runs. The rule: a line that cannot be a committed trial is never
mixed into the results; it is moved (its bytes unchanged) to ``trials.csv.rejected`` / ``steps.csv.rejected`` with
a one-line warning naming the file and line, and its trial runs again (trials are seeded by ``(seed, episode,
agent)``, so the re-run reproduces what an intact row would have held). Rejected are: undecodable bytes, a wrong
number of fields, a value that does not parse (a non-numeric ``steps``, ...), a trial listed twice, a row whose
``check`` does not match its values or its steps rows (an edited value), and an incomplete last line (a write cut
off by a kill). Step rows of a trial that never committed (an interrupt between the two writes) are dropped
silently. A header that differs from the expected columns refuses the folder (another version or configuration).
The files are then rewritten atomically once, before new trials are appended.
"""

from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import math
import os
import socket
import sys
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from embodied_adhoc.atomic import atomic_write_bytes, atomic_write_text
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.experiments.trial import TrialResult

FORMAT_VERSION = 2
RESULT_FIELDS = ("success", "steps", "identify_step", "final_entropy", "true_task_probability", "return")
CHECK_FIELD = "check"
"""The last column of ``trials.csv``, after every result column (columns added to the results go before it)."""
CHECK_LENGTH = 16
MAX_WARNINGS = 5
"""Rejected lines warned about one by one per file on resume; the rest are counted in one line."""


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
            if key not in spec_fields and key not in ("agent", "episode", *RESULT_FIELDS, CHECK_FIELD)
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


def _row_check(values: Iterable[str], steps: bytes) -> str:
    """The ``check`` column: a checksum of a trial row's other values and of its steps rows' exact bytes (it
    detects edits and damage, it is no signature)."""
    digest = hashlib.sha256((json.dumps(list(values)) + "\n").encode("utf-8"))
    digest.update(steps)
    return digest.hexdigest()[:CHECK_LENGTH]


def _optional_int(text: str) -> int | None:
    return None if text == "" else int(text)


def _flag(text: str) -> bool:
    if text not in ("0", "1"):
        raise ValueError(f"{text!r} is not 0 or 1")
    return text == "1"


FIELD_PARSERS = {
    "episode": int,
    "step": int,
    "success": _flag,
    "steps": int,
    "identify_step": _optional_int,
    "final_entropy": _parse_float,
    "true_task_probability": _parse_float,
    "return": _parse_float,
    "action": _optional_int,
    "observation": _optional_int,
    "reward": _parse_float,
    "entropy": _parse_float,
}
"""How a stored column must parse (a column not listed is free text, e.g. an episode spec's); a row with a value
that does not parse is rejected on resume. Columns added to the trial files add their parser here."""


@dataclass(frozen=True)
class _Line:
    number: int  # 1-based line number in its file
    raw: bytes  # the line's bytes, without its newline
    values: dict[str, str]


def _field_problem(values: dict[str, str]) -> str | None:
    for key, text in values.items():
        parse = FIELD_PARSERS.get(key) or (_parse_float if key.startswith("posterior_") else None)
        if parse is None:
            continue
        try:
            parse(text)
        except ValueError:
            return f"field '{key}' = {text[:40]!r} does not parse"
    return None


def _scan(path: Path, fields: tuple[str, ...]) -> tuple[list[_Line], list[tuple[int, bytes, str]], bool]:
    """The lines of a stored CSV: ``(parsed lines, rejected (line number, bytes, reason), needs rewrite)``.

    The files hold one record per physical line (no field holds a newline), so each line is decoded and parsed on
    its own: damage stays on its line. A missing or empty file needs writing (its header)."""
    if not path.exists():
        return [], [], True
    data = path.read_bytes()
    if not data:
        return [], [], True
    lines = data.split(b"\n")
    tail = lines.pop()  # b"" when the file ends with its newline; else the last line, never finished
    if not lines:
        lines, tail = [tail], b""
    try:
        header = next(csv.reader([lines[0].decode("utf-8")]), [])
    except UnicodeDecodeError:
        header = None
    if header is None or tuple(header) != fields:
        raise ConfigError(
            f"{path}:1: columns {header} differ from the expected {list(fields)}; it was written by another "
            "configuration or version; pass --new-run or use a new --out folder"
        )
    parsed, rejected = [], []
    for index, raw in enumerate(lines[1:], start=2):
        try:
            values = next(csv.reader([raw.decode("utf-8")]), [])
        except (UnicodeDecodeError, csv.Error) as error:
            rejected.append((index, raw, f"undecodable ({type(error).__name__})"))
            continue
        if len(values) != len(fields):
            rejected.append((index, raw, f"{len(values)} fields, expected {len(fields)}"))
            continue
        row = dict(zip(fields, values, strict=True))
        problem = _field_problem(row)
        if problem:
            rejected.append((index, raw, problem))
            continue
        parsed.append(_Line(index, raw, row))
    if tail:
        rejected.append(
            (len(lines) + 1, tail, "incomplete last line (no newline: a write cut off, or bytes appended)")
        )
    return parsed, rejected, bool(rejected)


def _warn(message: str) -> None:
    print(f"embodied-adhoc: warning: {message}", file=sys.stderr)


def _quarantine(path: Path, rejected: list[tuple[int, bytes, str]], warn_each: bool = True) -> None:
    """Append the rejected lines' bytes to ``path.rejected`` (each as it was, one per line) and warn."""
    if not rejected:
        return
    target = path.with_name(path.name + ".rejected")
    with open(target, "ab") as stream:
        for _, raw, _ in rejected:
            stream.write(raw + b"\n")
        stream.flush()
        os.fsync(stream.fileno())
    if not warn_each:
        return
    shown = rejected[:MAX_WARNINGS]
    for number, _, reason in shown:
        _warn(f"{path}:{number}: {reason}; moved to {target.name} (a trial it held runs again)")
    if len(rejected) > len(shown):
        _warn(f"{path}: {len(rejected) - len(shown)} more rejected line(s) moved to {target.name}")


class RunLock:
    """The lock of one run folder (see the module docstring): ``flock`` on ``run.lock``, which names its owner.

    The kernel releases a ``flock`` when its owner dies, so a lock file that can be locked was left by a process
    that no longer runs; where the file system has no ``flock``, a live PID on this host in the file refuses."""

    NAME = "run.lock"

    def __init__(self, folder: Path):
        self.path = Path(folder) / self.NAME
        self._descriptor: int | None = None

    def acquire(self) -> None:
        import fcntl

        self.path.parent.mkdir(parents=True, exist_ok=True)
        while True:
            descriptor = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
            try:
                fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                owner = _describe_owner(_read_owner(descriptor))
                os.close(descriptor)
                raise ConfigError(
                    f"{self.path.parent} is in use by {owner}; wait until it finishes (or stop it), or choose "
                    "another --out folder"
                ) from None
            except OSError:  # no flock on this file system: the PID in the file decides
                owner = _read_owner(descriptor)
                if _alive_here(owner):
                    os.close(descriptor)
                    raise ConfigError(
                        f"{self.path.parent} is in use by {_describe_owner(owner)}; wait until it finishes, or "
                        "choose another --out folder"
                    ) from None
            try:
                same = os.fstat(descriptor).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(descriptor)  # its owner removed it while releasing: lock the file now at the path
        previous = _read_owner(descriptor)
        if previous:
            _note(
                f"{self.path}: took over the lock left by {_describe_owner(previous)}, which no longer runs"
            )
        os.ftruncate(descriptor, 0)
        os.pwrite(
            descriptor, (json.dumps({"pid": os.getpid(), "host": socket.gethostname()}) + "\n").encode(), 0
        )
        os.fsync(descriptor)
        self._descriptor = descriptor

    def release(self) -> None:
        if self._descriptor is None:
            return
        try:
            self.path.unlink(missing_ok=True)
        finally:
            os.close(self._descriptor)
            self._descriptor = None


def _read_owner(descriptor: int) -> dict | None:
    try:
        text = os.pread(descriptor, 4096, 0).decode("utf-8", errors="replace").strip()
        owner = json.loads(text) if text else None
    except (OSError, json.JSONDecodeError):
        return {"pid": None, "host": None}
    if owner is None:
        return None  # a fresh lock file
    return owner if isinstance(owner, dict) else {"pid": None, "host": None}


def _describe_owner(owner: dict | None) -> str:
    if not owner or owner.get("pid") is None:
        return "another process (its lock file names none)"
    return f"PID {owner['pid']} on {owner.get('host') or 'an unknown host'}"


def _alive_here(owner: dict | None) -> bool:
    if not owner or not isinstance(owner.get("pid"), int) or owner.get("host") != socket.gethostname():
        return False
    try:
        os.kill(owner["pid"], 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _note(message: str) -> None:
    print(f"embodied-adhoc: note: {message}", file=sys.stderr)


def _read_config(path: Path) -> dict:
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ConfigError(
            f"{path}: not a run's config.json ({error}); pass --new-run or use a new --out folder"
        ) from None
    if not isinstance(document, dict):
        raise ConfigError(f"{path}: not a run's config.json; pass --new-run or use a new --out folder")
    return document


def holds_other_run(folder: Path, identity: dict) -> bool:
    """Whether ``folder`` holds a stored run whose identity differs from ``identity`` (or an unreadable one)."""
    path = Path(folder) / "config.json"
    if not path.exists():
        return False
    try:
        stored = _read_config(path)
    except ConfigError:
        return True
    return stored.get("identity") != json.loads(json.dumps(identity))


def fresh_sibling(folder: Path, identity: dict) -> Path:
    """``--new-run``: ``folder`` itself unless it holds another run, else the first of ``folder-2``, ``folder-3``,
    ... that is new or holds this very run (so repeating the command resumes that one, not a third)."""
    folder = Path(folder)
    if not holds_other_run(folder, identity):
        return folder
    for number in itertools.count(2):
        candidate = folder.with_name(f"{folder.name}-{number}")
        if not holds_other_run(candidate, identity):
            return candidate
    raise AssertionError("unreachable")


class ResultStore:
    """The files of one sweep in ``folder`` (see the module docstring)."""

    def __init__(
        self,
        folder: Path,
        identity: dict,
        task_names: tuple[str, ...],
        spec_fields: tuple[str, ...],
        extra_fields: tuple[str, ...] = (),
        notes: dict | None = None,
    ):
        self.folder = Path(folder)
        self.identity = json.loads(json.dumps(identity))
        self.notes = json.loads(json.dumps(notes or {}))
        self.task_names = tuple(task_names)
        self.spec_fields = tuple(spec_fields)
        self.extra_fields = tuple(extra_fields)
        clash = set(self.spec_fields) & {"agent", "episode", *RESULT_FIELDS, *self.extra_fields, CHECK_FIELD}
        if clash:
            raise ConfigError(
                f"episode spec keys {sorted(clash)} clash with result columns; rename them in the domain"
            )
        self.trial_fields = (
            "agent",
            "episode",
            *self.spec_fields,
            *RESULT_FIELDS,
            *self.extra_fields,
            CHECK_FIELD,
        )
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
        self.lock = RunLock(self.folder)

    def open(self, request: dict) -> list[dict[str, str]]:
        """Lock, create or resume the folder; returns the rows of trials already finished (checked: see the
        module docstring). The lock is held until :meth:`close`."""
        self.folder.mkdir(parents=True, exist_ok=True)
        self.lock.acquire()
        try:
            return self._open(request)
        except BaseException:
            self.lock.release()
            raise

    def close(self) -> None:
        self.lock.release()

    def _open(self, request: dict) -> list[dict[str, str]]:
        notes = dict(self.notes)
        if self.config_path.exists():
            document = _read_config(self.config_path)
            stored = document.get("identity", {})
            differences = _differences(stored, self.identity)
            # a plug-in agent's source is part of its trials' identity; other agents may join the run
            sources = dict(document.get("agent_sources") or {})
            for name, digest in notes.get("agent_sources", {}).items():
                if sources.get(name, digest) != digest:
                    differences.append(
                        f"agent {name}: source sha256 stored {_short(sources[name])}, now {_short(digest)} (the "
                        "plug-in's file changed)"
                    )
            if differences:
                raise ConfigError(
                    f"{self.folder} holds a different run ({'; '.join(differences)}); resume it with the same "
                    "options and input files, pass --new-run to start a fresh run in a sibling folder, or choose "
                    "another --out folder"
                )
            if "agent_sources" in notes:
                notes["agent_sources"] = {**sources, **notes["agent_sources"]}
        config = {
            "format": FORMAT_VERSION,
            "identity": self.identity,
            "task_names": list(self.task_names),
            "spec_fields": list(self.spec_fields),
            "request": request,
            "files": {"trials": self.trials_path.name, "steps": self.steps_path.name},
            **notes,
        }
        atomic_write_text(self.config_path, json.dumps(config, indent=2) + "\n")
        trials, trials_rejected, trials_dirty = _scan(self.trials_path, self.trial_fields)
        steps, steps_rejected, steps_dirty = _scan(self.steps_path, self.step_fields)
        steps_of: dict[tuple[str, str], list[_Line]] = {}
        for line in steps:
            steps_of.setdefault((line.values["agent"], line.values["episode"]), []).append(line)
        committed: dict[tuple[str, str], dict[str, str]] = {}
        refused: set[tuple[str, str]] = set()
        for line in trials:
            row = line.values
            key = (row["agent"], row["episode"])
            own_steps = b"".join(step.raw + b"\n" for step in steps_of.get(key, ()))
            if key in committed or key in refused:
                reason = "the trial is listed twice"
            elif row[CHECK_FIELD] != _row_check((row[f] for f in self.trial_fields[:-1]), own_steps):
                reason = f"its values or its {len(steps_of.get(key, ()))} steps.csv rows were changed (check)"
            else:
                committed[key] = row
                continue
            trials_rejected.append((line.number, line.raw, reason))
            refused.add(key)
        for key in refused:  # a trial listed twice is rejected with every copy
            if key in committed:
                line_of = next(line for line in trials if line.values is committed[key])
                trials_rejected.append((line_of.number, line_of.raw, "the trial is listed twice"))
                del committed[key]
        moved = [(step.number, step.raw, "") for key in sorted(refused) for step in steps_of.get(key, ())]
        kept_steps = [line for line in steps if (line.values["agent"], line.values["episode"]) in committed]
        _quarantine(self.trials_path, sorted(trials_rejected))
        _quarantine(self.steps_path, sorted(steps_rejected))
        _quarantine(self.steps_path, moved, warn_each=False)
        rows = list(committed.values())
        if trials_dirty or trials_rejected:
            atomic_write_text(self.trials_path, _csv_text(self.trial_fields, rows, header=True))
        if steps_dirty or len(kept_steps) != len(steps):
            text = _csv_text(self.step_fields, (), header=True)
            atomic_write_bytes(
                self.steps_path, text.encode("utf-8") + b"".join(s.raw + b"\n" for s in kept_steps)
            )
        return rows

    def append(self, result: TrialResult) -> dict[str, str]:
        """Append one finished trial (its steps first, then its row) and flush both to disk."""
        steps = _csv_text(self.step_fields, step_rows(result, len(self.task_names)), header=False)
        row = trial_row(result, self.spec_fields)
        row[CHECK_FIELD] = _row_check((row[f] for f in self.trial_fields[:-1]), steps.encode("utf-8"))
        for path, text in (
            (self.steps_path, steps),
            (self.trials_path, _csv_text(self.trial_fields, [row], False)),
        ):
            with open(path, "a", encoding="utf-8", newline="") as stream:
                stream.write(text)
                stream.flush()
                os.fsync(stream.fileno())
        return row

    def entropy_curves(self) -> dict[tuple[str, int], list[float]]:
        """Normalised task entropy per step of every stored trial that keeps a posterior (the files were checked
        when the store was opened)."""
        lines, _, _ = _scan(self.steps_path, self.step_fields)
        curves: dict[tuple[str, int], list[float]] = {}
        for line in lines:
            row = line.values
            if row["entropy"] != "":
                curves.setdefault((row["agent"], int(row["episode"])), []).append(float(row["entropy"]))
        return curves


def _differences(stored: dict, current: dict) -> list[str]:
    differences = []
    for key in sorted(set(stored) | set(current)):
        if stored.get(key) == current.get(key):
            continue
        if key == "inputs" and isinstance(stored.get(key), dict) and isinstance(current.get(key), dict):
            for label in sorted(set(stored[key]) | set(current[key])):
                old, new = stored[key].get(label), current[key].get(label)
                if old != new:
                    differences.append(
                        f"input {label}: sha256 stored {_short(old)}, now {_short(new)} (the file's content changed)"
                    )
        else:
            differences.append(f"{key}: stored {stored.get(key)!r}, now {current.get(key)!r}")
    return differences


def _short(digest) -> str:
    return "none" if digest is None else f"{str(digest)[:12]}..."
