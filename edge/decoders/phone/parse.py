"""Parsing what a phone sends (docs/phone.md): the browser page's WebSocket JSON and the Sensor
Logger app's HTTP push, into samples for edge/decoders/phone/samples.py (and camera frames for
edge/decoders/phone/qr_frame.py). Pure: no socket, no clock.

A message that cannot be used whole raises PhoneInputError(reason); a value that is null, NaN or
not a number becomes NaN and a time that is not one becomes -1, for the batcher to count and drop.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
from typing import Any

from protocol.errors import InputError

DEG_PER_RAD = 180.0 / math.pi
MAX_TEXT_CHARS = 1 << 20  # a WebSocket message or push body larger than this is refused unread
MAX_SAMPLES_PER_MESSAGE = 5000  # 50 s at 100 Hz: more in one message is not a phone's batch
SCAN_TEXT_CHARS = 1000  # a QR code holds at most ~3 KB; stand codes are < 300 characters


class PhoneInputError(InputError):
    """A whole message that cannot be used; `reason` in plain words (sent back to the phone)."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


# A sample: (time_ns, (ax, ay, az) m/s^2, (gx, gy, gz) deg/s, (mx, my, mz) uT or None).
Sample = tuple[int, tuple[float, float, float], tuple[float, float, float], "tuple[float, float, float] | None"]


def _json(text: str | bytes) -> Any:
    if len(text) > MAX_TEXT_CHARS:
        raise PhoneInputError(f"message of {len(text)} bytes exceeds {MAX_TEXT_CHARS}")
    try:
        return json.loads(text)
    except (ValueError, UnicodeDecodeError) as error:
        raise PhoneInputError(f"not JSON ({error})") from None


def as_number(value: Any) -> float:
    """A finite float, or NaN for anything else (counted by the caller as non-finite)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return math.nan
    return float(value)


def epoch_ms_to_ns(t_ms: float) -> int:
    """Epoch ms (a float) -> ns, through whole microseconds: a float holds epoch us exactly (< 2^53)
    but not epoch ns, and browsers give at best 5 us anyway. -1 for a non-finite time."""
    if not math.isfinite(t_ms) or not 0 <= t_ms < 1e14:
        return -1
    return round(t_ms * 1000.0) * 1000


def _rows(data: Any, key: str, width: int, where: str) -> list[list[Any]]:
    rows = data.get(key)
    if not isinstance(rows, list):
        raise PhoneInputError(f"{where}: {key!r} must be a list of samples, got {type(rows).__name__}")
    if len(rows) > MAX_SAMPLES_PER_MESSAGE:
        raise PhoneInputError(f"{where}: {len(rows)} samples exceed {MAX_SAMPLES_PER_MESSAGE} per message")
    for index, row in enumerate(rows):
        if not isinstance(row, list) or len(row) != width:
            raise PhoneInputError(f"{where}: sample {index} must be a list of {width} values, got {row!r:.80}")
    return rows


def _frame(data: dict[str, Any]) -> tuple[int, bytes, int, int]:
    """A camera frame's envelope -> (time_ns, JPEG bytes, width px, height px); the pixels are
    edge/decoders/phone/qr_frame.py's to check."""
    t_ms = as_number(data.get("t"))
    if not math.isfinite(t_ms) or t_ms < 0:
        raise PhoneInputError(f"frame: \"t\" must be epoch milliseconds, got {data.get('t')!r:.40}")
    width, height, encoded = data.get("width"), data.get("height"), data.get("jpeg")
    if not all(isinstance(side, int) and not isinstance(side, bool) for side in (width, height)):
        raise PhoneInputError(f"frame: \"width\" and \"height\" must be whole pixels, got {width!r:.20}, {height!r:.20}")
    if not isinstance(encoded, str):
        raise PhoneInputError(f"frame: \"jpeg\" must be base64 text, got {type(encoded).__name__}")
    try:
        jpeg = base64.b64decode(encoded, validate=True)
    except binascii.Error as error:
        raise PhoneInputError(f"frame: \"jpeg\" is not base64 ({error})") from None
    return epoch_ms_to_ns(t_ms), jpeg, width, height


