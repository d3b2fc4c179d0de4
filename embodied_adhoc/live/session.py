"""One live study session: a participant plays the human of the real-time lab while the robot's agent helps.

:class:`LiveSession` owns the simulation thread (the real-time episode of ``live.episode`` with a
``live.humans.Participant``), the latest overhead frame (JPEG, rendered on the simulation thread at
``stream_fps`` wall frames per second), the events the page shows (the robot's question with its spoken audio,
each step's observation and task posterior, the outcome) and the run folder::

    <out>/<participant>_<UTC time>/
        episode.rrd, episode.mp4, metrics.json   the recording of ``run toxic-waste --record`` (same observers)
        inputs.jsonl                             every participant input as applied in the simulation
        replies/reply-001.wav ...                the audio of each spoken reply, as received
        session.json                             participant id, settings, message counts, latency figures

The participant id is anonymous: ``P001``, ``P002``, ... in order of the folders already in ``<out>`` (no name,
address or browser detail is stored). Every file name is made here; nothing a client sends becomes a path.
Replies are recognised here too (:meth:`reply_from_text`, :meth:`reply_from_audio`), off the simulation thread.
"""

from __future__ import annotations

import io
import json
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from embodied_adhoc import checks
from embodied_adhoc.atomic import atomic_write_bytes, atomic_write_text
from embodied_adhoc.comms.synthesis import wav_bytes
from embodied_adhoc.episodes.loop import EpisodeObserver, StepRecord
from embodied_adhoc.episodes.presenters import action_label, describe_observation
from embodied_adhoc.errors import ConfigError, SpeechError
from embodied_adhoc.experiments.recorded import EpisodeConfig
from embodied_adhoc.live.humans import Participant, Reply, heard_line

__all__ = ["FRAME_READY", "LiveSession", "LiveSettings", "next_participant_id"]

PARTICIPANT_PATTERN = re.compile(r"^P(\d{3,})_")
SAMPLE_RATE = 16_000  # the recogniser's rate (comms.recognition)
MAX_REPLY_SECONDS = 15.0
MAX_TEXT = 200
QUESTION_INTERVAL = 8.0  # s after an answer before the robot asks again, unless its belief moved
BELIEF_SHIFT = (
    0.25  # change of a task's probability since the last answer that lets a question through at once
)
HISTORY = 200  # page events kept for a page that reconnects
FRAME_READY = {"type": "frame"}
"""Published (not sent) when a new frame is ready: the server then sends the latest state and frame."""


@dataclass(frozen=True)
class LiveSettings:
    """What ``embodied-adhoc live toxic-waste`` runs (its flags map one to one)."""

    agent: str = "hotspot"
    seed: int = 0
    out: Path = Path("runs/live")
    participant: str | None = None  # None: the next free P### in ``out``
    speed: float = 1.0
    reply_timeout: float = 30.0
    max_steps: int = 100
    stream_fps: float = 10.0
    question_interval: float = QUESTION_INTERVAL
    run_name: str | None = None  # the run folder's name (a study's episodes); None: <participant>_<UTC time>
    width: int = 640
    height: int = 480


def next_participant_id(out: Path) -> str:
    """``P001`` for an empty study folder, else one more than the highest ``P###`` run folder in it."""
    numbers = [int(m.group(1)) for p in out.glob("P*_*") if (m := PARTICIPANT_PATTERN.match(p.name))]
    return f"P{max(numbers, default=0) + 1:03d}"


