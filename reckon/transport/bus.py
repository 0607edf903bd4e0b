"""Zenoh I/O adapter: session config and lifetime, publishing, lossless subscriptions, ready signals.

The wire format (payloads, encodings, control keys) is `protocol.bus`; this module only moves
bytes. Rules it follows (field-notes.md, Zenoh section):

- Explicit tcp endpoints, multicast and gossip scouting off: opening takes milliseconds and
  works in containers. Default endpoint `tcp/127.0.0.1:7447` (Zenoh's usual port on loopback):
  the hub and the recorder *listen* on it, edges and the replayer *connect* to it. A real venue
  passes its own, e.g. listen `tcp/0.0.0.0:7447` on the hub, connect `tcp/<hub ip>:7447` on a Pi.
- Every session is closed (`open_session` is a context manager): a subscriber left declared at
  interpreter exit hangs it.
- Measurements are never dropped: publishers use CongestionControl.BLOCK and a `Subscription`
  moves samples from a Zenoh FIFO into a bounded `queue.Queue` on its own thread, blocking when
  the queue is full. A slow consumer therefore slows the publisher down (back-pressure) instead
  of losing data. `PolledSubscription` (the hub's) has no thread: its consumer empties the Zenoh
  FIFOs itself, in batches, and a full FIFO holds the publishers back the same way. Limit: Zenoh closes a link whose transmit queue stays blocked for
  `transport.link.tx.queue.congestion_control.block.wait_before_close` (5 s by default), so a
  consumer must not stall for seconds. Nothing here blocks inside a Zenoh callback.
- Tests and start-up wait on ready signals (liveliness tokens, flush replies), never on sleep.
"""

from __future__ import annotations

import json
import logging
import math
import queue
import re
import threading
import time
from collections import deque
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import json5
import zenoh

from protocol import bus as wire
from protocol.errors import ConfigError, ReckonError

log = logging.getLogger(__name__)

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
MODES = ("peer", "client", "router")
_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic|unixsock-stream|ws)/\S+$")
RETRY_INIT_MS = 250  # first reconnect after 250 ms (Zenoh's default 1 s): an edge started before
RETRY_MAX_MS = 2000  # its hub joins within 2 s of the hub coming up (Zenoh's default 4 s)
QUEUE_CAPACITY = 1024  # samples held between the Zenoh FIFO and the consumer (~1 MB of ImuBatch)
FIFO_CAPACITY = 256  # Zenoh's default FIFO size
POLL_S = 0.1  # how often a blocked hand-over re-checks whether the subscription is closing


class BusError(ReckonError):
    """A Zenoh session cannot be opened, or a peer did not show up in time."""


def zenoh_config(mode: str = "peer", listen: Sequence[str] = (), connect: Sequence[str] = (),
                 timestamping: bool = True) -> zenoh.Config:
    """A Zenoh config with explicit endpoints and no scouting.

    mode: `peer` (default; every process talks directly to the ones it connects to or accepts),
      `client` (only through a router), `router` (relays for clients).
    listen: endpoints to accept connections on, e.g. `tcp/127.0.0.1:7447` (hub, recorder).
    connect: endpoints to dial, e.g. `tcp/127.0.0.1:7447` (edges, replayer); a peer that finds
      nobody keeps retrying in the background (250 ms, doubling to 2 s).
    timestamping: stamp every sample this session publishes with its hybrid logical clock, so a
      subscriber sees when it left (`Received.source_ns`).
    ConfigError when the mode is unknown, an endpoint is malformed, or there is no endpoint at
    all (with scouting off such a session could never meet anyone).
    """
    _check_mode_and_endpoints(mode, listen, connect)
    if not listen and not connect:
        raise ConfigError("zenoh config: no listen and no connect endpoint (scouting is off, so "
                          f"give at least one, e.g. listen {DEFAULT_ENDPOINT})")
    retry = {"period_init_ms": RETRY_INIT_MS, "period_max_ms": RETRY_MAX_MS, "period_increase_factor": 2}
    document = {
        "mode": mode,
        "listen": {"endpoints": list(listen)},
        "connect": {"endpoints": list(connect), "retry": retry},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "timestamping": {"enabled": bool(timestamping)},
    }
    return zenoh.Config.from_json5(json.dumps(document))


