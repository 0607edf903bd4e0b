"""Subscriptions: samples copied out of Zenoh's handlers, FIFO (never drops) or ring (drops oldest) on purpose.

Measurements are never dropped (style rule 7): a `Subscription` moves samples from a Zenoh FIFO
into a bounded `queue.Queue` on its own thread, blocking when the queue is full, so a slow
consumer slows the publisher down (back-pressure) instead of losing data. `PolledSubscription`
(the hub's, reckon/transport/polled.py) has no thread: its consumer empties the Zenoh FIFOs
itself, in batches, and a full FIFO holds the publishers back the same way. `DirectSubscription`
is one Zenoh handler read on the consumer's thread: a FIFO, or a ring for status views that may
miss samples. `CallbackSubscription` hands each sample to a function on Zenoh's callback thread.
Nothing here blocks inside a Zenoh callback: that would stall the whole session (field-notes.md).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import zenoh

from protocol import bus as wire
from protocol.errors import ConfigError
from reckon.transport.session import BusError, BusSession, source_ns

log = logging.getLogger(__name__)

QUEUE_CAPACITY = 1024  # samples held between the Zenoh FIFO and the consumer (~1 MB of ImuBatch)
FIFO_CAPACITY = 256  # Zenoh's default FIFO size
POLL_S = 0.1  # how often a blocked hand-over re-checks whether the subscription is closing


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
    what was not delivered (counted in `stats.discarded`). `held_back` is set the first time the
    queue was full and the hand-over had to wait: from then on the consumer, not the publisher,
    sets the pace (a test waits on it instead of polling `stats.full_waits`).
    """

    def __init__(self, session: BusSession, selector: str | Sequence[str], capacity: int = QUEUE_CAPACITY,
                 fifo_capacity: int = FIFO_CAPACITY):
        selectors = [selector] if isinstance(selector, str) else list(selector)
        if capacity < 1 or fifo_capacity < 1 or not selectors:
            raise ConfigError(f"subscription {selector!r}: capacity {capacity} and fifo_capacity "
                              f"{fifo_capacity} must be at least 1, and a selector is needed")
        self.selector = ", ".join(selectors)
        self.stats = SubscriptionStats()
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=capacity)
        self._closing = threading.Event()
        self.held_back = threading.Event()
        self._ended = False
        self._running = len(selectors)  # drain threads still delivering
        self._undeclared = False
        self._threads: list[threading.Thread] = []
        # several selectors (a union) share the one queue, each with its drain thread
        self._subscribers, handlers = declare_fifos(session, selectors, fifo_capacity)
        for one, handler in zip(selectors, handlers):
            self._threads.append(threading.Thread(target=self._drain, args=(handler,), daemon=True, name=f"drain {one}"))
        for thread in self._threads:
            thread.start()

    def _drain(self, handler: Any) -> None:
        for sample in handler:  # ends when the subscriber is undeclared and its FIFO is empty
            self.stats.received += 1
            self._hand_over(received_from(sample))
        self._hand_over(_END)

    def _hand_over(self, item: Any) -> None:
        if self._closing.is_set():
            self.stats.discarded += int(item is not _END)
            return
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            self.stats.full_waits += 1
            self.held_back.set()
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


def declare_fifos(session: BusSession, selectors: Sequence[str], fifo_capacity: int) -> tuple[list[Any], list[Any]]:
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


class DirectSubscription:
    """One selector's samples read straight from one Zenoh handler on the consumer's thread: no
    drain thread, no queue, no stats. Build it with `fifo` or `ring`, chosen on purpose:

    - `fifo(session, selector, capacity)`: a Zenoh FIFO; when it is full Zenoh holds the
      publishers back, so nothing is lost while the subscription is open.
    - `ring(session, selector, capacity)`: a Zenoh ring; when it is full the oldest sample goes,
      and nobody is ever held back. For status views only (style rule 7).

    `try_get()` is the oldest sample held, or None when there is none (or the subscription was
    undeclared: a ring's samples go with it, a FIFO's remaining ones still come out first).
    Iterating blocks for each next sample, stamping `received_ns` as it leaves the handler, and
    ends once the subscription is undeclared and its handler empty (so a thread iterating ends
    when another undeclares). BusError naming the selector when it cannot be declared.
    """

    def __init__(self, session: BusSession, selector: str, handler: Any):
        self.selector = selector
        try:
            self._subscriber = session.declare_subscriber(selector, handler)
        except zenoh.ZError as error:
            raise BusError(f"cannot subscribe to {selector!r}: {error}") from None
        self._handler = self._subscriber.handler  # taken now: the attribute is gone after undeclare
        self._undeclared = False

    @classmethod
    def fifo(cls, session: BusSession, selector: str, capacity: int) -> DirectSubscription:
        return cls(session, selector, zenoh.handlers.FifoChannel(_at_least_one(selector, capacity)))

    @classmethod
    def ring(cls, session: BusSession, selector: str, capacity: int) -> DirectSubscription:
        return cls(session, selector, zenoh.handlers.RingChannel(_at_least_one(selector, capacity)))

    def try_get(self) -> Received | None:
        try:
            sample = self._handler.try_recv()
        except zenoh.ZError:  # undeclared (a ring is deleted; a FIFO is empty and closed)
            return None
        return None if sample is None else received_from(sample)

    def __iter__(self) -> Iterator[Received]:
        for sample in self._handler:
            yield received_from(sample)

    def undeclare(self) -> None:
        if not self._undeclared:
            self._undeclared = True
            self._subscriber.undeclare()

    close = undeclare

    def __enter__(self) -> DirectSubscription:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class CallbackSubscription:
    """Each sample of `selector` handed to `callback(Received)` on Zenoh's callback thread.

    The callback must return at once (never block, never publish): put the sample on an
    unbounded queue, set an event. Nothing is dropped and nobody is held back while the callback
    keeps up. BusError naming the selector when it cannot be declared.
    """

    def __init__(self, session: BusSession, selector: str, callback: Callable[[Received], None]):
        self.selector = selector
        try:
            self._subscriber = session.declare_subscriber(selector, lambda sample: callback(received_from(sample)))
        except zenoh.ZError as error:
            raise BusError(f"cannot subscribe to {selector!r}: {error}") from None
        self._undeclared = False

    def undeclare(self) -> None:
        if not self._undeclared:
            self._undeclared = True
            self._subscriber.undeclare()

    close = undeclare

    def __enter__(self) -> CallbackSubscription:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def received_from(sample: Any) -> Received:
    """A Zenoh sample (from a handler, a callback or a query reply) copied out, stamped now."""
    return Received(str(sample.key_expr), sample.payload.to_bytes(), str(sample.encoding),
                    sample.kind == zenoh.SampleKind.DELETE, time.time_ns(), source_ns(sample))


def _at_least_one(selector: str, capacity: int) -> int:
    if capacity < 1:
        raise ConfigError(f"subscription {selector!r}: capacity {capacity} must be at least 1")
    return capacity
