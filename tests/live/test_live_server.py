"""The live server over a loopback WebSocket: frames stream, inputs reach the simulation, a hostile client is
refused or rate-limited without hurting the simulation, the token and the origin are enforced, no URL becomes a
path, and a spoken reply goes through the offline recogniser into the run folder."""

from __future__ import annotations

import asyncio
import json
import os
import socket
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
import websockets

from embodied_adhoc.live.server import MAX_AUDIO_BYTES, LiveServer, RateLimit
from embodied_adhoc.live.session import LiveSession, LiveSettings, next_participant_id


class _Served:
    """A LiveServer's app on a free loopback port, in a thread (stopped by ``close``)."""

    def __init__(self, tmp: Path, host_label: str = "127.0.0.1", study=None):
        import uvicorn

        self.socket = socket.socket()
        self.socket.bind(("127.0.0.1", 0))
        self.port = self.socket.getsockname()[1]
        self.live = LiveServer(LiveSettings(seed=9, out=tmp, stream_fps=10.0), host_label, self.port, study)
        config = uvicorn.Config(
            self.live.app(), log_level="warning", ws="websockets-sansio", ws_max_size=MAX_AUDIO_BYTES + 1024
        )
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self.socket]}, daemon=True)
        self.thread.start()
        deadline = time.monotonic() + 30
        while not self.server.started:
            assert time.monotonic() < deadline, "server did not start"
            time.sleep(0.05)

    def url(self, path: str = "/") -> str:
        return f"http://127.0.0.1:{self.port}{path}"

    def close(self) -> None:
        self.server.should_exit = True
        self.thread.join(40)


@pytest.fixture
def served(tmp_path):
    served = _Served(tmp_path)
    yield served
    served.close()


async def _drain(ws, seconds: float) -> tuple[list[dict], int]:
    """Messages for ``seconds``: the JSON events and the number of frames."""
    events, frames, end = [], 0, time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        try:
            message = await asyncio.wait_for(ws.recv(), left)
        except TimeoutError:
            break
        if isinstance(message, bytes):
            frames += message[:1] == b"F"
        else:
            events.append(json.loads(message))
    return events, frames


def test_hostile_messages_are_refused_and_the_simulation_runs_on(served):
    async def scenario():
        uri = f"ws://127.0.0.1:{served.port}/ws"
        async with websockets.connect(uri, max_size=None) as ws:
            hello = json.loads(await ws.recv())
            assert hello["type"] == "hello" and hello["participant"] == "P001"
            await ws.send(json.dumps({"type": "start"}))
            while json.loads(await ws.recv()).get("type") != "state":  # the simulation is running
                pass
            await ws.send(json.dumps({"type": "keys", "held": ["right"], "seq": 1}))
            events, frames = await _drain(ws, 2.0)
            states = [e for e in events if e["type"] == "state"]
            assert frames >= 3 and states[-1]["ack"] == 1
            assert states[-1]["human"][0] > states[0]["human"][0]  # walking east
            for junk in (
                "not json",
                json.dumps([1, 2]),
                json.dumps({"type": "fly"}),
                json.dumps({"type": "keys", "held": ["up", "jump"], "seq": 2}),
                json.dumps({"type": "keys", "held": "up", "seq": 3}),
                json.dumps({"type": "act", "seq": -1}),
                json.dumps({"type": "reply", "text": "at the door", "seq": 4}),  # no question asked yet
                "x" * 5000,
            ):
                await ws.send(junk)
            await ws.send(b"RIFF this is no wav")
            for _ in range(200):  # a flood of key messages
                await ws.send(json.dumps({"type": "keys", "held": [], "seq": 5}))
            events, frames = await _drain(ws, 2.0)
            errors = [e["message"] for e in events if e["type"] == "error"]
            assert any("not JSON" in m for m in errors) and any("unknown message type" in m for m in errors)
            assert any("unknown direction" in m for m in errors) and any("exceeds 4096" in m for m in errors)
            assert any("no reply expected" in m for m in errors) and any("rate limit" in m for m in errors)
            assert frames >= 3  # the simulation kept streaming
        # an audio message over the size limit closes that connection; a new one is served
        async with websockets.connect(uri, max_size=None) as ws:
            await ws.recv()
            await ws.send(b"\0" * (MAX_AUDIO_BYTES + 4096))
            with pytest.raises(websockets.ConnectionClosed):
                await _drain(ws, 5.0)
                await ws.recv()
        async with websockets.connect(uri, max_size=None) as ws:
            assert json.loads(await ws.recv())["started"] is True
            _, frames = await _drain(ws, 1.5)
            assert frames >= 3
        # a page from another site may not drive a local session
        with pytest.raises(websockets.InvalidStatus):
            async with websockets.connect(uri, origin="http://evil.example"):
                pass

    asyncio.run(scenario())
    assert served.live.session.running
    counters = served.live.session.counters
    assert counters["rate_limited"] > 0 and counters["refused"] >= 8


