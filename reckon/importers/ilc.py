"""Indoor Location Competition 2.0 walk files (`.txt` or `.txt.gz`), as numpy arrays (floor plans:
reckon/importers/ilc_plan.py).

Source: location-competition/indoor-location-competition-20 (MIT), commit 8ab177cd, data/site1/F1
(shared/data/pdr/ilc-site1-F1, see its PROVENANCE.tsv). A walk file is tab-separated text:

    #  startTime:1574559652119                     header lines: key:value pairs
    #  SiteID:...  SiteName:...  FloorId:...  FloorName:F1
    #  Brand:OPPO  Model:PBCM10  AndroidName:8.1.0  APILevel:27
    1574559652241  TYPE_ACCELEROMETER  x  y  z  [accuracy]      unix ms, m/s^2 (gravity included)
    1574559652241  TYPE_GYROSCOPE       x  y  z  [accuracy]      rad/s
    1574559652241  TYPE_MAGNETIC_FIELD  x  y  z  [accuracy]      uT
    1574559652241  TYPE_ROTATION_VECTOR x  y  z  [accuracy]      Android's unit-quaternion vector part
    1574559652126  TYPE_WAYPOINT        x  y                     metres, floor-plan frame (ground truth)

Android frame: x to the right of the screen, y to its top, z out of the screen. Other record types
(Wi-Fi, beacons, uncalibrated sensors, ...) are counted per type and not parsed.

Alignment: Android logs the four motion sensors with one shared timestamp per sample. An IMU sample
is a timestamp at which every one of those sensors the file carries has a row; a row whose partner
is missing, or a second row of one sensor at the same time, is dropped and counted in
`skipped_lines`. Bad input: a line that cannot be read (bad time, bad number, wrong field count)
raises InputError naming `file:line` and the value. A truncated or corrupt gzip stream raises
IlcTruncatedError (an InputError) naming the file; its `partial` holds the walk parsed from the
complete lines before the damage (a last line cut mid-way is dropped, never half-read).
"""

from __future__ import annotations

import gzip
import math
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from protocol.errors import InputError

NS_PER_MS = 1_000_000
ACCELEROMETER, GYROSCOPE, MAGNETOMETER, ROTATION = ("TYPE_ACCELEROMETER", "TYPE_GYROSCOPE",
                                                    "TYPE_MAGNETIC_FIELD", "TYPE_ROTATION_VECTOR")
WAYPOINT = "TYPE_WAYPOINT"
MOTION_TYPES = (ACCELEROMETER, GYROSCOPE, MAGNETOMETER, ROTATION)
# values after the type: three axes plus Android's optional accuracy (an integer 0-3)
AXES_FIELDS = (3, 4)
WAYPOINT_FIELDS = (2,)
HEADER_KEYS = {"startTime", "endTime", "SiteID", "SiteName", "FloorId", "FloorName", "Brand", "Model",
               "AndroidName"}


class IlcTruncatedError(InputError):
    """The gzip stream ended early or is corrupt; `partial` is the walk read before the damage."""

    def __init__(self, message: str, partial: "IlcWalk"):
        super().__init__(message)
        self.partial = partial


@dataclass(frozen=True)
class IlcWalk:
    """One walk. IMU arrays share `time_ns` (unix ns); `mag_ut`/`rotation_vector` are None when the
    file has no such rows. `ignored_lines`: record type -> lines not parsed (Wi-Fi, beacons...)."""

    source: str
    time_ns: np.ndarray
    accel_ms2: np.ndarray
    gyro_rads: np.ndarray
    mag_ut: np.ndarray | None
    rotation_vector: np.ndarray | None
    waypoint_time_ns: np.ndarray
    waypoint_xy: np.ndarray
    header: dict[str, str] = field(default_factory=dict)
    skipped_lines: int = 0
    ignored_lines: dict[str, int] = field(default_factory=dict)
    truncated: bool = False

    @property
    def phone(self) -> str:
        return f"{self.header.get('Brand', '')} {self.header.get('Model', '')}".strip() or "unknown"

    @property
    def site_id(self) -> str:
        return self.header.get("SiteID", "")

    @property
    def floor_id(self) -> str:
        return self.header.get("FloorId", "")


def read_ilc(path: Path | str) -> IlcWalk:
    """Parse one walk file (gzip by its `.gz` suffix). InputError naming `file:line` on a bad line;
    IlcTruncatedError (with `.partial`) on a damaged gzip stream; InputError if unreadable."""
    path = Path(path)
    parser = _Parser(str(path))
    try:
        for number, raw in _lines(path):
            parser.line(number, raw)
    except (EOFError, gzip.BadGzipFile, zlib.error) as error:
        partial = parser.walk(truncated=True)
        raise IlcTruncatedError(
            f"{path}: gzip stream truncated or corrupt after line {parser.last_line} ({error}); the "
            f"{parser.last_line} complete lines before it were parsed ({len(partial.time_ns)} IMU samples, "
            f"{len(partial.waypoint_xy)} waypoints) and are kept in this error's `partial`", partial) from None
    except OSError as error:
        raise InputError(f"{path}: cannot read ({error.strerror or error})") from None
    return parser.walk(truncated=False)


