"""`reckon import csv DIR -o session.mcap`: a folder of plain CSV files -> one session MCAP.

The folder (docs/csv-import.md, example in docs/examples/csv-session/):
  session.toml    the session description, as `protocol.session.load_toml` reads it
  <sensor_id>.csv one per sensor of the TOML: time_s, accel_{x,y,z}_g, gyro_{x,y,z}_dps and
                  optional mag_{x,y,z}_gauss, each with a unit suffix (tables.TO_PROTOCOL_UNIT)
  beacons.csv     optional: time_s, sensor_id, beacon_id, rssi_dbm (sensor = the receiver)
  truth.csv       optional: time_s, agent_id, x_m, y_m and optional heading_rad
  stands.csv      optional: time_s, sensor_id, stand_id (a phone put on one of the venue's stands)
Bad input never gives a traceback: file-level mistakes raise InputError/ConfigError naming the
file; stray rows are skipped and counted in the ImportReport (rules in reckon.importers.tables).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import re
from array import array
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from protocol import keys
from protocol import messages as protocol_messages
from protocol.errors import InputError
from protocol.session import Session, load_toml
from reckon.importers.report import ImportReport
from reckon.importers.tables import (MAX_TIME_NS, NS_PER_TIME_UNIT, REPEAT_WINDOW_NS, TO_PROTOCOL_UNIT, HeaderName,
                                     ImuArrays, csv_rows, layout_from_header, parse_time_ns, read_imu_rows)
from reckon.importers.writing import (Stamped, imu_messages, sensor_count, sighting_message, truth_message,
                                      write_messages)

log = logging.getLogger(__name__)

SESSION_FILE = "session.toml"
BEACONS_FILE = "beacons.csv"
TRUTH_FILE = "truth.csv"
STANDS_FILE = "stands.csv"
RATE_TOLERANCE = 0.10  # warn when the data's median rate differs from the TOML rate_hz by more than 10 %
_IMU_COLUMN = re.compile(r"^(accel|gyro|mag)_([xyz])_(.+)$")
_TIME_COLUMN = re.compile(r"^time_(.+)$")


def import_csv_folder(folder: Path, output: Path) -> ImportReport:
    """Import a CSV folder into the session MCAP `output`; the report says what was kept and skipped.

    Raises ConfigError (session.toml) or InputError (folder, files, columns, time order); writes
    nothing when it raises.
    """
    folder, output = Path(folder), Path(output)
    if not folder.is_dir():
        raise InputError(f"{folder}: not a folder (expected a folder with {SESSION_FILE} and one CSV per sensor)")
    if not (folder / SESSION_FILE).is_file():
        raise InputError(f"{folder}: no {SESSION_FILE} (the session description; see docs/csv-import.md)")
    session = load_toml(folder / SESSION_FILE)
    session = dataclasses.replace(session, source={**session.source, "importer": "reckon import csv",
                                                   "folder": folder.name})
    files = _sensor_files(folder, session)
    report = ImportReport(output)
    owners = session.sensor_owner()
    venue = session.venue.name
    imu: dict[str, ImuArrays] = {}
    for sensor_id, path in files.items():
        imu[sensor_id] = read_sensor_csv(path, report)
        rate_hz = next(sensor.rate_hz for sensor in owners[sensor_id].sensors if sensor.id == sensor_id)
        _check_rate(path, imu[sensor_id], rate_hz, report)
    streams: list[Iterator[Stamped]] = []
    for sensor_id, data in imu.items():
        agent_id = owners[sensor_id].id
        report.sensors[sensor_id] = sensor_count(agent_id, data)
        streams.append(imu_messages(venue, agent_id, sensor_id, data, report.sensors[sensor_id]))
    streams.append(_read_beacons(folder / BEACONS_FILE, session, report))
    streams.extend(_read_truth(folder / TRUTH_FILE, session, report))
    streams.append(_read_stands(folder / STANDS_FILE, session, report))
    write_messages(output, session, streams)
    log.info("imported %s: %d sensors, %d rows skipped", folder, len(imu), report.rows_skipped)
    return report


def read_sensor_csv(path: Path, report: ImportReport) -> ImuArrays:
    """One sensor's CSV -> arrays in protocol units (g, deg/s, gauss); rules in reckon.importers.tables."""
    with csv_rows(path, str(path)) as (header, rows):
        layout = layout_from_header(header, _parse_name, _name_hint, str(path), report)
        return read_imu_rows(rows, layout, str(path), report)


