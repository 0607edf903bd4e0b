"""x-io x-IMU3 data-message decoder, push style: `Ximu3Decoder().feed(chunk) -> list[Frame]`.

Protocol (x-IMU3 User Manual, "Communication protocol"; x-IMU3-Software `x-IMU3-API/Rust/src/
decoder.rs` and `data_messages/`):
- every message ends in LF (0x0A), which appears nowhere else in a message;
- first byte `{` = JSON command response, `^` = mux-wrapped message, 'A'..'Z' = ASCII data,
  >= 0x80 = binary data (binary id = ASCII id + 0x80: inertial 0xC9, magnetometer 0xCD);
- ASCII: `I,<timestamp us>,gx,gy,gz,ax,ay,az\\r\\n` (deg/s, g), `M,<timestamp us>,mx,my,mz\\r\\n`
  (a.u.), numbers to four decimal places; the vendor parser also takes a bare `\\n`, so do we;
- binary: id, u64 timestamp in us, little-endian f32 arguments, LF; the bytes before LF are
  byte-stuffed (0x0A -> DB DC, 0xDB -> DB DD: SLIP with END = 0x0A).

What becomes of each line (the bytes up to and including LF):
- a valid `I`/`M` message -> `InertialFrame` / `MagnetometerFrame`, raw bytes kept;
- a JSON command response -> skipped and counted (`command_responses`);
- another message id (Q, A, B, binary 0xD1, mux `^`, ...) -> skipped and counted per id (a mux
  stream, several devices on one port, is not supported: read each device on its own port);
- anything else -> `Rejected(raw, reason, offset, detail)`, returned in order among the frames.

Resync: a line that does not parse whole is searched for a valid `I`/`M` message at its end
(garbage that arrived before the message, or a damaged message whose LF was lost). The shortest
such suffix whose timestamp lies within `salvage_window_us` of the last accepted frame is decoded
and the bytes before it are rejected (GARBAGE). The timestamp test is what stops a float's bytes
from being read as a message: a timestamp assembled from payload bytes is wildly off. Before the
first accepted frame there is no reference: two damaged lines whose candidates agree make one.

Bounded buffer: a line that reaches `max_message_bytes` without LF is rejected in pieces of that
size (OVERLONG) and decoding resumes after the next LF. Every outcome depends on the byte stream
only, never on how it was cut into chunks. Pure: no I/O, no clock, no logging.
"""

from __future__ import annotations

import array
import enum
import json
import math
import re
import struct
from dataclasses import dataclass
from typing import Union

from edge.decoders.devices import DeviceDecoder
from protocol.errors import ConfigError

Vector3 = tuple[float, float, float]

ESCAPE = b"\xdb"
ESCAPED_LF = b"\xdb\xdc"
ESCAPED_ESCAPE = b"\xdb\xdd"
INERTIAL_ID = ord("I")
MAGNETOMETER_ID = ord("M")
BINARY_ID_OFFSET = 0x80
BINARY_INERTIAL = struct.Struct("<BQ6f")  # id, timestamp us, gyro xyz deg/s, accel xyz g: 33 bytes + LF
BINARY_MAGNETOMETER = struct.Struct("<BQ3f")  # id, timestamp us, magnetometer xyz a.u.: 21 bytes + LF
# The vendor decoder's buffer (decoder.rs BUFFER_SIZE); JSON settings responses are the longest
# messages a device sends, an I/M message is at most ~200 bytes.
MAX_MESSAGE_BYTES = 4096
# How far back from the end of a damaged line a message start is looked for: longer than any
# I/M message (ASCII I with a 20-digit timestamp and six long numbers, or binary stuffed 2x).
SALVAGE_SEARCH_BYTES = 256
DEFAULT_SALVAGE_WINDOW_US = 1_000_000
# x-IMU3 manual, magnetometer specification: "1 a.u. is equal to the magnitude of the ambient
# magnetic field during calibration, approximately 50 uT". Change it when a device's calibration
# certificate states another field.
MAG_UT_PER_AU = 50.0
UINT64_MAX = 2**64 - 1
# Plausibility bounds, 5 x the x-IMU3's ranges (+-2000 deg/s, +-16 g; the magnetometer reads a few
# a.u.). Binary messages carry no checksum: fuzzing found a message cut short whose bytes plus the
# next message's make exactly one message's length, with absurd floats (1e13 deg/s) where the
# next message's bytes landed. A value beyond these bounds rejects the line, which is then salvaged.
MAX_GYRO_DPS = 10_000.0
MAX_ACCEL_G = 80.0
MAX_MAG_AU = 100.0

