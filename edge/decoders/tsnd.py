"""ATR-Promotions TSND121/TSND151 decoder, push style: `TsndDecoder().feed(chunk) -> list[Frame]`,
and the command builders a host sends to start, stop and configure the device.

Protocol (no public vendor document in reach; reconstructed from four public codebases that
agree, read, not copied): getty708/atr-tsnd-control `control/tsndctl/commands.py`, maselab/tsnd
`tsnd151.py`, KikuchiTomo/SerialTSND151 `include/packet_define_tsnd151.hpp`, lcdsmao/TSND121-Android
`TSNDService/.../TSNDServiceImpl.java`. Summary and what is verified: docs/tsnd.md.

- Frame: `0x9A | code | params | BCC`, BCC = XOR of every byte before it. There is no length
  byte: each code has a fixed parameter length (DEVICE_PARAM_BYTES, COMMAND_PARAM_BYTES).
- 0x80 acc+gyro event: tick u32, then acc x, y, z and gyro x, y, z as 3-byte signed
  little-endian integers, acc in 0.1 mg, gyro in 0.01 deg/s. 0x81 magnetometer: tick, x, y, z
  as 3-byte signed, 0.1 uT. Multi-byte fields are little-endian and the 3-byte ones are signed
  (one public Android helper reads them big-endian without sign extension: a trap, not the protocol).
- The tick counts ms since 00:00 of the measurement day and wraps to 0 at midnight.

What becomes of the bytes:
- 0x80 / 0x81 -> `InertialFrame` / `MagnetometerFrame` (the x-IMU3 decoder's types, so
  `ImuBatcher` batches them unchanged): gyro deg/s, accel g, magnetometer in a.u. of
  `mag_ut_per_au` uT (default the batcher's 50 uT), raw bytes kept;
- any other known code (0x8F ack, 0x88/0x89 measurement started/stopped, 0x90 device info,
  0x93 start response, ...) -> `TsndMessage(code, params, raw)`, counted per code;
- anything else -> `Rejected(raw, reason, offset, detail)` in stream order, reasons in RejectReason.

Time: `timestamp_us` = (days * 86 400 000 + tick) ms in us, where `days` counts the midnight wraps seen
(a tick in the last 10 minutes of the day, then one in the first 10), so timestamps keep increasing across
midnight; the origin is 00:00 of the day of the first frame. The day count survives `reset()`
(a reopened port does not move the clock back). A smaller step back is left alone: the
batcher counts it as a clock jump.

Resync: a byte that does not start a frame which checks out is rejected with the bytes after it
up to the next frame (one Rejected per run, its reason that of its first byte), so a bad checksum
costs only the damaged frame. An 8-bit XOR passes one damaged frame in 256, so a data frame must
also hold values within the device's widest range (0x80: +-16 g, +-2000 deg/s, getty708's
documented -160000..160000 and -200000..200000 counts, plus 5 %; 0x81: +-5000 uT, no range is
published, 100 x the Earth's field): a frame that lost a byte has its bytes shifted, and a
shifted 3-byte value lands far outside. A run of rejected bytes is given back in
pieces of at most `max_run_bytes`, so the buffer is bounded. Every outcome depends on the byte
stream only, never on how it was cut into chunks. Pure: no I/O, no clock, no logging.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Union

from edge.decoders.devices import DeviceDecoder
from edge.decoders.ximu3 import MAG_UT_PER_AU, InertialFrame, MagnetometerFrame, Rejected
from protocol.errors import ConfigError

HEADER = 0x9A
ACC_GYRO = 0x80
MAGNETOMETER = 0x81
STARTED = 0x88
STOPPED = 0x89
ACK = 0x8F
G_PER_COUNT = 1e-4  # acc: 0.1 mg
DPS_PER_COUNT = 0.01  # gyro: 0.01 deg/s
UT_PER_COUNT = 0.1  # magnetometer: 0.1 uT
ACC_LIMIT_COUNTS = 168_000  # +-16 g in 0.1 mg, plus 5 %
GYRO_LIMIT_COUNTS = 210_000  # +-2000 deg/s in 0.01 deg/s, plus 5 %
MAG_LIMIT_COUNTS = 50_000  # +-5000 uT in 0.1 uT: above any magnetometer's full scale we know of
DAY_MS = 86_400_000
WRAP_WINDOW_MS = 600_000  # 10 min either side of midnight: see TickClock
MAX_RUN_BYTES = 4096

# Parameter bytes of what the device sends (responses 0x8F..0xDD, events 0x80..0x8C):
# maselab/tsnd tsnd151.py _RESPONSE_ARG_LEN_MAP_; the event sizes agree with KikuchiTomo's
# NOTIFY_*_SIZE, and 0x8F/0x90/0x92/0x93 with getty708's response_param_size.
DEVICE_PARAM_BYTES: Mapping[int, int] = {
    0x80: 22, 0x81: 13, 0x82: 9, 0x83: 7, 0x84: 9, 0x85: 6, 0x86: 13, 0x87: 5, 0x88: 1, 0x89: 1,
    0x8A: 30, 0x8B: 22, 0x8C: 12,
    0x8F: 1, 0x90: 30, 0x92: 8, 0x93: 13, 0x97: 3, 0x99: 3, 0x9B: 3, 0x9D: 2, 0x9F: 5, 0xA1: 3,
    0xA3: 1, 0xA6: 1, 0xAA: 12, 0xAB: 9, 0xAD: 1, 0xAF: 1, 0xB1: 4, 0xB3: 1, 0xB6: 1, 0xB7: 24,
    0xB8: 60, 0xB9: 1, 0xBA: 5, 0xBB: 3, 0xBC: 1, 0xBD: 12, 0xBE: 12, 0xD1: 1, 0xD3: 1, 0xD6: 3,
    0xD8: 78, 0xDA: 7, 0xDC: 28, 0xDD: 1,
}
# Parameter bytes of what a host sends (the simulated device frames them with this table):
# getty708 commands.py encode(), maselab build_cmd() (a "get" command carries one 0x00),
# lcdsmao sendCommand() for 0x34.
COMMAND_PARAM_BYTES: Mapping[int, int] = {
    0x10: 1, 0x11: 8, 0x12: 1, 0x13: 14, 0x14: 1, 0x15: 1, 0x16: 3, 0x17: 1, 0x18: 3, 0x19: 1,
    0x1A: 3, 0x1B: 1, 0x1C: 2, 0x1D: 1, 0x22: 1, 0x23: 1, 0x25: 1, 0x26: 1, 0x2C: 1, 0x2D: 1,
    0x2E: 1, 0x2F: 1, 0x34: 1, 0x35: 1, 0x36: 1, 0x37: 1, 0x39: 1, 0x3A: 1, 0x3B: 1, 0x3C: 1,
    0x50: 1, 0x51: 1, 0x54: 1, 0x55: 3,
}
ACC_RANGES_G = (2, 4, 8, 16)  # 0x22 parameter 0..3
GYRO_RANGES_DPS = (250, 500, 1000, 2000)  # 0x25 parameter 0..3
MAX_PERIOD_MS = 255  # the 0x16/0x18 period is one byte


class RejectReason(str, enum.Enum):
    """Why bytes were rejected (the first byte of a run); the value is the counter key."""

    GARBAGE = "garbage"  # not 0x9A: no frame starts here
    UNKNOWN_CODE = "unknown_code"  # 0x9A followed by a code with no known length
    BAD_CHECKSUM = "bad_checksum"  # a known code, but the BCC does not match
    OUT_OF_RANGE = "out_of_range"  # a data frame that checks, but a value is beyond the device's range
    TRUNCATED = "truncated"  # a partial frame dropped by reset()


@dataclass(frozen=True, slots=True)
class TsndMessage:
    """A frame that is not a sample: ack (0x8F), started/stopped (0x88/0x89), device info, ..."""

    code: int
    params: bytes
    raw: bytes


Frame = Union[InertialFrame, MagnetometerFrame, TsndMessage, Rejected]


@dataclass(frozen=True)
class TsndCounters:
    """A snapshot. Every fed byte is in exactly one of: a frame's raw bytes, a Rejected's, or pending."""

    bytes_fed: int
    inertial_frames: int
    magnetometer_frames: int
    messages: int
    messages_by_code: dict[str, int]  # "0x8F": n, ... (at most 256 keys)
    rejected_frames: int
    rejected_bytes: int
    rejected_by_reason: dict[str, int]
    pending_bytes: int
    midnight_wraps: int


def bcc(data: bytes) -> int:
    """XOR of every byte: the frame check of the TSND protocol."""
    check = 0
    for byte in data:
        check ^= byte
    return check


def int24(data: bytes, at: int) -> int:
    """3-byte signed little-endian integer at `at`."""
    return int.from_bytes(data[at:at + 3], "little", signed=True)


class TickClock:
    """TSND tick (ms since midnight, wraps daily) -> ms since midnight of the first day seen.

    A wrap is a tick in the last WRAP_WINDOW_MS before midnight followed by one in the first
    WRAP_WINDOW_MS after it. Fuzzing found why the window is needed: a damaged frame that passes
    the 8-bit BCC carries a random tick, and "any tick half a day below the last" then added a day
    to every later timestamp. A device silent across midnight for longer than the window comes
    back a day early: a clock jump, which edge/health.py re-anchors."""

    def __init__(self) -> None:
        self.days = 0
        self._last: int | None = None

    def ms(self, tick_ms: int) -> int:
        last = self._last
        if last is not None and last >= DAY_MS - WRAP_WINDOW_MS and tick_ms < WRAP_WINDOW_MS:
            self.days += 1
        self._last = tick_ms
        return self.days * DAY_MS + tick_ms


class TsndDecoder:
    """Push-style TSND decoder. `feed` never raises on stream content; `reset` ends the stream.

    param_bytes: code -> parameter length (default DEVICE_PARAM_BYTES, what a device sends;
    COMMAND_PARAM_BYTES frames what a host sends). max_run_bytes: longest run of rejected bytes
    kept before it is given back (default 4096). mag_ut_per_au: uT per a.u. in MagnetometerFrame
    (default 50, ImuBatcher's default, so that the batcher's gauss are right).
    """

    def __init__(self, param_bytes: Mapping[int, int] = DEVICE_PARAM_BYTES, max_run_bytes: int = MAX_RUN_BYTES,
                 mag_ut_per_au: float = MAG_UT_PER_AU):
        if not 128 <= max_run_bytes <= 1 << 20:
            raise ConfigError(f"max_run_bytes: {max_run_bytes} is outside [128, {1 << 20}]")
        if not 0.0 < mag_ut_per_au < 1e4:
            raise ConfigError(f"mag_ut_per_au: {mag_ut_per_au} is outside (0, 10000)")
        self.param_bytes = dict(param_bytes)
        self.max_run_bytes = max_run_bytes
        self._au_per_count = UT_PER_COUNT / mag_ut_per_au
        self.clock = TickClock()
        self._pending = b""  # the run of rejected bytes, then the undecided bytes
        self._offset = 0  # stream position of _pending[0]
        self._scan = 0  # _pending[:_scan] is the run: decided, not a frame
        self._run_reason: tuple[RejectReason, str] | None = None  # why the run's first byte was rejected
        self._bytes_fed = 0
        self._inertial = self._magnetometer = self._messages = 0
        self._by_code: dict[str, int] = {}
        self._rejected = self._rejected_bytes = 0
        self._by_reason: dict[str, int] = {}

    def feed(self, chunk: bytes) -> list[Frame]:
        """Decode `chunk`; return frames and rejected runs in stream order. A frame not yet
        complete waits for the next chunk."""
        self._bytes_fed += len(chunk)
        return self._process(self._pending + bytes(chunk), final=False)

    def reset(self) -> list[Frame]:
        """End of stream (or a reopened port): the pending bytes come back as Rejected (a partial
        frame as TRUNCATED). Counters and the day count are kept."""
        return self._process(self._pending, final=True)

    @property
    def counters(self) -> TsndCounters:
        return TsndCounters(self._bytes_fed, self._inertial, self._magnetometer, self._messages, dict(self._by_code),
                            self._rejected, self._rejected_bytes, dict(self._by_reason), len(self._pending),
                            self.clock.days)

    # -- scanning -------------------------------------------------------------------------------

    def _process(self, data: bytes, final: bool) -> list[Frame]:
        out: list[Frame] = []
        run_start, position = 0, self._scan
        while True:
            while position - run_start >= self.max_run_bytes:  # bounded: give the run back in pieces
                self._emit_run(out, data[run_start:run_start + self.max_run_bytes], run_start, more=True)
                run_start += self.max_run_bytes
            if position >= len(data):
                break
            if data[position] != HEADER:
                found = data.find(HEADER, position)
                end = len(data) if found < 0 else found
                self._mark(RejectReason.GARBAGE, f"no 0x9A at byte {self._offset + position}")
                position = end
                continue
            verdict = self._candidate(data, position, final)
            if verdict is None:  # wait for more bytes
                break
            if isinstance(verdict, tuple):
                self._mark(*verdict)
                position += 1
                continue
            if position > run_start:
                self._emit_run(out, data[run_start:position], run_start, more=False)
            self._run_reason = None
            out.append(self._parse(data[position:position + verdict]))
            position += verdict
            run_start = position
        if final:
            if position > run_start:
                self._emit_run(out, data[run_start:position], run_start, more=False)
            self._run_reason = None
            run_start = position
        self._pending = data[run_start:]
        self._offset += run_start
        self._scan = position - run_start
        return out

    def _candidate(self, data: bytes, at: int, final: bool) -> int | tuple[RejectReason, str] | None:
        """At a 0x9A: the frame's length if a frame starts here, (reason, detail) if none does,
        None when more bytes are needed to tell."""
        where = f"at byte {self._offset + at}"
        if at + 1 >= len(data):
            return (RejectReason.TRUNCATED, f"0x9A without a code {where}") if final else None
        code = data[at + 1]
        params = self.param_bytes.get(code)
        if params is None:
            return RejectReason.UNKNOWN_CODE, f"0x9A then code 0x{code:02X}, which has no known length, {where}"
        length = params + 3
        if at + length > len(data):
            if final:
                return RejectReason.TRUNCATED, f"code 0x{code:02X} frame of {length} bytes cut short {where}"
            return None
        computed, sent = bcc(data[at:at + length - 1]), data[at + length - 1]
        if computed != sent:
            return (RejectReason.BAD_CHECKSUM,
                    f"code 0x{code:02X} frame ends in BCC 0x{sent:02X}, its bytes XOR to 0x{computed:02X}, {where}")
        if code == ACC_GYRO:
            acc = max(abs(int24(data, at + field)) for field in (6, 9, 12))
            gyro = max(abs(int24(data, at + field)) for field in (15, 18, 21))
            if acc > ACC_LIMIT_COUNTS or gyro > GYRO_LIMIT_COUNTS:
                return (RejectReason.OUT_OF_RANGE, f"code 0x80 frame checks, but holds |acc| {acc} or |gyro| {gyro} "
                        f"counts, beyond {ACC_LIMIT_COUNTS} and {GYRO_LIMIT_COUNTS}, {where}")
        elif code == MAGNETOMETER:
            mag = max(abs(int24(data, at + field)) for field in (6, 9, 12))
            if mag > MAG_LIMIT_COUNTS:
                return (RejectReason.OUT_OF_RANGE, f"code 0x81 frame checks, but holds |mag| {mag} counts, beyond "
                        f"{MAG_LIMIT_COUNTS}, {where}")
        return length

    def _mark(self, reason: RejectReason, detail: str) -> None:
        """One more byte decided not to start a frame; the first of a run names the run's reason."""
        if self._run_reason is None:
            self._run_reason = (reason, detail)

    def _emit_run(self, out: list[Frame], raw: bytes, start: int, more: bool) -> None:
        reason, detail = self._run_reason or (RejectReason.GARBAGE, "")
        offset = self._offset + start
        note = f"{len(raw)} bytes from byte {offset}" + (f" (a run longer than {self.max_run_bytes})" if more else "")
        self._rejected += 1
        self._rejected_bytes += len(raw)
        self._by_reason[reason.value] = self._by_reason.get(reason.value, 0) + 1
        # ximu3.Rejected's reason is annotated with the x-IMU3 enum; ours is another str enum.
        out.append(Rejected(raw, reason, offset, f"{note}: {detail}"))  # type: ignore[arg-type]

    # -- one frame ------------------------------------------------------------------------------

    def _parse(self, raw: bytes) -> Frame:
        code = raw[1]
        if code == ACC_GYRO:
            self._inertial += 1
            acc = (int24(raw, 6) * G_PER_COUNT, int24(raw, 9) * G_PER_COUNT, int24(raw, 12) * G_PER_COUNT)
            gyro = (int24(raw, 15) * DPS_PER_COUNT, int24(raw, 18) * DPS_PER_COUNT, int24(raw, 21) * DPS_PER_COUNT)
            return InertialFrame(self._timestamp_us(raw), gyro, acc, raw)
        if code == MAGNETOMETER:
            self._magnetometer += 1
            scale = self._au_per_count
            return MagnetometerFrame(self._timestamp_us(raw), (int24(raw, 6) * scale, int24(raw, 9) * scale,
                                                               int24(raw, 12) * scale), raw)
        self._messages += 1
        key = f"0x{code:02X}"
        self._by_code[key] = self._by_code.get(key, 0) + 1
        return TsndMessage(code, raw[2:-1], raw)

    def _timestamp_us(self, raw: bytes) -> int:
        return self.clock.ms(int.from_bytes(raw[2:6], "little")) * 1000


