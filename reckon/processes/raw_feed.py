"""An edge's raw IMU batches: on the bus only while someone subscribes to them; their clocks always.

The hub needs of the raw stream only each device's clock against the edge host's (hub/clocks.py),
unless a camera is on (the identity engine reads the IMU); a recorder (`reckon record`) or the
bench's latency watcher want it all. Publishing every batch anyway cost a third of the hub's inputs
and of the edges' puts (docs/benchmarks.md). So a batch goes out on `imu/<sensor>` only while a
subscriber matches that key (Zenoh's matching status, followed by a listener), and once a
second per sensor a ClockSample carries the one batch whose (arrival - device time) was smallest
in that second, which is all the hub's lower-envelope clock estimate keeps of the batches (and a
sensor's first batch at once, so the hub never converts a pose with no offset).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from protocol import keys, messages
from reckon.transport.matching import Listened
from reckon.transport.session import BusSession

CLOCK_PERIOD_S = 1.0


@dataclass
class _Clock:
    started_ns: int  # arrival (edge host clock) of the period's first batch
    device_ns: int  # the period's best pair so far
    received_ns: int
    sent: tuple[int, int] = (0, 0)  # the pair sent last (a period's best may be the one sent at once)


class RawFeed:
    """`push(batch)` for every raw batch the edge takes; `flush()` at the end. `publisher` is the edge's
    (Publisher or SpooledPublisher); `bus` follows, per sensor, whether anyone subscribes to its raw key."""

    def __init__(self, bus: BusSession, publisher: Any, venue: str, agent_id: str):
        self._bus, self._publisher, self._venue, self._agent_id = bus, publisher, venue, agent_id
        self._watch: dict[str, Listened] = {}  # per sensor: its raw key and whether someone subscribes to it
        self._clocks: dict[str, _Clock] = {}
        self.sent = 0  # raw batches published
        self.unasked = 0  # raw batches nobody subscribed to: not published
        self.clock_samples = 0

    def push(self, batch: Any) -> None:
        watch = self._watch.get(batch.sensor_id)
        if watch is None:
            watch = self._watch[batch.sensor_id] = Listened(self._bus, keys.imu(self._venue, self._agent_id,
                                                                                batch.sensor_id))
        if watch.matching:
            self._publisher.publish(watch.key_expr, batch)
            self.sent += 1
        else:
            self.unasked += 1
        if batch.received_ns and len(batch.sample_offset_ns):
            self._clock(batch.sensor_id, batch.timestamp_ns + batch.sample_offset_ns[-1], batch.received_ns)

    def _clock(self, sensor_id: str, device_ns: int, received_ns: int) -> None:
        clock = self._clocks.get(sensor_id)
        if clock is None:  # a sensor's first batch goes at once: the hub has no offset for it before
            self._clocks[sensor_id] = clock = _Clock(received_ns, device_ns, received_ns)
            self._send(sensor_id, clock)
            return
        if received_ns - clock.started_ns >= CLOCK_PERIOD_S * 1e9:
            self._send(sensor_id, clock)
            self._clocks[sensor_id] = _Clock(received_ns, device_ns, received_ns, clock.sent)
        elif received_ns - device_ns < clock.received_ns - clock.device_ns:
            clock.device_ns, clock.received_ns = device_ns, received_ns

    def _send(self, sensor_id: str, clock: _Clock) -> None:
        if clock.sent == (clock.device_ns, clock.received_ns):
            return
        clock.sent = (clock.device_ns, clock.received_ns)
        self._publisher.publish(keys.clock(self._venue, self._agent_id, sensor_id),
                                messages.new("ClockSample", timestamp_ns=clock.device_ns, agent_id=self._agent_id,
                                             sensor_id=sensor_id, received_ns=clock.received_ns))
        self.clock_samples += 1

    def flush(self) -> None:
        """The periods still open (end of the source)."""
        for sensor_id, clock in self._clocks.items():
            self._send(sensor_id, clock)
        self._clocks.clear()

    def close(self) -> None:
        for watch in self._watch.values():
            watch.close()
        self._watch.clear()

    def __enter__(self) -> "RawFeed":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