def _parse_name(cell: str) -> HeaderName | None:
    name = cell.strip().lower()
    if match := _TIME_COLUMN.match(name):
        return HeaderName("time", "", match.group(1))
    if match := _IMU_COLUMN.match(name):
        return HeaderName(match.group(1), match.group(2), match.group(3))
    return None


def _name_hint(quantity: str, axis: str) -> str:
    if quantity == "time":
        return "time_s (or " + ", ".join(f"time_{unit}" for unit in NS_PER_TIME_UNIT if unit != "s") + ")"
    names = [f"{quantity}_{axis}_{unit}" for unit in TO_PROTOCOL_UNIT[quantity] if "/" not in unit]
    return f"{quantity}_{axis} (as {', '.join(names)})"


def _sensor_files(folder: Path, session: Session) -> dict[str, Path]:
    """sensor id -> its CSV, in TOML order; InputError for a file with no sensor or a sensor with no file."""
    owners = session.sensor_owner()
    folded: dict[str, str] = {}
    for sensor_id in owners:
        if sensor_id.casefold() in folded:
            raise InputError(f"{folder / SESSION_FILE}: sensor ids {folded[sensor_id.casefold()]!r} and {sensor_id!r} "
                             "differ only in case; their CSV files would clash")
        if f"{sensor_id}.csv" in (BEACONS_FILE, TRUTH_FILE, STANDS_FILE):
            raise InputError(f"{folder / SESSION_FILE}: sensor id {sensor_id!r} clashes with {sensor_id}.csv, "
                             "which holds other data; rename the sensor")
        folded[sensor_id.casefold()] = sensor_id
    candidates: dict[str, list[Path]] = defaultdict(list)
    for path in sorted(folder.iterdir()):
        if path.is_file() and path.suffix.lower() == ".csv" and path.name not in (BEACONS_FILE, TRUTH_FILE, STANDS_FILE):
            candidates[path.stem.casefold()].append(path)
    found: dict[str, Path] = {}
    for paths in candidates.values():
        if len(paths) > 1:
            raise InputError(f"{folder}: {' and '.join(p.name for p in paths)} are two files for one sensor; keep one")
        path = paths[0]
        if path.stem not in owners:
            near = folded.get(path.stem.casefold())
            hint = f" (ids are case-sensitive: rename it {near}.csv)" if near else ""
            raise InputError(f"{path}: no sensor {path.stem!r} in {SESSION_FILE} "
                             f"(its sensors: {', '.join(owners) or 'none'}){hint}")
        found[path.stem] = path
    for sensor_id, agent in owners.items():
        if sensor_id not in found:
            raise InputError(f"{folder / SESSION_FILE}: sensor {sensor_id!r} of agent {agent.id!r} has no file "
                             f"{sensor_id}.csv in {folder}")
    return {sensor_id: found[sensor_id] for sensor_id in owners}


def _check_rate(path: Path, data: ImuArrays, rate_hz: float, report: ImportReport) -> None:
    if len(data.time_ns) < 3:
        return
    median_s = float(np.median(np.diff(data.time_ns))) * 1e-9
    measured_hz = 1.0 / median_s
    if abs(measured_hz / rate_hz - 1.0) > RATE_TOLERANCE:
        report.warn(f"{path}: samples every {median_s * 1e3:.2f} ms ({measured_hz:.1f} Hz) but {SESSION_FILE} "
                    f"says rate_hz = {rate_hz:g}")


# ---------------------------------------------------------------------------------------------
# beacons.csv and truth.csv


def _columns(header: list[str], required: tuple[str, ...], optional: tuple[str, ...], display: str,
             report: ImportReport) -> tuple[dict[str, int], int]:
    """Column name -> index (the time column under "time", with its ns per unit); InputError if one is missing."""
    index: dict[str, int] = {}
    ns_per_unit = 0
    lowered = [cell.lower() for cell in header]
    for position, cell in enumerate(lowered):
        match = _TIME_COLUMN.match(cell)
        if match and match.group(1) in NS_PER_TIME_UNIT and "time" not in index:
            index["time"], ns_per_unit = position, NS_PER_TIME_UNIT[match.group(1)]
        elif cell in required + optional and cell not in index:
            index[cell] = position
        else:
            report.warn(f"{display}: ignored column {header[position]!r}")
    for name in ("time",) + required:
        if name not in index:
            spelled = _name_hint("time", "") if name == "time" else name
            raise InputError(f"{display}: missing column {spelled}; found columns: {', '.join(header)}")
    return index, ns_per_unit


