"""The text inside a calibration stand's QR code, and its integrity check (docs/qr-stands.md).

A stand (the indoor-navigation paper's transparent stand) tells a phone placed in its corner where
it is: position, floor, facing and tilt. The code is one line of ASCII, fields separated by `:`:

    RKS1:<venue>:<stand>:<x_cm>:<y_cm>:<floor>:<heading_cdeg>:<tilt_cdeg>:<tag>

`RKS1` is the format tag and version; x and y are whole centimetres of the venue frame; heading and
tilt whole hundredths of a degree (heading counter-clockwise from +x, as in the venue file); `tag`
is HMAC-SHA256 over everything before its `:`, keyed with the venue's stand key, truncated to
64 bits and written as 11 characters of unpadded base64url.

Why 64 bits: nobody without the key can check a guess offline, so a forger must print each guess
and have a phone scan it at the venue, where every refusal is recorded. At 2^-64 per try that
never succeeds, and it costs 11 characters; a full 256-bit tag (43 characters) would push a
typical code from QR version 5 to 7 (45 to 53 mm printed at 1 mm per module) for no gain. The venue name is inside the
tagged text, so a code cannot be moved between venues even if two share a key.

Pure: nothing here opens a file, a camera, a socket or a clock; the venue's key file is
edge/sources/phone/stand_key.py.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import math
import re
import secrets
from collections.abc import Callable, Sequence
from typing import Any

from protocol import messages
from protocol.errors import ConfigError, InputError
from protocol.session import Stand

FORMAT_TAG = "RKS"  # reckon stand
VERSION = 1
SEPARATOR = ":"  # never inside a field: ids are letters, digits, `-` and `_`
KEY_BYTES = 32  # HMAC-SHA256's output size; more adds nothing, fewer weakens the key
TAG_BYTES = 8  # 64 bits, see the module docstring
TAG_CHARS = 11  # unpadded base64url of 8 bytes
MAX_TEXT_CHARS = 300  # two 64-character ids plus numbers fit in 200; refuse anything longer before splitting
# Limits equal to the venue file's (protocol/session.py), in the code's units.
POSITION_LIMIT_CM = 1_000_000  # 10 km
FLOOR_LIMITS = (-20, 200)
HEADING_LIMIT_CDEG = 36_000  # 360 deg
TILT_LIMIT_CDEG = 9_000  # 90 deg
# A code agrees with the venue file when the difference is within the code's own rounding.
STALE_POSITION_M = 0.01
STALE_ANGLE_DEG = 0.01

_ID = re.compile(r"[A-Za-z0-9_-]{1,64}")
_INTEGER = re.compile(r"-?[0-9]{1,9}")
_TAG = re.compile(r"[A-Za-z0-9_-]{11}")
_FIELDS = ("format", "venue", "stand_id", "x_cm", "y_cm", "floor", "heading_cdeg", "tilt_cdeg", "tag")


class StandCodeError(InputError):
    """A scanned stand code that must not be trusted; `reason` says why in plain words."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


def check_key(key: bytes) -> None:
    """ConfigError unless `key` is KEY_BYTES bytes."""
    if not isinstance(key, bytes) or len(key) != KEY_BYTES:
        size = len(key) if isinstance(key, bytes) else type(key).__name__
        raise ConfigError(f"stand key: expected {KEY_BYTES} bytes, got {size}")


def _tag(body: str, key: bytes) -> str:
    digest = hmac.new(key, body.encode("ascii"), hashlib.sha256).digest()[:TAG_BYTES]
    return base64.urlsafe_b64encode(digest).decode("ascii").rstrip("=")


