"""The hub's subscription: several selectors' Zenoh FIFOs emptied in batches on the consumer's own thread.

Like `Subscription` it never drops: a slow consumer leaves the FIFOs full and Zenoh holds the
publishers back. Unlike it, there is no drain thread and no queue, so a one-thread process (the
hub) takes a sample in under a microsecond and the GIL is never handed to another Python thread.
"""

from __future__ import annotations

import logging
import math
import queue
import time
from collections import deque
from collections.abc import Iterator, Sequence

import zenoh

from protocol.errors import ConfigError
from reckon.transport.session import BusSession
from reckon.transport.subscriptions import QUEUE_CAPACITY, Received, SubscriptionStats, declare_fifos

log = logging.getLogger(__name__)


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
    # The sleep after a quiet ACTIVE_FOR_S. Not longer: at 5 ms the first samples after start-up wait
    # long enough in the FIFOs for tests/reckon/test_bench.py's start-up check to fail about one run in two.
    IDLE_PAUSE_S = 0.001
    CLOSE_TIMEOUT_S = 5.0  # after undeclare, how long a FIFO may stay open but empty

    def __init__(self, session: BusSession, selector: str | Sequence[str], fifo_capacity: int = QUEUE_CAPACITY,
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
        self._session = session
        self._subscribers, self._handlers = declare_fifos(session, selectors, fifo_capacity)

    def add(self, selector: str) -> None:
        """Subscribe to one more selector (the hub asks for raw IMU once a camera is on)."""
        if self._undeclared_at is not None:
            return
        subscribers, handlers = declare_fifos(self._session, [selector], self._fifo_capacity)
        self._subscribers += subscribers
        self._handlers += handlers
        self.selector += ", " + selector

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