def _aux_rows(path: Path, required: tuple[str, ...], optional: tuple[str, ...],
              report: ImportReport) -> Iterator[tuple[int, dict[str, str], int, str]]:
    """Rows of beacons.csv / truth.csv as (line, {column: text}, time ns, time text); stray rows counted."""
    display = str(path)
    with csv_rows(path, display) as (header, rows):
        index, ns_per_unit = _columns(header, required, optional, display, report)
        for line, row in rows:
            if len(row) != len(header):
                report.skip(display, line, "wrong number of fields",
                            f"{len(row)} fields, expected {len(header)}: {','.join(row)[:80]!r}")
                continue
            fields = {name: row[position].strip() for name, position in index.items()}
            try:
                time_ns = parse_time_ns(fields["time"], ns_per_unit)
            except ValueError:
                report.skip(display, line, "not a number",
                            f"column {header[index['time']]}: {fields['time']!r} is not a number")
                continue
            if not 0 <= time_ns <= MAX_TIME_NS:
                raise InputError(f"{display} line {line}: time {fields['time']} is outside the range of unsigned "
                                 "nanoseconds; shift the times or check the unit")
            yield line, fields, time_ns, fields["time"]


def _number(fields: dict[str, str], name: str) -> float:
    """Finite float of column `name`; ValueError naming it otherwise."""
    text = fields[name]
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"column {name}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"column {name}: {text!r} is not a finite number")
    return value


def _read_beacons(path: Path, session: Session, report: ImportReport) -> Iterator[Stamped]:
    """BeaconSighting messages sorted by time. Rows may come in any order (several receivers write them)."""
    if not path.is_file():
        if session.venue.beacons:
            report.warn(f"no {path.name}: the venue has {len(session.venue.beacons)} beacons but no sightings")
        return iter(())
    display = str(path)
    owners = session.sensor_owner()
    sensor_ids = list(owners)
    beacon_ids = [beacon.id for beacon in session.venue.beacons]
    times, rssi, sensor_index, beacon_index = array("q"), array("d"), array("i"), array("i")
    for line, fields, time_ns, _ in _aux_rows(path, ("sensor_id", "beacon_id", "rssi_dbm"), (), report):
        sensor_id, beacon_id = fields["sensor_id"], fields["beacon_id"]
        if sensor_id not in owners:
            report.skip(display, line, "unknown sensor", f"sensor_id {sensor_id!r} is not in {SESSION_FILE}")
            continue
        if beacon_id not in beacon_ids:
            report.skip(display, line, "unknown beacon", f"beacon_id {beacon_id!r} is not in {SESSION_FILE}")
            continue
        try:
            rssi.append(_number(fields, "rssi_dbm"))
        except ValueError as error:
            report.skip(display, line, "not a number", str(error))
            continue
        times.append(time_ns)
        sensor_index.append(sensor_ids.index(sensor_id))
        beacon_index.append(beacon_ids.index(beacon_id))
    report.sightings = len(times)
    order = np.argsort(np.frombuffer(times, dtype=np.int64), kind="stable")  # equal times keep file order

    def messages() -> Iterator[Stamped]:
        for row in order:
            sensor_id = sensor_ids[sensor_index[row]]
            yield sighting_message(session.venue.name, owners[sensor_id].id, sensor_id, beacon_ids[beacon_index[row]],
                                   times[row], rssi[row])

    return messages()


