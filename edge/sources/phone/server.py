"""A phone as an edge source: `SENSOR=phone://HOST:PORT` serves the browser page over HTTPS and
takes the Sensor Logger app's HTTP push (docs/phone.md).

    with PhoneSource("phone://0.0.0.0:8443", session, "walker", "phone", stop, venue_toml=path) as source:
        for message in source:   # ImuBatch and StandScan, in arrival order
            ...

Routes: `/` the page (edge/sources/phone/page/), `/static/...`, `/ca.pem` (the CA a phone trusts once),
`/ws` the page's WebSocket, `POST /sensorlogger` the app's push. The aiohttp server runs on its
own thread and event loop (edge/sources/background_server.py); what it decodes
(edge/decoders/phone/parse.py, samples.py) goes into a blocking queue that never drops
(edge/sources/threaded.py): when the consumer falls behind, the server stops reading, and the
phone's TCP connection slows down. Bad input is counted (`counters`), summarised in at most one WARNING per
WARN_EVERY_S and sent back to the page; it never stops the server.

URL query keys: `tls_dir` (the certificate folder, default `<venue file folder>/phone-tls`;
tls.py), `key_file` (the venue's stand key, default `<venue file folder>/<venue>.standkey`),
`http_port` (also serve the Sensor Logger push over plain HTTP on this port: the app does not
trust a self-signed certificate; 0 = an ephemeral port; absent = HTTPS only).

Registered as the `phone` scheme (edge/sources/registry.py), with the doctor's `check_phone`.
"""

from __future__ import annotations

import asyncio
import datetime
import errno
import json
import logging
import queue
import socket
import ssl
import threading
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

from aiohttp import WSMsgType, web

from protocol import messages
from protocol.errors import ConfigError
from protocol.session import Session
from protocol.stand_code import scan_message
from edge.sources.phone.stand_key import key_path as stand_key_path
from edge.sources.phone.stand_key import load_key
from edge.sources.background_server import BackgroundServer
from edge.sources.phone import tls as phone_tls
from edge.sources.registry import CheckRequest, Finding, Level, OpenRequest, Scheme, live_session
from edge.sources.threaded import ThreadedSource
from edge.decoders.phone.parse import PhoneInputError, parse_browser, parse_sensor_logger
from edge.decoders.phone.qr_frame import QrFrameReader
from edge.decoders.phone.rotation import RotationUnitCheck
from edge.decoders.phone.samples import Aligner, Counters, MotionBatcher, PhoneSettings

log = logging.getLogger(__name__)

PAGE_DIR = Path(__file__).resolve().parent / "page"
URL_KEYS = ("tls_dir", "key_file", "http_port")
WARN_EVERY_S = 5.0
STOP_POLL_S = 0.1  # how often the server thread looks at the stop event


def parse_phone_url(url: str) -> tuple[str, int, dict[str, str]]:
    """(host, port, query options) of `phone://HOST:PORT?key=value`; ConfigError naming the URL."""
    parts = urlsplit(url)
    if parts.scheme != "phone" or not parts.hostname or parts.path not in ("", "/"):
        raise ConfigError(f"{url!r}: expected phone://HOST:PORT[?tls_dir=DIR&key_file=FILE&http_port=N]")
    try:
        port = parts.port
    except ValueError:
        raise ConfigError(f"{url!r}: the port must be a number 0-65535") from None
    if port is None:
        raise ConfigError(f"{url!r}: no port (phone://HOST:PORT, e.g. phone://0.0.0.0:8443)")
    options: dict[str, str] = {}
    for key, values in parse_qs(parts.query, keep_blank_values=True, strict_parsing=False).items():
        if key not in URL_KEYS:
            raise ConfigError(f"{url!r}: unknown key {key!r} (allowed: {', '.join(URL_KEYS)})")
        options[key] = values[-1]
    if "http_port" in options and not (options["http_port"].isdigit() and int(options["http_port"]) <= 65535):
        raise ConfigError(f"{url!r}: http_port {options['http_port']!r} must be a number 0-65535")
    return parts.hostname, port, options