def _check_mode_and_endpoints(mode: str, listen: Sequence[str], connect: Sequence[str]) -> None:
    if mode not in MODES:
        raise ConfigError(f"zenoh mode {mode!r} is not one of {', '.join(MODES)}")
    for where, endpoints in (("listen", listen), ("connect", connect)):
        if isinstance(endpoints, str):
            raise ConfigError(f"zenoh {where}: expected a list of endpoints, got the string {endpoints!r}")
        for endpoint in endpoints:
            if not _ENDPOINT.match(endpoint):
                raise ConfigError(f"zenoh {where} endpoint {endpoint!r} is not <protocol>/<address>, "
                                  f"e.g. {DEFAULT_ENDPOINT}")


# What a config file gets from us unless it sets the key itself: the same as `zenoh_config`.
FILE_DEFAULTS = {"scouting/multicast/enabled": False, "scouting/gossip/enabled": False, "timestamping/enabled": True}
# Keys of a config file that name files Zenoh opens only when the session starts: checked at once.
FILE_PATH_KEYS = ("transport/link/tls/root_ca_certificate", "transport/link/tls/listen_private_key",
                  "transport/link/tls/listen_certificate", "transport/link/tls/connect_private_key",
                  "transport/link/tls/connect_certificate", "transport/auth/usrpwd/dictionary_file")


def zenoh_config_from_file(path: str | Path, mode: str | None = None, listen: Sequence[str] = (),
                           connect: Sequence[str] = ()) -> zenoh.Config:
    """A Zenoh config from a JSON5 file (a venue's router, hub or edge config, e.g. deploy/zenoh/).

    Loaded with `zenoh.Config.from_file`, so every key is Zenoh's own (schema of eclipse-zenoh 1.10).
    Where the file is silent, scouting stays off and timestamping on, as in `zenoh_config`; what
    the file sets wins. `mode`, `listen` and `connect` (from the command line) replace the file's
    values when given. ConfigError naming the file and the problem when it cannot be read, is not
    JSON5, has a key or value Zenoh refuses, names a certificate or password file that does not
    exist, or an override is malformed.
    """
    path = Path(path)
    if path.suffix not in (".json5", ".json"):
        raise ConfigError(f"zenoh config {path}: expected a .json5 or .json file")
    try:
        document = json5.loads(path.read_text(encoding="utf-8"))
    except OSError as error:
        raise ConfigError(f"zenoh config {path}: cannot read it ({error.strerror})") from None
    except ValueError as error:
        raise ConfigError(f"zenoh config {path}: not valid JSON5: {error}") from None
    if not isinstance(document, dict):
        raise ConfigError(f"zenoh config {path}: expected an object {{...}} at the top, got {type(document).__name__}")
    try:
        config = zenoh.Config.from_file(str(path))
    except zenoh.ZError as error:
        raise ConfigError(f"zenoh config {path}: {_without_source_location(error)}") from None
    for key, value in FILE_DEFAULTS.items():
        if _lookup(document, key) is None:
            config.insert_json5(key, json.dumps(value))
    _check_mode_and_endpoints(mode or "peer", listen, connect)
    for key, value in (("mode", mode), ("listen/endpoints", list(listen)), ("connect/endpoints", list(connect))):
        if value:
            config.insert_json5(key, json.dumps(value))
    for key in FILE_PATH_KEYS:
        named = _lookup(document, key)
        if named is not None and not Path(named).is_file():
            raise ConfigError(f"zenoh config {path}: {key} names {named!r}, which is not a file")
    return config


def _lookup(document: dict[str, Any], key: str) -> Any:
    """The value at a `a/b/c` key path of a parsed config file, or None where it is not set."""
    value: Any = document
    for part in key.split("/"):
        if not isinstance(value, dict):
            return None
        value = value.get(part)
    return value


