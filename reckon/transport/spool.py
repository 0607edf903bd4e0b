"""The edge's disk spool: messages kept while no hub can take them, replayed in order when one can.

Layout: a directory of append-only segment files `spool-<n>.seg` (n from 1, zero-padded, so the
names sort in write order), each a sequence of records

    u32 body length | u32 CRC-32 of body | body = u16 key length | key | u16 encoding length | encoding | payload

all little-endian, key and encoding UTF-8. A segment is closed at `segment_bytes` and a new one
begun; a segment is deleted once every record in it has been replayed.

Durability (the fsync policy): every append is written straight to the OS (unbuffered), so a
crash of the edge process loses nothing; the file is fsynced at most every `fsync_every_s`
(default 1 s), when a segment is closed, and on `close`, so a power cut loses at most the last
second of entries. The record then cut short is detected on the next open (its length runs past
the end of the file, or its CRC fails), skipped with a warning, and the file is cut back to the
last whole record; every record before it is kept.

Bound: the segment files never exceed `limit_bytes` in total (default 512 MiB, `--spool-limit-mb`).
At the limit the spool keeps what it has and refuses new entries: `append` returns False, they
are counted in `refused`, and a warning goes out at most every `WARN_EVERY_S` with the count.
Replay is at least once: an edge killed while replaying sends the start of the segment in hand
again on its next start; the hub drops the repeats (hub/dedup.py).
"""

from __future__ import annotations

import logging
import os
import struct
import threading
import time
import zlib
from collections import deque
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from protocol import bus as wire
from protocol.errors import ConfigError, ReckonError
from reckon.transport.bus import BusSession, Publisher, TokenWatch

log = logging.getLogger(__name__)

DEFAULT_LIMIT_BYTES = 512 * 1024 * 1024
SEGMENT_BYTES = 8 * 1024 * 1024  # small enough that a replayed segment frees its space soon
MAX_RECORD_BYTES = 16 * 1024 * 1024  # far above any message (an ImuBatch is ~1 KB): a bigger length is damage
FSYNC_EVERY_S = 1.0
WARN_EVERY_S = 10.0
RESEND_WINDOW = 1024  # messages sent again after a hub loss (~12 s of one chair's edge at 80 messages/s)
REPLAY_PER_MESSAGE = 16  # spooled entries replayed per new message: the spool drains at 16 x the input rate
_HEADER = struct.Struct("<II")  # body length, CRC-32 of the body
_SHORT = struct.Struct("<H")
PREFIX, SUFFIX = "spool-", ".seg"


class SpoolError(ReckonError):
    """The spool directory cannot be used (not a directory, not writable)."""


@dataclass(frozen=True, slots=True)
class Entry:
    """One spooled message: its Zenoh key, its encoding and its encoded payload."""

    key: str
    encoding: str
    payload: bytes


def encode_record(entry: Entry) -> bytes:
    key, encoding = entry.key.encode("utf-8"), entry.encoding.encode("utf-8")
    body = b"".join((_SHORT.pack(len(key)), key, _SHORT.pack(len(encoding)), encoding, entry.payload))
    return _HEADER.pack(len(body), zlib.crc32(body)) + body


def _decode_body(body: bytes) -> Entry:
    (key_length,) = _SHORT.unpack_from(body, 0)
    key_end = _SHORT.size + key_length
    (encoding_length,) = _SHORT.unpack_from(body, key_end)
    encoding_end = key_end + _SHORT.size + encoding_length
    return Entry(body[_SHORT.size:key_end].decode("utf-8"), body[key_end + _SHORT.size:encoding_end].decode("utf-8"),
                 body[encoding_end:])