def test_no_url_becomes_a_path(served):
    assert b"live.js" in urllib.request.urlopen(served.url("/")).read()
    assert urllib.request.urlopen(served.url("/static/live.js")).status == 200
    for path in (
        "/static/../../etc/passwd",
        "/static/%2e%2e%2fserver.py",
        "/static/index.html",
        "/etc/passwd",
    ):
        with pytest.raises(urllib.error.HTTPError) as error:
            urllib.request.urlopen(served.url(path))
        assert error.value.code == 404, path


def test_an_open_server_needs_the_printed_token(tmp_path):
    served = _Served(
        tmp_path, host_label="192.0.2.10"
    )  # a non-loopback --host (the app's rules; bound on loopback)
    try:
        token = served.live.token
        assert token and len(token) >= 20
        with pytest.raises(urllib.error.HTTPError) as error:
            urllib.request.urlopen(served.url("/"))
        assert error.value.code == 403
        assert urllib.request.urlopen(served.url(f"/?token={token}")).status == 200

        async def scenario():
            with pytest.raises(websockets.InvalidStatus):
                async with websockets.connect(f"ws://127.0.0.1:{served.port}/ws?token=wrong"):
                    pass
            async with websockets.connect(f"ws://127.0.0.1:{served.port}/ws?token={token}") as ws:
                assert json.loads(await ws.recv())["type"] == "hello"
                # one participant at a time: a second page is told so and closed
                async with websockets.connect(f"ws://127.0.0.1:{served.port}/ws?token={token}") as second:
                    assert "another participant" in json.loads(await second.recv())["message"]
                    with pytest.raises(websockets.ConnectionClosed):
                        await asyncio.wait_for(second.recv(), 10)

        asyncio.run(scenario())
    finally:
        served.close()


def test_spoken_reply_is_recognised_saved_and_reaches_the_robot(tmp_path):
    from embodied_adhoc.comms.synthesis import SAMPLE_RATE, Voice, synthesize
    from embodied_adhoc.live.session import wav_bytes

    session = LiveSession(LiveSettings(seed=9, out=tmp_path))
    try:
        session.person.question_open = True  # as the env sets it when the robot asks
        data = wav_bytes(synthesize("I am at the robot station", Voice("en-us")), SAMPLE_RATE)
        detail = session.reply_from_audio(data, 0, MAX_AUDIO_BYTES)
        assert detail["node"] == 2 and "robot station" in detail["transcript"]
        saved = session.folder / detail["file"]
        assert saved.read_bytes() == data and saved.parent == session.folder / "replies"
        with pytest.raises(Exception, match="exceeds"):
            session.reply_from_audio(data, 0, len(data) - 1)
    finally:
        session.close()
    assert json.loads((session.folder / "session.json").read_text())["replies"][0]["node"] == 2