class _Warnings:
    """At most one WARNING per `every_s`, saying how many problems it stands for."""

    def __init__(self, where: str, every_s: float = WARN_EVERY_S):
        self.where, self.every_s = where, every_s
        self._last = -float("inf")
        self._held = 0

    def add(self, problems: list[str]) -> str | None:
        """Log the newest problem if the limit allows; return what was logged (to tell the page)."""
        if not problems:
            return None
        self._held += len(problems)
        now = time.monotonic()
        if now - self._last < self.every_s:
            return None
        text = problems[-1] if self._held == 1 else f"{problems[-1]} (and {self._held - 1} more problems)"
        log.warning("%s: %s", self.where, text)
        self._last, self._held = now, 0
        return text


class PhoneSource(ThreadedSource):
    """One phone (one sensor of a pedestrian agent) as an iterable of ImuBatch and StandScan.

    The server starts in the constructor and is listening when it returns (`port`, `http_port`:
    the bound ports, useful with port 0); a port in use or a bad certificate folder raises
    ConfigError there. Iteration ends when `stop` is set or `close()` is called, after the held
    samples are flushed. One phone per source: two phones' clocks would interleave.
    """

    def __init__(self, url: str, session: Session, agent_id: str, sensor_id: str, stop: threading.Event,
                 venue_toml: Path | str | None = None, settings: PhoneSettings | None = None):
        self.host, requested_port, options = parse_phone_url(url)
        folder = Path(venue_toml).parent if venue_toml else Path.cwd()
        self.tls_dir = Path(options.get("tls_dir") or folder / "phone-tls")
        super().__init__(stop)  # blocks the server, never drops
        self.session, self.agent_id, self.sensor_id = session, agent_id, sensor_id
        self.venue = session.venue
        key_path = stand_key_path(folder, self.venue.name, options.get("key_file"))
        self.key: bytes | None = load_key(key_path) if self.venue.stands or key_path.exists() else None
        self.counters = Counters()
        self.batcher = MotionBatcher(agent_id, sensor_id, settings, self.counters)
        self.aligner = Aligner(self.batcher.settings, self.counters)
        self.rotation_check = RotationUnitCheck(self.batcher.settings.gap_ns)  # the page's rotationRate only
        self._warnings = _Warnings(f"phone {agent_id}/{sensor_id}")
        cert, key = phone_tls.ensure_certificate(self.tls_dir, self.host)
        context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
        context.load_cert_chain(cert, key)
        sites: list[tuple[str, int, ssl.SSLContext | None]] = [(self.host, requested_port, context)]
        if "http_port" in options:
            sites.append((self.host, int(options["http_port"]), None))
        self.server = BackgroundServer(repr(url), self._app, sites, self._until_stopped, self._flush)
        self.start(self.server.run, name=f"phone-{sensor_id}")  # an error after start-up reaches the consumer
        self.server.wait_listening()
        self.port = self.server.ports[0]
        self.http_port: int | None = self.server.ports[1] if len(sites) > 1 else None
        log.info("%s", self.addresses())

    # -- the consumer's side

    def addresses(self) -> str:
        """Where the phone goes: the page (and the Sensor Logger push, when listening)."""
        host = self.host if self.host not in ("0.0.0.0", "::") else "<this machine's address>"
        text = f"phone {self.agent_id}/{self.sensor_id}: open https://{host}:{self.port}/ on the phone"
        if self.http_port is not None:
            text += f"; Sensor Logger push to http://{host}:{self.http_port}/sensorlogger"
        return text

    def close(self) -> None:
        """Stop the server (returns at once); iterating then yields what is queued and the flushed
        samples, and ends. Nothing is dropped."""
        self.server.close()

    def __enter__(self) -> PhoneSource:
        return self

    def __exit__(self, *exc: Any) -> None:
        """Stop the server and wait for it; what the consumer did not take is discarded here (the
        consumer is leaving), so that a server blocked on a full queue can end."""
        self.server.close()
        self.leave()
        self.join()

    # -- the server thread

    def _app(self) -> web.Application:
        self._lock = asyncio.Lock()  # keeps messages in the order they were decoded
        app = web.Application(client_max_size=4 << 20)
        app.add_routes([web.get("/", self._page), web.get("/ca.pem", self._ca), web.get("/ws", self._ws),
                        web.post("/sensorlogger", self._sensor_logger), web.static("/static", PAGE_DIR / "static")])
        return app

    async def _until_stopped(self) -> None:
        while not (self.stop.is_set() or self.server.closing):
            await asyncio.sleep(STOP_POLL_S)

    async def _flush(self) -> None:
        """After the server has closed: the samples still held go out."""
        batches, problems = self.batcher.flush()
        self._warnings.add(problems)
        await self._put(batches)

    async def _put(self, items: list[Any]) -> None:
        async with self._lock:
            for item in items:
                try:
                    self.queue.put_nowait(item)
                except queue.Full:  # the consumer is behind: wait for it off the event loop
                    await asyncio.get_running_loop().run_in_executor(None, self.put, item)

    def _stamp(self, batches: list[Any], received_ns: int) -> list[Any]:
        for batch in batches:
            batch.received_ns = received_ns
        return batches

    async def _page(self, request: web.Request) -> web.FileResponse:
        return web.FileResponse(PAGE_DIR / "index.html")

    async def _ca(self, request: web.Request) -> web.FileResponse:
        return web.FileResponse(self.tls_dir / "ca.pem", headers={"Content-Type": "application/x-x509-ca-cert"})

    async def _ws(self, request: web.Request) -> web.WebSocketResponse:
        socket = web.WebSocketResponse(heartbeat=10.0, max_msg_size=4 << 20)
        await socket.prepare(request)
        log.info("phone %s/%s: page connected from %s", self.agent_id, self.sensor_id, request.remote)
        frames = QrFrameReader()  # per page: its camera frames and the code it last passed on
        async for message in socket:
            received_ns = time.time_ns()
            if message.type not in (WSMsgType.TEXT, WSMsgType.BINARY):
                continue
            self.counters.messages += 1
            try:
                kind, data = parse_browser(message.data)
            except PhoneInputError as error:
                self.counters.bad_messages += 1
                self._warnings.add([error.reason])
                await socket.send_json({"type": "problem", "text": error.reason})
                continue
            reply: dict[str, Any] = {"type": "ack", "samples": self.counters.samples_out}
            problems: list[str] = []
            if kind == "motion":
                self.rotation_check.motion(data)
                batches, problems = self.batcher.feed(data)
                await self._put(self._stamp(batches, received_ns))
                reply["samples"] = self.counters.samples_out
            elif kind == "orientation":
                self.counters.orientation += len(data)
                self.rotation_check.orientation(data, problems)
                self.batcher.gyro_scale = self.rotation_check.scale
            elif kind == "scan":
                reply = await self._scan(*data)
            elif kind == "frame":
                reply = await self._frame(frames, data, problems)
            told = self._warnings.add(problems)
            if told:
                reply["problem"] = told
            await socket.send_json(reply)
        log.info("phone %s/%s: page disconnected (%s; frames %s)", self.agent_id, self.sensor_id,
                 json.dumps(vars(self.counters)), json.dumps(vars(frames.counts)))
        return socket

    async def _frame(self, frames: QrFrameReader, data: tuple[int, bytes, int, int],
                     problems: list[str]) -> dict[str, Any]:
        """A camera frame: its code, if new, is scanned as a page's `scan` message is. The reply
        says what the frame gave (`frame`), which the page waits for before sending the next one.
        zxing-cpp takes a few ms on the page's frames: run inline, as the rest of the message."""
        time_ns, jpeg, width, height = data
        outcome, text = frames.feed(time_ns, jpeg, width, height, problems)
        if text is None:
            return {"type": "frame_result", "frame": outcome.value, "samples": self.counters.samples_out}
        return {**await self._scan(time_ns, text), "frame": outcome.value}

    async def _scan(self, time_ns: int, text: str) -> dict[str, Any]:
        self.counters.scans += 1
        if self.key is None:
            scan = messages.new("StandScan", timestamp_ns=time_ns, agent_id=self.agent_id, sensor_id=self.sensor_id,
                                payload=text, accepted=False, reason=f"venue {self.venue.name!r} has no stand key "
                                f"on this edge (no stands in the venue file)")
        else:
            scan = scan_message(text, time_ns, self.agent_id, self.sensor_id, self.venue.name, self.key,
                                self.venue.stands)
        await self._put([scan])
        if not scan.accepted:
            log.info("phone %s/%s: scan refused: %s", self.agent_id, self.sensor_id, scan.reason)
        return {"type": "scan_result", "accepted": scan.accepted, "reason": scan.reason, "stand_id": scan.stand_id,
                "text": text}

    async def _sensor_logger(self, request: web.Request) -> web.Response:
        received_ns = time.time_ns()
        self.counters.messages += 1
        try:
            streams, ignored = parse_sensor_logger(await request.read())
        except PhoneInputError as error:
            self.counters.bad_messages += 1
            self._warnings.add([error.reason])
            return web.json_response({"accepted": False, "reason": error.reason}, status=400)
        self.counters.ignored_names += ignored
        problems: list[str] = []
        samples = self.aligner.feed(streams, problems)
        batches, more = self.batcher.feed(samples)
        await self._put(self._stamp(batches, received_ns))
        self._warnings.add(problems + more)
        return web.json_response({"accepted": True, "samples": self.counters.samples_out,
                                  "problems": len(problems) + len(more)})