def read_records(data: bytes, where: str) -> tuple[list[tuple[int, Entry]], int, str | None]:
    """(offset after each whole record, the record), the length of the intact part, and what is wrong
    after it (None when the data ends on a record boundary). Never raises on damage."""
    out: list[tuple[int, Entry]] = []
    offset = 0
    while offset < len(data):
        if len(data) - offset < _HEADER.size:
            return out, offset, f"{where}: a record header cut short at byte {offset} ({len(data) - offset} of {_HEADER.size} bytes)"
        length, crc = _HEADER.unpack_from(data, offset)
        start = offset + _HEADER.size
        if length > MAX_RECORD_BYTES:
            return out, offset, f"{where}: record length {length} exceeds {MAX_RECORD_BYTES} at byte {offset}"
        if start + length > len(data):
            return out, offset, (f"{where}: record at byte {offset} cut short ({len(data) - start} of {length} "
                                 "body bytes)")
        body = data[start:start + length]
        if zlib.crc32(body) != crc:
            return out, offset, f"{where}: record at byte {offset} fails its CRC"
        try:
            entry = _decode_body(body)
        except (struct.error, UnicodeDecodeError) as error:
            return out, offset, f"{where}: record at byte {offset} is malformed ({error})"
        offset = start + length
        out.append((offset, entry))
    return out, offset, None


class Spool:
    """A bounded, durable FIFO of messages on disk (see the module docstring for the format).

    `append(entry)` adds at the tail (False when full); `peek()` is the oldest entry not yet
    replayed, `pop()` marks it replayed (deleting its segment once the segment is used up).
    `pending` is how many entries wait. Opening an existing directory takes over what a
    previous process left, in order. Not thread-safe: one edge thread owns it.
    """

    def __init__(self, directory: Path | str, limit_bytes: int = DEFAULT_LIMIT_BYTES,
                 segment_bytes: int = SEGMENT_BYTES, fsync_every_s: float = FSYNC_EVERY_S):
        if limit_bytes < 1 or segment_bytes < 1:
            raise ConfigError(f"spool {directory}: limit {limit_bytes} B and segment size {segment_bytes} B must be "
                              "at least 1 byte")
        self.directory = Path(directory)
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise SpoolError(f"spool directory {self.directory}: cannot create it ({error})") from None
        if not os.access(self.directory, os.W_OK):
            raise SpoolError(f"spool directory {self.directory}: not writable")
        self.limit_bytes, self.segment_bytes, self.fsync_every_s = limit_bytes, segment_bytes, fsync_every_s
        self.refused = 0  # entries turned away at the limit
        self.recovered = 0  # entries found on disk when opening
        self.damaged = 0  # damaged tails cut off when opening
        self._refused_since, self._last_warning = 0, -WARN_EVERY_S
        self._segments: list[Path] = []  # oldest first; the last one is the one written to
        self._sizes: dict[Path, int] = {}
        self._read: deque[Entry] = deque()  # the oldest segment's entries not yet popped
        self._read_segment: Path | None = None
        self._pending = 0
        self._file = None
        self._last_sync = time.monotonic()
        self._open_existing()

    # -- opening ---------------------------------------------------------------------------------

    def _open_existing(self) -> None:
        for path in sorted(self.directory.glob(f"{PREFIX}*{SUFFIX}")):
            data = path.read_bytes()
            records, intact, problem = read_records(data, str(path))
            if problem is not None:
                self.damaged += 1
                log.warning("%s; skipped %d damaged bytes, kept the %d records before", problem, len(data) - intact,
                            len(records))
                with open(path, "r+b") as file:  # cut back to the last whole record, so appends continue cleanly
                    file.truncate(intact)
                    os.fsync(file.fileno())
            if not records:
                path.unlink()
                continue
            self._segments.append(path)
            self._sizes[path] = intact
            self._pending += len(records)
        self.recovered = self._pending
        if self.recovered:
            log.warning("spool %s: %d messages left by an earlier run, to be replayed first", self.directory,
                        self.recovered)

    # -- writing ---------------------------------------------------------------------------------

    @property
    def pending(self) -> int:
        """Entries spooled and not yet replayed."""
        return self._pending

    @property
    def size_bytes(self) -> int:
        return sum(self._sizes.values())

    def append(self, entry: Entry) -> bool:
        """Add `entry` at the tail. False (and counted in `refused`) when it would pass the limit."""
        record = encode_record(entry)
        if self.size_bytes + len(record) > self.limit_bytes:
            self._refuse()
            return False
        if self._file is None or self._sizes[self._segments[-1]] + len(record) > self.segment_bytes:
            self._roll()
        path = self._segments[-1]
        self._file.write(record)
        self._sizes[path] += len(record)
        self._pending += 1
        if path == self._read_segment:  # the segment being replayed is also the one written to
            self._read.append(entry)
        now = time.monotonic()
        if now - self._last_sync >= self.fsync_every_s:
            os.fsync(self._file.fileno())
            self._last_sync = now
        return True

    def _refuse(self) -> None:
        self.refused += 1
        self._refused_since += 1
        now = time.monotonic()
        if now - self._last_warning >= WARN_EVERY_S:
            log.warning("spool %s is full (%d of %d bytes): refused %d messages (%d in all); keeping the %d it holds",
                        self.directory, self.size_bytes, self.limit_bytes, self._refused_since, self.refused,
                        self._pending)
            self._refused_since, self._last_warning = 0, now

    def _roll(self) -> None:
        self._close_file()
        number = int(self._segments[-1].name[len(PREFIX):-len(SUFFIX)]) + 1 if self._segments else 1
        path = self.directory / f"{PREFIX}{number:09d}{SUFFIX}"
        self._file = open(path, "ab", buffering=0)  # unbuffered: a crash of this process loses nothing
        self._segments.append(path)
        self._sizes[path] = 0

    def _close_file(self) -> None:
        if self._file is not None:
            os.fsync(self._file.fileno())
            self._file.close()
            self._file = None

    # -- replaying -------------------------------------------------------------------------------

    def peek(self) -> Entry | None:
        """The oldest entry not yet replayed, or None when the spool is empty."""
        if not self._pending:
            return None
        if not self._read:
            self._load_oldest()
        return self._read[0]

    def pop(self) -> None:
        """Mark the oldest entry replayed; its segment goes once all of it has."""
        if self.peek() is None:
            raise IndexError(f"spool {self.directory}: pop from an empty spool")
        self._read.popleft()
        self._pending -= 1
        if not self._read and self._segments and self._segments[0] == self._read_segment:
            self._drop_oldest()

    def _load_oldest(self) -> None:
        path = self._segments[0]
        records, _, _ = read_records(path.read_bytes(), str(path))  # checked when opened or written by us
        self._read, self._read_segment = deque(entry for _, entry in records), path

    def _drop_oldest(self) -> None:
        path = self._segments.pop(0)
        if self._file is not None and not self._segments:  # the one being written to: start afresh
            self._file.close()
            self._file = None
        del self._sizes[path]
        path.unlink()
        self._read_segment = None

    def requeue(self, entries: Sequence[Entry]) -> None:
        """Put `entries` back in front of the oldest pending one, in memory only: they were on disk
        once and were replayed, to a hub that then went away."""
        if self._pending and not self._read:
            self._load_oldest()
        self._read.extendleft(reversed(entries))
        self._pending += len(entries)

    def replay(self) -> Iterator[Entry]:
        """Every pending entry, oldest first, each marked replayed once the caller asks for the next."""
        while (entry := self.peek()) is not None:
            yield entry
            self.pop()

    def close(self) -> None:
        self._close_file()

    def __enter__(self) -> Spool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# ---------------------------------------------------------------------------------------------
