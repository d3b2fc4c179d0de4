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

from embodied_adhoc.atomic import atomic_write_bytes, atomic_write_text
from embodied_adhoc.errors import ConfigError, SpeechError
from embodied_adhoc.experiments.episode import EpisodeObserver, StepRecord
from embodied_adhoc.experiments.recorded_episode import EpisodeConfig, action_label, describe_observation
from embodied_adhoc.live.humans import Participant, Reply, heard_line

__all__ = ["FRAME_READY", "LiveSession", "LiveSettings", "next_participant_id"]

PARTICIPANT_PATTERN = re.compile(r"^P(\d{3,})_")
SAMPLE_RATE = 16_000  # the recogniser's rate (comms.recognition)
MAX_REPLY_SECONDS = 15.0
MAX_TEXT = 200
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
    width: int = 640
    height: int = 480


def next_participant_id(out: Path) -> str:
    """``P001`` for an empty study folder, else one more than the highest ``P###`` run folder in it."""
    numbers = [int(m.group(1)) for p in out.glob("P*_*") if (m := PARTICIPANT_PATTERN.match(p.name))]
    return f"P{max(numbers, default=0) + 1:03d}"


def wav_bytes(audio: np.ndarray, sample_rate: int) -> bytes:
    import soundfile

    buffer = io.BytesIO()
    soundfile.write(
        buffer, np.asarray(audio, dtype=np.float32), int(sample_rate), format="WAV", subtype="PCM_16"
    )
    return buffer.getvalue()


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
        if action == env.library.locate_action:
            session.publish(
                {"type": "question", "step": step, "text": session.question_text}, session.question_wav
            )

    def step_finished(self, record: StepRecord) -> None:
        session = self.session
        if record.task_posterior is not None:
            session.posterior = record.task_posterior.tolist()
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
        self.session.publish({"type": "done", "outcome": outcome, "steps": trace.steps})


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
        self.folder = out / f"{participant}_{stamp}"
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
        self.publish_to_page(event, binary)

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
        image = env.render_camera("overhead")
        buffer = io.BytesIO()
        Image.fromarray(image).save(buffer, format="JPEG", quality=70)
        truth = env.world.ground_truth()
        walker = env.world.human
        state = {
            "sim_time": round(truth.time, 2),
            "human": [round(truth.human_pose[0], 3), round(truth.human_pose[1], 3)],
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
        try:
            audio, rate = soundfile.read(io.BytesIO(data), dtype="float32", always_2d=True)
        except (RuntimeError, soundfile.LibsndfileError, ValueError) as error:
            raise ConfigError(f"audio reply is not a readable WAV file ({error})") from None
        if not 8_000 <= rate <= 48_000:
            raise ConfigError(f"audio reply sample rate {rate} Hz outside 8000..48000")
        if audio.shape[0] > MAX_REPLY_SECONDS * rate:
            raise ConfigError(f"audio reply of {audio.shape[0] / rate:.1f} s exceeds {MAX_REPLY_SECONDS:g} s")
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
    def _write_logs(self) -> None:
        entries = "".join(json.dumps(entry) + "\n" for entry in self.person.log.entries)
        atomic_write_text(self.folder / "inputs.jsonl", entries)
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