def _without_source_location(error: zenoh.ZError) -> str:
    """Zenoh's message without the ` at /root/.cargo/...rs:123.` of the Rust code that raised it."""
    return re.sub(r"\s+at \S+\.rs:\d+\.?$", "", str(error).strip())


@contextmanager
def open_session(config: zenoh.Config) -> Iterator[zenoh.Session]:
    """Open a Zenoh session and always close it. BusError if it cannot open (e.g. port in use)."""
    try:
        session = zenoh.open(config)
    except zenoh.ZError as error:
        raise BusError(f"cannot open zenoh session (listen {config.get_json('listen/endpoints')}, "
                       f"connect {config.get_json('connect/endpoints')}): {error}") from None
    try:
        yield session
    finally:
        session.close()


def source_ns(sample: zenoh.Sample) -> int | None:
    """Publisher's clock at the put (ns since the Unix epoch), or None if it did not stamp."""
    stamp = sample.timestamp
    return None if stamp is None else int(stamp.get_time_as_ntp64().as_nanos())


# ---------------------------------------------------------------------------------------------
# Publishing


class Publisher:
    """Publish protocol messages on their keys with `Session.put`, congestion control BLOCK: when the
    link is full `publish` waits rather than drops.

    No Zenoh publisher or key expression is declared per key. Measured with eclipse-zenoh 1.10 on
    the bench VM (docs/benchmarks.md, Load): a process holding a declared publisher or key
    expression per key (the hub: live, refined and correction keys of 500 agents) spent about
    50 µs of its Zenoh receive thread on every sample it received, against 3 µs with plain puts;
    a put costs the publishing thread the same either way. Each key's `KeyExpr` is built (and
    checked) once and kept, as is each encoding's `Encoding`.
    """

    def __init__(self, session: zenoh.Session):
        self._session = session
        self._keys: dict[str, zenoh.KeyExpr] = {}
        self._zenoh_encodings: dict[str, zenoh.Encoding] = {}
        self._encodings: dict[type, str] = {}  # message class -> its encoding (wire.encode's answer)
        self._block = zenoh.CongestionControl.BLOCK
        self.sent = 0

    def publish(self, key: str, message: Any) -> None:
        encoding = self._encodings.get(type(message))
        if encoding is None:
            payload, encoding = wire.encode(message)
            self._encodings[type(message)] = encoding
        else:
            payload = message.SerializeToString()
        self.publish_bytes(key, payload, encoding)

    def publish_bytes(self, key: str, payload: bytes, encoding: str) -> None:
        """Publish an already-encoded payload (the replayer's path: no decode and re-encode)."""
        key_expr = self._keys.get(key)
        if key_expr is None:
            try:
                key_expr = self._keys[key] = zenoh.KeyExpr(key)
            except zenoh.ZError as error:
                raise BusError(f"cannot publish on key {key!r}: {error}") from None
        zenoh_encoding = self._zenoh_encodings.get(encoding)
        if zenoh_encoding is None:
            zenoh_encoding = self._zenoh_encodings[encoding] = zenoh.Encoding(encoding)
        try:
            self._session.put(key_expr, payload, encoding=zenoh_encoding, congestion_control=self._block)
        except zenoh.ZError as error:
            raise BusError(f"cannot publish on key {key!r}: {error}") from None
        self.sent += 1

    def close(self) -> None:
        self._keys.clear()

    def __enter__(self) -> "Publisher":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# ---------------------------------------------------------------------------------------------
# Subscribing


class Received(NamedTuple):
    """One sample, copied out of Zenoh: bytes and strings only. (A named tuple: built for every
    sample the hub takes, it costs a third of a frozen dataclass.)"""

    key: str
    payload: bytes
    encoding: str
    delete: bool  # a DELETE sample (e.g. the end-of-session marker), not a PUT
    received_ns: int  # this process's wall clock when the sample left Zenoh's FIFO (polled: its sweep began)
    source_ns: int | None  # the publisher's clock at the put, when it stamps samples

    def decode(self) -> Any:
        """The protocol message; InputError for a foreign encoding or bad bytes."""
        cls = _DECODERS.get(self.encoding)
        if cls is not None:
            try:
                return cls.FromString(self.payload)
            except Exception:  # noqa: BLE001 - protobuf's DecodeError; wire.decode says what is wrong
                pass
        message = wire.decode(self.encoding, self.payload, where=self.key)
        _DECODERS[self.encoding] = type(message)
        return message