def parse_browser(text: str | bytes) -> tuple[str, Any]:
    """One page message -> ("motion", [Sample-like rows]) | ("orientation", rows) | ("scan", (time_ns, text))
    | ("frame", (time_ns, jpeg bytes, width, height)) | ("hello", dict). Motion rows are [t_ms, ax,
    ay, az, alpha, beta, gamma, interval_ms] with t_ms the phone's epoch milliseconds; returned as
    (time_ns, accel_ms2, gyro_dps, None) with the rotation rate mapped to phone axes (x = beta,
    y = gamma, z = alpha); non-finite values stay NaN for the batcher to count. PhoneInputError for
    a message that is not one of these."""
    data = _json(text)
    if not isinstance(data, dict) or not isinstance(data.get("type"), str):
        raise PhoneInputError("expected a JSON object with a \"type\"")
    kind = data["type"]
    if kind == "motion":
        samples = []
        for t, ax, ay, az, alpha, beta, gamma, _interval in _rows(data, "samples", 8, "motion"):
            t_ms = as_number(t)
            time_ns = epoch_ms_to_ns(t_ms)
            samples.append((time_ns, (as_number(ax), as_number(ay), as_number(az)),
                            (as_number(beta), as_number(gamma), as_number(alpha)), None))
        return kind, samples
    if kind == "orientation":
        return kind, _rows(data, "samples", 5, "orientation")
    if kind == "scan":
        t_ms, scanned = as_number(data.get("t")), data.get("text")
        if not math.isfinite(t_ms) or t_ms < 0:
            raise PhoneInputError(f"scan: \"t\" must be epoch milliseconds, got {data.get('t')!r:.40}")
        if not isinstance(scanned, str) or not 0 < len(scanned) <= SCAN_TEXT_CHARS:
            raise PhoneInputError(f"scan: \"text\" must be 1-{SCAN_TEXT_CHARS} characters")
        return kind, (epoch_ms_to_ns(t_ms), scanned)
    if kind == "frame":
        return kind, _frame(data)
    if kind == "hello":
        return kind, data
    raise PhoneInputError(f"unknown message type {kind!r:.40} (expected motion, orientation, scan, frame, hello)")


SENSOR_LOGGER_NAMES = {"accelerometer": "accel", "totalacceleration": "accel", "gyroscope": "gyro",
                       "magnetometer": "mag"}


def parse_sensor_logger(body: str | bytes) -> tuple[dict[str, list[tuple[int, tuple[float, float, float]]]], int]:
    """A Sensor Logger push -> ({"accel": [(time_ns, xyz m/s^2)], "gyro": [(time_ns, xyz deg/s)],
    "mag": [(time_ns, xyz uT)]}, readings of other sensors). `totalacceleration` (gravity
    included) is taken for the accelerometer when the push has it, as `accelerometer` is gravity-
    free on some phones. PhoneInputError for a body that is not the documented shape."""
    data = _json(body)
    if not isinstance(data, dict) or not isinstance(data.get("payload"), list):
        raise PhoneInputError("expected a JSON object with a \"payload\" list (Sensor Logger HTTP push)")
    if len(data["payload"]) > 3 * MAX_SAMPLES_PER_MESSAGE:
        raise PhoneInputError(f"{len(data['payload'])} readings exceed {3 * MAX_SAMPLES_PER_MESSAGE} per push")
    entries = data["payload"]
    has_total = any(isinstance(e, dict) and e.get("name") == "totalacceleration" for e in entries)
    streams: dict[str, list[tuple[int, tuple[float, float, float]]]] = {"accel": [], "gyro": [], "mag": []}
    ignored = 0
    for index, entry in enumerate(entries):
        if not isinstance(entry, dict) or not isinstance(entry.get("name"), str):
            raise PhoneInputError(f"payload[{index}] must be an object with a \"name\"")
        name = entry["name"]
        stream = SENSOR_LOGGER_NAMES.get(name)
        if stream is None or (name == "accelerometer" and has_total):
            ignored += 1
            continue
        values, time = entry.get("values"), entry.get("time")
        if not isinstance(values, dict) or isinstance(time, bool) or not isinstance(time, (int, float)):
            raise PhoneInputError(f"payload[{index}] ({name}): needs \"time\" (epoch ns) and \"values\" {{x, y, z}}")
        xyz = (as_number(values.get("x")), as_number(values.get("y")), as_number(values.get("z")))
        if stream == "gyro":
            xyz = (xyz[0] * DEG_PER_RAD, xyz[1] * DEG_PER_RAD, xyz[2] * DEG_PER_RAD)
        streams[stream].append((int(time) if math.isfinite(time) else -1, xyz))
    return streams, ignored