def encode(stand: Stand, venue: str, key: bytes) -> str:
    """The code text for `stand` of `venue`: position rounded to 1 cm, angles to 0.01 deg.
    ConfigError when the venue name, stand id, a value's range or the key cannot make a valid code."""
    check_key(key)
    for name, value in (("venue", venue), ("stand id", stand.id)):
        if not isinstance(value, str) or not _ID.fullmatch(value):
            raise ConfigError(f"stand code: {name} {value!r} must be 1-64 characters of A-Z a-z 0-9 _ -")
    numbers = {"x_m": stand.x_m, "y_m": stand.y_m, "heading_deg": stand.heading_deg, "tilt_deg": stand.tilt_deg}
    for name, value in numbers.items():
        if not math.isfinite(value):
            raise ConfigError(f"stand {stand.id!r}: {name} {value!r} is not a finite number")
    fields = [f"{FORMAT_TAG}{VERSION}", venue, stand.id, round(stand.x_m * 100), round(stand.y_m * 100),
              stand.floor, round(stand.heading_deg * 100), round(stand.tilt_deg * 100)]
    body = SEPARATOR.join(str(field) for field in fields)
    _parse_numbers(body.split(SEPARATOR), error=lambda reason: ConfigError(f"stand {stand.id!r}: {reason}"))
    return f"{body}{SEPARATOR}{_tag(body, key)}"


def _parse_numbers(fields: Sequence[str], error: Callable[[str], Exception]) -> tuple[int, int, int, int, int]:
    """x_cm, y_cm, floor, heading_cdeg, tilt_cdeg from a split code; `error(reason)` builds the exception."""
    limits = {"x_cm": (-POSITION_LIMIT_CM, POSITION_LIMIT_CM), "y_cm": (-POSITION_LIMIT_CM, POSITION_LIMIT_CM),
              "floor": FLOOR_LIMITS, "heading_cdeg": (-HEADING_LIMIT_CDEG, HEADING_LIMIT_CDEG),
              "tilt_cdeg": (-TILT_LIMIT_CDEG, TILT_LIMIT_CDEG)}
    values = []
    for name, text in zip(_FIELDS[3:8], fields[3:8]):
        low, high = limits[name]
        if not _INTEGER.fullmatch(text):
            raise error(f"malformed field {name}: {text!r} is not a whole number")
        if not low <= int(text) <= high:
            raise error(f"malformed field {name}: {int(text)} is outside [{low}, {high}]")
        values.append(int(text))
    x_cm, y_cm, floor, heading_cdeg, tilt_cdeg = values
    return x_cm, y_cm, floor, heading_cdeg, tilt_cdeg


def decode(text: str, venue: str, key: bytes, stands: Sequence[Stand] = ()) -> Stand:
    """The stand a scanned code describes, as the code says it (1 cm, 0.01 deg), once its tag is
    checked with `key`. With `stands` (the venue file's), the stand must be listed there and agree
    with it. StandCodeError(reason) for anything not to trust; ConfigError for a wrong-size key."""
    check_key(key)
    if not text.startswith(FORMAT_TAG):
        raise StandCodeError(f"not a reckon stand code (it starts {text[:12]!r}, a stand code starts "
                             f"{FORMAT_TAG}{VERSION}{SEPARATOR})")
    if len(text) > MAX_TEXT_CHARS:
        raise StandCodeError(f"not a reckon stand code ({len(text)} characters, a stand code has at most "
                             f"{MAX_TEXT_CHARS})")
    fields = text.split(SEPARATOR)
    version = fields[0][len(FORMAT_TAG):]
    if not version.isdigit() or not version.isascii():
        raise StandCodeError(f"not a reckon stand code (it starts {fields[0][:12]!r})")
    if int(version) != VERSION:
        raise StandCodeError(f"unsupported stand code version {int(version)} (this reckon reads version {VERSION}); "
                             "update reckon on the phone or print the stand's code again")
    if len(fields) != len(_FIELDS):
        raise StandCodeError(f"malformed stand code: {len(fields)} fields, expected {len(_FIELDS)} "
                             f"({', '.join(_FIELDS)})")
    for name, value in zip(_FIELDS[1:3], fields[1:3]):
        if not _ID.fullmatch(value):
            raise StandCodeError(f"malformed field {name}: {value!r} is not 1-64 characters of A-Z a-z 0-9 _ -")
    if fields[1] != venue:
        raise StandCodeError(f"another venue's code: it is for venue {fields[1]!r}, this is venue {venue!r}")
    if not _TAG.fullmatch(fields[8]):
        raise StandCodeError(f"malformed field tag: {fields[8]!r} is not {TAG_CHARS} base64url characters")
    x_cm, y_cm, floor, heading_cdeg, tilt_cdeg = _parse_numbers(fields, StandCodeError)
    body = text[: -len(fields[8]) - len(SEPARATOR)]
    if not hmac.compare_digest(_tag(body, key), fields[8]):
        raise StandCodeError("integrity code does not match: the code was altered, forged, or made with "
                             "another key than this venue's")
    stand = Stand(id=fields[2], x_m=x_cm / 100, y_m=y_cm / 100, floor=floor, heading_deg=heading_cdeg / 100,
                  tilt_deg=tilt_cdeg / 100)
    if stands:
        _check_against_venue(stand, venue, stands)
    return stand