def open_phone(request: OpenRequest) -> tuple[Session, Iterable[Any]]:
    """`SENSOR=phone://HOST:PORT[?...]`: one per edge, alone (a phone's samples carry its own clock)."""
    if len(request.specs) != 1:
        raise ConfigError(f"--source {request.specs[1].given!r}: a phone source goes alone, one per edge (its "
                          "samples carry the phone's clock)")
    spec = request.specs[0]
    session, _ = live_session(request, "a phone source", "it names the agent's sensor, the stands and where their "
                              "key is")
    return session, PhoneSource(spec.url, session, request.agent_id, spec.sensor_id, request.stop, request.venue_toml)


def check_phone(request: CheckRequest) -> list[Finding]:
    """The port is free, the TLS certificate is there and valid, and the stand key if the venue has stands."""
    host, port, options = parse_phone_url(request.url)
    try:
        with socket.create_server((host, port)):
            pass
    except OSError as error:
        why = {errno.EADDRINUSE: f"port {port} is in use (another edge or server?)",
               errno.EACCES: f"no permission to listen on port {port} (below 1024)",
               errno.EADDRNOTAVAIL: f"{host} is not an address of this machine"}.get(error.errno, str(error))
        return [Finding(Level.FAIL, why, "choose another HOST:PORT, or stop what uses it")]
    folder = request.venue.parent if request.venue else Path.cwd()
    tls_dir = Path(options.get("tls_dir") or folder / "phone-tls")
    cert = tls_dir / "cert.pem"
    findings: list[Finding] = []
    if not cert.exists():
        findings.append(Finding(Level.WARN, f"port {port} free; no certificate yet in {tls_dir}",
                                "the edge makes one at its first start; each phone then trusts /ca.pem once "
                                "(docs/phone.md)"))
    else:
        days = _days_left(cert)
        level = Level.OK if days > 30 else Level.WARN
        findings.append(Finding(level, f"port {port} free; certificate {cert} valid {days:.0f} more days",
                                "" if level is Level.OK else "the edge issues a new one at its next start"))
    session = request.session
    key_file = stand_key_path(folder, session.venue.name, options.get("key_file")) if session else None
    if session is not None and session.venue.stands and key_file is not None and not key_file.exists():
        findings.append(Finding(Level.FAIL, f"the venue has QR stands but no stand key at {key_file}",
                                "`reckon qr make VENUE.toml -o DIR` creates it, or give ?key_file="))
    return findings


def _days_left(cert: Path) -> float:
    from cryptography import x509

    ends = x509.load_pem_x509_certificate(cert.read_bytes()).not_valid_after_utc
    return (ends - datetime.datetime.now(datetime.UTC)).total_seconds() / 86400.0


SCHEME = Scheme("phone", "SENSOR=phone://HOST:PORT", open_phone, check_phone)
