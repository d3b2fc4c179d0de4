"""A study: one participant plays a sequence of live episodes, answers a short questionnaire after each, and the
run writes one folder per participant with everything an analysis needs.

The plan (``live toxic-waste --study PLAN.json``)::

    {
      "episodes": [{"agent": "hotspot", "seed": 0}, {"agent": "random", "seed": 0}],
      "counterbalance": "latin",
      "instructions": "You are the person in the lab ...",
      "questionnaire": [{"id": "understood", "text": "The robot understood where I was.", "scale": 5}],
      "max_steps": 100,
      "reply_timeout": 30
    }

``counterbalance`` is ``"latin"`` (participant ``n`` plays the episodes in row ``n - 1`` of a balanced Latin
square: Williams' design, every episode in every position and, for an even number of episodes, after every other
episode equally often; an odd number uses the design's 2k rows) or ``"none"`` (the plan's order). Only
``episodes`` is required; ``instructions`` and ``questionnaire`` have defaults (:data:`DEFAULT_QUESTIONNAIRE`).

The study folder (``--out``) holds one folder per participant, ``P001``, ``P002``, ... in order::

    <out>/P001/
        plan.json                   the plan as run, with this participant's order
        E01_hotspot_seed0/          one live run folder per episode (recording, metrics, inputs, events, session)
        questionnaire.jsonl         one line per episode: the Likert answers, with wall-clock time
        study.csv                   one row per episode (columns: :data:`CSV_COLUMNS` + one per item)

``embodied-adhoc live summarise STUDY_DIR`` reads every ``study.csv`` and prints per-agent statistics across
participants (each participant's mean per agent, then the mean over participants with a percentile-bootstrap
interval: ``experiments.stats.summarise_sample``).
"""

from __future__ import annotations

import csv
import io
import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from embodied_adhoc import checks
from embodied_adhoc.errors import ConfigError

__all__ = [
    "CSV_COLUMNS",
    "DEFAULT_QUESTIONNAIRE",
    "StudyPlan",
    "episode_row",
    "latin_order",
    "load_plan",
    "next_study_participant",
    "summarise_study",
]

AGENTS = ("hotspot", "known-task", "oracle", "random", "atpo", "bopa")
MAX_PLAN_CHARS = 100_000
DEFAULT_INSTRUCTIONS = (
    "You are the person in the toxic-waste lab (green, seen from above). Walk with the arrow keys or WASD, pick up "
    "a ball on the floor with E or Space, and drop it into the orange robot's container with E or Space when the "
    "robot is in your area. The robot does not know where the balls are, nor which ones you collect; it may ask "
    "where you are: answer by typing (the map shows each place's name) or by speaking. Put all three balls into "
    "the container. After each episode a few questions follow."
)
DEFAULT_QUESTIONNAIRE = (
    {"id": "understood", "text": "The robot understood where I was.", "scale": 5},
    {"id": "helpful", "text": "The robot was a helpful teammate.", "scale": 5},
    {"id": "timing", "text": "The robot asked at the right moments.", "scale": 5},
)
CSV_COLUMNS = (
    "participant",
    "position",
    "episode",
    "agent",
    "seed",
    "outcome",
    "success",
    "steps",
    "sim_seconds",
    "wall_seconds",
    "questions",
    "answers",
    "picks",
    "drops",
    "drops_failed",
    "reconnects",
    "folder",
)
STUDY_FOLDER = re.compile(r"^P(\d{3,})$")


@dataclass(frozen=True)
class StudyPlan:
    episodes: tuple[dict, ...]
    counterbalance: str
    instructions: str
    questionnaire: tuple[dict, ...]
    max_steps: int
    reply_timeout: float

    def order(self, participant_number: int) -> list[int]:
        """The episode indices this participant plays, in order."""
        if self.counterbalance == "none":
            return list(range(len(self.episodes)))
        return latin_order(len(self.episodes), participant_number - 1)

    def as_json(self, order: Sequence[int]) -> dict:
        return {
            "episodes": list(self.episodes),
            "counterbalance": self.counterbalance,
            "order": list(order),
            "instructions": self.instructions,
            "questionnaire": list(self.questionnaire),
            "max_steps": self.max_steps,
            "reply_timeout": self.reply_timeout,
        }