_NUMBER = rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_ASCII_INERTIAL = re.compile(rb"I,(\d{1,20})" + (rb",(" + _NUMBER + rb")") * 6 + rb"\r?\n")
_ASCII_MAGNETOMETER = re.compile(rb"M,(\d{1,20})" + (rb",(" + _NUMBER + rb")") * 3 + rb"\r?\n")
_MESSAGE_START = re.compile(rb"[\xc9\xcdIM]")


class RejectReason(str, enum.Enum):
    """Why bytes were rejected; the value is the counter key."""

    BAD_ESCAPE = "bad_escape"  # 0xDB not followed by 0xDC/0xDD in a binary message
    BAD_LENGTH = "bad_length"  # binary I/M message of the wrong length after unstuffing
    BAD_ASCII = "bad_ascii"  # `I,`/`M,` line that is not a timestamp and the right count of numbers
    BAD_JSON = "bad_json"  # line starting with `{` that is not a JSON object
    NOT_FINITE = "not_finite"  # NaN or infinity in a measurement
    OUT_OF_RANGE = "out_of_range"  # a value beyond MAX_GYRO_DPS / MAX_ACCEL_G / MAX_MAG_AU
    NOT_A_MESSAGE = "not_a_message"  # first byte is no message id (lower case, digit, control byte)
    OVERLONG = "overlong"  # max_message_bytes reached without LF
    GARBAGE = "garbage"  # bytes before a message found at the end of a damaged line
    TRUNCATED = "truncated"  # partial message dropped by reset()


@dataclass(frozen=True, slots=True)
class InertialFrame:
    timestamp_us: int  # device clock
    gyro_dps: Vector3
    accel_g: Vector3
    raw: bytes  # the message as received, LF included


@dataclass(frozen=True, slots=True)
class MagnetometerFrame:
    timestamp_us: int  # device clock
    mag_au: Vector3  # calibrated, 1 a.u. = field magnitude at calibration: see mag_au_to_gauss
    raw: bytes


@dataclass(frozen=True, slots=True)
class Rejected:
    raw: bytes
    reason: RejectReason
    offset: int  # stream position of raw[0] (bytes fed since construction)
    detail: str


Frame = Union[InertialFrame, MagnetometerFrame, Rejected]


@dataclass(frozen=True)
class DecoderCounters:
    """A snapshot of what the decoder has seen. Every fed byte is in exactly one of: a frame's or a
    Rejected's raw bytes, skipped_bytes, or pending_bytes."""

    bytes_fed: int
    inertial_frames: int
    magnetometer_frames: int
    command_responses: int
    skipped_messages: int  # command responses + other message ids
    skipped_bytes: int
    skipped_by_id: dict[str, int]  # "Q", "^", "0xD1", ... (at most 256 keys)
    rejected_frames: int
    rejected_bytes: int
    rejected_by_reason: dict[str, int]
    pending_bytes: int


def mag_au_to_gauss(mag_au: Vector3, ut_per_au: float = MAG_UT_PER_AU) -> Vector3:
    """x-IMU3 magnetometer a.u. -> gauss (1 gauss = 100 uT)."""
    scale = ut_per_au / 100.0
    return (mag_au[0] * scale, mag_au[1] * scale, mag_au[2] * scale)


def gauss_to_mag_au(mag_gauss: Vector3, ut_per_au: float = MAG_UT_PER_AU) -> Vector3:
    """Inverse of mag_au_to_gauss (used by the simulated device)."""
    scale = 100.0 / ut_per_au
    return (mag_gauss[0] * scale, mag_gauss[1] * scale, mag_gauss[2] * scale)


def _id_name(first: int) -> str:
    return chr(first) if 0x20 < first < 0x7F else f"0x{first:02X}"


