"""The live mode's web server: a Starlette (ASGI) app on uvicorn, one WebSocket per participant.

``GET /`` is the page (``live/static/index.html``), ``GET /static/live.js|live.css`` its script and style (a fixed
list of names: no URL becomes a path), ``/ws`` the WebSocket. Nothing is loaded from another site; the page
works offline. Protocol on ``/ws`` (JSON text messages unless said otherwise):

| direction | message |
|---|---|
| page -> server | ``{"type": "start"}`` |
| page -> server | ``{"type": "keys", "held": ["up", "left"], "seq": n}``: the direction keys now held |
| page -> server | ``{"type": "act", "seq": n}``: pick up / drop |
| page -> server | ``{"type": "reply", "text": "...", "seq": n}``; ``{"type": "ping", "t": ms}`` |
| page -> server | a binary message: a spoken reply as a WAV file |
| server -> page | ``hello`` |
| server -> page | ``state`` (simulated time, human pose, balls, last input applied, notice, question open, posterior) |
| server -> page | binary ``b"F" + JPEG`` right after each ``state``: the overhead frame |
| server -> page | ``question``, followed by binary ``b"A" + WAV`` (the robot's spoken question) |
| server -> page | ``heard`` (transcript and node of a reply); ``step``; ``done``; ``error``; ``pong`` |

``state`` and its frame are sent ``stream_fps`` times a second, as soon as the simulation thread has rendered
the frame.

Safety: the server binds 127.0.0.1 unless ``--host`` says otherwise, and then the page and the WebSocket need the
token printed at start-up (``?token=...``); a WebSocket whose ``Origin`` is another site is refused (no
cross-site hijacking of a local session). Text messages are at most 4 KiB, audio at most
``MAX_AUDIO_BYTES`` (uvicorn closes the connection on anything larger) and 15 s; control messages are limited to
``CONTROL_RATE`` per second (bursts of ``CONTROL_BURST``) and spoken replies to one per ``AUDIO_INTERVAL`` s.
Refused and rate-limited messages are answered with an ``error`` message and counted in ``session.json``; none
reaches the simulation thread, which reads only validated inputs from a queue. One participant at a time.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import json
import math
import secrets
import socket
import time
from collections.abc import Callable

from embodied_adhoc import paths
from embodied_adhoc.comms.vocabulary import NODE_NAMES
from embodied_adhoc.errors import ConfigError, EmbodiedAdhocError
from embodied_adhoc.live.humans import DIRECTIONS
from embodied_adhoc.live.session import FRAME_READY, LiveSession, LiveSettings

__all__ = ["LiveServer", "RateLimit", "is_loopback", "serve"]

MAX_TEXT_BYTES = 4096
MAX_AUDIO_BYTES = 1_000_000  # 15 s of 16 kHz 16-bit mono is 480 kB: room for 32 kHz, not for a file dump
CONTROL_RATE, CONTROL_BURST = (
    30.0,
    60,
)  # key changes are a few per second; auto-repeat is filtered by the page
AUDIO_INTERVAL = 2.0
IDLE_TIMEOUT = 30.0  # s without a message from the page (it pings every 5 s) before its slot is freed
SEND_TIMEOUT = 10.0  # s a message may wait for a page that stopped reading before the page is dropped
MAX_JSON_DEPTH = 4  # nesting of a message's arrays and objects ({"held": [...]} is 2)
STATIC_FILES = {"live.js": "text/javascript", "live.css": "text/css"}
SECURITY_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; img-src 'self' blob:; media-src 'self' blob:; "
    "connect-src 'self'; style-src 'self'; script-src 'self'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
}


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def browser_hosts(host: str) -> list[str]:
    """Names a browser can use for a server bound to ``host``: a wildcard address (0.0.0.0, ::) is no
    address a browser opens, so this machine's loopback address and its host names stand in for it."""
    if host in ("0.0.0.0", "::", ""):
        names = ["127.0.0.1", "localhost", socket.gethostname(), socket.getfqdn()]
        with contextlib.suppress(OSError):
            names += sorted({info[4][0] for info in socket.getaddrinfo(socket.gethostname(), None)})
        return list(dict.fromkeys(n for n in names if n))
    if is_loopback(host):
        return list(dict.fromkeys([host, "127.0.0.1", "localhost", "::1"]))
    return [host]


