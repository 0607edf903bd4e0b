"""Per-sensor device health: what is wrong with a stream of `ImuBatch` messages, and its repair.

    health = DeviceHealth("chair01", ranges=ximu3.DEVICE.full_scale)  # edge.decoders.ximu3
    for batch in health.push(raw_batch, arrival_ns):  # 0..n batches, in order, safe to estimate on
        ...
    status = health.status("chair01-seat", now_ns)  # a protocol DeviceStatus

Faults, how each is found, and what "handled" means here (docs/device-faults.md):
- duplicate batch (a sequence already passed, among the last `SEEN_BATCHES`): dropped, counted
  in `duplicates`; a sample not later than the previous one passed (a repeated frame, a device
  that resends) is dropped from its batch, counted in `duplicates` (same time) or `out_of_order`
  (earlier). The estimator never sees a sample twice.
- gap / out-of-order batches: a batch ahead of the next expected sequence is held, up to
  `reorder_batches`, waiting for the missing ones; a missing batch that arrives in time is put
  back in order (counted in `out_of_order`), one that never does is counted in `gaps` once the
  hold is full (the merger bridges the time: a wheel's next increment spans it). A batch that comes after its place was
  given up is dropped (its samples are older than what the estimator has consumed) and counted in
  `out_of_order`. A sequence more than `SEEN_BATCHES` back is a producer that restarted its
  count: taken as the new start.
- clock jump: the device clock stepped, forward (device time advanced more than the host's
  arrival clock by more than `clock_jump_s`) or back (a sample more than `clock_jump_s` before
  the previous one). The sensor's times are re-anchored: a fixed shift is added to every later
  sample so the estimator sees continuous time, the first sample after the jump placed where the
  host's arrival clock says it belongs. Batches leave with shifted times, so the hub's
  lower-envelope clock offset (hub/clocks.py) is never moved by the jump either. Counted in
  `clock_jumps`; the shift is in `shift_ns` and in the warning. A forward jump of a batch with no
  arrival stamp (received_ns 0) cannot be told from a gap and is left alone.
- stuck: one axis of accel or gyro (or the whole sample) unchanged for `stuck_samples` samples
  in a row, not at full scale. Real MEMS outputs always move in their last bits; a run that long
  is a frozen sensor or a driver repeating its last reading. Flagged while it lasts, counted in
  `stuck_samples_seen`; the samples pass on (see below).
- saturation: an accel or gyro axis within `SATURATION_FRACTION` of the device's full scale
  (`ranges`: per sensor, from its decoder's `DEVICE.full_scale`, edge/decoders/devices.py, which
  the source passes on; None: unknown, not checked). Counted per sample in `saturated`, flagged.
- malformed batch: its accel or gyro values are not 3 per sample, or its magnetometer values neither
  none nor 3 per sample (a corrupt log or a decoder bug: no device sends that). Dropped whole,
  after its sequence is taken (so it is not also a gap), counted in `malformed`, flagged.
- stale: no batch for `stale_s` of the edge's clock; disconnected: the source says so.

Stuck and saturated samples still reach the chair estimator: the merger has no weights, and
dropping a wheel's samples makes it extrapolate at its last rate, which for a frozen or clipped
gyro is that same value; a clipped reading is also the best lower bound of the true rate.
Flags and counts tell the operator. Memory is fixed: a few numbers per sensor, at most
`reorder_batches` held batches. Pure: no clock (times are passed in), no I/O, no logging.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from protocol import messages
from protocol.errors import ConfigError

SEEN_BATCHES = 64  # sequences remembered (a bit mask) to tell a duplicate from a late batch
SATURATION_FRACTION = 0.999  # at or above this fraction of full scale counts as saturated
UINT32 = 1 << 32
FLAG_NAMES = ("disconnected", "stale", "stuck", "saturated", "clock_jump", "out_of_order", "duplicate", "gap",
              "malformed")

@dataclass(frozen=True)
class HealthSettings:
    """reorder_batches: batches held while a missing sequence may still come (default 4: 0.4 s at
    20-sample batches of 200 Hz; 0 drops every late batch). clock_jump_s: a device-vs-host step
    larger than this is a clock jump (default 1 s: above the latency spikes of a BLE or USB link
    and of a busy 2-core host, below any clock reset or resync worth repairing). stuck_samples:
    consecutive identical values of one axis that make it stuck (default 100: 0.5 s at 200 Hz;
    real noise changes the last bits every few samples). stale_s: no batch for this long sets
    `stale` (default 2 s: 20 batches at 200 Hz). flag_hold_s: a fault keeps its flag this long after
    it was last seen (default 2 s: two status messages)."""

    reorder_batches: int = 4
    clock_jump_s: float = 1.0
    stuck_samples: int = 100
    stale_s: float = 2.0
    flag_hold_s: float = 2.0

    def __post_init__(self) -> None:
        for name, value, low, high in (("reorder_batches", self.reorder_batches, 0, 64),
                                       ("clock_jump_s", self.clock_jump_s, 0.01, 3600.0),
                                       ("stuck_samples", self.stuck_samples, 2, 1_000_000),
                                       ("stale_s", self.stale_s, 0.01, 3600.0),
                                       ("flag_hold_s", self.flag_hold_s, 0.0, 3600.0)):
            if not low <= value <= high:
                raise ConfigError(f"device health {name}: {value} is outside [{low}, {high}]")


@dataclass
class SensorHealth:
    """One sensor's fixed-size state and totals."""

    expected_sequence: int | None = None
    seen_mask: int = 0  # bit k: sequence expected - 1 - k was passed
    held: list[Any] = field(default_factory=list)  # at most reorder_batches, sorted by sequence
    last_sample_ns: int | None = None  # device time (shifted) of the last sample passed
    last_received_ns: int = 0  # received_ns of the last batch passed (host clock)
    shift_ns: int = 0  # added to every device time since the last clock jump
    last_values: tuple[float, ...] | None = None  # accel xyz, gyro xyz of the last sample
    runs: list[int] = field(default_factory=lambda: [0] * 6)  # identical values in a row, per axis
    last_arrival_ns: int | None = None  # edge clock
    watch_from_ns: int | None = None  # edge clock from which silence counts as stale (expect())
    samples: int = 0
    gaps: int = 0
    duplicates: int = 0
    out_of_order: int = 0
    clock_jumps: int = 0
    saturated: int = 0
    stuck_samples_seen: int = 0
    malformed: int = 0
    seen_at: dict[str, int] = field(default_factory=dict)  # flag -> edge clock it was last seen


