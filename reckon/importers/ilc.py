"""Indoor Location Competition 2.0 walk files (`.txt` or `.txt.gz`) and floor plans, as numpy arrays.

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
from typing import Any, Iterator

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


def floor_plan_metres(geojson: dict[str, Any], width_m: float, height_m: float) -> list[list[list[list[float]]]]:
    """The walkable area of an ILC floor in the floor-plan frame (metres), as `[outer, hole, ...]`
    polygons whose rings are lists of [x, y].

    ILC's convention (checked on site1/F1: every waypoint of the 10 walks falls inside the outline,
    docs/pdr-estimator.md): the bounding box of the `floor` feature (lon/lat degrees) maps linearly
    onto [0, width_m] x [0, height_m], east to +x, north to +y. The floor feature (a MultiPolygon,
    or a Polygon) is the outline; every other Polygon is a shop or obstacle and becomes a hole of
    the outline polygon holding most of its vertices (one wholly outside every outline is dropped).
    Test walkability with `in_walkable_area` (inside an outline, outside its holes).
    InputError on a GeoJSON without a floor feature or with malformed coordinates.
    """
    features = geojson.get("features") if isinstance(geojson, dict) else None
    if not isinstance(features, list):
        raise InputError("floor plan: the GeoJSON has no 'features' list")
    floors = [f for f in features if _properties(f).get("type") == "floor"]
    if len(floors) != 1:
        raise InputError(f"floor plan: expected one feature with properties.type 'floor', found {len(floors)}")
    outlines = _polygons(floors[0], "floor feature")
    if not outlines:
        raise InputError("floor plan: the floor feature has no polygon")
    corners = np.concatenate([np.array(ring) for polygon in outlines for ring in polygon])
    low, high = corners.min(axis=0), corners.max(axis=0)
    if not np.all(high > low) or not (width_m > 0 and height_m > 0):
        raise InputError(f"floor plan: degenerate bounding box {low.tolist()}-{high.tolist()} or map size "
                         f"{width_m} x {height_m} m")
    scale = np.array([width_m, height_m]) / (high - low)

    def to_metres(ring: list[list[float]]) -> list[list[float]]:
        return ((np.array(ring, dtype=float) - low) * scale).tolist()

    plan = [[to_metres(polygon[0])] for polygon in outlines]  # holes of the outline itself are not used
    for index, feature in enumerate(features):
        if feature is floors[0]:
            continue
        for polygon in _polygons(feature, f"feature {index}"):
            hole = to_metres(polygon[0])
            # Shops along the outer wall straddle the outline (20 of 172 on site1/F1): a hole goes to
            # the outline holding most of its vertices, so a hole may cross its outline's edge.
            inside = [sum(point_in_ring(point, outline[0]) for point in hole) for outline in plan]
            if max(inside) > 0:
                plan[inside.index(max(inside))].append(hole)
    return plan


def floor_centre_lonlat(geojson: dict[str, Any]) -> tuple[float, float]:
    """(longitude, latitude) in degrees of the centre of the floor feature's bounding box."""
    floors = [f for f in geojson.get("features", []) if _properties(f).get("type") == "floor"]
    if len(floors) != 1:
        raise InputError(f"floor plan: expected one feature with properties.type 'floor', found {len(floors)}")
    corners = np.concatenate([np.array(ring) for polygon in _polygons(floors[0], "floor feature") for ring in polygon])
    low, high = corners.min(axis=0), corners.max(axis=0)
    return float(low[0] + high[0]) / 2.0, float(low[1] + high[1]) / 2.0


def _properties(feature: Any) -> dict[str, Any]:
    properties = feature.get("properties") if isinstance(feature, dict) else None
    return properties if isinstance(properties, dict) else {}


def _polygons(feature: Any, where: str) -> list[list[list[list[float]]]]:
    geometry = feature.get("geometry") if isinstance(feature, dict) else None
    kind = geometry.get("type") if isinstance(geometry, dict) else None
    if kind not in ("Polygon", "MultiPolygon"):
        return []
    polygons = [geometry["coordinates"]] if kind == "Polygon" else geometry["coordinates"]
    for polygon in polygons:
        for ring in polygon:
            if (not isinstance(ring, list) or len(ring) < 3
                    or not all(isinstance(p, list) and len(p) >= 2 and all(map(_is_number, p[:2])) for p in ring)):
                raise InputError(f"floor plan: {where} has a ring that is not a list of >= 3 [lon, lat] points")
    return [[[point[:2] for point in ring] for ring in polygon] for polygon in polygons]


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def point_in_ring(point: list[float] | tuple[float, float], ring: list[list[float]]) -> bool:
    """Even-odd rule: is (x, y) inside the closed ring (first point need not repeat)?"""
    x, y = point
    inside = False
    previous_x, previous_y = ring[-1]
    for current_x, current_y in ring:
        if (current_y > y) != (previous_y > y):
            crossing_x = previous_x + (y - previous_y) * (current_x - previous_x) / (current_y - previous_y)
            if x < crossing_x:
                inside = not inside
        previous_x, previous_y = current_x, current_y
    return inside


def in_walkable_area(point: tuple[float, float], plan: list[list[list[list[float]]]]) -> bool:
    """Inside some outline and outside all of its holes."""
    for polygon in plan:
        if point_in_ring(point, polygon[0]):
            return not any(point_in_ring(point, hole) for hole in polygon[1:])
    return False