class _PageObserver(EpisodeObserver):
    """Turns the episode loop's hooks into page events (on the simulation thread)."""

    def __init__(self, session: LiveSession):
        self.session = session

    def episode_started(self, info: dict, task_posterior) -> None:
        self.session.posterior = None if task_posterior is None else task_posterior.tolist()
        self.session.publish(
            {"type": "started", "posterior": self.session.posterior, "tasks": self.session.tasks}
        )

    def action_chosen(self, step: int, action: int) -> None:
        session = self.session
        env = session.episode.env
        session.action = action_label(env.library, action, env.move_target(action))
        session.step = step

    def step_finished(self, record: StepRecord) -> None:
        session = self.session
        if record.task_posterior is not None:
            session.posterior = record.task_posterior.tolist()
        if record.action == session.episode.env.library.locate_action:
            session.posterior_at_answer = session.posterior
        session.publish(
            {
                "type": "step",
                "step": record.step,
                "action": session.action,
                "observation": describe_observation(session.episode.env.library, record.observation_index),
                "utterances": list(record.info["utterances"]),
                "posterior": session.posterior,
                "balls": list(record.info["ball_status"]),
            }
        )

    def episode_finished(self, trace) -> None:
        outcome = "success" if trace.success else "truncated"
        session = self.session
        sim_time = round(float(session.episode.env.world.data.time), 1)
        session.publish({"type": "done", "outcome": outcome, "steps": trace.steps, "sim_time": sim_time})