def latin_order(k: int, row: int) -> list[int]:
    """Row ``row`` of Williams' balanced Latin square of ``k`` treatments (2k rows when ``k`` is odd: the
    second half reversed), cycled when there are more participants than rows."""
    first, low, high = [0], 1, k - 1
    while len(first) < k:
        first.append(low)
        low += 1
        if len(first) < k:
            first.append(high)
            high -= 1
    rows = [[(entry + r) % k for entry in first] for r in range(k)]
    if k % 2:
        rows += [list(reversed(r)) for r in rows]
    return rows[row % len(rows)]


def load_plan(path: Path) -> StudyPlan:
    """The plan file, checked field by field (one clear line naming the file and field on any error)."""
    text = checks.read_text(path, MAX_PLAN_CHARS, "study plan")
    try:
        raw = json.loads(text)
    except json.JSONDecodeError as error:
        raise ConfigError(
            f"{path}:{error.lineno}: not JSON ({error.msg}); see docs/live.md#study-mode"
        ) from None
    if not isinstance(raw, dict):
        raise ConfigError(f'{path}: the plan must be a JSON object with an "episodes" list')
    where = str(path)
    checks.refuse_unknown(
        where,
        raw,
        ("episodes", "counterbalance", "instructions", "questionnaire", "max_steps", "reply_timeout"),
        "field",
    )
    episodes = raw.get("episodes")
    if not isinstance(episodes, list) or not 1 <= len(episodes) <= 50:
        raise ConfigError(f'{where}: "episodes" must be a list of 1-50 {{"agent", "seed"}} objects')
    checked = []
    for index, episode in enumerate(episodes):
        name = f"{where}: episodes[{index}]"
        if not isinstance(episode, dict):
            raise ConfigError(f'{name} must be an object like {{"agent": "hotspot", "seed": 0}}')
        checks.refuse_unknown(name, episode, ("agent", "seed"), "field")
        agent = episode.get("agent", "hotspot")
        if not isinstance(agent, str) or not agent:
            raise ConfigError(
                f"{name}.agent must be an agent name or a plug-in spec (docs/plugins.md), not {agent!r}"
            )
        # a plug-in: an unknown name or an unimportable module stops here, before any work
        if agent not in AGENTS:
            from embodied_adhoc.experiments.domains.toxic_waste import DOMAIN
            from embodied_adhoc.experiments.registry import agent_plugin

            agent_plugin(DOMAIN, agent, f"{name}.agent")
        seed = checks.integer(f"{name}.seed", episode.get("seed", 0), 0, 2**31 - 1)
        checked.append({"agent": agent, "seed": seed})
    counterbalance = checks.choice(
        f"{where}: counterbalance", raw.get("counterbalance", "latin"), ("latin", "none")
    )
    instructions = raw.get("instructions", DEFAULT_INSTRUCTIONS)
    if not isinstance(instructions, str) or not 0 < len(instructions) <= 5000:
        raise ConfigError(f'{where}: "instructions" must be a text of 1-5000 characters')
    items = raw.get("questionnaire", list(DEFAULT_QUESTIONNAIRE))
    if not isinstance(items, list) or len(items) > 20:
        raise ConfigError(f'{where}: "questionnaire" must be a list of at most 20 items')
    questionnaire, seen = [], set()
    for index, item in enumerate(items):
        name = f"{where}: questionnaire[{index}]"
        if not isinstance(item, dict):
            raise ConfigError(f'{name} must be an object like {{"id": "helpful", "text": "...", "scale": 5}}')
        checks.refuse_unknown(name, item, ("id", "text", "scale"), "field")
        identifier, text_ = item.get("id"), item.get("text")
        if not isinstance(identifier, str) or not re.fullmatch(r"[a-z][a-z0-9_]{0,31}", identifier):
            raise ConfigError(f"{name}.id: use 1-32 lower-case letters, digits or '_' (a CSV column name)")
        if identifier in seen or identifier in CSV_COLUMNS:
            raise ConfigError(f"{name}.id {identifier!r} is used twice or names a study.csv column")
        if not isinstance(text_, str) or not 0 < len(text_) <= 300:
            raise ConfigError(f"{name}.text must be a statement of 1-300 characters")
        scale = checks.integer(f"{name}.scale", item.get("scale", 5), 3, 11)
        seen.add(identifier)
        questionnaire.append({"id": identifier, "text": text_, "scale": scale})
    return StudyPlan(
        episodes=tuple(checked),
        counterbalance=counterbalance,
        instructions=instructions,
        questionnaire=tuple(questionnaire),
        max_steps=checks.integer(f"{where}: max_steps", raw.get("max_steps", 100), 1, 10_000),
        reply_timeout=checks.number(
            f"{where}: reply_timeout", raw.get("reply_timeout", 30.0), 0.0, 600.0, low_open=True
        ),
    )