_DECODERS: dict[str, Any] = {}  # encoding -> protobuf class, for encodings `wire.decode` accepted


@dataclass
class SubscriptionStats:
    received: int = 0  # samples taken out of Zenoh
    delivered: int = 0  # samples handed to the consumer
    full_waits: int = 0  # times the queue was full and the hand-over had to wait (back-pressure)
    max_depth: int = 0  # deepest the queue has been
    discarded: int = 0  # samples dropped because the subscription was closed before delivery


_END = object()


class Subscription:
    """Samples of `selector`, oldest first, none dropped while the subscription is open.

    A Zenoh FIFO handler (`fifo_capacity`) feeds a drain thread that copies each sample into a
    `queue.Queue(capacity)`; when that queue is full the drain thread waits, the FIFO fills, and
    Zenoh pushes back on the publisher. `get` returns the next sample, raises `queue.Empty` after
    `timeout` seconds, and returns None once `undeclare` was called and everything received
    before it has been delivered. `close` (also on leaving `with`) stops at once and discards
    what was not delivered (counted in `stats.discarded`).
    """

    def __init__(self, session: zenoh.Session, selector: str | Sequence[str], capacity: int = QUEUE_CAPACITY,
                 fifo_capacity: int = FIFO_CAPACITY):
        selectors = [selector] if isinstance(selector, str) else list(selector)
        if capacity < 1 or fifo_capacity < 1 or not selectors:
            raise ConfigError(f"subscription {selector!r}: capacity {capacity} and fifo_capacity "
                              f"{fifo_capacity} must be at least 1, and a selector is needed")
        self.selector = ", ".join(selectors)
        self.stats = SubscriptionStats()
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=capacity)
        self._closing = threading.Event()
        self._ended = False
        self._running = len(selectors)  # drain threads still delivering
        self._undeclared = False
        self._threads: list[threading.Thread] = []
        # several selectors (a union) share the one queue, each with its drain thread
        self._subscribers, handlers = _declare_fifos(session, selectors, fifo_capacity)
        for one, handler in zip(selectors, handlers):
            self._threads.append(threading.Thread(target=self._drain, args=(handler,), daemon=True, name=f"drain {one}"))
        for thread in self._threads:
            thread.start()

    def _drain(self, handler: Any) -> None:
        for sample in handler:  # ends when the subscriber is undeclared and its FIFO is empty
            self.stats.received += 1
            self._hand_over(Received(str(sample.key_expr), sample.payload.to_bytes(), str(sample.encoding),
                                     sample.kind == zenoh.SampleKind.DELETE, time.time_ns(), source_ns(sample)))
        self._hand_over(_END)

    def _hand_over(self, item: Any) -> None:
        if self._closing.is_set():
            self.stats.discarded += int(item is not _END)
            return
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            self.stats.full_waits += 1
            while True:  # wait for the consumer, but notice a close
                if self._closing.is_set():
                    self.stats.discarded += int(item is not _END)
                    return
                try:
                    self._queue.put(item, timeout=POLL_S)
                    break
                except queue.Full:
                    continue
        self.stats.max_depth = max(self.stats.max_depth, self._queue.qsize())

    def get(self, timeout: float | None = None) -> Received | None:
        """Next sample; queue.Empty after `timeout` s; None when undeclared and fully delivered."""
        if self._ended:
            return None
        while True:
            item = self._queue.get(timeout=timeout)
            if item is not _END:
                break
            self._running -= 1
            if self._running == 0:
                self._ended = True
                return None
        self.stats.delivered += 1
        return item

    def __iter__(self) -> Iterator[Received]:
        while (item := self.get()) is not None:
            yield item

    def undeclare(self) -> None:
        """Stop receiving; samples already received are still delivered, then `get` returns None."""
        if not self._undeclared:
            self._undeclared = True
            for subscriber in self._subscribers:
                subscriber.undeclare()

    def close(self) -> None:
        self._closing.set()  # from now on the drain thread discards instead of waiting
        self.undeclare()
        for thread in self._threads:
            thread.join(timeout=5.0)
            if thread.is_alive():
                log.warning("subscription %s: drain thread did not stop within 5 s", self.selector)
        while True:
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                break
            self.stats.discarded += int(item is not _END)

    def __enter__(self) -> "Subscription":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _declare_fifos(session: zenoh.Session, selectors: Sequence[str], fifo_capacity: int) -> tuple[list[Any], list[Any]]:
    """A FIFO-handler subscriber per selector, and their handlers (taken now: the attribute is gone
    after undeclare). BusError naming the selector if one cannot be declared (the others undeclared)."""
    subscribers: list[Any] = []
    for one in selectors:
        try:
            subscribers.append(session.declare_subscriber(one, zenoh.handlers.FifoChannel(fifo_capacity)))
        except zenoh.ZError as error:
            for declared in subscribers:
                declared.undeclare()
            raise BusError(f"cannot subscribe to {one!r}: {error}") from None
    return subscribers, [subscriber.handler for subscriber in subscribers]


