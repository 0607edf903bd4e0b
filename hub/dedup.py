"""Which hub inputs are repeats: fixed memory per stream, no I/O.

An edge's spool replays, after a hub loss, a window of messages the hub may already have had
(reckon/transport/spool.py), and a restarted hub may see again what its recording already held. Each
input belongs to one stream, and within a stream it has a position that only moves forward:

- counted streams: ImuBatch by (agent, sensor) and its `sequence`; CameraFrame by camera and its
  `frame`; SwimLength by (agent, sensor) and its `index`. A window of the last `window` positions
  (a bit mask) tells a repeat from a late arrival that is new: the bus may reorder across keys but
  a repeat is exact;
- timed streams: every other input by its key (and the beacon of a BeaconSighting, the source of
  a PositionFix: several of those share a key and a time) and its `timestamp_ns`. A message not
  newer than the last one taken on its stream is a repeat (the same time: `duplicates`) or out of
  order (`stale`); both are dropped. A repeat of an older message than the newest counts as
  stale: one timestamp per stream cannot tell it from an out-of-order one (a fixed memory's price;
  a counted stream can).

A position far behind the stream's (more than `window` counts, or `reset_s` seconds) is a
device or edge that started again (its counter or clock from zero): taken, counted in `resets`,
and the stream starts over from it. Streams are capped at `max_streams` (the oldest forgotten
first), so a flood of made-up keys cannot grow the memory.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any

from protocol import messages

WINDOW = 4096  # positions remembered per counted stream: above the edges' resend window (1024 messages)
RESET_S = 60.0  # a timed stream this far behind its newest message restarted; a resend spans ~12 s
RESET_NS = int(RESET_S * 1e9)  # the hubs' own rule for an agent's poses going back (a clock restart)
MAX_STREAMS = 65536  # 10 chairs use ~60; each stream costs ~1 KB at most


class Verdict(enum.Enum):
    NEW = "new"
    DUPLICATE = "duplicate"  # exactly a message already taken
    STALE = "stale"  # older than the newest taken on its stream, and not a restart


@dataclass
class DedupCounters:
    duplicates: int = 0
    stale: int = 0
    resets: int = 0  # streams that started over (a device's counter or clock restarted)


@dataclass(slots=True)
class _Counted:
    newest: int
    seen: int  # bit i: position newest - i was taken


@dataclass(frozen=True)
class DedupSettings:
    window: int = WINDOW
    reset_s: float = RESET_S
    max_streams: int = MAX_STREAMS

    def __post_init__(self) -> None:
        if self.window < 1 or self.reset_s <= 0 or self.max_streams < 1:
            raise ValueError(f"dedup window {self.window} and max_streams {self.max_streams} must be >= 1 "
                             f"and reset_s {self.reset_s} > 0")


_COUNTED = {"ImuBatch": "sequence", "CameraFrame": "frame", "SwimLength": "index"}
# Types whose several streams share a key and a time, told apart by this field (named per type: a
# getattr with a default on a protobuf message that lacks the field raises inside, 2 µs a call)
_DISCRIMINATOR = {"BeaconSighting": "beacon_id", "PositionFix": "source_id", "Correction": "source_id"}


class Deduplicator:
    def __init__(self, settings: DedupSettings = DedupSettings()):
        self.settings = settings
        self.counters = DedupCounters()
        self._counted: dict[tuple[str, ...], _Counted] = {}
        self._timed: dict[tuple[str, ...], int] = {}

    def check(self, key: str, message: Any) -> Verdict:
        """Whether `message`, which arrived on `key`, is new (and, if so, remember it)."""
        name = messages.type_name(message)
        field = _COUNTED.get(name)
        if field is not None:
            stream = (name, message.camera_id) if name == "CameraFrame" else (name, message.agent_id, message.sensor_id)
            verdict = self._check_counted(stream, int(getattr(message, field)))
        else:
            field = _DISCRIMINATOR.get(name)
            discriminator = getattr(message, field) if field else ""
            verdict = self._check_timed((key, discriminator), int(message.timestamp_ns))
        if verdict is Verdict.DUPLICATE:
            self.counters.duplicates += 1
        elif verdict is Verdict.STALE:
            self.counters.stale += 1
        return verdict

    def _check_counted(self, stream: tuple[str, ...], position: int) -> Verdict:
        state = self._counted.get(stream)
        if state is None:
            self._remember(self._counted, stream, _Counted(position, 1))
            return Verdict.NEW
        behind = state.newest - position
        if behind < 0:  # ahead: shift the window
            shift = -behind
            state.seen = ((state.seen << shift) | 1) & self._mask if shift < self.settings.window else 1
            state.newest = position
            return Verdict.NEW
        if behind >= self.settings.window:
            self.counters.resets += 1
            state.newest, state.seen = position, 1
            return Verdict.NEW
        bit = 1 << behind
        if state.seen & bit:
            return Verdict.DUPLICATE
        state.seen |= bit  # a late arrival the window had not seen
        return Verdict.NEW

    def _check_timed(self, stream: tuple[str, ...], time_ns: int) -> Verdict:
        newest = self._timed.get(stream)
        if newest is None:
            self._remember(self._timed, stream, time_ns)
            return Verdict.NEW
        if time_ns > newest:  # most inputs: a known stream moving on
            self._timed[stream] = time_ns
            return Verdict.NEW
        if time_ns == newest:
            return Verdict.DUPLICATE
        if newest - time_ns > self.settings.reset_s * 1e9:
            self.counters.resets += 1
            self._timed[stream] = time_ns
            return Verdict.NEW
        return Verdict.STALE

    @property
    def _mask(self) -> int:
        return (1 << self.settings.window) - 1

    def _remember(self, table: dict, stream: tuple[str, ...], value: Any) -> None:
        if stream not in table and len(table) >= self.settings.max_streams:
            del table[next(iter(table))]  # the stream that came first: dicts keep insertion order
        table[stream] = value