def origins(host: str, port: int) -> frozenset[str]:
    """The Origin values accepted on the WebSocket: the page as served from the bound address (never from
    whatever the request's Host header claims, which a DNS-rebinding page controls)."""
    return frozenset(f"http://{_bracketed(name)}:{port}" for name in browser_hosts(host))


def _bracketed(name: str) -> str:
    return f"[{name}]" if ":" in name else name


def check_depth(text: str, limit: int = MAX_JSON_DEPTH) -> None:
    """Refuse a JSON text nested deeper than ``limit`` before it is parsed (a scan outside strings)."""
    depth, in_string, escaped = 0, False, False
    for char in text:
        if in_string:
            if escaped:
                escaped = False
            elif char == "\\":
                escaped = True
            elif char == '"':
                in_string = False
        elif char == '"':
            in_string = True
        elif char in "[{":
            depth += 1
            if depth > limit:
                raise ConfigError(f"message nested deeper than {limit} levels")
        elif char in "]}":
            depth -= 1


def _refuse_constant(name: str):
    raise ConfigError(f"message contains {name}: only finite numbers are accepted")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ConfigError(f"message contains the number {text}, too large to be finite")
    return value


def parse_message(text: str):
    """A page message as JSON: size checked by the caller, depth here, non-finite numbers refused."""
    check_depth(text)
    try:
        return json.loads(text, parse_constant=_refuse_constant, parse_float=_finite_float)
    except json.JSONDecodeError as error:
        raise ConfigError(f"message is not JSON ({error.msg} at column {error.colno})") from None


class RateLimit:
    """Token bucket: ``rate`` events per second on average, bursts of ``burst``."""

    def __init__(self, rate: float, burst: float, clock: Callable[[], float] = time.monotonic):
        self.rate, self.burst, self.clock = float(rate), float(burst), clock
        self.tokens, self.last = float(burst), clock()

    def allow(self) -> bool:
        now = self.clock()
        self.tokens = min(self.burst, self.tokens + (now - self.last) * self.rate)
        self.last = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        return False