class LiveSession:
    """See the module docstring. ``publish`` (set by the server) delivers ``(event, binary)`` to the page."""

    def __init__(self, settings: LiveSettings, publish: Callable[[dict, bytes | None], None] | None = None):
        from embodied_adhoc.comms.robot_speech import WHERE_ARE_YOU, speak
        from embodied_adhoc.comms.synthesis import SAMPLE_RATE as TTS_RATE

        self.settings = settings
        out = Path(settings.out)
        out.mkdir(parents=True, exist_ok=True)
        participant = settings.participant or next_participant_id(out)
        if not re.fullmatch(r"[A-Za-z0-9-]{1,32}", participant):
            raise ConfigError(
                f"--participant {participant!r}: use 1-32 letters, digits or '-' (an anonymous code, no names)"
            )
        self.participant_id = participant
        stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
        self.folder = out / (settings.run_name or f"{participant}_{stamp}")
        self.folder.mkdir(parents=True, exist_ok=False)
        self.started_at = stamp
        self.publish_to_page = publish or (lambda event, binary: None)
        self.person = Participant()
        self.stop = threading.Event()
        self.question_text = WHERE_ARE_YOU
        self.question_wav = wav_bytes(speak(WHERE_ARE_YOU), TTS_RATE)
        self.frame: tuple[int, bytes, dict] | None = None  # (sequence, JPEG, state)
        self.frame_lock = threading.Lock()
        self.posterior: list[float] | None = None
        self.action, self.step = "", 0
        self.replies: list[dict] = []
        self.counters = {"messages": 0, "rate_limited": 0, "refused": 0}
        self.frame_intervals: list[float] = []
        self._reply_lock = threading.Lock()
        self._next_frame_wall = 0.0
        self._frame_seq = 0
        self._last_xy = None
        self.outcome = None
        self.error: str | None = None
        self.done: dict | None = None
        self.posterior_at_answer: list[float] | None = None
        self.history: list[dict] = []  # the page's events so far (a reconnecting page replays them)
        self.notes: list[dict] = []  # connections, from the server's threads
        self._history_lock = threading.Lock()
        self._balls: tuple[str, ...] | None = None
        config = EpisodeConfig(
            agent=settings.agent,
            seed=settings.seed,
            max_steps=settings.max_steps,
            record_dir=self.folder,
            width=settings.width,
            height=settings.height,
            # real time: the video plays at the speed the participant lived it, at run --record's frame rate
            # (EpisodeConfig.video_fps: one setting for every recorded episode)
            video_speed=1.0,
        )
        from embodied_adhoc.live.episode import open_realtime_episode

        self.episode = open_realtime_episode(
            config,
            human=self.person,
            speed=settings.speed,
            reply_timeout=settings.reply_timeout,
            tick_listener=self._on_tick,
            stop=self.stop,
        )
        self.tasks = [list(task) for task in self.episode.session.library.tasks]
        env = self.episode.env
        env.question_interval = checks.number("question_interval", settings.question_interval, 0.0)
        env.question_gate = self._belief_moved
        self.person.on_event = self._person_event
        self.labels = map_labels(env.layout, settings.width, settings.height)
        self._thread: threading.Thread | None = None

    # ------------------------------------------------------------------ lifecycle
    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> bool:
        """Start the episode (once); False if it was already started."""
        if self._thread is not None:
            return False
        self._thread = threading.Thread(target=self._run, name="live-simulation", daemon=True)
        self._thread.start()
        return True

    def _run(self) -> None:
        from embodied_adhoc.live.episode import run_realtime_episode

        try:
            self.outcome = run_realtime_episode(self.episode, [_PageObserver(self)])
        except Exception as error:  # the page must learn why the simulation stopped; the files are kept
            self.error = f"{type(error).__name__}: {error}"
            self.publish({"type": "error", "message": f"simulation stopped: {self.error}"})
        finally:
            self._write_logs()

    def close(self, timeout: float = 30.0) -> None:
        """Stop the simulation (the episode ends as interrupted if unfinished) and write the logs."""
        self.stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
        else:
            self.episode.env.close()
            self._write_logs()

    def publish(self, event: dict, binary: bytes | None = None) -> None:
        if event is not FRAME_READY:
            with self._history_lock:
                self.history.append(event)
                del self.history[:-HISTORY]
            if event.get("type") == "done":
                self.done = event
        self.publish_to_page(event, binary)

    def restore(self) -> dict:
        """What a (re)connecting page needs to show the session as it is: the events so far, the latest state."""
        with self._history_lock:
            history = list(self.history)
        with self.frame_lock:
            state = None if self.frame is None else self.frame[2]
        return {"history": history, "state": state, "posterior": self.posterior, "done": self.done}

    def note(self, kind: str, **detail) -> None:
        """A session event from a server thread (a page connected, left, came back) for the events log."""
        with self.frame_lock:
            sim_time = None if self.frame is None else self.frame[2]["sim_time"]
        with self._history_lock:
            self.notes.append(
                {"kind": kind, "sim_time": sim_time, "wall_time": round(time.time(), 3), **detail}
            )

    # ------------------------------------------------------------------ the robot's questions (simulation thread)
    def _belief_moved(self) -> bool:
        """Whether the task posterior moved by ``BELIEF_SHIFT`` since the last answer (a new question is due)."""
        now, then = self.posterior, self.posterior_at_answer
        if now is None or then is None:
            return False
        return max(abs(a - b) for a, b in zip(now, then, strict=True)) >= BELIEF_SHIFT

    def _person_event(self, entry: dict) -> None:
        if entry["kind"] == "question":
            self.publish(
                {
                    "type": "question",
                    "step": self.step,
                    "text": self.question_text,
                    "sim_time": entry["sim_time"],
                },
                self.question_wav,
            )
        else:  # a pick or a drop finished: say how it went
            self.publish(
                {"type": "outcome", **{k: entry[k] for k in ("kind", "ball", "result", "succeeded")}}
            )

    # ------------------------------------------------------------------ frames (simulation thread)
    def _on_tick(self, env) -> None:
        now = time.perf_counter()
        if now < self._next_frame_wall:
            return
        from PIL import Image

        period = 1.0 / self.settings.stream_fps
        self._next_frame_wall = (
            max(now, self._next_frame_wall + period) if self._next_frame_wall else now + period
        )
        image = Image.fromarray(env.render_camera("overhead"))
        draw_labels(image, self.labels)
        buffer = io.BytesIO()
        image.save(buffer, format="JPEG", quality=70)
        truth = env.world.ground_truth()
        walker = env.world.human
        if truth.ball_states != self._balls:  # the ball-state timeline of the events log
            self._balls = truth.ball_states
            self.person.note(env, "balls", states=list(truth.ball_states))
        state = {
            "sim_time": round(truth.time, 2),
            "human": [round(truth.human_pose[0], 3), round(truth.human_pose[1], 3)],
            "robot": [round(truth.robot_pose[0], 3), round(truth.robot_pose[1], 3)],
            "robot_node": env.true_robot_node(truth),
            "ball_xy": [[round(p[0], 3), round(p[1], 3)] for p in truth.ball_positions],
            "human_node": truth.human_node,
            "holding": walker.holding,
            "busy": not walker.finished,
            "balls": [{"ground": 0, "held": 1, "container": 2}[s] for s in truth.ball_states],
            "ack": self.person.last_seq,
            "notice": self.person.notice,
            "question_open": self.person.question_open,
            "action": self.action,
            "step": self.step,
            "posterior": self.posterior,
            "slip_s": round(env.clock.slipped, 3),
        }
        with self.frame_lock:
            self._frame_seq += 1
            self.frame = (self._frame_seq, buffer.getvalue(), state)
        self.publish(FRAME_READY)  # the page gets it now, not at the next tick of a timer of its own

    # ------------------------------------------------------------------ replies (server threads)
    def reply_from_text(self, text: str, seq: int) -> dict:
        from embodied_adhoc.comms.parsing import parse

        if not isinstance(text, str) or not 0 < len(text) <= MAX_TEXT or not text.isprintable():
            raise ConfigError(f"typed reply must be 1-{MAX_TEXT} printable characters")
        result = parse(text)
        lines = (
            f'robot: "{self.question_text}"',
            f'participant typed: "{text}"',
            heard_line(result.node, "typed"),
        )
        detail = {"reply": "typed", "text": text, "place": result.place, "node": result.node}
        self.person.answer(Reply(result.node, lines, None), seq, detail)
        return detail

    def reply_from_audio(self, data: bytes, seq: int, max_bytes: int) -> dict:
        """Decode a WAV reply (mono or stereo, any rate up to 48 kHz, at most ``MAX_REPLY_SECONDS``), save it,
        recognise it with the project's offline recogniser and parse the place it names."""
        import soundfile
        from scipy.signal import resample_poly

        from embodied_adhoc.comms.parsing import parse
        from embodied_adhoc.comms.recognition import shared_recognizer

        if len(data) > max_bytes:
            raise ConfigError(f"audio reply of {len(data)} bytes exceeds the {max_bytes}-byte limit")
        try:  # the header first: format, channels, rate and length are checked before anything is decoded
            header = soundfile.info(io.BytesIO(data))
        except (RuntimeError, soundfile.LibsndfileError, ValueError) as error:
            raise ConfigError(f"audio reply is not a readable WAV file ({error})") from None
        if header.format != "WAV":
            raise ConfigError(f"audio reply is {header.format}, not WAV: send 16-bit PCM WAV")
        if header.channels not in (1, 2):
            raise ConfigError(f"audio reply has {header.channels} channels; send mono or stereo")
        rate = int(header.samplerate)
        if not 8_000 <= rate <= 48_000:
            raise ConfigError(f"audio reply sample rate {rate} Hz outside 8000..48000")
        cap = int(MAX_REPLY_SECONDS * rate)
        if header.frames > cap:
            raise ConfigError(f"audio reply of {header.frames / rate:.1f} s exceeds {MAX_REPLY_SECONDS:g} s")
        try:  # at most one sample more than allowed is decoded, whatever the header claimed
            audio, _ = soundfile.read(io.BytesIO(data), frames=cap + 1, dtype="float32", always_2d=True)
        except (RuntimeError, soundfile.LibsndfileError, ValueError) as error:
            raise ConfigError(f"audio reply is not a readable WAV file ({error})") from None
        if audio.shape[0] > cap:
            raise ConfigError(f"audio reply exceeds {MAX_REPLY_SECONDS:g} s")
        mono = audio.mean(axis=1)
        if rate != SAMPLE_RATE:
            divisor = np.gcd(int(rate), SAMPLE_RATE)
            mono = resample_poly(mono, SAMPLE_RATE // divisor, int(rate) // divisor).astype(np.float32)
        with self._reply_lock:  # one decoder, one reply at a time
            number = len(self.replies) + 1
            path = self.folder / "replies" / f"reply-{number:03d}.wav"
            path.parent.mkdir(exist_ok=True)
            atomic_write_bytes(path, data)
            try:
                transcript = shared_recognizer().transcribe(mono)
            except SpeechError as error:
                transcript, detail_error = "", str(error)
            else:
                detail_error = None
            result = parse(transcript)
            detail = {
                "reply": "spoken",
                "file": str(path.relative_to(self.folder)),
                "seconds": round(len(mono) / SAMPLE_RATE, 2),
                "transcript": transcript,
                "place": result.place,
                "node": result.node,
            }
            if detail_error:
                detail["error"] = detail_error
            self.replies.append(detail)
        lines = (
            f'robot: "{self.question_text}"',
            f"participant spoke ({detail['file']})",
            f'recognised: "{transcript}"',
            heard_line(result.node, "spoken"),
        )
        self.person.answer(Reply(result.node, lines, wav_bytes(mono, SAMPLE_RATE)), seq, detail)
        return detail

    # ------------------------------------------------------------------ study log
    def events(self) -> list[dict]:
        """The events log: inputs, picks and drops with outcomes, questions, answers, ball states and
        connections, in wall-clock order."""
        with self._history_lock:
            notes = list(self.notes)
        return sorted([*self.person.log.entries, *notes], key=lambda entry: entry["wall_time"])

    def _write_logs(self) -> None:
        entries = "".join(json.dumps(entry) + "\n" for entry in self.person.log.entries)
        atomic_write_text(self.folder / "inputs.jsonl", entries)
        events = "".join(json.dumps(entry) + "\n" for entry in self.events())
        atomic_write_text(self.folder / "events.jsonl", events)
        motion = self.person.log.motion_latency_s
        intervals = np.array(self.frame_intervals) if self.frame_intervals else None
        summary = {
            "participant": self.participant_id,
            "started_utc": self.started_at,
            "settings": {k: str(v) if isinstance(v, Path) else v for k, v in vars(self.settings).items()},
            "outcome": None if self.outcome is None else self.outcome.metrics.get("outcome"),
            "error": self.error,
            "replies": self.replies,
            "messages": dict(self.counters),
            "latency": {
                "key_to_motion_in_simulation_ms": _stats(np.array(motion) * 1000) if motion else None,
                "frame_interval_sent_ms": None if intervals is None else _stats(intervals * 1000),
            },
        }
        atomic_write_text(self.folder / "session.json", json.dumps(summary, indent=2) + "\n")


def _stats(values: np.ndarray) -> dict:
    return {
        "n": int(values.size),
        "mean": round(float(values.mean()), 2),
        "p50": round(float(np.percentile(values, 50)), 2),
        "p95": round(float(np.percentile(values, 95)), 2),
        "max": round(float(values.max()), 2),
    }


def map_labels(layout, width: int, height: int) -> list[tuple[str, tuple[int, int]]]:
    """Each area's name as the recogniser understands it (``comms.vocabulary.NODE_NAMES``) at the pixel of its
    polygon's centroid in the overhead camera (``scenes/lab.xml``: orthographic, 8.2 m tall, centred at 0, 0)."""
    from embodied_adhoc.comms.vocabulary import NODE_NAMES

    view_height = OVERHEAD_VIEW_HEIGHT
    view_width = view_height * width / height
    labels = []
    for node, polygon in enumerate(layout.area_polygons):
        x, y = np.asarray(polygon, dtype=float).mean(axis=0)
        pixel = (int(round((x / view_width + 0.5) * width)), int(round((0.5 - y / view_height) * height)))
        labels.append((NODE_NAMES[node], pixel))
    return labels


OVERHEAD_VIEW_HEIGHT = 8.2  # m: the overhead camera's orthographic fovy


def draw_labels(image, labels) -> None:
    """The area names on the streamed frame, white on a dark box so they read on every floor colour."""
    from PIL import ImageDraw, ImageFont

    draw = ImageDraw.Draw(image)
    font = ImageFont.load_default(size=max(12, image.height // 32))
    for text, (x, y) in labels:
        left, top, right, bottom = draw.textbbox((x, y), text, font=font, anchor="mm")
        draw.rectangle((left - 4, top - 3, right + 4, bottom + 3), fill=(20, 20, 20))
        draw.text((x, y), text, font=font, anchor="mm", fill=(255, 255, 255))
