"""A thin episode recorder over rerun-sdk 0.41: one ``rr.RecordingStream`` saved to ``episode.rrd``.

No viewer is spawned and nothing touches the global recording; open the file afterwards with
``rerun episode.rrd`` (the ``rerun`` binary ships in the rerun-sdk wheel). A default blueprint (3D lab view,
belief bars, entropy plot, text logs, camera) is stored in the file.

Entity paths (the documented contract; ``tests/record`` reads them back):

===============================  =================  ==========================================================
entity                           archetype          content
===============================  =================  ==========================================================
``world/lab/outline``            LineStrips3D       lab walls outline (static)
``world/lab/areas``              LineStrips3D       one closed polygon per area, labelled (static)
``world/lab/waypoints``          Points3D           node waypoints, labelled with node index and name (static)
``world/lab/edges``              LineStrips3D       topological graph edges between waypoints (static)
``world/robot``                  Transform3D        ground-truth robot pose (x, y, yaw)
``world/robot/body``             Boxes3D            robot footprint (static, in the robot frame)
``world/human``                  Points3D           ground-truth human position
``world/balls``                  Points3D           ball positions, coloured and labelled
``world/odometry``               Points3D           dead-reckoning (odometry) robot position
``world/tracks/ground_truth``    LineStrips3D       ground-truth robot track so far (updated at each macro step)
``world/tracks/odometry``        LineStrips3D       odometry track so far (beside the ground truth; each step)
``world/localisation/estimate``  Points3D           the localiser's pose estimate (what the controller tracks)
``world/localisation/particles`` Points3D           the localiser's particle cloud (at the camera rate)
``belief/task``                  BarChart           task posterior over the task library
``belief/entropy``               Scalars            normalised entropy of the task posterior
``metrics/odometry_error``       Scalars            distance between odometry and ground-truth position (m)
``log/observations``             TextLog            decoded observation after each macro step
``log/actions``                  TextLog            macro action chosen at each step
``log/utterances``               TextLog            robot and human speech (question, transcript, reply)
``log/events``                   TextLog            episode events (RFID reads, task identified, outcome)
``speech/audio``                 AssetAudio         WAV of the human's reply (``speech="audio"`` only)
``camera/<name>``                EncodedImage       JPEG camera frames (``camera/overhead``, ``camera/robot``)
===============================  =================  ==========================================================

Timelines: ``step`` (macro step, sequence) and ``sim_time`` (simulated seconds, duration).

Batching: per-frame poses (robot, odometry, human, balls, odometry error) and the localiser's estimate and
particle clouds are buffered and sent as columns (``send_columns``), their colours and sizes logged once
(static); everything else is logged row by row and compacted by the SDK's batcher, which flushes by size only
(no 200 ms wall-clock tick). An episode's file thus holds one or two chunks per entity, not one per row.
Camera frames are JPEG-encoded on a worker thread (``record.worker``) and sent as columns too, every
``IMAGE_BATCH`` images and on close.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from datetime import timedelta
from pathlib import Path

import numpy as np

from embodied_adhoc.atomic import publish, temporary_sibling
from embodied_adhoc.record.worker import BackgroundWorker

ENTITY_PATHS: tuple[str, ...] = (
    "world/lab/outline",
    "world/lab/areas",
    "world/lab/waypoints",
    "world/lab/edges",
    "world/robot",
    "world/robot/body",
    "world/human",
    "world/balls",
    "world/odometry",
    "world/tracks/ground_truth",
    "world/tracks/odometry",
    "world/localisation/estimate",
    "world/localisation/particles",
    "belief/task",
    "belief/entropy",
    "metrics/odometry_error",
    "log/observations",
    "log/actions",
    "log/utterances",
    "log/events",
    "speech/audio",
    "camera",
)
TEXT_CHANNELS = ("observations", "actions", "utterances", "events")
FRAME_BATCH = 1024
"""Per-frame poses are buffered and sent as columns at least this often (bounds the buffer)."""
IMAGE_BATCH = 64
"""Camera JPEGs are buffered and sent as columns at least this often (bounds the buffer: ~3 MB at 640x480)."""
BATCH_BYTES = 32 * 1024 * 1024
"""The SDK's batcher flushes row-logged data past this many bytes (bounds its memory)."""
BALL_COLOURS = ((220, 50, 47), (235, 200, 40), (40, 110, 220), (133, 153, 0), (108, 113, 196))
"""Marker colours of balls 0, 1, 2 (red, yellow, blue as in ``scenes/lab.xml``), then extras."""


