"""A phone as an edge source: `SENSOR=phone://HOST:PORT` serves the browser page over HTTPS and
takes the Sensor Logger app's HTTP push (docs/phone.md).

    with PhoneSource("phone://0.0.0.0:8443", session, "walker", "phone", stop, venue_toml=path) as source:
        for message in source:   # ImuBatch and StandScan, in arrival order
            ...

Routes: `/` the page (edge/sources/phone/page/), `/static/...`, `/ca.pem` (the CA a phone trusts once),
`/ws` the page's WebSocket, `POST /sensorlogger` the app's push. The aiohttp server runs on its
own thread and event loop; what it decodes (edge/decoders/phone/parse.py, phone_samples.py) goes into a blocking queue
that never drops: when the consumer falls behind, the server stops reading, and the phone's TCP
connection slows down. Bad input is counted (`counters`), summarised in at most one WARNING per
WARN_EVERY_S and sent back to the page; it never stops the server.

URL query keys: `tls_dir` (the certificate folder, default `<venue file folder>/phone-tls`;
phone_tls.py), `key_file` (the venue's stand key, default `<venue file folder>/<venue>.standkey`),
`http_port` (also serve the Sensor Logger push over plain HTTP on this port: the app does not
trust a self-signed certificate; 0 = an ephemeral port; absent = HTTPS only).
"""

from __future__ import annotations

import asyncio
import json
import logging
import queue
import ssl
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

from aiohttp import WSMsgType, web

from protocol import messages
from protocol.errors import ConfigError
from protocol.session import Session
from protocol.stand_code import load_key, scan_message
from edge.sources.phone import tls as phone_tls
from edge.decoders.phone.parse import PhoneInputError, parse_browser, parse_sensor_logger
from edge.decoders.phone.rotation import RotationUnitCheck
from edge.decoders.phone.samples import Aligner, Counters, MotionBatcher, PhoneSettings

log = logging.getLogger(__name__)

PAGE_DIR = Path(__file__).resolve().parent / "page"
URL_KEYS = ("tls_dir", "key_file", "http_port")
WARN_EVERY_S = 5.0
QUEUE_SIZE = 1000
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