def test_participant_ids_are_sequential_and_anonymous(tmp_path):
    assert next_participant_id(tmp_path) == "P001"
    (tmp_path / "P007_20260101T000000Z").mkdir()
    (tmp_path / "notes").mkdir()
    assert next_participant_id(tmp_path) == "P008"
    with pytest.raises(Exception, match="participant"):
        LiveSession(LiveSettings(out=tmp_path, participant="../escape"))


def test_rate_limit_bucket():
    now = [0.0]
    bucket = RateLimit(rate=2.0, burst=3, clock=lambda: now[0])
    assert [bucket.allow() for _ in range(4)] == [True, True, True, False]
    now[0] += 0.5
    assert bucket.allow() and not bucket.allow()


def _live_cli(*args: str, tmp: Path):
    import subprocess
    import sys

    command = [sys.executable, "-m", "embodied_adhoc.cli", "live", "toxic-waste", "--out", str(tmp), *args]
    return subprocess.run(
        command, capture_output=True, text=True, timeout=120, env={**os.environ, "MUJOCO_GL": "egl"}
    )


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (("--port", "70000"), "--port"),
        (("--speed", "0"), "--speed"),
        (("--participant", "../escape"), "--participant"),
        (("--max-steps", "0"), "--max-steps"),
        (("--question-interval", "-1"), "--question-interval"),
    ],
)
def test_bad_live_flags_are_one_line_and_status_2(tmp_path, args, named):
    result = _live_cli(*args, tmp=tmp_path)
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and named in result.stderr
    assert "Traceback" not in result.stderr