def next_study_participant(out: Path) -> tuple[str, int]:
    """The next participant folder name (``P001``, ...) of a study folder, with its number."""
    numbers = [int(m.group(1)) for p in out.glob("P*") if (m := STUDY_FOLDER.match(p.name)) and p.is_dir()]
    number = max(numbers, default=0) + 1
    return f"P{number:03d}", number


def check_answers(plan: StudyPlan, answers) -> dict[str, int]:
    """The questionnaire answers of one page message: every item answered on its scale."""
    if not isinstance(answers, dict):
        raise ConfigError('"answers" must be an object of item id -> rating')
    checks.refuse_unknown("questionnaire", answers, [item["id"] for item in plan.questionnaire], "item")
    checked = {}
    for item in plan.questionnaire:
        if item["id"] not in answers:
            raise ConfigError(f"questionnaire: please answer {item['text']!r}")
        checked[item["id"]] = checks.integer(
            f"questionnaire.{item['id']}", answers[item["id"]], 1, item["scale"]
        )
    return checked


def episode_row(participant: str, position: int, episode: int, spec: dict, session, answers: dict) -> dict:
    """One ``study.csv`` row from a finished live session (its metrics and events log) and the answers."""
    events = session.events()
    metrics = {} if session.outcome is None else session.outcome.metrics
    outcome = metrics.get("outcome", "error" if session.error else "interrupted")
    walls = [e["wall_time"] for e in events]
    drops = [e for e in events if e["kind"] == "drop"]
    return {
        "participant": participant,
        "position": position,
        "episode": episode,
        "agent": spec["agent"],
        "seed": spec["seed"],
        "outcome": outcome,
        "success": int(outcome == "success"),
        "steps": metrics.get("steps", ""),
        "sim_seconds": metrics.get("sim_time_s", ""),
        "wall_seconds": round(max(walls) - min(walls), 1) if walls else "",
        "questions": sum(e["kind"] == "question" for e in events),
        "answers": sum(e["kind"] == "reply" and e.get("result") == "answered" for e in events),
        "picks": sum(e["kind"] == "pick" and e["succeeded"] for e in events),
        "drops": sum(d["succeeded"] for d in drops),
        "drops_failed": sum(not d["succeeded"] for d in drops),
        "reconnects": sum(e["kind"] == "reconnected" for e in events),
        "folder": session.folder.name,
        **answers,
    }


def write_csv(path: Path, rows: list[dict], items: Sequence[str]) -> None:
    from embodied_adhoc.atomic import atomic_write_text

    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=[*CSV_COLUMNS, *items], lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    atomic_write_text(path, buffer.getvalue())


SUMMARY_METRICS = ("success", "steps", "sim_seconds", "questions", "drops_failed")


