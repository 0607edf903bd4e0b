"""Record a venue's bus traffic into a session log (MCAP), losslessly.

Sequence (the session protocol of `protocol.bus`):
1. get the session description: the `description` argument, else from the bus: a subscriber on
   `reckon/<venue>/session` catches the source's PUT, and a query on the same key, repeated every
   `DESCRIPTION_RETRY_S` until answered, catches a source that started first;
2. subscribe to `reckon/<venue>/**` (blocking queue: a slow disk slows the publishers down, it
   never loses a message), then declare the liveliness token `reckon/<venue>/alive/recorder/<id>`
   and set `ready`: a replayer waiting for a recorder starts only now;
3. write every protocol message with its key as topic (not the hub's pose batches,
   `reckon/<venue>/hub/poses/*`: each of their poses comes on its own agent's key too); log time =
   when this process took it out of Zenoh (wall clock ns), publish time = the message's own
   `timestamp_ns` (SessionWriter);
4. on `stop` (or, with `until_end`, on the source's end-of-session DELETE) stop receiving, write
   what was already received, close the log.

Samples with a foreign encoding or unreadable bytes are counted and skipped, never fatal.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from protocol import bus as wire
from protocol.errors import ConfigError, InputError
from protocol.keys import ROOT, check_id, pose_batch
from protocol.session import Session
from protocol.session_log import SessionWriter
from reckon.transport.bus import Alive, BusConfig, BusSession, Subscription, open_session, query

log = logging.getLogger(__name__)
DESCRIPTION_RETRY_S = 0.5  # how often to ask for the session description while none has come
STOP_POLL_S = 0.1  # how often the write loop notices `stop` while the bus is quiet


@dataclass(frozen=True)
class RecordSummary:
    output: str
    venue: str
    written: int
    topics: dict[str, int]  # messages per topic
    skipped: dict[str, int]  # reason -> count (foreign encoding, bad bytes, stray samples)
    end_seen: bool  # the source's end-of-session DELETE arrived
    full_waits: int  # times the queue was full (back-pressure on the publishers)
    max_queue_depth: int
    duration_s: float
    problems: list[str] = field(default_factory=list)

    def __str__(self) -> str:
        lines = [f"{self.output}: recorded {self.written} messages on {len(self.topics)} topics of venue "
                 f"{self.venue!r} in {self.duration_s:.1f} s"
                 + (" (end of session seen)" if self.end_seen else "")]
        if self.full_waits:
            lines.append(f"  back-pressure: queue full {self.full_waits} times (deepest {self.max_queue_depth})")
        lines += [f"  skipped {count}: {reason}" for reason, count in sorted(self.skipped.items())]
        lines += [f"  {problem}" for problem in self.problems]
        return "\n".join(lines)


def record(config: BusConfig, venue: str, output: Path | str, stop: threading.Event,
           ready: threading.Event | None = None, *, description: Session | None = None,
           until_end: bool = False, process_id: str | None = None,
           progress: Callable[[int], None] | None = None) -> RecordSummary:
    """Write every message published under `reckon/<venue>/` to the session log `output`.

    Blocks until `stop` is set (or, with `until_end`, until the session's source says it is
    over). `ready` is set once the recorder has the description, is subscribed and has declared
    its liveliness token: from then on nothing published is missed. Without `description` that
    needs a source on the bus, so start the source with `wait_for` rather than after `ready`.
    `description`: the session description, when known here; else it comes from the bus.
    `process_id`: the id in the liveliness key (default: the Zenoh session id).
    `progress`, if given, is called with the count written, every 1,000 messages.
    ConfigError for a bad venue or an output that cannot be written. If `stop` comes before any
    description, nothing is written and the summary says so.
    """
    check_id(venue, "venue")
    if description is not None and description.venue.name != venue:
        raise ConfigError(f"record: the session description is for venue {description.venue.name!r}, "
                          f"not {venue!r}")
    started = time.monotonic()
    with open_session(config) as session:
        description = description or _await_description(session, venue, stop)
        if description is None:
            return RecordSummary(str(output), venue, 0, {}, {}, False, 0, 0, time.monotonic() - started,
                                 ["stopped before any session description arrived; nothing written"])
        try:
            writer = SessionWriter(output, description)
        except OSError as error:
            raise ConfigError(f"{output}: cannot write ({error.strerror})") from None
        with writer, Subscription(session, f"{ROOT}/{venue}/**") as subscription, \
                Alive(session, venue, wire.Role.RECORDER, process_id):
            if ready is not None:
                ready.set()
            loop = _Loop(writer, subscription, wire.session_key(venue), pose_batch(venue, ""), stop, until_end, progress)
            loop.run()
            stats = subscription.stats
    return RecordSummary(str(output), venue, loop.written, dict(loop.topics), dict(loop.skipped), loop.end_seen,
                         stats.full_waits, stats.max_depth, time.monotonic() - started)


class _Loop:
    """The write loop: drains the subscription into the writer until it ends."""

    def __init__(self, writer: SessionWriter, subscription: Subscription, session_key: str, batches: str,
                 stop: threading.Event, until_end: bool, progress: Callable[[int], None] | None):
        self.writer, self.subscription, self.session_key, self.batches = writer, subscription, session_key, batches
        self.stop, self.until_end, self.progress = stop, until_end, progress
        self.written = 0
        self.topics: Counter[str] = Counter()
        self.skipped: Counter[str] = Counter()
        self.end_seen = False
        self.stopping = False

    def run(self) -> None:
        while True:
            if self.stop.is_set() and not self.stopping:
                self._finish()
            try:
                item = self.subscription.get(timeout=STOP_POLL_S)
            except queue.Empty:
                continue
            if item is None:  # undeclared and everything received before has been written
                return
            if item.key == self.session_key:
                if item.delete:
                    self.end_seen = True
                    if self.until_end:
                        self._finish()
                continue  # the description itself (already in the log's metadata)
            if item.key.startswith(self.batches):
                continue
            try:
                message = item.decode()
            except InputError as error:
                reason = _skip_reason(item.encoding)
                if not self.skipped[reason]:
                    log.warning("skipping samples: %s (first: %s)", reason, error)
                self.skipped[reason] += 1
                continue
            self.writer.write(item.key, message, item.received_ns)
            self.written += 1
            self.topics[item.key] += 1
            if self.progress is not None and self.written % 1000 == 0:
                self.progress(self.written)

    def _finish(self) -> None:
        """Stop receiving; the loop goes on until what was received is written."""
        self.stopping = True
        self.subscription.undeclare()


def _skip_reason(encoding: str) -> str:
    try:
        wire.message_class(encoding)
    except InputError:
        return f"encoding {encoding!r} is not a reckon message"
    return f"unreadable {encoding.partition(';')[2]} payload"


def _await_description(session: BusSession, venue: str, stop: threading.Event) -> Session | None:
    """The session description from the bus (PUT or query answer); None if `stop` comes first."""
    key = wire.session_key(venue)
    log.info("waiting for the session description on %s", key)
    with Subscription(session, key, capacity=16, fifo_capacity=16) as announcements:
        while not stop.is_set():
            for reply in query(session, key, DESCRIPTION_RETRY_S):
                return wire.decode_session(reply.payload, where=f"{key} (query reply)")
            try:
                item = announcements.get(timeout=DESCRIPTION_RETRY_S)
            except queue.Empty:
                continue
            if item is not None and not item.delete:
                return wire.decode_session(item.payload, where=key)
    return None