def test_a_busy_port_is_one_line_and_status_2(tmp_path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        result = _live_cli("--port", str(busy.getsockname()[1]), tmp=tmp_path)
    assert result.returncode == 2 and "cannot listen there" in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def _get(url: str, host: str | None = None) -> int:
    request = urllib.request.Request(url, headers={"Host": host} if host else {})
    try:
        return urllib.request.urlopen(request).status
    except urllib.error.HTTPError as error:
        return error.code


def test_dns_rebinding_host_and_origin_are_refused(served):
    """The Origin allowlist comes from the bound address, not from the request's Host header."""
    evil = f"evil.example:{served.port}"
    assert _get(served.url("/"), host=evil) == 403
    assert _get(served.url("/static/live.js"), host=evil) == 403
    assert _get(served.url("/")) == 200

    async def scenario():
        uri = f"ws://127.0.0.1:{served.port}/ws"
        for headers in ({"Host": evil}, {}):
            with pytest.raises(websockets.InvalidStatus):
                async with websockets.connect(uri, origin=f"http://{evil}", additional_headers=headers):
                    pass
        async with websockets.connect(uri, origin=f"http://localhost:{served.port}") as ws:
            assert json.loads(await ws.recv())["type"] == "hello"

    asyncio.run(scenario())
    assert served.live.session.running is False  # nothing reached the simulation


def test_duplicate_tokens_and_static_files_without_the_token_are_refused(tmp_path):
    served = _Served(tmp_path, host_label="192.0.2.10")
    try:
        token = served.live.token
        assert _get(served.url(f"/?token=wrong&token={token}")) == 403
        assert _get(served.url(f"/?token={token}&token={token}")) == 403
        assert _get(served.url("/static/live.js")) == 403
        assert _get(served.url(f"/static/live.js?token={token}")) == 200
        page = urllib.request.urlopen(served.url(f"/?token={token}")).read().decode()
        assert f"/static/live.js?token={token}" in page and f"/static/live.css?token={token}" in page

        async def scenario():
            with pytest.raises(websockets.InvalidStatus):
                async with websockets.connect(f"ws://127.0.0.1:{served.port}/ws?token=wrong&token={token}"):
                    pass

        asyncio.run(scenario())
    finally:
        served.close()


def test_the_printed_url_names_an_address_a_browser_opens(tmp_path):
    live = LiveServer(LiveSettings(out=tmp_path), "0.0.0.0", 8123)
    try:
        urls = live.urls()
        assert urls[0] == f"http://127.0.0.1:8123/?token={live.token}"
        assert all("0.0.0.0" not in url for url in urls)
        assert "http://127.0.0.1:8123" in live.allowed_origins
        assert all("0.0.0.0" not in origin for origin in live.allowed_origins)
    finally:
        live.session.close()


def _no_constant(name: str):
    raise AssertionError(f"the server sent {name}, which is not JSON")


def test_deep_huge_and_non_finite_json_is_refused_before_parsing(served):
    async def scenario():
        async with websockets.connect(f"ws://127.0.0.1:{served.port}/ws", max_size=None) as ws:
            await ws.recv()
            await ws.send("[" * 2000 + "]" * 2000)
            await ws.send(json.dumps({"type": "ping", "t": [[[[[[1]]]]]]}))
            await ws.send('{"type": "ping", "t": NaN}')
            await ws.send('{"type": "ping", "t": -Infinity}')
            await ws.send('{"type": "ping", "t": 1e999}')
            await ws.send('{"type": "ping", "t": 12.5}')
            replies = []
            while len(replies) < 6:
                text = await asyncio.wait_for(ws.recv(), 10)
                if isinstance(text, str) and '"state"' not in text[:20]:
                    replies.append(json.loads(text, parse_constant=_no_constant))  # strict JSON only
            errors = [r["message"] for r in replies if r["type"] == "error"]
            assert sum("nested deeper" in m for m in errors) == 2
            assert sum("finite" in m for m in errors) == 3
            assert {"type": "pong", "t": 12.5} in replies

    asyncio.run(scenario())
    assert served.live.session.counters["refused"] == 5


def _flac_of_silence(seconds: float) -> bytes:
    import io

    import numpy as np
    import soundfile

    buffer = io.BytesIO()
    with soundfile.SoundFile(buffer, "w", 16_000, 1, format="FLAC") as sound:
        block = np.zeros(16_000 * 60, dtype=np.float32)
        for _ in range(int(seconds // 60)):
            sound.write(block)
    return buffer.getvalue()


def test_long_or_odd_audio_is_refused_from_its_header_without_decoding(tmp_path):
    """A FLAC of 90 minutes of silence (under 1 MB) and WAVs of too many channels or seconds are refused from
    their headers: no reply file is written and the Python heap grows by less than 2 MB."""
    import io
    import tracemalloc

    import numpy as np
    import soundfile

    from embodied_adhoc.errors import ConfigError

    flac = _flac_of_silence(5400)
    assert len(flac) < MAX_AUDIO_BYTES
    long_wav, six_channels = io.BytesIO(), io.BytesIO()
    soundfile.write(long_wav, np.zeros((16_000 * 16, 1), dtype=np.int16), 16_000, format="WAV")
    soundfile.write(six_channels, np.zeros((16_000, 6), dtype=np.int16), 16_000, format="WAV")
    session = LiveSession(LiveSettings(seed=9, out=tmp_path))
    try:
        session.person.question_open = True
        for data, why in (
            (flac, "not WAV"),
            (long_wav.getvalue(), "exceeds 15"),
            (six_channels.getvalue(), "6 channels"),
        ):
            tracemalloc.start()
            with pytest.raises(ConfigError, match=why):
                session.reply_from_audio(data, 0, 10 * MAX_AUDIO_BYTES)
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
            assert peak < 2_000_000, (why, peak)
        assert not (session.folder / "replies").exists() and session.replies == []
    finally:
        session.close()


def test_an_idle_or_non_reading_page_loses_its_slot(served, monkeypatch):
    from embodied_adhoc.live import server as server_module

    monkeypatch.setattr(server_module, "IDLE_TIMEOUT", 2.0)
    monkeypatch.setattr(server_module, "SEND_TIMEOUT", 2.0)

    async def scenario():
        uri = f"ws://127.0.0.1:{served.port}/ws"
        async with websockets.connect(uri) as silent:  # says nothing after connecting
            await silent.recv()
            async with websockets.connect(uri) as second:
                assert "another participant" in json.loads(await second.recv())["message"]
            with pytest.raises(websockets.ConnectionClosed):
                await asyncio.wait_for(_drain(silent, 4.0), 6)
                await silent.recv()
        async with websockets.connect(uri) as page:
            assert json.loads(await page.recv())["type"] == "hello"

    asyncio.run(scenario())
    kinds = [note["kind"] for note in served.live.session.notes]
    assert kinds[:3] == ["connected", "dropped", "disconnected"] and "reconnected" in kinds
    assert served.live.session.notes[1]["why"] == "idle"


async def _ping_every(ws, seconds: float) -> None:
    while True:
        await asyncio.sleep(seconds)
        await ws.send(json.dumps({"type": "ping", "t": 0}))


PLAN = {
    "episodes": [{"agent": "hotspot", "seed": 1}, {"agent": "random", "seed": 2}],
    "questionnaire": [{"id": "helpful", "text": "The robot was a helpful teammate.", "scale": 5}],
    "max_steps": 1,
}


def test_a_study_runs_its_episodes_with_a_questionnaire_and_summarises(tmp_path):
    """Two one-step episodes (each ends truncated at once) of a plan; the second participant plays them in the
    other order (Latin square); study.csv and questionnaire.jsonl per participant; summarise reads them."""
    from embodied_adhoc.commands.live import handle_summarise
    from embodied_adhoc.live.study import StudyRun, load_plan, summarise_study

    plan_file = tmp_path / "plan.json"
    plan_file.write_text(json.dumps(PLAN))
    plan = load_plan(plan_file)
    study_dir = tmp_path / "study"
    for participant, expected_agents in ((1, ["hotspot", "random"]), (2, ["random", "hotspot"])):
        study = StudyRun(plan, study_dir)
        assert study.participant == f"P00{participant}"
        served = _Served(tmp_path, study=study)
        try:

            async def scenario(port=served.port):
                async with websockets.connect(f"ws://127.0.0.1:{port}/ws", max_size=None) as ws:
                    # The real page pings every 5 s; without it a slow host's episode outlasts the idle timeout.
                    keepalive = asyncio.create_task(_ping_every(ws, 5.0))
                    hello = json.loads(await ws.recv())
                    for position in (1, 2):
                        assert hello["study"]["position"] == position and hello["study"]["of"] == 2
                        assert hello["study"]["questionnaire"][0]["id"] == "helpful"
                        await ws.send(json.dumps({"type": "questionnaire", "answers": {"helpful": 4}}))
                        await ws.send(json.dumps({"type": "start"}))
                        seen = []
                        while not seen or seen[-1]["type"] != "done":
                            message = await asyncio.wait_for(ws.recv(), 60)
                            if isinstance(message, str):
                                seen.append(json.loads(message))
                        answers = ({"helpful": 9}, {"helpful": position + 2})
                        for answer in answers:
                            await ws.send(json.dumps({"type": "questionnaire", "answers": answer}))
                        while seen[-1]["type"] not in ("hello", "study_complete"):
                            message = await asyncio.wait_for(ws.recv(), 60)
                            if isinstance(message, str):
                                seen.append(json.loads(message))
                        errors = [r["message"] for r in seen if r["type"] == "error"]
                        assert any("comes after the episode" in m for m in errors)
                        assert any("questionnaire.helpful" in m for m in errors)
                        hello = seen[-1]
                    assert hello["type"] == "study_complete"
                    keepalive.cancel()

            asyncio.run(scenario())
        finally:
            served.close()
        folder = study_dir / f"P00{participant}"
        rows = (folder / "study.csv").read_text().splitlines()
        assert len(rows) == 3 and rows[0].startswith("participant,position,episode,agent,seed,outcome")
        assert [row.split(",")[3] for row in rows[1:]] == expected_agents
        assert [row.split(",")[-1] for row in rows[1:]] == ["3", "4"]
        assert all(",truncated,0,1," in row for row in rows[1:])
        runs = sorted(p.name for p in folder.iterdir() if p.is_dir())
        assert runs == [
            f"E01_{expected_agents[0]}_seed{1 if participant == 1 else 2}",
            f"E02_{expected_agents[1]}_seed{2 if participant == 1 else 1}",
        ]
        events = [json.loads(line) for line in (folder / runs[0] / "events.jsonl").read_text().splitlines()]
        assert {"connected", "balls"} <= {e["kind"] for e in events}
        assert all("wall_time" in e and "sim_time" in e for e in events)
        assert json.loads((folder / "plan.json").read_text())["order"] == (
            [0, 1] if participant == 1 else [1, 0]
        )
        assert len((folder / "questionnaire.jsonl").read_text().splitlines()) == 2
    text = summarise_study(study_dir)
    assert "4 episodes of 2 participants" in text
    hotspot = [line for line in text.splitlines() if line.startswith("hotspot") and " helpful " in line]
    assert len(hotspot) == 1 and hotspot[0].split()[2] == "2" and float(hotspot[0].split()[3]) == 3.5
    assert handle_summarise(type("Args", (), {"study_dir": study_dir})()) == 0


@pytest.mark.parametrize(
    ("plan", "named"),
    [
        ({"episodes": []}, '"episodes"'),
        ({"episodes": [{"agent": "robot"}]}, "episodes[0].agent"),
        ({"episodes": [{"agent": "no_such_module_xyz:make"}]}, "episodes[0].agent"),
        ({"episodes": [{"agent": 3}]}, "episodes[0].agent"),
        ({"episodes": [{"seed": -1}]}, "episodes[0].seed"),
        ({"episodes": [{}], "counterbalance": "random"}, "counterbalance"),
        ({"episodes": [{}], "questionnaire": [{"id": "Bad id", "text": "x"}]}, "questionnaire[0].id"),
        (
            {"episodes": [{}], "questionnaire": [{"id": "a", "text": "x", "scale": 2}]},
            "questionnaire[0].scale",
        ),
        ({"episodes": [{}], "episode": []}, "did you mean 'episodes'"),
    ],
)
def test_a_bad_study_plan_is_one_line_naming_the_field_and_status_2(tmp_path, plan, named):
    plan_file = tmp_path / "plan.json"
    plan_file.write_text(json.dumps(plan))
    result = _live_cli("--study", str(plan_file), tmp=tmp_path / "study")
    assert result.returncode == 2, result.stderr
    assert (
        len(result.stderr.strip().splitlines()) == 1
        and named in result.stderr
        and str(plan_file) in result.stderr
    )
    assert not (tmp_path / "study").exists()  # refused before any work


def test_latin_orders_balance_positions_and_successions():
    from embodied_adhoc.live.study import latin_order

    for k in (2, 3, 4, 5):
        rows = [latin_order(k, r) for r in range(2 * k if k % 2 else k)]
        assert all(sorted(row) == list(range(k)) for row in rows)
        for position in range(k):  # every episode in every position equally often
            counts = [sum(row[position] == e for row in rows) for e in range(k)]
            assert len(set(counts)) == 1
        pairs = [(a, b) for row in rows for a, b in zip(row, row[1:], strict=False)]
        follows = [pairs.count((a, b)) for a in range(k) for b in range(k) if a != b]
        assert len(set(follows)) == 1  # every episode after every other equally often


def test_a_reconnecting_page_gets_the_whole_page_state(served):
    async def scenario():
        uri = f"ws://127.0.0.1:{served.port}/ws"
        async with websockets.connect(uri, max_size=None) as ws:
            assert json.loads(await ws.recv())["restore"]["history"] == []
            await ws.send(json.dumps({"type": "start"}))
            seen = []
            while not any(e["type"] == "step" for e in seen):
                message = await asyncio.wait_for(ws.recv(), 60)
                if isinstance(message, str):
                    seen.append(json.loads(message))
        async with websockets.connect(uri, max_size=None) as ws:
            hello = json.loads(await ws.recv())
        restore = hello["restore"]
        kinds = [e["type"] for e in restore["history"]]
        assert "started" in kinds and "step" in kinds and hello["started"] is True
        step = next(e for e in restore["history"] if e["type"] == "step")
        assert step == next(e for e in seen if e["type"] == "step")
        assert {"question_open", "action", "balls", "human", "robot_node"} <= set(restore["state"])
        assert restore["posterior"] is not None and len(restore["posterior"]) == len(hello["tasks"])

    asyncio.run(scenario())
    # the server notes a disconnect when its handler unwinds, which can follow the client's close by a moment
    deadline = time.monotonic() + 20
    while len(served.live.session.notes) < 4 and time.monotonic() < deadline:
        time.sleep(0.05)
    kinds = [note["kind"] for note in served.live.session.notes]
    assert kinds == ["connected", "disconnected", "reconnected", "disconnected"]


def _masked_text_frame(text: str) -> bytes:
    payload = text.encode()
    assert len(payload) < 126
    mask = os.urandom(4)
    return bytes([0x81, 0x80 | len(payload)]) + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload))


def test_a_page_that_stops_reading_loses_its_slot(served, monkeypatch):
    """A raw client that completes the handshake, starts the episode and keeps sending pings but never reads:
    once the socket buffers are full the server's sends time out and the slot is freed for a real page."""
    import base64

    from embodied_adhoc.live import server as server_module

    monkeypatch.setattr(server_module, "SEND_TIMEOUT", 2.0)
    raw = socket.socket()
    raw.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    raw.connect(("127.0.0.1", served.port))
    key = base64.b64encode(os.urandom(16)).decode()
    raw.sendall(
        (
            f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{served.port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
        ).encode()
    )
    assert raw.recv(12) == b"HTTP/1.1 101"
    try:
        raw.sendall(_masked_text_frame(json.dumps({"type": "start"})))
        deadline = time.monotonic() + 60
        while not any(note["kind"] == "dropped" for note in served.live.session.notes):
            assert time.monotonic() < deadline, "the non-reading page kept its slot"
            try:
                raw.sendall(_masked_text_frame(json.dumps({"type": "ping", "t": 1})))
            except OSError:
                break  # the server closed it
            time.sleep(0.5)
    finally:
        raw.close()
    dropped = next(note for note in served.live.session.notes if note["kind"] == "dropped")
    assert dropped["why"] == "not reading"

    async def scenario():
        async with websockets.connect(f"ws://127.0.0.1:{served.port}/ws") as page:
            assert json.loads(await page.recv())["type"] == "hello"

    asyncio.run(scenario())


def test_a_study_plan_takes_a_plugin_agent(tmp_path):
    from embodied_adhoc.live.study import load_plan

    spec = f"{Path(__file__).resolve().parents[1] / 'fixtures' / 'my_agent.py'}:make"
    plan_file = tmp_path / "plan.json"
    plan_file.write_text(json.dumps({"episodes": [{"agent": spec, "seed": 1}, {"agent": "hotspot"}]}))
    plan = load_plan(plan_file)
    assert [episode["agent"] for episode in plan.episodes] == [spec, "hotspot"]


def test_the_default_questionnaire_is_a_valid_plan(tmp_path):
    from embodied_adhoc.live.study import CSV_COLUMNS, DEFAULT_QUESTIONNAIRE, load_plan

    plan_file = tmp_path / "plan.json"
    plan_file.write_text(json.dumps({"episodes": [{"agent": "hotspot"}]}))
    assert [item["id"] for item in load_plan(plan_file).questionnaire] == [
        i["id"] for i in DEFAULT_QUESTIONNAIRE
    ]
    assert not {item["id"] for item in DEFAULT_QUESTIONNAIRE} & set(CSV_COLUMNS)
