"""`reckon import getsensordata LOG.txt -o walk.mcap [--beacons BEACONS.csv] [--origin LAT,LON]`:
a GetSensorData log (reckon/importers/getsensordata.py) as one session log, as ILC walks are
(reckon/importers/ilc_session.py: the same agent, phone, units, stand stand-in and Earth field).

Time base: the app's clock (AppTimestamp, seconds since recording started: the one clock POSI,
BLE4 and every sensor share) in nanoseconds. A sensor's samples keep the spacing of its own
timestamps (the accurate one; AppTimestamp is when the app got the event, with delivery jitter),
moved onto the app clock by the median of AppTimestamp - SensorTimestamp over that sensor's lines.
The phone IMU's samples are the accelerometer's; the gyroscope and magnetometer are interpolated
linearly onto them. An accelerometer sample without a gyroscope (or, when the log has one, a
magnetometer) sample on each side less than MAX_INTERPOLATION_GAP_S apart is dropped and counted.

Frame: an east-north tangent plane (reckon/importers/geo.py; x east, y north, metres) at the origin,
`--origin` or the first POSI point. The venue's court is the frame's box from (0, 0): when a POSI
point or beacon lies west or south of the origin, the frame's (0, 0) is moved to COURT_MARGIN_M
(rounded out to whole metres) west/south of the farthest one, so every point has x, y >= 0 (the
session refuses beacons off the court: protocol/session.py). An origin south-west of the whole site
therefore is (0, 0) itself, whatever the log; the report and the session's `source.frame` say
where the origin lies in the frame.

Beacons (`--beacons`, CSV `id,lat,lon,floor`): `id` an identity `ibeacon:<uuid>:<major>:<minor>` or
`eddystone:<namespace>:<instance>`, or `eddystone:<instance>` (the log names an Eddystone by its
instance alone). They become the venue's beacons `beacon-1`, `beacon-2`, ... in the file's order
(each with its floor). A sighting of one is a BeaconSighting with that venue
id as `beacon_id`, as the live edge writes them (edge/sources/ble.py; the hub matches by id); a
sighting of a beacon not in the file keeps its identity (`eddystone:<instance>` for an Eddystone)
and is counted per identity in the report. A bad beacons file is an InputError naming file:line.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from protocol import keys, messages
from protocol.errors import ConfigError, InputError
from protocol.messages import STANDARD_GRAVITY_MS2, UT_PER_GAUSS
from protocol.session import beacon_identity, session_from_dict
from reckon.importers.geo import check_lat_lon, east_north_m
from reckon.importers.geomagnetic import venue_field
from reckon.importers.getsensordata import (GetSensorDataLog, Reference, SensorTable, creation_time_ns,
                                             read_getsensordata)
from reckon.importers.ilc_session import AGENT_ID, SENSOR_ID, START_HEADING_SD_RAD, START_NOTE
from reckon.importers.report import ImportReport
from reckon.importers.tables import ImuArrays
from reckon.importers.writing import (Stamped, imu_messages, sensor_count, sighting_message, truth_message,
                                      write_messages)

NS_PER_S = 1_000_000_000
# A gyroscope or magnetometer gap longer than this is lost data, not jitter: phones log at
# 50-200 Hz (5-20 ms), and interpolating across a fifth of a second would invent half a step's turn.
MAX_INTERPOLATION_GAP_S = 0.2
COURT_MARGIN_M = 5.0  # around the POSI points and beacons: the walker's path strays past its points
ON_THE_LINE_M = 0.01  # west or south of the origin by less than this: not west or south
MAX_COURT_M = 500.0  # the session's limit (protocol/session.py); a longer site is clamped, with a warning
_INSTANCE_ONLY = re.compile(r"eddystone:(?P<instance>[0-9a-f]{12})")
TIME_NOTE = ("the app's clock (s since recording started); each sensor at its own timestamps, moved onto the "
             "app clock by its median app-minus-sensor offset; gyroscope and magnetometer interpolated onto "
             "the accelerometer's samples")


@dataclass(frozen=True)
class Frame:
    """The venue frame: east/north of the origin, less (x0_m, y0_m), the court's south-west corner."""

    latitude_deg: float
    longitude_deg: float
    origin: str  # where the origin came from
    x0_m: float
    y0_m: float
    length_m: float
    width_m: float

    def xy(self, latitude_deg: np.ndarray, longitude_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        east, north = east_north_m(latitude_deg, longitude_deg, self.latitude_deg, self.longitude_deg)
        return east - self.x0_m, north - self.y0_m

    def describe(self) -> str:
        return (f"x east, y north (m): the WGS 84 tangent plane at {self.latitude_deg:.7f}, {self.longitude_deg:.7f} "
                f"({self.origin}), which lies at x {0.0 - self.x0_m:g}, y {0.0 - self.y0_m:g} m; court "
                f"{self.length_m:g} x {self.width_m:g} m from (0, 0)")


def make_frame(latitude_deg: float, longitude_deg: float, origin: str, points: list[tuple[float, float]]) -> Frame:
    """The frame at the origin whose court holds every (lat, lon) point with COURT_MARGIN_M around."""
    east, north = east_north_m(np.array([p[0] for p in points]), np.array([p[1] for p in points]),
                               latitude_deg, longitude_deg)
    # a point on the origin's own meridian or parallel comes out a rounding error either side of 0
    x0 = 0.0 if east.min() >= -ON_THE_LINE_M else math.floor(float(east.min()) - COURT_MARGIN_M)
    y0 = 0.0 if north.min() >= -ON_THE_LINE_M else math.floor(float(north.min()) - COURT_MARGIN_M)
    return Frame(latitude_deg, longitude_deg, origin, x0, y0, max(1.0, math.ceil(float(east.max()) - x0 + COURT_MARGIN_M)),
                 max(1.0, math.ceil(float(north.max()) - y0 + COURT_MARGIN_M)))


def clamped(frame: Frame, report: ImportReport) -> Frame:
    """The frame with its court at most MAX_COURT_M a side. Only beacons need the court (they must
    reach it); truth beyond it is kept, and a beacon beyond it is refused by the session."""
    if max(frame.length_m, frame.width_m) <= MAX_COURT_M:
        return frame
    report.warn(f"the POSI points and beacons span {frame.length_m:g} x {frame.width_m:g} m: the court is clamped to "
                f"{MAX_COURT_M:g} m a side (the session's limit); truth beyond it is kept")
    return dataclasses.replace(frame, length_m=min(frame.length_m, MAX_COURT_M), width_m=min(frame.width_m, MAX_COURT_M))


@dataclass(frozen=True)
class BeaconRow:
    line: int
    identity: str | None  # canonical; None for an Eddystone given by its instance alone
    instance: str | None  # an Eddystone's instance, which the log's BLE4 records name
    latitude_deg: float
    longitude_deg: float
    floor: int


def read_beacons(path: Path) -> list[BeaconRow]:
    """The beacons CSV (`id,lat,lon,floor`); InputError naming file:line on any mistake."""
    try:
        with open(path, newline="", encoding="utf-8") as stream:
            rows = list(csv.reader(stream))
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"{path}: cannot read ({getattr(error, 'strerror', None) or error})") from None
    header = [cell.strip().lower() for cell in rows[0]] if rows else []
    if header != ["id", "lat", "lon", "floor"]:
        raise InputError(f"{path}:1: expected the header 'id,lat,lon,floor', got {','.join(header)!r}")
    beacons: list[BeaconRow] = []
    seen: dict[str, int] = {}  # identity or Eddystone instance -> line
    for number, row in enumerate(rows[1:], start=2):
        where = f"{path}:{number}"
        if not any(cell.strip() for cell in row):
            continue
        if len(row) != 4:
            raise InputError(f"{where}: {len(row)} fields, expected 4 (id,lat,lon,floor)")
        text, lat_text, lon_text, floor_text = (cell.strip() for cell in row)
        instance_only = _INSTANCE_ONLY.fullmatch(text.lower())
        try:
            identity = None if instance_only else beacon_identity(text, f"{where}: id")
            latitude_deg, longitude_deg = check_lat_lon(float(lat_text), float(lon_text), where)
            floor = int(floor_text)
        except ConfigError as error:
            raise InputError(f"{error}, or eddystone:<instance, 12 hex digits> as the log names them") from None
        except ValueError:
            raise InputError(f"{where}: lat {lat_text!r} and lon {lon_text!r} must be decimal degrees and floor "
                             f"{floor_text!r} an integer") from None
        instance = instance_only["instance"] if instance_only else (
            identity.rsplit(":", 1)[1] if identity and identity.startswith("eddystone:") else None)
        for key in {identity, instance} - {None}:
            if key in seen:
                raise InputError(f"{where}: beacon {key} is also on line {seen[key]} (an Eddystone's instance must "
                                 "be unique too: the log names it by the instance alone)")
            seen[key] = number
        beacons.append(BeaconRow(number, identity, instance, latitude_deg, longitude_deg, floor))
    return beacons