class LiveServer:
    """The app around one :class:`LiveSession` (module docstring)."""

    def __init__(self, settings: LiveSettings, host: str = "127.0.0.1", port: int = 0, study=None):
        self.host = host
        self.token = None if is_loopback(host) else secrets.token_urlsafe(18)  # a credential, not simulation
        self.bind(port)
        self.settings, self.study = settings, study  # study: a live.study.StudyRun, or None
        self.session = LiveSession(
            settings if study is None else study.settings(settings), publish=self._publish
        )
        self.loop: asyncio.AbstractEventLoop | None = None
        self.outbox: asyncio.Queue | None = None  # the connected participant's queue of events
        self._last_error_notice = 0.0
        self._connections = 0

    def bind(self, port: int) -> None:
        """The port actually listened on: the Origin allowlist and the accepted Host names follow from it."""
        self.port = int(port)
        self.allowed_origins = origins(self.host, self.port)
        self.allowed_hosts = frozenset(o.removeprefix("http://") for o in self.allowed_origins)

    def urls(self) -> list[str]:
        """The addresses to print: ones a browser can open (a wildcard bind names this machine instead)."""
        query = f"?token={self.token}" if self.token else ""
        names = browser_hosts(self.host)
        shown = names[:1] if is_loopback(self.host) else names[: 3 if self.host in ("0.0.0.0", "::") else 1]
        return [f"http://{_bracketed(name)}:{self.port}/{query}" for name in shown]

    # ------------------------------------------------------------------ app
    def app(self):
        from starlette.applications import Starlette
        from starlette.routing import Route, WebSocketRoute

        @contextlib.asynccontextmanager
        async def lifespan(app):
            self.loop = asyncio.get_running_loop()
            try:
                yield
            finally:
                await asyncio.to_thread(self.session.close)

        routes = [
            Route("/", self._page),
            Route("/static/{name}", self._static),
            WebSocketRoute("/ws", self._websocket),
        ]
        return Starlette(routes=routes, lifespan=lifespan)

    def _token_ok(self, query) -> bool:
        """Exactly one ``token`` parameter, equal to the server's (no parameter at all without a token)."""
        given = query.getlist("token")
        if self.token is None:
            return not given
        return len(given) == 1 and secrets.compare_digest(given[0].encode(), self.token.encode())

    def _host_ok(self, headers) -> bool:
        """Without a token the server trusts the loopback alone: a request naming any other Host is a page
        of another site reached through DNS rebinding."""
        return self.token is not None or headers.get("host") in self.allowed_hosts

    def _refused(self, request):
        from starlette.responses import PlainTextResponse

        if not self._host_ok(request.headers):
            return PlainTextResponse("unknown host name", status_code=403)
        if not self._token_ok(request.query_params):
            return PlainTextResponse(
                "token required (once): open the URL printed by `embodied-adhoc live` at start-up",
                status_code=403,
            )
        return None

    async def _page(self, request):
        from starlette.responses import HTMLResponse

        refused = self._refused(request)
        if refused is not None:
            return refused
        page = paths.live_static("index.html").read_text(encoding="utf-8")
        if self.token:  # the page's own script and style need the token too
            query = f"?token={self.token}"
            for name in STATIC_FILES:
                page = page.replace(f'"/static/{name}"', f'"/static/{name}{query}"')
        return HTMLResponse(page, headers=SECURITY_HEADERS)

    async def _static(self, request):
        from starlette.responses import FileResponse, PlainTextResponse

        name = request.path_params["name"]
        if name not in STATIC_FILES:
            return PlainTextResponse("not found", status_code=404)
        refused = self._refused(request)
        if refused is not None:
            return refused
        return FileResponse(paths.live_static(name), media_type=STATIC_FILES[name], headers=SECURITY_HEADERS)

    # ------------------------------------------------------------------ events from the simulation thread
    def _publish(self, event: dict, binary: bytes | None) -> None:
        loop, outbox = self.loop, self.outbox
        if loop is None or outbox is None:
            return
        loop.call_soon_threadsafe(_offer, outbox, (event, binary))

    # ------------------------------------------------------------------ websocket
    async def _websocket(self, websocket):
        from starlette.websockets import WebSocketDisconnect

        origin = websocket.headers.get("origin")
        if (
            not self._token_ok(websocket.query_params)
            or not self._host_ok(websocket.headers)
            or (origin is not None and origin not in self.allowed_origins)
        ):
            await websocket.close(code=1008)
            return
        await websocket.accept()
        if self.outbox is not None:
            await websocket.send_json({"type": "error", "message": "another participant is connected"})
            await websocket.close(code=1013)
            return
        outbox: asyncio.Queue = asyncio.Queue(maxsize=512)
        self.outbox = outbox
        session = self.session
        self._connections += 1
        session.note("connected" if self._connections == 1 else "reconnected", connection=self._connections)
        sender = None
        try:
            await asyncio.wait_for(websocket.send_json(self._hello()), SEND_TIMEOUT)
            sender = asyncio.create_task(self._send_loop(websocket, outbox))
            await self._receive_loop(websocket, sender)
        except TimeoutError:  # a reply could not be sent in SEND_TIMEOUT: the page stopped reading
            self.session.note("dropped", why="not reading")
        except WebSocketDisconnect:
            pass
        finally:
            session = self.session  # (a study may have moved on to its next episode)
            session.person.keys(
                set(), session.person.last_seq
            )  # a dropped page must not leave the human walking
            if sender is not None:
                sender.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await sender
            if self.outbox is outbox:
                self.outbox = None
            session.note("disconnected", connection=self._connections)

    def _hello(self) -> dict:
        session = self.session
        return {
            "type": "hello",
            "participant": session.participant_id,
            "tasks": session.tasks,
            "places": list(NODE_NAMES),
            "started": session.running or session.done is not None,
            "stream_fps": session.settings.stream_fps,
            "keys": sorted(DIRECTIONS),
            "restore": session.restore(),
            "study": None if self.study is None else self.study.page_info(),
            "limits": {
                "text_bytes": MAX_TEXT_BYTES,
                "audio_bytes": MAX_AUDIO_BYTES,
                "control_rate": CONTROL_RATE,
                "idle_timeout_s": IDLE_TIMEOUT,
            },
        }

    async def _receive_loop(self, websocket, sender: asyncio.Task) -> None:
        """Messages until the page leaves, stops reading (the sender gave up) or says nothing for
        ``IDLE_TIMEOUT`` seconds."""
        control = RateLimit(CONTROL_RATE, CONTROL_BURST)
        audio = RateLimit(1.0 / AUDIO_INTERVAL, 1)
        while True:
            receiving = asyncio.ensure_future(websocket.receive())
            done, _ = await asyncio.wait(
                {receiving, sender}, timeout=IDLE_TIMEOUT, return_when="FIRST_COMPLETED"
            )
            if receiving not in done or sender in done:
                receiving.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await receiving
                # a sender that failed other than by timing out met a page that closed: a disconnect, not a drop
                stalled = (
                    sender in done and not sender.cancelled() and isinstance(sender.exception(), TimeoutError)
                )
                if stalled or sender not in done:
                    self.session.note("dropped", why="not reading" if stalled else "idle")
                return
            message = receiving.result()
            if message["type"] == "websocket.disconnect":
                return
            session = self.session
            session.counters["messages"] += 1
            try:
                reply = await self._handle(message, control, audio)
            except EmbodiedAdhocError as error:
                session.counters["refused"] += 1
                reply = {"type": "error", "message": str(error)}
            except (ValueError, TypeError, KeyError) as error:  # malformed fields of a message
                session.counters["refused"] += 1
                reply = {
                    "type": "error",
                    "message": f"malformed message ({type(error).__name__}: {error})",
                }
            if reply is not None:
                await asyncio.wait_for(websocket.send_json(reply), SEND_TIMEOUT)

    async def _handle(self, message: dict, control: RateLimit, audio: RateLimit) -> dict | None:
        session = self.session
        data = message.get("bytes")
        if data is not None:
            if not audio.allow():
                return self._limited(f"one spoken reply per {AUDIO_INTERVAL:g} s")
            if not session.person.question_open:
                raise ConfigError("the robot has not asked anything: no reply expected now")
            detail = await asyncio.to_thread(session.reply_from_audio, data, 0, MAX_AUDIO_BYTES)
            return {"type": "heard", **detail}
        text = message.get("text") or ""
        if len(text.encode()) > MAX_TEXT_BYTES:
            raise ConfigError(f"message of {len(text.encode())} bytes exceeds {MAX_TEXT_BYTES}")
        if not control.allow():
            return self._limited(f"at most {CONTROL_RATE:g} messages per second")
        request = parse_message(text)
        if not isinstance(request, dict) or not isinstance(request.get("type"), str):
            raise ConfigError('message must be a JSON object with a "type" string')
        kind = request["type"]
        if kind == "ping":
            t = request.get("t", 0.0)
            if isinstance(t, bool) or not isinstance(t, (int, float)):
                raise ConfigError('"t" of a ping must be a number')
            return {"type": "pong", "t": t}
        if kind == "questionnaire":
            return await self._questionnaire(request.get("answers"))
        if kind == "start":
            started = session.start()
            return {
                "type": "starting" if started else "error",
                "message": "" if started else "already started",
            }
        seq = request.get("seq", 0)
        if not isinstance(seq, int) or isinstance(seq, bool) or not 0 <= seq < 2**53:
            raise ConfigError('"seq" must be a non-negative integer')
        if kind == "keys":
            held = request.get("held")
            if (
                not isinstance(held, list)
                or len(held) > len(DIRECTIONS)
                or not all(isinstance(k, str) for k in held)
            ):
                raise ConfigError(f'"held" must be a list of direction keys {sorted(DIRECTIONS)}')
            session.person.keys(set(held), seq)
            return None
        if kind == "act":
            session.person.act(seq)
            return None
        if kind == "reply":
            if not session.person.question_open:
                raise ConfigError("the robot has not asked anything: no reply expected now")
            return {"type": "heard", **session.reply_from_text(request.get("text"), seq)}
        raise ConfigError(f"unknown message type {kind!r}; use start, keys, act, reply or ping")

    async def _questionnaire(self, answers) -> dict:
        """A study's post-episode questionnaire: recorded, then the next episode's session is built and the
        page gets a fresh hello (or the study is complete)."""
        study, session = self.study, self.session
        if study is None or study.complete:
            raise ConfigError("no questionnaire is due: this is no study, or it is complete")
        if session.done is None:
            raise ConfigError("the questionnaire comes after the episode")
        await asyncio.to_thread(session.close)  # the episode is over: its files are written once it returns
        study.record(session, answers)
        if study.complete:
            return {"type": "study_complete", "folder": str(study.folder)}
        self.session = await asyncio.to_thread(LiveSession, study.settings(self.settings), self._publish)
        return self._hello()

    def _limited(self, what: str) -> dict | None:
        self.session.counters["rate_limited"] += 1
        now = time.monotonic()
        if now - self._last_error_notice < 1.0:
            return None  # one notice a second is enough; every drop is counted
        self._last_error_notice = now
        return {"type": "error", "message": f"rate limit: {what}; messages dropped"}

    async def _send_loop(self, websocket, outbox: asyncio.Queue) -> None:
        """Events in order; on each FRAME_READY the latest state and frame (rendered by the simulation thread at
        ``stream_fps`` wall frames per second, so the page's rate is the renderer's, with no second timer)."""
        session = self.session
        last_seq, last_sent = 0, None
        while True:
            event, binary = await outbox.get()
            if session is not self.session:  # a study's next episode
                session, last_seq, last_sent = self.session, 0, None
            if event is FRAME_READY:
                with session.frame_lock:
                    frame = session.frame
                if frame is None or frame[0] == last_seq:
                    continue
                last_seq, jpeg, state = frame
                await asyncio.wait_for(websocket.send_json({"type": "state", **state}), SEND_TIMEOUT)
                await asyncio.wait_for(websocket.send_bytes(b"F" + jpeg), SEND_TIMEOUT)
                now = time.perf_counter()
                if last_sent is not None:
                    session.frame_intervals.append(now - last_sent)
                last_sent = now
                continue
            await asyncio.wait_for(websocket.send_json(event), SEND_TIMEOUT)
            if binary is not None:
                await asyncio.wait_for(websocket.send_bytes(b"A" + binary), SEND_TIMEOUT)