def _unstuff(body: bytes) -> bytes | None:
    """Undo byte stuffing; None on an invalid escape. In valid data every 0xDB starts a pair, so
    counting pairs validates, and replacing DB DC before DB DD cannot misread an escaped 0xDB."""
    if ESCAPE not in body:
        return body
    if body.count(ESCAPE) != body.count(ESCAPED_LF) + body.count(ESCAPED_ESCAPE):
        return None
    return body.replace(ESCAPED_LF, b"\n").replace(ESCAPED_ESCAPE, ESCAPE)


def _beyond_range(inertial: bool, values: tuple[float, ...] | list[float]) -> str:
    """'' when every value is plausible, else what is not (the value and the bound)."""
    if inertial:
        gyro, accel = max(abs(v) for v in values[0:3]), max(abs(v) for v in values[3:6])
        if gyro > MAX_GYRO_DPS:
            return f"|gyro| {gyro:.6g} deg/s exceeds {MAX_GYRO_DPS:g}"
        if accel > MAX_ACCEL_G:
            return f"|accel| {accel:.6g} g exceeds {MAX_ACCEL_G:g}"
        return ""
    mag = max(abs(v) for v in values)
    return f"|mag| {mag:.6g} a.u. exceeds {MAX_MAG_AU:g}" if mag > MAX_MAG_AU else ""


ParseResult = Union[InertialFrame, MagnetometerFrame, tuple[RejectReason, str], None]


def parse_message(line: bytes) -> ParseResult:
    """Parse one I/M message (LF included). Returns a frame, (reason, detail), or None for a line
    that is not an I/M message at all."""
    first = line[0]
    if first == INERTIAL_ID + BINARY_ID_OFFSET or first == MAGNETOMETER_ID + BINARY_ID_OFFSET:
        body = _unstuff(line[:-1])
        if body is None:
            return RejectReason.BAD_ESCAPE, "0xDB not followed by 0xDC or 0xDD"
        layout = BINARY_INERTIAL if first == INERTIAL_ID + BINARY_ID_OFFSET else BINARY_MAGNETOMETER
        if len(body) != layout.size:
            return (RejectReason.BAD_LENGTH,
                    f"binary {chr(first - BINARY_ID_OFFSET)} message is {len(body) + 1} bytes after unstuffing, "
                    f"expected {layout.size + 1}")
        values = layout.unpack(body)
        if not math.isfinite(sum(values[2:])):  # one NaN or inf makes the sum non-finite
            return RejectReason.NOT_FINITE, "NaN or infinity in a binary message"
        beyond = _beyond_range(layout is BINARY_INERTIAL, values[2:])
        if beyond:
            return RejectReason.OUT_OF_RANGE, beyond
        if layout is BINARY_INERTIAL:
            return InertialFrame(values[1], values[2:5], values[5:8], line)
        return MagnetometerFrame(values[1], values[2:5], line)
    if first == INERTIAL_ID or first == MAGNETOMETER_ID:
        pattern = _ASCII_INERTIAL if first == INERTIAL_ID else _ASCII_MAGNETOMETER
        match = pattern.fullmatch(line)
        if match is None:
            count = 6 if first == INERTIAL_ID else 3
            return RejectReason.BAD_ASCII, f"not '{chr(first)},<timestamp>' and {count} numbers"
        timestamp_us = int(match[1])
        if timestamp_us > UINT64_MAX:
            return RejectReason.BAD_ASCII, f"timestamp {timestamp_us} exceeds u64"
        numbers = array.array("f", map(float, match.groups()[1:])).tolist()  # f32, as the device sends
        if not math.isfinite(sum(numbers)):
            return RejectReason.NOT_FINITE, "number out of f32 range"
        beyond = _beyond_range(first == INERTIAL_ID, numbers)
        if beyond:
            return RejectReason.OUT_OF_RANGE, beyond
        if first == INERTIAL_ID:
            return InertialFrame(timestamp_us, tuple(numbers[0:3]), tuple(numbers[3:6]), line)  # type: ignore[arg-type]
        return MagnetometerFrame(timestamp_us, tuple(numbers), line)  # type: ignore[arg-type]
    return None


