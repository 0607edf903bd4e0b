"""The hub's live court view: a web page (reckon/web/static/) fed over a WebSocket at ~10 Hz.

    with CourtView(session, "127.0.0.1", 8080) as view:
        run_hub(config, session, stop, on_input=view.on_input, on_output=view.on_output, on_bus=view.attach)

Why it can never slow the hub: the hub thread only appends to a bounded deque (`on_input`,
`on_output`: O(1), no lock, no wait; when the view falls `HANDOVER` messages behind the oldest
are dropped and counted). Truth poses and device status, which the hub does not subscribe to,
come from the view's own subscribers on the hub's Zenoh session with ring handlers (drop oldest,
never push back on a publisher). The view's thread runs an aiohttp server on its own event loop
(edge/sources/background_server.py, shared with the phone source);
every TICK_S it drains both into `ViewState` (fixed size, reckon/web/court_state.py), builds one
JSON snapshot (coalescing: however many poses came, the page gets the latest) and wakes each
browser's sender, which sends the newest snapshot when its socket is free: a slow browser skips
snapshots and delays only itself.

Routes: `/` the page, `/static/...`, `/venue.json` (drawn once), `/state.json` (the latest
snapshot), `/ws` (the venue, then the newest snapshot each tick).
"""

from __future__ import annotations

import asyncio
import json
import logging
import threading
import time
from collections import deque
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web

from edge.sources.background_server import BackgroundServer
from protocol import bus as wire
from protocol import keys
from protocol.errors import ConfigError, InputError
from protocol.session import Session
from reckon.transport.bus import BusSession, DirectSubscription
from reckon.web.court_state import ViewState, venue_description

log = logging.getLogger(__name__)

STATIC_DIR = Path(__file__).resolve().parent / "static"
TICK_S = 0.1  # 10 Hz: smooth to the eye, a few kB per tick per browser
HANDOVER = 16384  # messages held between the hub thread and the view (a second of 300 agents at 50 Hz)
RING = 4096  # samples each of the view's own Zenoh subscribers holds between ticks
SKIPPED_STREAMS = ("ImuBatch", "CameraFrame", "ImpactEvent", "BeaconSighting", "Pressure")  # only their arrival is shown


def parse_view_address(text: str) -> tuple[str, int]:
    """(host, port) of `--view HOST:PORT` (port 0: any free one); ConfigError naming the value."""
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or int(port) > 65535:
        raise ConfigError(f"--view {text!r}: expected HOST:PORT with a port 0-65535, e.g. 127.0.0.1:8080")
    return host.strip("[]"), int(port)