def _lines(path: Path) -> Iterator[tuple[int, bytes]]:
    """(1-based line number, bytes) of complete lines. A last line without its newline is whole
    only if the stream then ends cleanly, so it is held back until then (a damaged stream drops it)."""
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rb") as stream:
        number = 0
        unterminated = b""
        for raw in stream:
            number += 1
            if raw.endswith(b"\n"):
                yield number, raw
            else:
                unterminated = raw
        if unterminated:
            yield number, unterminated


class _Parser:
    """Accumulates rows line by line, so a damaged stream keeps everything before the damage."""

    def __init__(self, source: str):
        self.source = source
        self.last_line = 0
        self.header: dict[str, str] = {}
        self.rows: dict[str, list[tuple[int, tuple[float, ...]]]] = {name: [] for name in MOTION_TYPES}
        self.waypoints: list[tuple[int, float, float]] = []
        self.ignored: dict[str, int] = {}
        self.blank = 0

    def line(self, number: int, raw: bytes) -> None:
        self.last_line = number
        where = f"{self.source}:{number}"
        try:
            text = raw.decode("utf-8").rstrip("\r\n")
        except UnicodeDecodeError as error:
            raise InputError(f"{where}: not UTF-8 text ({error.reason} at byte {error.start})") from None
        if not text.strip():
            self.blank += 1
            return
        fields = text.split("\t")
        if fields[0].strip() == "#":
            self._header(fields[1:])
            return
        if len(fields) < 2:
            raise InputError(f"{where}: expected 'unix_ms<TAB>TYPE_...<TAB>values', got {_show(text)}")
        time_ms = _integer(fields[0], where)
        kind = fields[1]
        if not kind.startswith("TYPE_"):
            raise InputError(f"{where}: record type {_show(kind)} is not a TYPE_... name")
        values = [value for value in fields[2:] if value != ""]  # the files end some lines with a tab
        if kind in self.rows:
            self.rows[kind].append((time_ms, _numbers(values, AXES_FIELDS, 3, kind, where)))
        elif kind == WAYPOINT:
            x_m, y_m = _numbers(values, WAYPOINT_FIELDS, 2, kind, where)
            self.waypoints.append((time_ms, x_m, y_m))
        else:
            self.ignored[kind] = self.ignored.get(kind, 0) + 1

    def _header(self, fields: list[str]) -> None:
        for item in fields:
            key, separator, value = item.partition(":")
            if separator and key in HEADER_KEYS:
                self.header[key] = value.strip()

    def walk(self, truncated: bool) -> IlcWalk:
        # every motion sensor the file carries must have a row at a sample's time
        required = {name for name in MOTION_TYPES if self.rows[name]} | {ACCELEROMETER, GYROSCOPE}
        tables = {name: _by_time(self.rows[name]) for name in MOTION_TYPES}
        duplicates = sum(len(self.rows[name]) - len(tables[name][0]) for name in MOTION_TYPES)
        common = None
        for name in required:
            times = tables[name][0]
            common = times if common is None else np.intersect1d(common, times, assume_unique=True)
        aligned = sum(len(tables[name][0]) for name in MOTION_TYPES) - len(common) * len(required)
        picked = {name: tables[name][1][np.searchsorted(tables[name][0], common)] if name in required else None
                  for name in MOTION_TYPES}
        waypoints = np.array(sorted(self.waypoints), dtype=float).reshape(-1, 3)
        return IlcWalk(
            source=self.source,
            time_ns=common * NS_PER_MS,
            accel_ms2=picked[ACCELEROMETER].reshape(-1, 3),
            gyro_rads=picked[GYROSCOPE].reshape(-1, 3),
            mag_ut=picked[MAGNETOMETER],
            rotation_vector=picked[ROTATION],
            waypoint_time_ns=waypoints[:, 0].astype(np.int64) * NS_PER_MS,
            waypoint_xy=waypoints[:, 1:3].copy(),
            header=dict(self.header),
            skipped_lines=duplicates + aligned + self.blank,
            ignored_lines=dict(self.ignored),
            truncated=truncated,
        )


def _by_time(rows: list[tuple[int, tuple[float, ...]]]) -> tuple[np.ndarray, np.ndarray]:
    """Sorted unique times (ms) and their (k, 3) values; of two rows at one time the first is kept."""
    if not rows:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    times = np.array([t for t, _ in rows], dtype=np.int64)
    values = np.array([v for _, v in rows], dtype=float)
    unique, first = np.unique(times, return_index=True)
    return unique, values[first]


def _show(text: str) -> str:
    return repr(text if len(text) <= 60 else text[:57] + "...")


def _integer(text: str, where: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise InputError(f"{where}: time {_show(text)} is not an integer number of milliseconds") from None


def _numbers(values: list[str], counts: tuple[int, ...], keep: int, kind: str, where: str) -> tuple[float, ...]:
    if len(values) not in counts:
        raise InputError(f"{where}: {kind} needs {' or '.join(map(str, counts))} values, got {len(values)}: "
                         f"{_show(' '.join(values))}")
    numbers = []
    for text in values[:keep]:
        try:
            number = float(text)
        except ValueError:
            number = math.nan
        if not math.isfinite(number):
            raise InputError(f"{where}: {kind} value {_show(text)} is not a finite number")
        numbers.append(number)
    return tuple(numbers)