def _read_stands(path: Path, session: Session, report: ImportReport) -> Iterator[Stamped]:
    """StandScan messages (accepted, the stand's pose from the venue) in time order: a recording
    made without reckon's phone page has no scanned code, only when the phone was on which stand."""
    if not path.is_file():
        return iter(())
    display = str(path)
    owners = session.sensor_owner()
    stands = {stand.id: stand for stand in session.venue.stands}
    rows: list[tuple[int, str, str]] = []
    for line, fields, time_ns, _ in _aux_rows(path, ("sensor_id", "stand_id"), (), report):
        if fields["sensor_id"] not in owners:
            report.skip(display, line, "unknown sensor", f"sensor_id {fields['sensor_id']!r} is not in {SESSION_FILE}")
        elif fields["stand_id"] not in stands:
            report.skip(display, line, "unknown stand", f"stand_id {fields['stand_id']!r} is not in {SESSION_FILE}")
        else:
            rows.append((time_ns, fields["sensor_id"], fields["stand_id"]))
    rows.sort(key=lambda row: row[0])

    def messages() -> Iterator[Stamped]:
        for time_ns, sensor_id, stand_id in rows:
            stand, agent_id = stands[stand_id], owners[sensor_id].id
            yield time_ns, keys.scan(session.venue.name, agent_id), protocol_messages.new(
                "StandScan", timestamp_ns=time_ns, agent_id=agent_id, sensor_id=sensor_id, stand_id=stand.id,
                x_m=stand.x_m, y_m=stand.y_m, floor=stand.floor, heading_rad=math.radians(stand.heading_deg),
                tilt_rad=math.radians(stand.tilt_deg), payload=f"{display} (no code scanned)", accepted=True,
                reason="")

    return messages()


def _read_truth(path: Path, session: Session, report: ImportReport) -> list[Iterator[Stamped]]:
    """TruthPose messages, one time-sorted stream per agent; times going back raise InputError."""
    if not path.is_file():
        return []
    display = str(path)
    agent_ids = [agent.id for agent in session.agents]
    columns: dict[str, tuple[array, array]] = {}  # agent -> (times ns, flat x, y, heading triples)
    previous: dict[str, tuple[int, int, str, tuple[float, ...]]] = {}  # agent -> (ns, line, time text, pose)
    warned = False
    for line, fields, time_ns, time_text in _aux_rows(path, ("agent_id", "x_m", "y_m"), ("heading_rad",), report):
        has_heading = "heading_rad" in fields
        if not has_heading and not warned:
            report.warn(f"{display}: no heading_rad column; truth headings are written as NaN (unknown)")
            warned = True
        agent_id = fields["agent_id"]
        if agent_id not in agent_ids:
            report.skip(display, line, "unknown agent", f"agent_id {agent_id!r} is not in {SESSION_FILE}")
            continue
        try:
            pose = (_number(fields, "x_m"), _number(fields, "y_m"),
                    _number(fields, "heading_rad") if has_heading else math.nan)
        except ValueError as error:
            report.skip(display, line, "not a number", str(error))
            continue
        last = previous.get(agent_id)
        if last is not None and time_ns <= last[0]:
            if _same_pose(pose, last[3]) and last[0] - time_ns <= REPEAT_WINDOW_NS:
                report.skip(display, line, "repeated sample",
                            f"agent {agent_id} at {time_text}: same pose as line {last[1]}")
                continue
            raise InputError(f"{display} line {line}: time {time_text} of agent {agent_id!r} is not after its "
                             f"previous row's {last[2]} (line {last[1]}); a clock that jumps back is refused, "
                             "not reordered")
        previous[agent_id] = (time_ns, line, time_text, pose)
        agent_times, agent_poses = columns.setdefault(agent_id, (array("q"), array("d")))
        agent_times.append(time_ns)
        agent_poses.extend(pose)
    for agent_id in agent_ids:
        if agent_id not in columns:
            report.warn(f"{display}: no truth poses for agent {agent_id!r}")
    report.truth_poses = sum(len(agent_times) for agent_times, _ in columns.values())

    def messages(agent_id: str, agent_times: array, agent_poses: array) -> Iterator[Stamped]:
        for row, time_ns in enumerate(agent_times):
            yield truth_message(session.venue.name, agent_id, time_ns, *agent_poses[3 * row:3 * row + 3])

    return [messages(agent_id, *arrays) for agent_id, arrays in columns.items()]


def _same_pose(first: tuple[float, ...], second: tuple[float, ...]) -> bool:
    """Equal poses, NaN (unknown heading) equal to NaN."""
    return all(a == b or (math.isnan(a) and math.isnan(b)) for a, b in zip(first, second))