# The edge's publishing path


class HubWatch:
    """Whether a hub of the venue is up, from the hubs' liveliness tokens (`reckon.transport.bus.Alive`).

    `up` is set while at least one token is present; `losses` counts the times the last one went
    (a hub stopped, was killed, or this edge lost the bus). Zenoh drops a token when its link
    closes, so a killed hub on a live network is noticed within milliseconds; a cut network only
    after the link's lease (10 s by default), which the resend window covers.
    """

    def __init__(self, session: BusSession, venue: str):
        self.up = threading.Event()
        self.losses = 0
        self._present: set[str] = set()
        self._lock = threading.Lock()
        self._tokens = TokenWatch(session, wire.alive_selector(venue, wire.Role.HUB), self._on_token)

    def _on_token(self, key: str, up: bool) -> None:  # Zenoh's callback thread: never blocks
        with self._lock:
            if up:
                self._present.add(key)
                self.up.set()
            elif key in self._present:
                self._present.discard(key)
                if not self._present:
                    self.losses += 1
                    self.up.clear()

    def close(self) -> None:
        self._tokens.close()


class SpooledPublisher:
    """`reckon.transport.bus.Publisher` with a disk spool in front for when no hub is up.

    While a hub is up and the spool is empty, messages go straight out, and the last
    `resend_window` of them are also kept in memory. When the hub goes (HubWatch), that window is
    spooled first, since the hub may have died before taking or recording them (its repeats are
    dropped by the hub's deduplication), and every later message is spooled. When a hub is back,
    each publish replays up to `replay_per_message` spooled entries before its own, which goes to
    the spool's tail while it drains, so the hub sees every stream in its original order; once
    the spool is empty, messages go straight out again. `finish` replays what is left if a hub is
    (or within `wait_s` comes) up, and otherwise leaves it on disk for the next start.
    """

    def __init__(self, session: BusSession, publisher: Publisher, venue: str, spool: Spool,
                 resend_window: int = RESEND_WINDOW, replay_per_message: int = REPLAY_PER_MESSAGE):
        self.publisher, self.spool = publisher, spool
        self.watch = HubWatch(session, venue)
        self.replay_per_message = replay_per_message
        self.replayed = 0  # spooled entries published
        self._recent: deque[Entry] = deque(maxlen=resend_window)
        self._losses_seen = 0

    @property
    def sent(self) -> int:
        return self.publisher.sent

    @property
    def spooled(self) -> int:
        """Messages waiting in the spool (DeviceStatus.spooled)."""
        return self.spool.pending

    @property
    def refused(self) -> int:
        """Messages turned away at the spool's limit (lost: the spool was full)."""
        return self.spool.refused

    def publish(self, key: str, message: Any) -> None:
        payload, encoding = wire.encode(message)
        self.publish_bytes(key, payload, encoding)

    def publish_bytes(self, key: str, payload: bytes, encoding: str) -> None:
        entry = Entry(key, encoding, payload)
        self._notice_losses()
        up = self.watch.up.is_set()
        if up and not self.spool.pending:
            self._send(entry)
            return
        self.spool.append(entry)
        if up:
            self._replay(self.replay_per_message)

    def finish(self, wait_s: float) -> None:
        """Replay everything spooled if a hub is up within `wait_s`; else keep it on disk."""
        self._notice_losses()
        if self.spool.pending and self.watch.up.wait(wait_s):
            self._replay(None)
        if self.spool.pending:
            log.warning("no hub to replay to: %d messages stay in the spool %s for the next start",
                        self.spool.pending, self.spool.directory)

    def _notice_losses(self) -> None:
        losses = self.watch.losses
        if losses != self._losses_seen:
            self._losses_seen = losses
            log.warning("the hub is gone: spooling to %s (with the last %d messages sent)", self.spool.directory,
                        len(self._recent))
            if self.spool.pending:  # they were replayed from the spool, whose rest must follow them
                self.spool.requeue(list(self._recent))
            else:
                for entry in self._recent:
                    self.spool.append(entry)
            self._recent.clear()

    def _replay(self, limit: int | None) -> None:
        count = 0
        while limit is None or count < limit:
            self._notice_losses()
            if not self.watch.up.is_set():
                return
            entry = self.spool.peek()
            if entry is None:
                log.info("spool %s replayed (%d messages in all)", self.spool.directory, self.replayed)
                return
            self._send(entry)
            self.spool.pop()
            self.replayed += 1
            count += 1

    def _send(self, entry: Entry) -> None:
        self.publisher.publish_bytes(entry.key, entry.payload, entry.encoding)
        self._recent.append(entry)

    def close(self) -> None:
        self.watch.close()
        self.spool.close()

    def __enter__(self) -> SpooledPublisher:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@contextmanager
def edge_publisher(bus: BusSession, venue: str, directory: Path | None,
                   limit_bytes: int = DEFAULT_LIMIT_BYTES) -> Iterator[Publisher | SpooledPublisher]:
    """The edge's publisher: spooled to `directory` while no hub is up, or plain when None."""
    with Publisher(bus) as publisher:
        if directory is None:
            yield publisher
            return
        with SpooledPublisher(bus, publisher, venue, Spool(directory, limit_bytes)) as spooled:
            yield spooled