def summarise_study(folder: Path) -> str:
    """Per-agent statistics across participants (module docstring) as a text table."""
    from embodied_adhoc.experiments.stats import summarise_sample

    files = sorted(folder.glob("P*/study.csv"))
    if not files:
        raise ConfigError(
            f"{folder}: no P###/study.csv here; give the --out folder of `live toxic-waste --study`"
        )
    rows, items = [], []
    for path in files:
        with open(path, encoding="utf-8", newline="") as stream:
            reader = csv.DictReader(stream)
            extra = [name for name in reader.fieldnames or () if name not in CSV_COLUMNS]
            items += [name for name in extra if name not in items]
            rows += list(reader)
    metrics = [*SUMMARY_METRICS, *items]
    per_agent: dict[str, dict[str, dict[str, list[float]]]] = {}
    for row in rows:
        by_participant = per_agent.setdefault(row["agent"], {}).setdefault(row["participant"], {})
        for metric in metrics:
            if row.get(metric) not in (None, ""):
                by_participant.setdefault(metric, []).append(float(row[metric]))
    lines = [
        f"{len(rows)} episodes of {len({r['participant'] for r in rows})} participants in {folder}",
        "per agent: the mean over participants of each participant's mean, 95 % percentile-bootstrap interval",
        f"{'agent':<12} {'metric':<14} {'participants':>12} {'mean':>9}   95 % CI",
    ]
    for agent in sorted(per_agent):
        for metric in metrics:
            means = [sum(v[metric]) / len(v[metric]) for v in per_agent[agent].values() if v.get(metric)]
            if not means:
                continue
            summary = summarise_sample(means)
            interval = "—" if summary.n < 2 else f"[{summary.ci_low:.2f}, {summary.ci_high:.2f}]"
            lines.append(f"{agent:<12} {metric:<14} {summary.n:>12} {summary.mean:>9.2f}   {interval}")
    return "\n".join(lines)


class StudyRun:
    """One participant's pass through a plan: which episode comes next, the questionnaire answers, the files."""

    def __init__(self, plan: StudyPlan, out: Path, participant: str | None = None):
        from embodied_adhoc.atomic import atomic_write_text

        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        name, number = next_study_participant(out)
        if participant is not None:
            if not re.fullmatch(r"[A-Za-z0-9-]{1,32}", participant):
                raise ConfigError(f"--participant {participant!r}: use 1-32 letters, digits or '-'")
            name = participant
        self.plan, self.participant, self.number = plan, name, number
        self.folder = out / name
        self.folder.mkdir(exist_ok=False)
        self.order = plan.order(number)
        self.position = 0  # index into order of the episode being played
        self.rows: list[dict] = []
        atomic_write_text(self.folder / "plan.json", json.dumps(plan.as_json(self.order), indent=2) + "\n")

    @property
    def complete(self) -> bool:
        return self.position >= len(self.order)

    def current(self) -> tuple[int, dict]:
        episode = self.order[self.position]
        return episode, self.plan.episodes[episode]

    def settings(self, base):
        """The live settings of the current episode: the study's participant, folder and the plan's episode."""
        from dataclasses import replace

        episode, spec = self.current()
        return replace(
            base,
            agent=spec["agent"],
            seed=spec["seed"],
            out=self.folder,
            participant=self.participant,
            run_name=f"E{self.position + 1:02d}_{spec['agent']}_seed{spec['seed']}",
            max_steps=self.plan.max_steps,
            reply_timeout=self.plan.reply_timeout,
        )

    def page_info(self) -> dict:
        return {
            "instructions": self.plan.instructions,
            "questionnaire": list(self.plan.questionnaire),
            "position": min(self.position, len(self.order) - 1) + 1,
            "of": len(self.order),
            "complete": self.complete,
        }

    def record(self, session, answers) -> None:
        """The questionnaire of the finished episode: appended to ``questionnaire.jsonl``, its row written to
        ``study.csv``; then the next episode is due."""
        from embodied_adhoc.atomic import atomic_write_text

        checked = check_answers(self.plan, answers)
        episode, spec = self.current()
        self.rows.append(episode_row(self.participant, self.position + 1, episode, spec, session, checked))
        lines = [
            json.dumps(
                {
                    **{k: r[k] for k in ("position", "episode", "agent", "seed")},
                    "answers": {item["id"]: r[item["id"]] for item in self.plan.questionnaire},
                }
            )
            for r in self.rows
        ]
        atomic_write_text(self.folder / "questionnaire.jsonl", "".join(line + "\n" for line in lines))
        write_csv(self.folder / "study.csv", self.rows, [item["id"] for item in self.plan.questionnaire])
        self.position += 1