class DeviceHealth:
    """Every sensor of one agent. `push(batch, arrival_ns) -> [batch]`, `flush()`,
    `status(sensor_id, now_ns, ...) -> DeviceStatus`. `ranges`: (accel g, gyro deg/s) full scale for
    all sensors, or a dict per sensor id; None: saturation not checked."""

    def __init__(self, agent_id: str, settings: HealthSettings | None = None,
                 ranges: tuple[float, float] | dict[str, tuple[float, float] | None] | None = None):
        self.agent_id = agent_id
        self.settings = settings or HealthSettings()
        self.ranges = ranges
        self.sensors: dict[str, SensorHealth] = {}

    def sensor(self, sensor_id: str) -> SensorHealth:
        health = self.sensors.get(sensor_id)
        if health is None:
            health = self.sensors[sensor_id] = SensorHealth()
        return health

    def expect(self, sensor_id: str, now_ns: int) -> None:
        """A sensor that should report from `now_ns` on: stale if nothing comes within stale_s."""
        self.sensor(sensor_id).watch_from_ns = now_ns

    def push(self, batch: Any, arrival_ns: int) -> list[Any]:
        """One ImuBatch as it came; returns the batches to estimate on, in order (none, this one,
        or held ones released with it). A batch that needs no repair is returned as is."""
        health = self.sensor(batch.sensor_id)
        health.last_arrival_ns = arrival_ns
        out = []
        for ready in self._order(health, batch, arrival_ns):
            checked = self._check(health, ready, arrival_ns)
            if checked is not None:
                out.append(checked)
        return out

    def flush(self) -> list[Any]:
        """End of stream: the held batches of every sensor, in order (their gaps counted)."""
        out = []
        for health in self.sensors.values():
            while health.held:
                first = health.held[0]
                health.gaps += _ahead(first.sequence, health.expected_sequence or first.sequence)
                for ready in self._accept(health, health.held.pop(0)):
                    checked = self._check(health, ready, health.last_arrival_ns or 0)
                    if checked is not None:
                        out.append(checked)
        return out

    def flags(self, sensor_id: str, now_ns: int, connected: bool = True) -> list[str]:
        """What is wrong with the sensor now (names from FLAG_NAMES, in that order)."""
        health = self.sensor(sensor_id)
        hold_ns = int(self.settings.flag_hold_s * 1e9)
        now_flags = {name for name, at in health.seen_at.items() if now_ns - at <= hold_ns}
        if not connected:
            now_flags.add("disconnected")
        last = health.last_arrival_ns if health.last_arrival_ns is not None else health.watch_from_ns
        if last is not None and now_ns - last > self.settings.stale_s * 1e9:
            now_flags.add("stale")
        if max(health.runs) >= self.settings.stuck_samples:
            now_flags.add("stuck")
        return [name for name in FLAG_NAMES if name in now_flags]

    def status(self, sensor_id: str, now_ns: int, *, connected: bool = True, reconnects: int = 0,
               battery_pct: float = -1.0, spooled: int = 0) -> Any:
        """The sensor's DeviceStatus at edge time `now_ns` (the venue clock)."""
        health = self.sensor(sensor_id)
        age_s = -1.0 if health.last_arrival_ns is None else max(0.0, (now_ns - health.last_arrival_ns) * 1e-9)
        flags = self.flags(sensor_id, now_ns, connected)
        if spooled:
            flags.append("spooling")
        return messages.new(
            "DeviceStatus", timestamp_ns=now_ns, agent_id=self.agent_id, sensor_id=sensor_id, connected=connected,
            battery_pct=battery_pct, last_sample_age_s=age_s, samples=health.samples, gaps=_u32(health.gaps),
            duplicates=_u32(health.duplicates), out_of_order=_u32(health.out_of_order),
            clock_jumps=_u32(health.clock_jumps), saturated=_u32(health.saturated), reconnects=_u32(reconnects),
            spooled=_u32(spooled), flags=flags, malformed=_u32(health.malformed))

    # -- sequence order ---------------------------------------------------------------------------

    def _order(self, health: SensorHealth, batch: Any, arrival_ns: int) -> list[Any]:
        sequence = batch.sequence
        if health.expected_sequence is None:
            return self._accept(health, batch)
        ahead = _ahead(sequence, health.expected_sequence)
        if ahead == 0:
            if health.held:  # later batches came first: this one is put back in its place
                health.out_of_order += 1
                health.seen_at["out_of_order"] = arrival_ns
            return self._accept(health, batch)
        if 0 < ahead < UINT32 // 2:
            if any(held.sequence == sequence for held in health.held):
                return self._fault(health, "duplicate", arrival_ns)
            health.held.append(batch)
            health.held.sort(key=lambda held: _ahead(held.sequence, health.expected_sequence or 0))
            if len(health.held) <= self.settings.reorder_batches:
                return []
            first = health.held.pop(0)  # the hold is full: give up on what is missing before it
            health.gaps += _ahead(first.sequence, health.expected_sequence)
            health.seen_at["gap"] = arrival_ns
            return self._accept(health, first)
        age = UINT32 - ahead - 1  # 0: the last sequence passed
        if age < SEEN_BATCHES:
            kind = "duplicate" if health.seen_mask >> age & 1 else "out_of_order"
            return self._fault(health, kind, arrival_ns)
        health.held.clear()  # the producer restarted its count: a new start
        health.expected_sequence, health.seen_mask = None, 0
        return self._accept(health, batch)

    def _accept(self, health: SensorHealth, batch: Any) -> list[Any]:
        """Pass `batch` and every held batch that follows it without a gap."""
        out = [batch]
        self._mark(health, batch.sequence)
        while health.held and health.held[0].sequence == health.expected_sequence:
            out.append(health.held.pop(0))
            self._mark(health, out[-1].sequence)
        return out

    def _mark(self, health: SensorHealth, sequence: int) -> None:
        if health.expected_sequence is None:
            health.seen_mask = 1
        else:
            step = _ahead(sequence, health.expected_sequence) + 1  # 1 when in order
            health.seen_mask = ((health.seen_mask << step) | 1) & ((1 << SEEN_BATCHES) - 1)
        health.expected_sequence = (sequence + 1) % UINT32

    def _fault(self, health: SensorHealth, kind: str, arrival_ns: int) -> list[Any]:
        if kind == "duplicate":
            health.duplicates += 1
        else:
            health.out_of_order += 1
        health.seen_at[kind] = arrival_ns
        return []

    # -- samples --------------------------------------------------------------------------------

    def _check(self, health: SensorHealth, batch: Any, arrival_ns: int) -> Any | None:
        count = len(batch.sample_offset_ns)
        if not count:
            return None
        if len(batch.accel_g) != 3 * count or len(batch.gyro_dps) != 3 * count or len(batch.mag_gauss) not in (
                0, 3 * count):
            health.malformed += 1
            health.seen_at["malformed"] = arrival_ns
            return None
        first_ns = batch.timestamp_ns + health.shift_ns
        span_ns = batch.sample_offset_ns[-1]
        last_ns = health.last_sample_ns
        keep = list(range(count))
        if last_ns is not None:
            self._clock(health, batch, last_ns, first_ns, span_ns, count, arrival_ns)
            first_ns = batch.timestamp_ns + health.shift_ns
            keep = [i for i, offset in enumerate(batch.sample_offset_ns) if first_ns + offset > last_ns]
            if len(keep) < count:
                self._overlap(health, batch, last_ns, first_ns, keep, arrival_ns)
                if not keep:
                    return None
        out = batch if (health.shift_ns == 0 and len(keep) == count) else _rebuilt(batch, first_ns, keep)
        self._values(health, out, arrival_ns)
        health.samples += len(keep)
        health.last_sample_ns = out.timestamp_ns + out.sample_offset_ns[-1]
        if batch.received_ns:
            health.last_received_ns = batch.received_ns
        return out

    def _clock(self, health: SensorHealth, batch: Any, last_ns: int, first_ns: int, span_ns: int, count: int,
               arrival_ns: int) -> None:
        """Re-anchor the sensor's times on a clock jump (see the module docstring)."""
        limit_ns = int(self.settings.clock_jump_s * 1e9)
        host_ns = batch.received_ns - health.last_received_ns if batch.received_ns and health.last_received_ns else None
        device_ns = first_ns + span_ns - last_ns
        backward = first_ns - last_ns < -limit_ns
        forward = host_ns is not None and device_ns - host_ns > limit_ns
        if not (backward or forward):
            return
        spacing_ns = span_ns // (count - 1) if count > 1 else 1_000_000
        gap_ns = max(spacing_ns, (host_ns or 0) - span_ns)  # where the host clock puts the first sample
        health.shift_ns += last_ns + gap_ns - first_ns
        health.clock_jumps += 1
        health.seen_at["clock_jump"] = arrival_ns

    def _overlap(self, health: SensorHealth, batch: Any, last_ns: int, first_ns: int, keep: list[int],
                 arrival_ns: int) -> None:
        kept = set(keep)
        for i, offset in enumerate(batch.sample_offset_ns):
            if i not in kept:
                kind = "duplicate" if first_ns + offset == last_ns else "out_of_order"
                self._fault(health, kind, arrival_ns)

    def _values(self, health: SensorHealth, batch: Any, arrival_ns: int) -> None:
        """Saturation and stuck runs over the batch's samples."""
        ranges = self.ranges.get(batch.sensor_id) if isinstance(self.ranges, dict) else self.ranges
        accel, gyro = batch.accel_g, batch.gyro_dps
        limits = None if ranges is None else (ranges[0] * SATURATION_FRACTION, ranges[1] * SATURATION_FRACTION)
        stuck = self.settings.stuck_samples
        runs, last = health.runs, health.last_values
        for i in range(len(batch.sample_offset_ns)):
            values = (accel[3 * i], accel[3 * i + 1], accel[3 * i + 2], gyro[3 * i], gyro[3 * i + 1], gyro[3 * i + 2])
            clipped = limits is not None and (max(abs(v) for v in values[:3]) >= limits[0]
                                              or max(abs(v) for v in values[3:]) >= limits[1])
            if clipped:
                health.saturated += 1
                health.seen_at["saturated"] = arrival_ns
            for axis in range(6):
                at_limit = limits is not None and abs(values[axis]) >= limits[axis // 3]
                same = last is not None and values[axis] == last[axis] and not at_limit
                runs[axis] = runs[axis] + 1 if same else 1
            if max(runs) >= stuck:
                health.stuck_samples_seen += 1
            last = values
        health.last_values = last


def _ahead(sequence: int, expected: int) -> int:
    """How far `sequence` is past `expected`, modulo 2^32 (0: the expected one)."""
    return (sequence - expected) % UINT32


def _u32(value: int) -> int:
    return min(value, UINT32 - 1)


def _rebuilt(batch: Any, first_ns: int, keep: list[int]) -> Any:
    """A copy of `batch` holding samples `keep`, its times shifted to start at first_ns."""
    out = messages.ImuBatch()
    out.CopyFrom(batch)
    offsets = [batch.sample_offset_ns[i] for i in keep]
    start = first_ns + offsets[0]
    out.timestamp_ns = start
    del out.sample_offset_ns[:], out.accel_g[:], out.gyro_dps[:], out.mag_gauss[:]
    out.sample_offset_ns.extend(offset - offsets[0] for offset in offsets)
    for source, target in ((batch.accel_g, out.accel_g), (batch.gyro_dps, out.gyro_dps)):
        target.extend(v for i in keep for v in source[3 * i:3 * i + 3])
    if len(batch.mag_gauss):
        out.mag_gauss.extend(v for i in keep for v in batch.mag_gauss[3 * i:3 * i + 3])
    return out
