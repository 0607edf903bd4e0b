"""Replay a session log on the Zenoh bus, as if its edges were live.

Sequence (the session protocol of `protocol.bus`):
1. read the session description (the log's `reckon.session` metadata, written before any message);
2. answer queries on `reckon/<venue>/session` with it and PUT it once;
3. optionally wait until `wait_for` hubs or recorders hold liveliness tokens, so nobody misses
   the start;
4. publish every message on its topic (= its key) with its own encoding, in file order, paced by
   log time at `speed` x real time (0: as fast as the subscribers take them, back-pressure only);
5. a flush barrier to every live process (its answer means it has every message), then DELETE
   `reckon/<venue>/session` (end of session) and one more barrier so that the end marker is out
   too: closing a Zenoh session drops whatever is still queued in it.

Messages are published as stored (no decode and re-encode). Channels that are not `reckon.v1`
protobuf are skipped and counted. A truncated log replays up to the damage, with a note.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema

from protocol import bus as wire
from protocol import messages
from protocol.errors import ConfigError, InputError
from protocol.keys import ROOT
from protocol.session_log import description_from_records, iter_records
from reckon.transport.bus import Answer, BusConfig, Publisher, flush, open_session, wait_for_peers

log = logging.getLogger(__name__)
PROGRESS_EVERY = 1000  # messages between progress reports
FLUSH_TIMEOUT_S = 10.0  # how long the consumers get to confirm the tail at the end


@dataclass(frozen=True)
class ReplayProgress:
    phase: str  # "waiting" for subscribers, "publishing", "done"
    published: int
    total: int | None  # from the log's summary; None for a log without one (truncated)

    def __str__(self) -> str:
        if self.phase == "waiting":
            return "replay: waiting for subscribers"
        share = f" of {self.total} ({100 * self.published / self.total:.0f} %)" if self.total else ""
        return f"replay: {self.phase}, {self.published}{share} messages"


@dataclass(frozen=True)
class ReplaySummary:
    path: str
    venue: str
    published: int
    skipped: int  # messages on channels that are not reckon.v1 protobuf
    topics: int
    log_span_s: float  # last minus first log time of the published messages
    publish_s: float  # wall time spent publishing (after the wait)
    waited_s: float
    confirm_s: float  # wall time from the last message to the consumers' end-of-stream confirmation
    consumers: list[str]  # liveliness keys waited for
    confirmed: list[str]  # live processes that confirmed the whole stream at the end
    problems: list[str] = field(default_factory=list)

    @property
    def rate_per_s(self) -> float:
        """Messages per second until every confirmed consumer had them all."""
        elapsed = self.publish_s + self.confirm_s
        return self.published / elapsed if elapsed > 0 else 0.0

    def __str__(self) -> str:
        lines = [f"{self.path}: replayed {self.published} messages on {self.topics} topics of venue "
                 f"{self.venue!r} ({self.log_span_s:.1f} s of log) in {self.publish_s:.2f} s, "
                 f"{self.publish_s + self.confirm_s:.2f} s until confirmed ({self.rate_per_s:.0f} messages/s)"]
        if self.consumers:
            lines.append(f"  waited {self.waited_s:.2f} s for {', '.join(self.consumers)}")
        lines.append(f"  confirmed by: {', '.join(self.confirmed) or 'nobody'}")
        if self.skipped:
            lines.append(f"  skipped {self.skipped} messages on channels that are not {messages.PACKAGE}")
        lines += [f"  {problem}" for problem in self.problems]
        return "\n".join(lines)


def replay(session_path: Path | str, config: BusConfig, speed: float = 1.0,
           progress: Callable[[ReplayProgress], None] | None = None, *, wait_for: int = 0,
           wait_timeout_s: float | None = 60.0, stop: threading.Event | None = None) -> ReplaySummary:
    """Publish every message of a session log on its key; see the module docstring for the sequence.

    speed: multiple of real time (1 = as recorded, 10 = ten times faster); 0 = no pacing.
    wait_for: number of hub or recorder liveliness tokens to wait for before publishing (0: start
      at once); BusError if they are not there after `wait_timeout_s` (None: wait for ever).
    stop: set it to end the replay early (the end-of-session DELETE is still sent).
    InputError for a missing or foreign log, ConfigError for a bad speed or wait count.
    """
    if not (isinstance(speed, (int, float)) and math.isfinite(speed) and speed >= 0):
        raise ConfigError(f"replay speed {speed!r} must be a finite number >= 0 (0 = as fast as possible)")
    if wait_for < 0:
        raise ConfigError(f"replay wait_for {wait_for} must be >= 0")
    path = Path(session_path)
    report = progress or (lambda _: None)
    total = _message_count(path)
    problems: list[str] = []
    records = iter_records(path, problems)
    description = description_from_records(path, records)
    venue = description.venue.name
    description_payload = wire.encode_session(description)
    consumers: list[str] = []
    with open_session(config) as session, Publisher(session) as publisher:
        key = wire.session_key(venue)
        # late joiners ask for the description
        with Answer(session, key, description_payload, wire.SESSION_ENCODING):
            publisher.publish_bytes(key, description_payload, wire.SESSION_ENCODING)
            started = time.monotonic()
            if wait_for:
                report(ReplayProgress("waiting", 0, total))
                consumers = wait_for_peers(session, [wire.alive_selector(venue, wire.Role.HUB),
                                                     wire.alive_selector(venue, wire.Role.RECORDER)],
                                           wait_for, wait_timeout_s)
            waited_s = time.monotonic() - started
            stats = _publish(records, publisher, venue, speed, stop, total, report)
            flushing = time.monotonic()
            # Barrier before the end marker: every live process answers, and each answer means
            # it has every message. After the marker a recorder may leave at once, so the second
            # barrier's answers are not counted; its round trip (answered, or "no such
            # queryable") only makes sure the marker itself is out before the session closes.
            confirmed = flush(session, wire.alive_selector(venue), FLUSH_TIMEOUT_S)
            confirm_s = time.monotonic() - flushing
            publisher.delete(key)
            flush(session, wire.alive_selector(venue), FLUSH_TIMEOUT_S)
    if stats.other_venue:
        problems.append(f"{stats.other_venue} messages were on keys outside reckon/{venue}/ (the description's "
                        "venue): a recorder of that venue does not see them")
    missing = sorted(set(consumers) - set(confirmed))
    if missing:
        problems.append(f"no end-of-stream confirmation from {', '.join(missing)} within {FLUSH_TIMEOUT_S:.0f} s")
    summary = ReplaySummary(str(path), venue, stats.published, stats.skipped, len(stats.topics), stats.log_span_s,
                            stats.publish_s, waited_s, confirm_s, consumers, confirmed, problems)
    report(ReplayProgress("done", stats.published, total))
    for problem in problems:
        log.warning("%s", problem)
    return summary


@dataclass
class _Stats:
    published: int = 0
    skipped: int = 0
    other_venue: int = 0  # published on a key of another venue than the description's
    topics: set[str] = field(default_factory=set)
    first_log_ns: int | None = None
    last_log_ns: int = 0
    publish_s: float = 0.0

    @property
    def log_span_s(self) -> float:
        return 0.0 if self.first_log_ns is None else (self.last_log_ns - self.first_log_ns) / 1e9


def _publish(records: Iterator[Any], publisher: Publisher, venue: str, speed: float,
             stop: threading.Event | None, total: int | None, report: Callable[[ReplayProgress], None]) -> _Stats:
    stats = _Stats()
    prefix = f"{ROOT}/{venue}/"
    stopping = stop or threading.Event()  # an event nobody sets: the pacing wait is then a plain sleep
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str | None]] = {}  # id -> (topic, encoding or None if not ours)
    start_wall = time.monotonic()
    report(ReplayProgress("publishing", 0, total))
    for record in records:
        if isinstance(record, Schema):
            schemas[record.id] = record.name
        elif isinstance(record, Channel):
            channels[record.id] = (record.topic, _encoding(schemas.get(record.schema_id, ""), record.message_encoding))
        elif isinstance(record, Message):
            topic, encoding = channels.get(record.channel_id, ("?", None))
            if encoding is None:
                stats.skipped += 1
                continue
            if stats.first_log_ns is None:
                stats.first_log_ns = record.log_time
            if speed > 0:  # pace: this message is due (log time since the first) / speed after the start
                delay = start_wall + (record.log_time - stats.first_log_ns) / 1e9 / speed - time.monotonic()
                if delay > 0:
                    stopping.wait(delay)
            if stopping.is_set():
                break
            publisher.publish_bytes(topic, record.data, encoding)
            stats.published += 1
            stats.other_venue += not topic.startswith(prefix)
            stats.topics.add(topic)
            stats.last_log_ns = max(stats.last_log_ns, record.log_time)
            if stats.published % PROGRESS_EVERY == 0:
                report(ReplayProgress("publishing", stats.published, total))
    stats.publish_s = time.monotonic() - start_wall
    return stats


def _encoding(schema_name: str, message_encoding: str) -> str | None:
    """Zenoh encoding of a channel, or None when it is not one of our protobuf messages."""
    short = schema_name.removeprefix(messages.PACKAGE + ".")
    if message_encoding != "protobuf" or short == schema_name or short not in messages.CLASSES:
        return None
    return wire.encoding_for(short)


def _message_count(path: Path) -> int | None:
    """Message count from the log's summary section, or None when it has none (truncated log)."""
    try:
        with open(path, "rb") as stream:
            summary = make_reader(stream).get_summary()
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (McapError, ValueError, EOFError, OSError, KeyError):
        return None
    return None if summary is None or summary.statistics is None else int(summary.statistics.message_count)