# ---------------------------------------------------------------------------------------------
# Commands (host -> device)


def build_frame(code: int, params: bytes | list[int] = b"\x00") -> bytes:
    """`0x9A code params BCC`; a command without parameters carries one 0x00, as the sources send it."""
    body = bytes((HEADER, code)) + bytes(params)
    return body + bytes((bcc(body),))


def start_measurement() -> bytes:
    """0x13: start now, run until stopped. Each of start and end is (mode, yy, mm, dd, h, m, s);
    mode 0 = relative, and relative 0:00:00 start / 0:00:00 end means now / no end."""
    now_forever = [0, 0, 1, 1, 0, 0, 0]
    return build_frame(0x13, now_forever + now_forever)


def stop_measurement() -> bytes:
    """0x15: stop measuring (the device answers 0x8F, then the 0x89 event)."""
    return build_frame(0x15)


def _byte_setting(name: str, value: int, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ConfigError(f"TSND {name}: {value!r} is outside [{low}, {high}]")
    return value


def acc_gyro_settings(period_ms: int, send_average: int = 1, record_average: int = 0) -> bytes:
    """0x16: sample every `period_ms` (1..255; 1 = 1000 Hz), send the mean of `send_average`
    samples (1 = every sample; 0 = send none), record the mean of `record_average` (0 = none)."""
    return build_frame(0x16, [_byte_setting("period_ms", period_ms, 1, MAX_PERIOD_MS),
                              _byte_setting("send_average", send_average, 0, 255),
                              _byte_setting("record_average", record_average, 0, 255)])


def magnetometer_settings(period_ms: int, send_average: int = 1, record_average: int = 0) -> bytes:
    """0x18: as 0x16 for the magnetometer; period 0 = off, else 10..255 ms (maselab's limits)."""
    if period_ms != 0:
        _byte_setting("magnetometer period_ms", period_ms, 10, MAX_PERIOD_MS)
    return build_frame(0x18, [period_ms, _byte_setting("send_average", send_average, 0, 255),
                              _byte_setting("record_average", record_average, 0, 255)])


def acc_range(range_g: int) -> bytes:
    """0x22: accelerometer range +-2/4/8/16 g (parameter 0..3)."""
    if range_g not in ACC_RANGES_G:
        raise ConfigError(f"TSND acc range: {range_g!r} g is not one of {', '.join(map(str, ACC_RANGES_G))}")
    return build_frame(0x22, [ACC_RANGES_G.index(range_g)])


def gyro_range(range_dps: int) -> bytes:
    """0x25: gyroscope range +-250/500/1000/2000 deg/s (parameter 0..3)."""
    if range_dps not in GYRO_RANGES_DPS:
        raise ConfigError(f"TSND gyro range: {range_dps!r} deg/s is not one of "
                          f"{', '.join(map(str, GYRO_RANGES_DPS))}")
    return build_frame(0x25, [GYRO_RANGES_DPS.index(range_dps)])


def period_for_rate(rate_hz: float, where: str = "rate_hz") -> int:
    """Sample period in whole ms for `rate_hz`; ConfigError naming `where` unless 1000 / rate_hz
    is a whole number of ms in 1..255 (rate_hz 1000, 500, 250, 200, 125, 100, ..., 4)."""
    if not 1.0 <= rate_hz <= 1000.0:
        raise ConfigError(f"{where}={rate_hz:g} is outside [1, 1000]")
    period = round(1000.0 / rate_hz)
    if abs(period * rate_hz - 1000.0) > 1e-6:
        raise ConfigError(f"{where}={rate_hz:g}: the period 1000/{rate_hz:g} = {1000.0 / rate_hz:.3f} ms is not a "
                          "whole number of ms (the TSND samples every 1..255 ms: rate_hz 1000, 500, 250, 200, 125, ...)")
    if period > MAX_PERIOD_MS:
        raise ConfigError(f"{where}={rate_hz:g}: the period {period} ms exceeds the {MAX_PERIOD_MS} ms the TSND "
                          f"can be set to (the slowest rate is 4 Hz, a 250 ms period)")
    return period


# The ranges the host sets: the widest, as the lcdsmao TSND121 app does. Reported units do not
# change with the range (0.1 mg, 0.01 deg/s), only saturation and sensor resolution do.
SETUP_ACC_RANGE_G = 16
SETUP_GYRO_RANGE_DPS = 2000


def setup_commands(rate_hz: float) -> bytes:
    """What a host sends after opening the port: stop (settings are refused while measuring), the
    acc+gyro period for `rate_hz`, the ranges, start. Sent back to back, as the lcdsmao app does."""
    return (stop_measurement() + acc_gyro_settings(period_for_rate(rate_hz)) + acc_range(SETUP_ACC_RANGE_G)
            + gyro_range(SETUP_GYRO_RANGE_DPS) + start_measurement())


def teardown_commands() -> bytes:
    """What a host sends before closing the port: stop."""
    return stop_measurement()


# Full scales as the edge sets the device up (saturation: edge/health.py); `reckon fuzz` frames from
# the simulated device's encoder, with garbage rich in the header and the 0x80/0x81 codes.
DEVICE = DeviceDecoder("tsnd", full_scale=(float(SETUP_ACC_RANGE_G), float(SETUP_GYRO_RANGE_DPS)),
                       new_decoder=TsndDecoder, sync_bytes=b"\x9a\x80\x81",
                       fuzz_frames="sim_devices.devices.tsnd_encoder:fuzz_frames")