class PolledSubscription:
    """Samples of `selector`, taken in batches on the consumer's own thread: no drain thread at all.

    For a process whose one thread does all the work (the hub). `take` empties the selectors'
    Zenoh FIFOs with `try_recv` (under a microsecond a sample: no lock, no thread hand-off, the GIL
    never handed to another Python thread), CHUNK samples of one selector at a time, round-robin,
    so no selector waits behind another for more than a few samples. Nothing is dropped: when the
    consumer is slow the FIFOs (`fifo_capacity` samples each) fill and Zenoh pushes back on the
    publishers, as with `Subscription`. One selector's samples come out in the order Zenoh
    delivered them; across selectors, in the order they were taken, or with `by_source_time` in
    the order they were published (each sweep of the FIFOs sorted by the samples' Zenoh timestamps,
    a stable sort: one publisher's samples keep their order, and the interleaving of the streams
    is that of their puts, not of the sweep, however the samples fell into sweeps). `received_ns`
    is the sweep's start: one clock reading per sweep, never decreasing. Same end-of-stream rules as
    `Subscription`: after `undeclare`, what was received before still comes out, then `take` and
    `get` return None; `close` discards what is left (counted in `stats.discarded`).

    stats.full_waits counts the times `fifo_capacity` samples or more were taken from one FIFO in a
    row without finding it empty: it was full, so Zenoh was holding the publishers back.
    stats.max_depth is the largest batch. When every FIFO is empty, `take` sleeps ACTIVE_PAUSE_S
    (0.2 ms) if samples came in the last ACTIVE_FOR_S, else IDLE_PAUSE_S (1 ms): under traffic a
    sample waits at most about 0.2 ms in its FIFO for the consumer to look (1 ms sleeps put the
    load bench's median latency at 100 chairs from 3 to 14 ms on the loaded 2-vCPU VM), the first
    sample after a quiet spell at most about 1 ms, an idle consumer wakes 1,000 times a second
    (3 % of a core on that VM), and a busy one never sleeps.
    """

    CHUNK = 32
    ACTIVE_PAUSE_S = 0.0002  # the sleep when every FIFO is empty but samples came in the last ACTIVE_FOR_S
    ACTIVE_FOR_S = 0.5
    IDLE_PAUSE_S = 0.001  # the sleep after a quiet ACTIVE_FOR_S (5 ms made tests/reckon/test_bench.py's start-up fail one run in two)
    CLOSE_TIMEOUT_S = 5.0  # after undeclare, how long a FIFO may stay open but empty

    def __init__(self, session: zenoh.Session, selector: str | Sequence[str], fifo_capacity: int = QUEUE_CAPACITY,
                 by_source_time: bool = False):
        selectors = [selector] if isinstance(selector, str) else list(selector)
        self._by_source_time = by_source_time
        if fifo_capacity < 1 or not selectors:
            raise ConfigError(f"subscription {selector!r}: fifo_capacity {fifo_capacity} must be at least 1, "
                              "and a selector is needed")
        self.selector = ", ".join(selectors)
        self.stats = SubscriptionStats()
        self._fifo_capacity = fifo_capacity
        self._undeclared_at: float | None = None
        self._pending: deque[Received] = deque()  # taken from the FIFOs, not yet handed out
        self._run: dict[int, int] = {}  # per FIFO (by id): samples taken in a row without finding it empty
        self._last_data = -math.inf  # monotonic time of the last sweep that found something
        self._subscribers, self._handlers = _declare_fifos(session, selectors, fifo_capacity)

    def _sweep(self, limit: int) -> list[Received]:
        """What the FIFOs hold now, up to about `limit` samples."""
        batch: list[Received] = []
        append, delete, now_ns = batch.append, zenoh.SampleKind.DELETE, time.time_ns()
        chunk, capacity = self.CHUNK, self._fifo_capacity
        active, run = list(self._handlers), self._run
        while active and len(batch) < limit:
            busy = []
            for handler in active:
                try_recv, taken = handler.try_recv, 0
                try:
                    while taken < chunk:
                        sample = try_recv()
                        if sample is None:
                            break
                        stamp = sample.timestamp
                        append(Received(str(sample.key_expr), sample.payload.to_bytes(), str(sample.encoding),
                                        sample.kind == delete, now_ns,
                                        None if stamp is None else int(stamp.get_time_as_ntp64().as_nanos())))
                        taken += 1
                except zenoh.ZError:  # "channel is empty and closed": undeclared, or the session closed
                    self._handlers.remove(handler)
                    continue
                key = id(handler)
                before = run.get(key, 0)
                if before < capacity <= before + taken:
                    self.stats.full_waits += 1
                if taken == chunk:
                    run[key] = before + taken
                    busy.append(handler)
                else:  # found empty
                    run[key] = 0
            active = busy
        self.stats.received += len(batch)
        self.stats.max_depth = max(self.stats.max_depth, len(batch))
        if self._by_source_time and len(batch) > 1:  # stable: one publisher's samples keep their order
            batch.sort(key=lambda item: now_ns if item.source_ns is None else item.source_ns)
        return batch

    def take(self, limit: int = 4096, timeout: float | None = None) -> list[Received] | None:
        """The next samples: at least one, at most `limit`, each selector's oldest first.

        queue.Empty after `timeout` s with nothing (None: wait for ever); None once undeclared and
        everything received before has been delivered.
        """
        if self._pending:
            batch = [self._pending.popleft() for _ in range(min(limit, len(self._pending)))]
            self.stats.delivered += len(batch)
            return batch
        deadline = None if timeout is None else time.monotonic() + timeout
        while self._handlers:
            batch = self._sweep(limit)
            if batch:
                self._last_data = time.monotonic()
                if len(batch) > limit:  # a sweep takes CHUNK samples of a FIFO at a time: hold the excess
                    self._pending.extend(batch[limit:])
                    del batch[limit:]
                self.stats.delivered += len(batch)
                return batch
            now = time.monotonic()
            if self._undeclared_at is not None and now - self._undeclared_at > self.CLOSE_TIMEOUT_S:
                log.warning("subscription %s: %d FIFO(s) still open %.0f s after undeclare; stopping", self.selector,
                            len(self._handlers), self.CLOSE_TIMEOUT_S)
                self._handlers.clear()
                break
            if deadline is not None and now >= deadline:
                raise queue.Empty
            pause = self.ACTIVE_PAUSE_S if now - self._last_data < self.ACTIVE_FOR_S else self.IDLE_PAUSE_S
            time.sleep(pause if deadline is None else min(pause, deadline - now))
        return None

    def get(self, timeout: float | None = None) -> Received | None:
        """Next sample; queue.Empty after `timeout` s; None when undeclared and fully delivered."""
        if not self._pending:
            batch = self.take(timeout=timeout)
            if batch is None:
                return None
            self.stats.delivered -= len(batch)  # counted as each is handed out
            self._pending.extendleft(reversed(batch))  # before what `take` held back, if anything
        self.stats.delivered += 1
        return self._pending.popleft()

    def __iter__(self) -> Iterator[Received]:
        while (item := self.get()) is not None:
            yield item

    def undeclare(self) -> None:
        """Stop receiving; samples already received are still delivered, then `take` returns None."""
        if self._undeclared_at is None:
            self._undeclared_at = time.monotonic()
            for subscriber in self._subscribers:
                subscriber.undeclare()

    def close(self) -> None:
        self.undeclare()
        self.stats.discarded += len(self._pending)
        self._pending.clear()
        while self._handlers and time.monotonic() - self._undeclared_at <= self.CLOSE_TIMEOUT_S:
            taken = self._sweep(1 << 30)
            self.stats.discarded += len(taken)
            if not taken:
                time.sleep(self.ACTIVE_PAUSE_S)
        self._handlers.clear()

    def __enter__(self) -> "PolledSubscription":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# ---------------------------------------------------------------------------------------------