class CourtView:
    """The view's server, listening when the constructor returns (`port`; ConfigError if it cannot).

    `on_input(message)` / `on_output(message)`: the hub's hooks, callable from any one thread.
    `attach(bus)`: a context manager that subscribes to truth and status on the hub's session.
    `close()` (or leaving `with`) stops the server.
    """

    def __init__(self, session: Session, host: str = "127.0.0.1", port: int = 8080, ring: int = HANDOVER):
        self.session, self.host = session, host
        self.venue_json = json.dumps(venue_description(session))
        self.state = ViewState(session)
        self._handover: deque[tuple[int, Any, bool]] = deque(maxlen=ring)
        self._last_input: dict[str, int] = {}  # agent -> arrival of a message kept out of the hand-over
        self.handed = 0  # written by the hub thread only
        self.taken = 0  # written by the view thread only
        self.bad_samples = 0
        self.snapshot_json = json.dumps(self.state.snapshot(time.time_ns()))
        self.ticks = 0
        self._subscribers: list[Any] = []
        self._subscribers_lock = threading.Lock()
        self.server = BackgroundServer(f"--view {host}:{port}", self._app, [(host, port, None)], self._tick)
        self._thread = threading.Thread(target=self._run, name="court-view", daemon=True)
        self._thread.start()
        self.server.wait_listening()
        self.port = self.server.ports[0]
        log.info("court view: %s", self.url)

    @property
    def url(self) -> str:
        host = self.host if self.host not in ("0.0.0.0", "::") else "<this machine's address>"
        return f"http://{host}:{self.port}/"

    @property
    def dropped(self) -> int:
        """Messages the hub handed over that the view never took (it fell behind)."""
        return max(0, self.handed - self.taken - len(self._handover))

    # -- the hub's side: never blocks, never raises for the view's sake

    def on_input(self, message: Any) -> None:
        if message.DESCRIPTOR.name in SKIPPED_STREAMS:
            agent_id = getattr(message, "agent_id", "")
            if agent_id in self.state.agents:
                self._last_input[agent_id] = time.time_ns()  # one dict store: atomic under the GIL
            return
        self._offer(message, True)

    def on_output(self, message: Any) -> None:
        self._offer(message, False)

    def _offer(self, message: Any, is_input: bool) -> None:
        self._handover.append((time.time_ns(), message, is_input))
        self.handed += 1

    @contextmanager
    def attach(self, bus: BusSession) -> Iterator[None]:
        """Subscribe to every agent's truth pose and device status on `bus` until the block ends."""
        venue = self.session.venue.name
        declared = [DirectSubscription.ring(bus, keys.all_agents(venue, stream), RING)
                    for stream in ("truth/pose", "status/*")]
        with self._subscribers_lock:
            self._subscribers = declared
        try:
            yield
        finally:
            with self._subscribers_lock:
                self._subscribers = []
            for subscriber in declared:
                subscriber.undeclare()

    # -- the view's thread

    def drain(self) -> None:
        """Move what arrived into the state. Runs on the view's thread."""
        now = time.time_ns()
        while self._handover:
            received_ns, message, is_input = self._handover.popleft()
            self.taken += 1
            self.state.apply(message, received_ns, is_input)
        for agent_id in list(self._last_input):  # list(): the hub thread may add keys meanwhile
            received_ns = self._last_input.pop(agent_id)
            agent = self.state.agents[agent_id]
            agent.last_input_ns = max(agent.last_input_ns or 0, received_ns)
        with self._subscribers_lock:
            subscribers = list(self._subscribers)
        for subscriber in subscribers:
            while (sample := subscriber.try_get()) is not None:
                try:
                    message = wire.decode(sample.encoding, sample.payload, sample.key)
                except InputError:
                    self.bad_samples += 1
                    continue
                self.state.apply(message, now)
        self.state.score()

    def publish_snapshot(self) -> str:
        """Build the page's snapshot now (ages move on every tick, so there is one per tick)."""
        snapshot = self.state.snapshot(time.time_ns())
        snapshot["dropped"], snapshot["bad_samples"] = self.dropped, self.bad_samples
        self.snapshot_json = json.dumps(snapshot)
        self.ticks += 1
        return self.snapshot_json

    def _run(self) -> None:
        try:
            self.server.run()
        except BaseException as error:  # before start-up the constructor raises it (wait_listening); after: logged
            log.error("court view stopped: %s", error)

    def _app(self) -> web.Application:
        self._fresh = asyncio.Condition()
        self._sockets: set[web.WebSocketResponse] = set()
        app = web.Application()
        app.on_shutdown.append(self._close_sockets)
        app.add_routes([web.get("/", self._page), web.get("/venue.json", self._venue), web.get("/state.json", self._state),
                        web.get("/ws", self._ws), web.static("/static", STATIC_DIR)])
        return app

    async def _tick(self) -> None:
        """While the server listens: every TICK_S, take what arrived and wake the browsers' senders."""
        while not self.server.closing:
            await asyncio.sleep(TICK_S)
            self.drain()
            self.publish_snapshot()
            async with self._fresh:
                self._fresh.notify_all()

    async def _page(self, request: web.Request) -> web.FileResponse:
        return web.FileResponse(STATIC_DIR / "index.html")

    async def _venue(self, request: web.Request) -> web.Response:
        return web.Response(text=self.venue_json, content_type="application/json")

    async def _state(self, request: web.Request) -> web.Response:
        return web.Response(text=self.snapshot_json, content_type="application/json")

    async def _ws(self, request: web.Request) -> web.WebSocketResponse:
        socket = web.WebSocketResponse(heartbeat=10.0)
        await socket.prepare(request)
        self._sockets.add(socket)
        sender = asyncio.create_task(self._send_snapshots(socket))
        try:
            async for message in socket:  # the page sends nothing; this notices it leaving
                if message.type == WSMsgType.ERROR:
                    break
        finally:
            sender.cancel()
            self._sockets.discard(socket)
        return socket

    async def _close_sockets(self, app: web.Application) -> None:
        for socket in list(self._sockets):  # else the server's shutdown waits for the browsers to leave
            await socket.close(code=1001, message=b"hub stopping")

    async def _send_snapshots(self, socket: web.WebSocketResponse) -> None:
        try:
            await socket.send_str(self.venue_json)
            sent = None
            while not socket.closed:
                if sent is not self.snapshot_json:
                    sent = self.snapshot_json  # the newest; those built while this socket was busy are skipped
                    await socket.send_str(sent)
                async with self._fresh:
                    await self._fresh.wait()
        except ConnectionError:  # the browser left mid-send: its handler ends with the socket
            return

    def close(self) -> None:
        self.server.close()
        self._thread.join(timeout=5.0)

    def __enter__(self) -> CourtView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