class PhoneSource:
    """One phone (one sensor of a pedestrian agent) as an iterable of ImuBatch and StandScan.

    The server starts in the constructor and is listening when it returns (`port`, `http_port`:
    the bound ports, useful with port 0); a port in use or a bad certificate folder raises
    ConfigError there. Iteration ends when `stop` is set or `close()` is called, after the held
    samples are flushed. One phone per source: two phones' clocks would interleave.
    """

    _DONE = object()

    def __init__(self, url: str, session: Session, agent_id: str, sensor_id: str, stop: threading.Event,
                 venue_toml: Path | str | None = None, settings: PhoneSettings | None = None):
        self.host, requested_port, options = parse_phone_url(url)
        folder = Path(venue_toml).parent if venue_toml else Path.cwd()
        self.tls_dir = Path(options.get("tls_dir") or folder / "phone-tls")
        self.session, self.agent_id, self.sensor_id, self.stop = session, agent_id, sensor_id, stop
        self.venue = session.venue
        key_path = Path(options.get("key_file") or folder / f"{self.venue.name}.standkey")
        self.key: bytes | None = load_key(key_path) if self.venue.stands or key_path.exists() else None
        self.counters = Counters()
        self.batcher = MotionBatcher(agent_id, sensor_id, settings, self.counters)
        self.aligner = Aligner(self.batcher.settings, self.counters)
        self.rotation_check = RotationUnitCheck(self.batcher.settings.gap_ns)  # the page's rotationRate only
        self.queue: queue.Queue[Any] = queue.Queue(maxsize=QUEUE_SIZE)  # blocks the server, never drops
        self._warnings = _Warnings(f"phone {agent_id}/{sensor_id}")
        self._closing = threading.Event()
        self._started = threading.Event()
        self._error: BaseException | None = None
        self.port = 0
        self.http_port: int | None = None
        cert, key = phone_tls.ensure_certificate(self.tls_dir, self.host)
        self._ssl = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
        self._ssl.load_cert_chain(cert, key)
        self._plain_port = int(options["http_port"]) if "http_port" in options else None
        self._thread = threading.Thread(target=self._run, args=(requested_port,), name=f"phone-{sensor_id}",
                                        daemon=True)
        self._thread.start()
        self._started.wait()
        if self._error is not None:
            raise ConfigError(f"{url!r}: cannot listen ({self._error})") from self._error
        log.info("%s", self.addresses())

    # -- the consumer's side

    def addresses(self) -> str:
        """Where the phone goes: the page (and the Sensor Logger push, when listening)."""
        host = self.host if self.host not in ("0.0.0.0", "::") else "<this machine's address>"
        text = f"phone {self.agent_id}/{self.sensor_id}: open https://{host}:{self.port}/ on the phone"
        if self.http_port is not None:
            text += f"; Sensor Logger push to http://{host}:{self.http_port}/sensorlogger"
        return text

    def __iter__(self) -> Iterator[Any]:
        while True:
            item = self.queue.get()
            if item is self._DONE:
                return
            if isinstance(item, BaseException):
                raise item
            yield item

    def close(self) -> None:
        """Stop the server (returns at once); iterating then yields what is queued and the flushed
        samples, and ends. Nothing is dropped."""
        self._closing.set()

    def __enter__(self) -> PhoneSource:
        return self

    def __exit__(self, *exc: Any) -> None:
        """Stop the server and wait for it; what the consumer did not take is discarded here (the
        consumer is leaving), so that a server blocked on a full queue can end."""
        self._closing.set()
        while self._thread.is_alive():
            try:
                self.queue.get(timeout=STOP_POLL_S)
            except queue.Empty:
                pass

    # -- the server thread

    def _run(self, requested_port: int) -> None:
        try:
            asyncio.run(self._serve(requested_port))
        except BaseException as error:  # handed to the consumer (or the constructor), raised there
            if not self._started.is_set():
                self._error = error
                self._started.set()
                return
            self.queue.put(error)
        self.queue.put(self._DONE)

    async def _serve(self, requested_port: int) -> None:
        self._lock = asyncio.Lock()  # keeps messages in the order they were decoded
        app = web.Application(client_max_size=4 << 20)
        app.add_routes([web.get("/", self._page), web.get("/ca.pem", self._ca), web.get("/ws", self._ws),
                        web.post("/sensorlogger", self._sensor_logger), web.static("/static", PAGE_DIR / "static")])
        runner = web.AppRunner(app, access_log=None, handle_signals=False)
        await runner.setup()
        try:
            site = web.TCPSite(runner, self.host, requested_port, ssl_context=self._ssl)
            await site.start()
            self.port = site._server.sockets[0].getsockname()[1]  # type: ignore[union-attr]
            if self._plain_port is not None:
                plain = web.TCPSite(runner, self.host, self._plain_port)
                await plain.start()
                self.http_port = plain._server.sockets[0].getsockname()[1]  # type: ignore[union-attr]
            self._started.set()
            while not (self.stop.is_set() or self._closing.is_set()):
                await asyncio.sleep(STOP_POLL_S)
        finally:
            await runner.cleanup()
        batches, problems = self.batcher.flush()
        self._warnings.add(problems)
        await self._put(batches)

    async def _put(self, items: list[Any]) -> None:
        async with self._lock:
            for item in items:
                try:
                    self.queue.put_nowait(item)
                except queue.Full:  # the consumer is behind: wait for it off the event loop
                    await asyncio.get_running_loop().run_in_executor(None, self.queue.put, item)

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
            told = self._warnings.add(problems)
            if told:
                reply["problem"] = told
            await socket.send_json(reply)
        log.info("phone %s/%s: page disconnected (%s)", self.agent_id, self.sensor_id, json.dumps(vars(self.counters)))
        return socket

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


def open_phone_source(urls: list[str], agent_id: str, stop: threading.Event,
                      venue_toml: Path | None) -> tuple[Session, PhoneSource]:
    """(session, source) for the edge's `--source SENSOR=phone://HOST:PORT[?...]` (one per edge,
    alone: a phone's samples carry its own clock). ConfigError naming the --source otherwise."""
    from reckon.processes.edge import _check_agent, session_description

    phones = [url for url in urls if urlsplit(url.partition("=")[2]).scheme == "phone"]
    if len(urls) != 1:
        other = next((url for url in urls if url not in phones), phones[-1])
        raise ConfigError(f"--source {other!r}: a phone source goes alone, one per edge (its samples carry the "
                          "phone's clock)")
    sensor_id, _, url = urls[0].partition("=")
    if venue_toml is None:
        raise ConfigError("--venue VENUE.toml is needed with a phone source (it names the agent's sensor, the "
                          "stands and where their key is)")
    session = session_description(venue_toml)
    agent = _check_agent(session, agent_id, str(venue_toml))
    known = {s.id for s in agent.sensors}
    if sensor_id not in known:
        raise ConfigError(f"--source {urls[0]!r}: {agent_id} has no sensor {sensor_id!r} "
                          f"(sensors: {', '.join(sorted(known)) or 'none'})")
    return session, PhoneSource(url, session, agent_id, sensor_id, stop, venue_toml)