def _closed_strip(polygon: np.ndarray, z: float) -> np.ndarray:
    points = np.asarray(polygon, dtype=np.float64).reshape(-1, 2)
    closed = np.vstack([points, points[:1]])
    return np.column_stack([closed, np.full(len(closed), z)])


def _default_blueprint():
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(name="lab", origin="/world"),
                rrb.TextLogView(name="log", origin="/log"),
                row_shares=[3, 1],
            ),
            rrb.Vertical(
                rrb.Horizontal(
                    rrb.Spatial2DView(name="overhead camera", origin="/camera/overhead"),
                    rrb.Spatial2DView(name="robot camera", origin="/camera/robot"),
                ),
                rrb.BarChartView(name="task belief", origin="/belief/task"),
                rrb.TimeSeriesView(
                    name="entropy and odometry error", contents=["/belief/entropy", "/metrics/**"]
                ),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


class RerunRecorder:
    """Record one episode into ``path`` (an ``.rrd``), published atomically on :meth:`close`.

    Call :meth:`set_time` before logging each macro step's data; static map data goes through
    :meth:`log_lab`. All ``log_*`` methods take plain numpy data, so the recorder knows nothing of MuJoCo.
    """

    def __init__(self, path: str | Path, recording_name: str = "episode", jpeg_quality: int = 75):
        import rerun as rr

        self._rr = rr
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.jpeg_quality = int(jpeg_quality)
        self._temporary = temporary_sibling(self.path)
        # Row-logged data (text, beliefs, images) is compacted by the SDK's batcher: no time-based flush, only past
        # BATCH_BYTES, so an episode's .rrd holds a few chunks per entity instead of one per 200 ms of wall time.
        batching = rr.ChunkBatcherConfig(flush_tick=timedelta(days=1), flush_num_bytes=BATCH_BYTES)
        self._stream = rr.RecordingStream(
            "embodied-adhoc", make_default=False, make_thread_default=False, batcher_config=batching
        )
        self._stream.set_log_tick_enabled(False)
        self._stream.set_log_time_enabled(False)
        self._stream.save(self._temporary, default_blueprint=_default_blueprint())
        self._stream.send_recording_name(recording_name)
        self._ground_truth_track: list[np.ndarray] = []
        self._odometry_track: list[np.ndarray] = []
        self._frames: list[tuple] = []
        self._estimates: list[tuple] = []  # (step, sim_time, x, y)
        self._clouds: list[tuple] = []  # (step, sim_time, P x 3 points)
        self._localisation_styled = False
        self._ball_style: int | None = None
        self._step, self._sim_time = 0, 0.0
        self._images = BackgroundWorker(self._encode_image, f"rerun images {self.path.name}", max_queued=8)
        self._jpegs: list[tuple] = []  # (camera, step, sim_time, JPEG bytes), filled on the images thread
        self._closed = False

    # -- time ---------------------------------------------------------------------------------------------
    def set_time(self, step: int, sim_time: float) -> None:
        """Position subsequent logs on the ``step`` (macro step) and ``sim_time`` (seconds) timelines."""
        if int(step) != self._step:
            self._log_tracks()  # the tracks of the macro step just finished, at its last time
        self._step, self._sim_time = int(step), float(sim_time)
        self._stream.set_time("step", sequence=self._step)
        self._stream.set_time("sim_time", duration=self._sim_time)

    # -- static map -----------------------------------------------------------------------------------------
    def log_lab(
        self,
        outline: np.ndarray,
        areas: Mapping[str, np.ndarray],
        waypoints: Sequence[tuple[float, float]],
        node_names: Sequence[str],
        edges: Sequence[tuple[int, int]],
        robot_size: tuple[float, float, float] = (0.5, 0.5, 0.4),
    ) -> None:
        """Log the lab map once: outline polygon, area polygons, node waypoints, graph edges, robot footprint."""
        rr = self._rr
        self._stream.log(
            "world/lab/outline",
            rr.LineStrips3D([_closed_strip(outline, 0.0)], colors=[(200, 200, 200)], radii=0.03),
            static=True,
        )
        self._stream.log(
            "world/lab/areas",
            rr.LineStrips3D(
                [_closed_strip(polygon, 0.01) for polygon in areas.values()],
                labels=list(areas.keys()),
                radii=0.015,
            ),
            static=True,
        )
        points = np.array([[x, y, 0.02] for x, y in waypoints])
        labels = [f"{index} {name}" for index, name in enumerate(node_names)]
        self._stream.log("world/lab/waypoints", rr.Points3D(points, labels=labels, radii=0.08), static=True)
        self._stream.log(
            "world/lab/edges",
            rr.LineStrips3D([points[[a, b]] for a, b in edges], colors=[(120, 120, 120)], radii=0.01),
            static=True,
        )
        self._stream.log(
            "world/robot/body",
            rr.Boxes3D(
                sizes=[robot_size],
                centers=[(0.0, 0.0, robot_size[2] / 2)],
                colors=[(90, 90, 100)],
                labels=["robot"],
            ),
            static=True,
        )

    # -- per frame (batched) ------------------------------------------------------------------------------
    def log_poses(
        self,
        robot_pose: Sequence[float],
        odometry_pose: Sequence[float],
        human_position: Sequence[float],
        ball_positions: np.ndarray,
        ball_labels: Sequence[str] | None = None,
    ) -> None:
        """Log ground-truth robot pose (x, y, yaw), odometry pose (x, y, yaw), human (x, y[, z]) and balls (n, 3)
        at the current time. Buffered and sent as one column per entity (``send_columns``) every ``FRAME_BATCH``
        frames and on :meth:`close`; the tracks so far are logged when the macro step changes and on close."""
        if self._ball_style is None:
            self._log_styles(len(np.asarray(ball_positions).reshape(-1, 3)), ball_labels)
        human = np.zeros(3)
        human[: len(human_position)] = human_position
        human[2] = 0.9 if len(human_position) < 3 else human[2]
        balls = np.asarray(ball_positions, dtype=np.float64).reshape(-1, 3)
        if len(balls) != self._ball_style:
            raise ValueError(
                f"log_poses: {len(balls)} ball positions, the recording started with {self._ball_style}"
            )
        self._frames.append(
            (
                self._step,
                self._sim_time,
                tuple(float(v) for v in robot_pose[:3]),
                (float(odometry_pose[0]), float(odometry_pose[1])),
                human,
                balls,
            )
        )
        self._ground_truth_track.append(np.array([robot_pose[0], robot_pose[1], 0.03], dtype=np.float64))
        self._odometry_track.append(np.array([odometry_pose[0], odometry_pose[1], 0.04], dtype=np.float64))
        if len(self._frames) >= FRAME_BATCH:
            self._send_frames()

    def _log_styles(self, n_balls: int, ball_labels: Sequence[str] | None) -> None:
        """Colours, sizes and labels once (static); the per-frame columns carry only positions and poses."""
        rr, log = self._rr, self._stream.log
        self._ball_style = n_balls
        labels = list(ball_labels) if ball_labels is not None else [f"ball {i}" for i in range(n_balls)]
        colours = [BALL_COLOURS[i % len(BALL_COLOURS)] for i in range(n_balls)]
        log("world/balls", rr.Points3D.from_fields(colors=colours, radii=0.06, labels=labels), static=True)
        log("world/odometry", rr.Points3D.from_fields(colors=[(255, 140, 0)], radii=0.07), static=True)
        log(
            "world/human",
            rr.Points3D.from_fields(colors=[(230, 180, 150)], radii=0.25, labels=["human"]),
            static=True,
        )
        for track, colour in (("ground_truth", (0, 170, 0)), ("odometry", (255, 140, 0))):
            log(
                f"world/tracks/{track}", rr.LineStrips3D.from_fields(colors=[colour], radii=0.02), static=True
            )

    def _send_frames(self) -> None:
        """Send the buffered frames as one column per entity."""
        self._send_localisation()
        if not self._frames:
            return
        rr, send = self._rr, self._stream.send_columns
        steps, times, robot, odometry, human, balls = zip(*self._frames, strict=True)
        self._frames = []
        robot, odometry = np.array(robot), np.array(odometry)
        indexes = [
            rr.TimeColumn("step", sequence=np.array(steps)),
            rr.TimeColumn("sim_time", duration=np.array(times)),
        ]
        half_yaw = 0.5 * robot[:, 2]
        zeros = np.zeros(len(robot))
        send(
            "world/robot",
            indexes=indexes,
            columns=rr.Transform3D.columns(
                translation=np.column_stack([robot[:, :2], zeros]),
                quaternion=np.column_stack([zeros, zeros, np.sin(half_yaw), np.cos(half_yaw)]),
            ),
        )
        send(
            "world/odometry",
            indexes=indexes,
            columns=rr.Points3D.columns(positions=np.column_stack([odometry, np.full(len(odometry), 0.05)])),
        )
        send("world/human", indexes=indexes, columns=rr.Points3D.columns(positions=np.array(human)))
        send(
            "world/balls",
            indexes=indexes,
            columns=rr.Points3D.columns(positions=np.concatenate(balls)).partition(
                [self._ball_style] * len(balls)
            ),
        )
        error = np.hypot(robot[:, 0] - odometry[:, 0], robot[:, 1] - odometry[:, 1])
        send("metrics/odometry_error", indexes=indexes, columns=rr.Scalars.columns(scalars=error))

    def _send_localisation(self) -> None:
        """Send the buffered estimates and particle clouds as columns."""
        rr, send = self._rr, self._stream.send_columns

        def indexes(rows):
            return [
                rr.TimeColumn("step", sequence=np.array([row[0] for row in rows])),
                rr.TimeColumn("sim_time", duration=np.array([row[1] for row in rows])),
            ]

        if self._estimates:
            rows, self._estimates = self._estimates, []
            points = np.array([(x, y, 0.05) for _, _, x, y in rows])
            send(
                "world/localisation/estimate",
                indexes=indexes(rows),
                columns=rr.Points3D.columns(positions=points),
            )
        if self._clouds:
            rows, self._clouds = self._clouds, []
            send(
                "world/localisation/particles",
                indexes=indexes(rows),
                columns=rr.Points3D.columns(positions=np.concatenate([row[2] for row in rows])).partition(
                    [len(row[2]) for row in rows]
                ),
            )

    def _log_tracks(self) -> None:
        """The ground-truth and odometry tracks so far, one row each at the current time."""
        if len(self._ground_truth_track) >= 2:
            for name, track in (
                ("ground_truth", self._ground_truth_track),
                ("odometry", self._odometry_track),
            ):
                self._stream.log(
                    f"world/tracks/{name}", self._rr.LineStrips3D.from_fields(strips=[np.array(track)])
                )

    def log_belief(self, probabilities: np.ndarray, entropy: float) -> None:
        """Log the task posterior as bars and its (normalised) entropy as a scalar."""
        self._stream.log("belief/task", self._rr.BarChart(np.asarray(probabilities, dtype=np.float64)))
        self._stream.log("belief/entropy", self._rr.Scalars(float(entropy)))

    def log_localisation(self, estimate: Sequence[float], particles: np.ndarray | None = None) -> None:
        """Log the localiser's pose estimate (x, y[, yaw]) and, if given, its particle cloud (P x 2 xy) at the
        current time, beside the ground truth and odometry of :meth:`log_poses`. Buffered and sent as columns with
        the poses (module docstring)."""
        if not self._localisation_styled:
            self._localisation_styled = True
            rr, log = self._rr, self._stream.log
            log(
                "world/localisation/estimate",
                rr.Points3D.from_fields(colors=[(30, 110, 255)], radii=0.07),
                static=True,
            )
            log(
                "world/localisation/particles",
                rr.Points3D.from_fields(colors=[(90, 160, 255)], radii=0.02),
                static=True,
            )
        self._estimates.append((self._step, self._sim_time, float(estimate[0]), float(estimate[1])))
        if particles is not None:
            cloud = np.empty((len(particles), 3))
            cloud[:, :2] = np.asarray(particles, dtype=np.float64)[:, :2]
            cloud[:, 2] = 0.02
            self._clouds.append((self._step, self._sim_time, cloud))
        if len(self._estimates) >= FRAME_BATCH:
            self._send_frames()

    def log_text(self, channel: str, text: str, level: str = "INFO") -> None:
        """Log a line on ``log/<channel>``; channel is one of observations, actions, utterances, events."""
        if channel not in TEXT_CHANNELS:
            raise ValueError(f"text channel '{channel}' unknown; use one of {TEXT_CHANNELS}")
        self._stream.log(f"log/{channel}", self._rr.TextLog(text, level=level))

    def log_camera(
        self, name: str, frame: np.ndarray, step: int | None = None, sim_time: float | None = None
    ) -> None:
        """Log an RGB frame as a JPEG-encoded image on ``camera/<name>`` (keeps the .rrd small), at ``step`` and
        ``sim_time`` (default: the current time; give them when logging from another thread, e.g. a render
        thread, as the current time is the simulation thread's). The JPEG is encoded on a worker thread: do not
        modify ``frame`` afterwards."""
        step = self._step if step is None else int(step)
        sim_time = self._sim_time if sim_time is None else float(sim_time)
        self._images.submit((name, step, sim_time, frame))

    def _encode_image(self, item: tuple) -> None:
        """Worker thread: JPEG-encode the frame and buffer it with the time it was taken; every ``IMAGE_BATCH``
        images (and on close) they go out as columns, one call per camera instead of one per image (each call
        holds the GIL, which the simulation thread then waits for). Pillow (libjpeg-turbo) encodes a 640x512
        frame in about half the CPU time of ``rr.Image.compress``."""
        import io

        from PIL import Image

        name, step, sim_time, frame = item
        jpeg = io.BytesIO()
        Image.fromarray(np.ascontiguousarray(frame)).save(jpeg, format="JPEG", quality=self.jpeg_quality)
        self._jpegs.append((name, step, sim_time, jpeg.getvalue()))
        if len(self._jpegs) >= IMAGE_BATCH:
            self._send_images()

    def _send_images(self) -> None:
        """Send the buffered JPEGs as one column per camera (images thread, or after it has stopped)."""
        rr, buffered, self._jpegs = self._rr, self._jpegs, []
        for name in dict.fromkeys(row[0] for row in buffered):
            rows = [row for row in buffered if row[0] == name]
            self._stream.send_columns(
                f"camera/{name}",
                indexes=[
                    rr.TimeColumn("step", sequence=np.array([row[1] for row in rows])),
                    rr.TimeColumn("sim_time", duration=np.array([row[2] for row in rows])),
                ],
                columns=rr.EncodedImage.columns(
                    blob=[row[3] for row in rows], media_type=["image/jpeg"] * len(rows)
                ),
            )

    def log_audio(self, wav_bytes: bytes) -> None:
        """Log a WAV clip (e.g. the human's synthesised reply) on ``speech/audio``."""
        self._stream.log("speech/audio", self._rr.AssetAudio(contents=wav_bytes, media_type="audio/wav"))

    # -- finish -------------------------------------------------------------------------------------------
    def close(self) -> Path:
        """Flush and publish the ``.rrd`` under its final name (idempotent; call it in ``finally``)."""
        if not self._closed:
            self._closed = True
            try:
                self._images.close()
            finally:
                self._send_images()
                self._send_frames()
                self._log_tracks()
                self._stream.flush()
                self._stream.disconnect()
                publish(self._temporary, self.path)
        return self.path

    def __enter__(self) -> RerunRecorder:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