def _check_against_venue(stand: Stand, venue: str, stands: Sequence[Stand]) -> None:
    listed = next((s for s in stands if s.id == stand.id), None)
    if listed is None:
        raise StandCodeError(f"stand {stand.id!r} is not listed in venue {venue!r} (removed from the venue file "
                             "since this code was printed?)")
    differences = []
    if math.hypot(stand.x_m - listed.x_m, stand.y_m - listed.y_m) > STALE_POSITION_M:
        differences.append(f"x {stand.x_m:.2f} m, y {stand.y_m:.2f} m where the venue file has "
                           f"x {listed.x_m:.2f} m, y {listed.y_m:.2f} m")
    if stand.floor != listed.floor:
        differences.append(f"floor {stand.floor} where the venue file has floor {listed.floor}")
    heading_off_deg = (stand.heading_deg - listed.heading_deg + 180.0) % 360.0 - 180.0  # 359 deg = -1 deg
    if abs(heading_off_deg) > STALE_ANGLE_DEG:
        differences.append(f"heading {stand.heading_deg:.2f} deg where the venue file has {listed.heading_deg:.2f} deg")
    if abs(stand.tilt_deg - listed.tilt_deg) > STALE_ANGLE_DEG:
        differences.append(f"tilt {stand.tilt_deg:.2f} deg where the venue file has {listed.tilt_deg:.2f} deg")
    if differences:
        raise StandCodeError(f"stale print of stand {stand.id!r}: the code says {'; '.join(differences)}; "
                             "print its code again (reckon qr make)")


def scan_message(text: str, time_ns: int, agent_id: str, sensor_id: str, venue: str, key: bytes,
                 stands: Sequence[Stand] = ()) -> Any:
    """A StandScan message for a phone's scan of `text` at `time_ns` (device clock): the stand's
    pose (angles in radians) when accepted, else `accepted` false with the reason. Either way the
    scanned text is kept in `payload`. A wrong-size key is a ConfigError, not a refused scan."""
    try:
        stand = decode(text, venue, key, stands)
    except StandCodeError as error:
        return messages.new("StandScan", timestamp_ns=time_ns, agent_id=agent_id, sensor_id=sensor_id,
                            payload=text, accepted=False, reason=error.reason)
    return messages.new("StandScan", timestamp_ns=time_ns, agent_id=agent_id, sensor_id=sensor_id,
                        stand_id=stand.id, x_m=stand.x_m, y_m=stand.y_m, floor=stand.floor,
                        heading_rad=math.radians(stand.heading_deg), tilt_rad=math.radians(stand.tilt_deg),
                        payload=text, accepted=True, reason="")


# ---------------------------------------------------------------------------------------------
# The venue's key (its file, 64 hex digits, is read and written by edge/sources/phone/stand_key.py)


def new_key() -> bytes:
    """A fresh random stand key."""
    return secrets.token_bytes(KEY_BYTES)