class Ximu3Decoder:
    """Push-style x-IMU3 decoder. `feed` never raises on stream content; `reset` drops a partial message.

    max_message_bytes: longest line kept while waiting for LF (default 4096, the vendor's buffer).
    salvage_window_us: how close to the last accepted frame a message recovered from a damaged line
    must be stamped (default 1 s; a device clock jump inside a damaged line costs that one message).
    """

    def __init__(self, max_message_bytes: int = MAX_MESSAGE_BYTES,
                 salvage_window_us: int = DEFAULT_SALVAGE_WINDOW_US):
        if not SALVAGE_SEARCH_BYTES <= max_message_bytes <= 1 << 20:
            raise ConfigError(f"max_message_bytes: {max_message_bytes} is outside [{SALVAGE_SEARCH_BYTES}, {1 << 20}]")
        if salvage_window_us < 0:
            raise ConfigError(f"salvage_window_us: {salvage_window_us} is negative")
        self.max_message_bytes = max_message_bytes
        self.salvage_window_us = salvage_window_us
        self._pending = b""
        self._offset = 0  # stream position of _pending[0]
        self._discarding = False  # inside an overlong line, until its LF
        self._last_timestamp_us: int | None = None
        self._previous_timestamp_us: int | None = None  # the frame accepted before the last
        self._unconfirmed_us: int | None = None  # a salvage candidate seen before any accepted frame
        self._bytes_fed = 0
        self._inertial = 0
        self._magnetometer = 0
        self._commands = 0
        self._skipped = 0
        self._skipped_bytes = 0
        self._skipped_by_id: dict[str, int] = {}
        self._rejected = 0
        self._rejected_bytes = 0
        self._rejected_by_reason: dict[str, int] = {}

    def feed(self, chunk: bytes) -> list[Frame]:
        """Decode `chunk`; return complete frames and rejected bytes in stream order. An incomplete
        message at the end waits for the next chunk."""
        self._bytes_fed += len(chunk)
        data = self._pending + chunk if self._pending else bytes(chunk)
        out: list[Frame] = []
        limit = self.max_message_bytes
        start = 0
        while True:
            end = data.find(b"\n", start, start + limit)
            if end >= 0:
                self._line(data[start:end + 1], self._offset + start, out)
                start = end + 1
            elif len(data) - start >= limit:
                self._overlong(data[start:start + limit], self._offset + start, out)
                start += limit
            else:
                break
        self._pending = data[start:]
        self._offset += start
        return out

    def reset(self) -> list[Rejected]:
        """Forget stream state (after reopening a port or at end of stream). The partial message
        that was waiting, if any, comes back as one TRUNCATED Rejected. Counters are kept."""
        out: list[Frame] = []
        if self._pending:
            self._reject(out, self._pending, RejectReason.TRUNCATED, self._offset,
                         f"{len(self._pending)} bytes without LF at reset")
        self._offset += len(self._pending)
        self._pending = b""
        self._discarding = False
        self._last_timestamp_us = self._previous_timestamp_us = self._unconfirmed_us = None
        return out  # type: ignore[return-value]

    @property
    def counters(self) -> DecoderCounters:
        return DecoderCounters(
            self._bytes_fed, self._inertial, self._magnetometer, self._commands, self._skipped,
            self._skipped_bytes, dict(self._skipped_by_id), self._rejected, self._rejected_bytes,
            dict(self._rejected_by_reason), len(self._pending))

    # -- one line -------------------------------------------------------------------------------

    def _line(self, line: bytes, offset: int, out: list[Frame]) -> None:
        if self._discarding:  # the tail of an overlong line
            self._discarding = False
            if not self._salvage(line, offset, out, RejectReason.OVERLONG, 0):
                self._reject(out, line, RejectReason.OVERLONG, offset, "end of an overlong line")
            return
        first = line[0]
        parsed = parse_message(line)
        if isinstance(parsed, (InertialFrame, MagnetometerFrame)):
            self._accept(parsed, out)
            return
        if parsed is None and first == 0x7B and _is_json_object(line):  # "{"
            self._commands += 1
            self._skip(line, None)
            return
        if self._salvage(line, offset, out, RejectReason.GARBAGE, 1):
            return
        if parsed is None:
            if first >= 0x80 or 0x41 <= first <= 0x5A or first == 0x5E:  # binary, 'A'..'Z', mux '^'
                self._skip(line, _id_name(first))
                return
            if first == 0x7B:
                parsed = RejectReason.BAD_JSON, "line starting with '{' is not a JSON object"
            else:
                parsed = RejectReason.NOT_A_MESSAGE, f"first byte 0x{first:02X} is no message id"
        reason, detail = parsed
        self._reject(out, line, reason, offset, f"{detail} at byte {offset}")

    def _salvage(self, line: bytes, offset: int, out: list[Frame], prefix_reason: RejectReason,
                 lowest_start: int) -> bool:
        """Decode the shortest valid I/M suffix of a damaged line; reject the bytes before it.

        Its timestamp must lie within salvage_window_us of the last accepted frame or of the one
        before it: binary messages carry no checksum, so a damaged timestamp can be accepted, and
        found by fuzzing, it must not make the next salvage fail. Before any frame was accepted, a
        candidate is only remembered, and the next damaged line's candidate within the window of
        it is accepted: garbage before every message costs the first one."""
        reference = self._last_timestamp_us if self._last_timestamp_us is not None else self._unconfirmed_us
        window = self.salvage_window_us
        previous = self._previous_timestamp_us
        lowest = max(lowest_start, len(line) - SALVAGE_SEARCH_BYTES)
        starts = [match.start() for match in _MESSAGE_START.finditer(line, lowest)]
        candidate_us: int | None = None
        for start in reversed(starts):
            parsed = parse_message(line[start:])
            if not isinstance(parsed, (InertialFrame, MagnetometerFrame)):
                continue
            if (reference is not None and abs(parsed.timestamp_us - reference) <= window) or (
                    previous is not None and abs(parsed.timestamp_us - previous) <= window):
                if start:
                    self._reject(out, line[:start], prefix_reason, offset,
                                 f"{start} bytes before a message at byte {offset + start}")
                self._accept(parsed, out)
                return True
            if candidate_us is None:
                candidate_us = parsed.timestamp_us
        if self._last_timestamp_us is None and candidate_us is not None:
            self._unconfirmed_us = candidate_us
        return False

    def _overlong(self, piece: bytes, offset: int, out: list[Frame]) -> None:
        self._discarding = True
        self._reject(out, piece, RejectReason.OVERLONG, offset,
                     f"no LF within {self.max_message_bytes} bytes at byte {offset}")

    def _accept(self, frame: InertialFrame | MagnetometerFrame, out: list[Frame]) -> None:
        self._previous_timestamp_us = self._last_timestamp_us
        self._last_timestamp_us = frame.timestamp_us
        self._unconfirmed_us = None
        if isinstance(frame, InertialFrame):
            self._inertial += 1
        else:
            self._magnetometer += 1
        out.append(frame)

    def _skip(self, line: bytes, id_name: str | None) -> None:
        self._skipped += 1
        self._skipped_bytes += len(line)
        if id_name is not None:
            self._skipped_by_id[id_name] = self._skipped_by_id.get(id_name, 0) + 1

    def _reject(self, out: list[Frame], raw: bytes, reason: RejectReason, offset: int, detail: str) -> None:
        self._rejected += 1
        self._rejected_bytes += len(raw)
        self._rejected_by_reason[reason.value] = self._rejected_by_reason.get(reason.value, 0) + 1
        out.append(Rejected(raw, reason, offset, detail))


def _is_json_object(line: bytes) -> bool:
    try:
        return isinstance(json.loads(line), dict)
    except ValueError:  # JSONDecodeError and UnicodeDecodeError are both ValueErrors
        return False


# The x-IMU3 datasheet's full scales, +-16 g and +-2000 deg/s (saturation: edge/health.py); `reckon
# fuzz` frames from the simulated device's encoder, with garbage rich in LF, the binary ids and I/M.
DEVICE = DeviceDecoder("ximu3", full_scale=(16.0, 2000.0), new_decoder=Ximu3Decoder,
                       sync_bytes=b"\n\xc9\xcdIM,\r\xdb", fuzz_frames="sim_devices.devices.ximu3_encoder:fuzz_frames")