def on_app_clock(kind: str, table: SensorTable, report: ImportReport, file: str
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(app-clock ns, values, lines) in time order, and the offset used (s, the median of app -
    sensor time). Of two samples at one sensor time the first is kept, the other skipped."""
    offset_s = float(np.median(table.app_s - table.sensor_s))
    time_ns = np.round((table.sensor_s + offset_s) * NS_PER_S).astype(np.int64)
    order = np.argsort(time_ns, kind="stable")
    time_ns, values, lines = time_ns[order], table.values[order], table.lines[order]
    repeated = np.concatenate([[False], np.diff(time_ns) == 0])
    for line in lines[repeated]:
        report.skip(file, int(line), f"{kind}: repeated sensor time", f"{kind} at the same sensor time as the one before")
    return time_ns[~repeated], values[~repeated], lines[~repeated], offset_s


def interpolate_onto(time_ns: np.ndarray, source_ns: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`values` (k, 3) at `source_ns` linearly onto `time_ns`, and which of `time_ns` have a
    source sample on each side, the two less than MAX_INTERPOLATION_GAP_S apart."""
    right = np.clip(np.searchsorted(source_ns, time_ns, side="left"), 1, len(source_ns) - 1)
    before, after = source_ns[right - 1], source_ns[right]
    covered = (before <= time_ns) & (time_ns <= after) & (after - before <= MAX_INTERPOLATION_GAP_S * NS_PER_S)
    return np.column_stack([np.interp(time_ns, source_ns, values[:, axis]) for axis in range(3)]), covered


@dataclass
class PhoneStreams:
    imu: ImuArrays  # protocol units: g, deg/s, gauss
    offsets_s: dict[str, float]  # sensor type -> app - sensor clock offset used
    pressure_ns: np.ndarray
    pressure_hpa: np.ndarray


def phone_streams(log: GetSensorDataLog, report: ImportReport, file: str) -> PhoneStreams:
    """The phone IMU on the accelerometer's samples, and the barometer; InputError without ACCE+GYRO."""
    for kind in ("ACCE", "GYRO"):
        if len(log.sensors[kind].app_s) < 2:
            raise InputError(f"{log.source}: {len(log.sensors[kind].app_s)} readable {kind} lines; the phone IMU "
                             "needs ACCE and GYRO lines (at least 2 of each)")
    streams, offsets = {}, {}
    for kind in ("ACCE", "GYRO", "MAGN", "PRES"):
        if len(log.sensors[kind].app_s):
            *streams[kind], offsets[kind] = on_app_clock(kind, log.sensors[kind], report, file)
    time_ns, accel_ms2, lines = streams["ACCE"]
    gyro_rads, keep = interpolate_onto(time_ns, *streams["GYRO"][:2])
    mag_ut = None
    if "MAGN" in streams and len(streams["MAGN"][0]) >= 2:
        mag_ut, covered = interpolate_onto(time_ns, *streams["MAGN"][:2])
        keep &= covered
    partners = "GYRO/MAGN" if mag_ut is not None else "GYRO"
    for index in np.flatnonzero(~keep):
        report.skip(file, int(lines[index]), f"ACCE: no {partners} samples around it",
                    f"ACCE at {time_ns[index] / NS_PER_S:.3f} s has no {partners} samples on both sides within "
                    f"{MAX_INTERPOLATION_GAP_S:g} s")
    if keep.sum() < 2:
        raise InputError(f"{log.source}: {int(keep.sum())} ACCE samples have {partners} samples around them; the "
                         "phone IMU needs at least 2")
    imu = ImuArrays(time_ns[keep], accel_ms2[keep] / STANDARD_GRAVITY_MS2, np.degrees(gyro_rads[keep]),
                    None if mag_ut is None else mag_ut[keep] / UT_PER_GAUSS)
    pressure_ns, pressure, _ = streams.get("PRES", (np.zeros(0, dtype=np.int64), np.zeros((0, 1)), None))
    return PhoneStreams(imu, offsets, pressure_ns, pressure[:, 0])  # mbar = hPa


def unique_references(log: GetSensorDataLog, report: ImportReport, file: str) -> list[Reference]:
    """POSI points in time order; of two at one time the first is kept, the other skipped."""
    points: list[Reference] = []
    for point in sorted(log.references, key=lambda p: p.app_s):
        if points and round(point.app_s * NS_PER_S) == round(points[-1].app_s * NS_PER_S):
            report.skip(file, point.line, "POSI: repeated time", f"POSI at the same time as line {points[-1].line}")
        else:
            points.append(point)
    if len(points) < 2:
        raise InputError(f"{log.source}: {len(points)} POSI points; a walk needs at least 2 (the first stands in "
                         "for a calibration stand, the rest are scored)")
    return points


def venue_name(path: Path) -> str:
    """The log's file name without suffixes, as an id (letters, digits, - and _; at most 64)."""
    return re.sub(r"[^A-Za-z0-9_-]", "-", path.name.split(".")[0])[:64] or "walk"


def floor_number(text: str) -> int | None:
    """floor_ID as an integer floor (-20..200, as a stand's), or None when it is not one."""
    try:
        value = float(text)
    except ValueError:
        return None
    return int(value) if value.is_integer() and -20 <= value <= 200 else None


def log_date_ns(log: GetSensorDataLog, path: Path, report: ImportReport) -> int:
    """When the log was recorded, for the World Magnetic Model: the header's date, else the file's."""
    date_ns = creation_time_ns(log.header.get("date", ""))
    if date_ns is None:
        date_ns = path.stat().st_mtime_ns
        report.warn(f"no readable '% Date of creation' in the header: the Earth's field is taken for the file's "
                    f"date, {np.datetime64(date_ns, 'ns').astype('datetime64[D]')}")
    return date_ns


@dataclass(frozen=True)
class GetSensorDataImport:
    """What one import did; `str` is the report the CLI prints."""

    report: ImportReport
    frame: Frame
    truth_floors: tuple[str, ...]  # floor_ID of each POSI point, in time order
    buildings: tuple[str, ...]
    stand: tuple[float, float, int, float]  # x m, y m, floor, heading deg
    offsets_s: dict[str, float]
    pressure: tuple[int, float, float]  # messages, min hPa, max hPa
    venue_beacons: int
    unknown_sightings: dict[str, int]  # identity -> sightings of beacons not in the beacons file
    not_used: dict[str, int]
    ahrs_lines: int
    unknown_types: dict[str, int]

    def __str__(self) -> str:
        x_m, y_m, floor, heading_deg = self.stand
        floors = ", ".join(sorted(set(self.truth_floors)))
        lines = [str(self.report),
                 f"frame: {self.frame.describe()}",
                 "time: app clock; sensor offsets (app - sensor) " + ", ".join(
                     f"{kind} {offset:.3f} s" for kind, offset in self.offsets_s.items()),
                 f"truth: {len(self.truth_floors)} POSI points on floor{'s' if ',' in floors else ''} {floors} "
                 f"(building {', '.join(sorted(set(self.buildings)))}); stand scan at POSI 1: x {x_m:.2f}, "
                 f"y {y_m:.2f} m, floor {floor}, heading {heading_deg:.1f} deg",
                 f"pressure: {self.pressure[0]} messages" + (f", {self.pressure[1]:.2f}-{self.pressure[2]:.2f} hPa"
                                                             if self.pressure[0] else ""),
                 f"beacons: {self.venue_beacons} in the venue; sightings of beacons not in it: "
                 + (", ".join(f"{key} {count}" for key, count in sorted(self.unknown_sightings.items())) or "none")]
        used_not = {"AHRS": self.ahrs_lines, **self.not_used} if self.ahrs_lines else dict(self.not_used)
        lines.append("read, not used: " + (", ".join(f"{kind} {count}" for kind, count in used_not.items()) or "none"))
        if self.unknown_types:
            lines.append("unknown record types (counted, not read): "
                         + ", ".join(f"{kind} {count}" for kind, count in sorted(self.unknown_types.items())))
        return "\n".join(lines)


def pressure_message(venue: str, time_ns: int, pressure_hpa: float) -> Stamped:
    message = messages.new("Pressure", timestamp_ns=time_ns, agent_id=AGENT_ID, sensor_id=SENSOR_ID,
                           pressure_hpa=pressure_hpa)
    return time_ns, keys.pressure(venue, AGENT_ID, SENSOR_ID), message


def stand_scan(venue: str, time_ns: int, x_m: float, y_m: float, floor: int, heading_rad: float) -> Stamped:
    """The first POSI point standing in for a calibration stand, as ILC's first waypoint does."""
    message = messages.new("StandScan", timestamp_ns=time_ns, agent_id=AGENT_ID, sensor_id=SENSOR_ID,
                           stand_id="posi-1", x_m=x_m, y_m=y_m, floor=floor, heading_rad=heading_rad,
                           heading_sd_rad=START_HEADING_SD_RAD, tilt_rad=0.0, payload=START_NOTE, accepted=True,
                           reason="")
    return time_ns, keys.scan(venue, AGENT_ID), message


def sighting_messages(venue: str, log: GetSensorDataLog, beacon_rows: list[BeaconRow]
                      ) -> tuple[list[Stamped], dict[str, int]]:
    """BeaconSighting messages in time order, `beacon_id` the venue beacon's id where the beacons
    file has the beacon, else its identity; and the sightings per identity not in the file."""
    venue_ids = {}
    for number, row in enumerate(beacon_rows, start=1):
        # the log names an iBeacon by its identity and an Eddystone by its instance alone
        venue_ids[row.instance if row.instance else str(row.identity)] = f"beacon-{number}"
    unknown: dict[str, int] = {}
    stamped = []
    for seen in sorted(log.sightings, key=lambda s: s.app_s):
        beacon_id = venue_ids.get(seen.key)
        if beacon_id is None:
            beacon_id = seen.key if seen.kind == "ibeacon" else f"eddystone:{seen.key}"
            unknown[beacon_id] = unknown.get(beacon_id, 0) + 1
        stamped.append(sighting_message(venue, AGENT_ID, SENSOR_ID, beacon_id, round(seen.app_s * NS_PER_S),
                                        seen.rssi_dbm))
    return stamped, unknown


def session_description(name: str, log: GetSensorDataLog, frame: Frame, points: list[Reference],
                        beacon_rows: list[BeaconRow], rate_hz: float, date_ns: int) -> dict:
    """The session (a plain dict, validated by session_from_dict), as ILC's walk_session."""
    beacon_x, beacon_y = frame.xy(np.array([b.latitude_deg for b in beacon_rows]),
                                  np.array([b.longitude_deg for b in beacon_rows]))
    beacons = [{"id": f"beacon-{number}", "x_m": float(x_m), "y_m": float(y_m), "identity": row.identity,
                "floor": row.floor}
               for number, (row, x_m, y_m) in enumerate(zip(beacon_rows, beacon_x, beacon_y), start=1)]
    return {
        "venue": {"name": name, "court_length_m": frame.length_m, "court_width_m": frame.width_m, "beacons": beacons,
                  **venue_field(frame.latitude_deg, frame.longitude_deg, date_ns)},
        "agents": [{"id": AGENT_ID, "kind": "pedestrian",  # held in front: the screen's top (+y) where they walk
                    "sensors": [{"id": SENSOR_ID, "mount": "hand", "rate_hz": rate_hz, "forward_axis": "+y",
                                 "left_axis": "-x"}]}],
        "source": {"importer": "getsensordata", "log": name, "phone": log.phone, "start": START_NOTE,
                   "height": "the walker's height is not recorded: the default 1.70 m is used",
                   "frame": frame.describe(), "origin_lat_deg": frame.latitude_deg,
                   "origin_lon_deg": frame.longitude_deg, "time": TIME_NOTE, "truth_floors": [p.floor for p in points]},
    }


def check_points(points: list[Reference], x_m: np.ndarray, y_m: np.ndarray, times_ns: np.ndarray,
                 phone: PhoneStreams, report: ImportReport) -> int:
    """The stand's floor (POSI 1's floor_ID, else 0), with warnings for what makes the truth doubtful."""
    floor = floor_number(points[0].floor)
    if floor is None:
        report.warn(f"POSI 1's floor_ID {points[0].floor!r} is not an integer floor: the stand scan says floor 0")
    if math.hypot(x_m[1] - x_m[0], y_m[1] - y_m[0]) < 0.5:
        report.warn("POSI 2 is less than 0.5 m from POSI 1: the stand's heading (the bearing to it) means little")
    outside = int(np.sum((times_ns < phone.imu.time_ns[0]) | (times_ns > phone.imu.time_ns[-1])))
    if outside:
        report.warn(f"{outside} POSI points lie outside the phone samples' time span: nothing is estimated there")
    return floor or 0


def import_getsensordata(path: Path | str, output: Path | str, beacons_csv: Path | str | None = None,
                         origin: tuple[float, float] | None = None) -> GetSensorDataImport:
    """Write one GetSensorData log as a session log at `output`. `origin`: (lat, lon) degrees of
    the frame's tangent point, default the first POSI point. InputError naming the file when the
    log has no ACCE+GYRO or fewer than 2 POSI points, or the beacons file is wrong."""
    path, output = Path(path), Path(output)
    report, file = ImportReport(output), path.name
    log = read_getsensordata(path, report)
    points = unique_references(log, report, file)
    phone = phone_streams(log, report, file)
    beacon_rows = read_beacons(Path(beacons_csv)) if beacons_csv is not None else []
    latitude_deg, longitude_deg = origin or (points[0].latitude_deg, points[0].longitude_deg)
    frame = clamped(make_frame(latitude_deg, longitude_deg, "--origin" if origin else "the first POSI point",
                               [(p.latitude_deg, p.longitude_deg) for p in points]
                               + [(b.latitude_deg, b.longitude_deg) for b in beacon_rows]), report)
    x_m, y_m = frame.xy(np.array([p.latitude_deg for p in points]), np.array([p.longitude_deg for p in points]))
    times_ns = np.array([round(p.app_s * NS_PER_S) for p in points], dtype=np.int64)
    floor = check_points(points, x_m, y_m, times_ns, phone, report)
    name = venue_name(path)
    rate_hz = float(np.clip(round(1e9 / float(np.median(np.diff(phone.imu.time_ns))), 1), 1.0, 10_000.0))
    session = session_from_dict(session_description(name, log, frame, points, beacon_rows, rate_hz,
                                                    log_date_ns(log, path, report)), where=f"{path} (import)")
    count = sensor_count(AGENT_ID, phone.imu)
    report.sensors[SENSOR_ID] = count
    # a floor_ID that is not an integer floor scores as floor 0 (the stand's check above warns of POSI 1's)
    truth = [truth_message(name, AGENT_ID, int(t), float(x), float(y), math.nan, floor_number(p.floor) or 0)
             for t, x, y, p in zip(times_ns, x_m, y_m, points)]
    heading_rad = math.atan2(y_m[1] - y_m[0], x_m[1] - x_m[0])
    sightings, unknown = sighting_messages(name, log, beacon_rows)
    pressures = [pressure_message(name, int(t), float(p)) for t, p in zip(phone.pressure_ns, phone.pressure_hpa)]
    scan = stand_scan(name, int(times_ns[0]), float(x_m[0]), float(y_m[0]), floor, heading_rad)
    write_messages(output, session, [imu_messages(name, AGENT_ID, SENSOR_ID, phone.imu, count), truth, sightings,
                                     pressures, [scan]])
    report.truth_poses, report.sightings = len(truth), len(sightings)
    hpa = (float(phone.pressure_hpa.min()), float(phone.pressure_hpa.max())) if len(pressures) else (math.nan, math.nan)
    return GetSensorDataImport(report, frame, tuple(p.floor for p in points), tuple(p.building for p in points),
                               (float(x_m[0]), float(y_m[0]), floor, math.degrees(heading_rad)), phone.offsets_s,
                               (len(pressures), *hpa), len(beacon_rows), unknown, log.not_used,
                               len(log.sensors["AHRS"].app_s), log.unknown)