# Ready signals


class Alive:
    """This process is up: a liveliness token plus a queryable on the same key that answers at once.

    The answer is a flush barrier for whoever asks (`flush`): it comes back only after every
    sample the asker sent earlier on the same link has been handed to this process's handlers.
    """

    def __init__(self, session: zenoh.Session, venue: str, role: wire.Role, process_id: str | None = None):
        self.key = wire.alive(venue, role, process_id or str(session.zid()))
        # Replying from the callback is safe: the reply is one empty message, and zenoh-python runs
        # Python callbacks on their own thread, not on Zenoh's network thread.
        self._queryable = session.declare_queryable(self.key, self._answer)
        self._token = session.liveliness().declare_token(self.key)

    def _answer(self, query: zenoh.Query) -> None:
        with query:  # leaving `with` sends the final reply at once
            query.reply(self.key, b"")

    def close(self) -> None:
        self._token.undeclare()
        self._queryable.undeclare()

    def __enter__(self) -> "Alive":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def wait_for_peers(session: zenoh.Session, selector: str | Sequence[str], count: int,
                   timeout_s: float | None) -> list[str]:
    """Wait until `count` distinct liveliness tokens match `selector` (one or several); their keys.

    Tokens already present count (history). A token that goes away stops counting. BusError after
    `timeout_s` seconds (None: wait for ever) naming the selector and what was seen.
    """
    selectors = [selector] if isinstance(selector, str) else list(selector)
    events: queue.Queue[tuple[str, bool]] = queue.Queue()  # unbounded: a few events per process

    def on_event(sample: zenoh.Sample) -> None:  # never blocks: put on an unbounded queue
        events.put((str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT))

    subscribers = [session.liveliness().declare_subscriber(s, on_event, history=True) for s in selectors]
    try:
        present: set[str] = set()
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while len(present) < count:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                key, up = events.get(timeout=remaining)
            except queue.Empty:
                raise BusError(f"waited {timeout_s:.1f} s for {count} live peer(s) on {', '.join(selectors)}; "
                               f"saw {len(present)}: {', '.join(sorted(present)) or 'none'}") from None
            if up:
                present.add(key)
            else:
                present.discard(key)
        return sorted(present)
    finally:
        for subscriber in subscribers:
            subscriber.undeclare()


def flush(session: zenoh.Session, selector: str, timeout_s: float) -> list[str]:
    """Ask every `Alive` process matching `selector` for a flush barrier; keys of those that answered.

    When a key is in the answer, every sample this session published before the call has reached
    that process. Call it before closing a publishing session: closing drops what is still queued.
    """
    replies = session.get(selector, target=zenoh.QueryTarget.ALL,
                          consolidation=zenoh.ConsolidationMode.NONE, timeout=timeout_s)
    return sorted(str(reply.ok.key_expr) for reply in replies if reply.ok is not None)