def _offer(outbox: asyncio.Queue, item) -> None:
    if outbox.full():  # a page that stopped reading: drop its oldest event, never block the simulation
        outbox.get_nowait()
    outbox.put_nowait(item)


def serve(
    settings: LiveSettings, host: str, port: int, announce: Callable[[str], None] = print, study=None
) -> LiveServer:
    """Listen on ``host:port`` (0: a free port), announce the URL and serve until interrupted."""
    import uvicorn

    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    listener = socket.socket(family, socket.SOCK_STREAM)
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        listener.bind((host, port))
    except OSError as error:
        listener.close()
        raise ConfigError(f"--host {host} --port {port}: cannot listen there ({error.strerror})") from None
    try:
        server = LiveServer(settings, host, listener.getsockname()[1], study)
    except BaseException:
        listener.close()
        raise
    announce(f"live: participant {server.session.participant_id}, run folder {server.session.folder}")
    first, *others = server.urls()
    announce(f"live: open {first}")
    for url in others:
        announce(f"live: or {url}")
    if server.token:
        announce(
            "live: the server is open beyond this machine; only the URL above (with its token) is accepted"
        )
    config = uvicorn.Config(
        server.app(),
        log_level="warning",
        ws="websockets-sansio",
        ws_max_size=MAX_AUDIO_BYTES + 1024,
        lifespan="on",
    )
    uvicorn.Server(config).run(sockets=[listener])
    return server
