"""GetSensorData (Android; LOPSI, CAR-CSIC) text logs, as numpy tables (session writing:
reckon/importers/getsensordata_session.py; the format as read: docs/getsensordata-import.md).

The app used for the IPIN competitions' smartphone tracks writes one record a line,
`TYPE;AppTimestamp(s);...`, separated by `;`; lines starting with `%` are comments (its header:
`% Date of creation: Fri Jul 27 11:28:34 GMT+02:00 2018`, `% Manufacturer: ...`, `% Model: ...`).
AppTimestamp is the app's clock (seconds since recording started), common to every record type;
sensor records then carry the sensor's own timestamp (seconds, Android's event clock):

    ACCE;AppTs;SensorTs;Acc_X;Acc_Y;Acc_Z;Accuracy              m/s^2, gravity included
    GYRO;AppTs;SensorTs;Gyr_X;Gyr_Y;Gyr_Z;Accuracy              rad/s
    MAGN;AppTs;SensorTs;Mag_X;Mag_Y;Mag_Z;Accuracy              uT
    PRES;AppTs;SensorTs;Pres;Accuracy                           mbar (= hPa)
    AHRS;AppTs;SensorTs;PitchX;RollY;YawZ;RotVecX;RotVecY;RotVecZ;Accuracy   deg (read, not used)
    BLE4;AppTs;iBeacon;MAC;RSSI;Power;MajorID;MinorID;UUID
    BLE4;AppTs;Eddystone;MAC;RSSI;instanceID;[voltage;temperature;uptime;count]
    POSI;Timestamp;Counter;Latitude;Longitude;floor_ID;Building_ID    the reference points (truth)

WIFI, BLUE, LIGH, PROX, HUMI, TEMP, SOUN, GNSS, RFID, IMUX, IMUL and IMUI records are counted per
type and not parsed (NOT_USED); other types are counted as unknown. Bad input never stops the
read: a line with the wrong field count, a field that is not a finite number, a latitude out of
range or a malformed beacon is skipped and counted in the ImportReport (file, line, what was
wrong); so is the app's last line when the recording was cut mid-line. Blank lines are ignored.
An Eddystone record carries only the instance (12 hex digits), not the namespace.
"""

from __future__ import annotations

import datetime as dt
import math
import re
from array import array
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from protocol.errors import ConfigError, InputError
from protocol.session import beacon_identity
from reckon.importers.report import ImportReport

# Record type -> values after the type (timestamps, values, accuracy): every one a number.
SENSOR_FIELDS = {"ACCE": 6, "GYRO": 6, "MAGN": 6, "PRES": 4, "AHRS": 9}
POSI_FIELDS = 6  # Timestamp, Counter, Latitude, Longitude, floor_ID, Building_ID
IBEACON_FIELDS = 8  # AppTs, "iBeacon", MAC, RSSI, Power, MajorID, MinorID, UUID
EDDYSTONE_MIN_FIELDS = 5  # AppTs, "Eddystone", MAC, RSSI, instanceID, then optional telemetry
NOT_USED = ("WIFI", "BLUE", "LIGH", "PROX", "HUMI", "TEMP", "SOUN", "GNSS", "RFID", "IMUX", "IMUL", "IMUI")
_TYPE = re.compile(r"[A-Z][A-Z0-9]{1,7}")
_HEX12 = re.compile(r"[0-9a-f]{12}")
_HEX32 = re.compile(r"[0-9a-f]{32}")
# Java's Date.toString(): "Fri Jul 27 11:28:34 GMT+02:00 2018"; the zone is ignored (hours do not
# matter to the World Magnetic Model, the only use of the date).
_JAVA_DATE = re.compile(r"(?P<month>[A-Z][a-z]{2}) +(?P<day>\d{1,2}) +(?P<time>\d{2}:\d{2}:\d{2}) +\S+ +(?P<year>\d{4})")
_ISO_DATE = re.compile(r"(?P<year>\d{4})-(?P<month>\d{2})-(?P<day>\d{2})")
_MONTHS = ("Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec")


@dataclass(frozen=True)
class SensorTable:
    """One sensor's records in file order: app and sensor times (s), values (k, n), 1-based lines."""

    app_s: np.ndarray
    sensor_s: np.ndarray
    values: np.ndarray
    lines: np.ndarray


@dataclass(frozen=True)
class Reference:
    """One POSI record: the surveyed point the walker stood at, at app time `app_s`."""

    line: int
    app_s: float
    counter: float
    latitude_deg: float
    longitude_deg: float
    floor: str  # floor_ID as written (an integer in the app's own logs)
    building: str


@dataclass(frozen=True)
class Sighting:
    """One BLE4 record. `key`: the canonical iBeacon identity (protocol.session.beacon_identity),
    or for an Eddystone the instance alone (12 lower-case hex digits)."""

    line: int
    app_s: float
    kind: str  # "ibeacon" or "eddystone"
    key: str
    rssi_dbm: float


@dataclass(frozen=True)
class GetSensorDataLog:
    source: str
    sensors: dict[str, SensorTable]  # ACCE, GYRO, MAGN, PRES, AHRS: each present, maybe empty
    references: tuple[Reference, ...]
    sightings: tuple[Sighting, ...]
    not_used: dict[str, int] = field(default_factory=dict)  # NOT_USED type -> lines
    unknown: dict[str, int] = field(default_factory=dict)  # any other type -> lines
    header: dict[str, str] = field(default_factory=dict)  # date, manufacturer, model (as written)

    @property
    def phone(self) -> str:
        return f"{self.header.get('manufacturer', '')} {self.header.get('model', '')}".strip() or "unknown"


def read_getsensordata(path: Path | str, report: ImportReport) -> GetSensorDataLog:
    """Parse one log; bad lines are skipped and counted in `report`. InputError if unreadable."""
    path = Path(path)
    parser = _Parser(path.name, report)
    try:
        with open(path, "rb") as stream:
            for number, raw in enumerate(stream, start=1):
                parser.line(number, raw.decode("utf-8", errors="replace").strip())
    except OSError as error:
        raise InputError(f"{path}: cannot read ({error.strerror or error})") from None
    return parser.result(str(path))


def creation_time_ns(text: str) -> int | None:
    """Unix ns of the header's `Date of creation` (Java's Date.toString, or an ISO date), as UTC;
    None when it cannot be read."""
    try:
        if match := _JAVA_DATE.search(text):
            hour, minute, second = (int(part) for part in match["time"].split(":"))
            moment = dt.datetime(int(match["year"]), _MONTHS.index(match["month"]) + 1, int(match["day"]),
                                 hour, minute, second, tzinfo=dt.timezone.utc)
        elif match := _ISO_DATE.search(text):
            moment = dt.datetime(int(match["year"]), int(match["month"]), int(match["day"]), tzinfo=dt.timezone.utc)
        else:
            return None
    except ValueError:  # an unknown month name, day 31 of a 30-day month
        return None
    return int(moment.timestamp()) * 1_000_000_000


def _show(text: str) -> str:
    return repr(text if len(text) <= 60 else text[:57] + "...")


class _Parser:
    def __init__(self, file: str, report: ImportReport):
        self.file, self.report = file, report
        self.tables = {kind: (array("d"), array("d"), array("d"), array("q")) for kind in SENSOR_FIELDS}
        self.references: list[Reference] = []
        self.sightings: list[Sighting] = []
        self.not_used: dict[str, int] = {}
        self.unknown: dict[str, int] = {}
        self.header: dict[str, str] = {}

    def skip(self, number: int, reason: str, detail: str) -> None:
        self.report.skip(self.file, number, reason, detail)

    def line(self, number: int, text: str) -> None:
        if not text:
            return
        if text.startswith("%"):
            self._comment(text[1:].strip())
            return
        fields = [part.strip() for part in text.split(";")]
        kind = fields[0]
        if not _TYPE.fullmatch(kind):
            self.skip(number, "not a TYPE;... record", f"{_show(text)} does not start with a record type")
        elif kind in SENSOR_FIELDS:
            self._sensor(number, kind, fields[1:])
        elif kind == "POSI":
            self._posi(number, fields[1:])
        elif kind == "BLE4":
            self._ble(number, fields[1:])
        elif kind in NOT_USED:
            self.not_used[kind] = self.not_used.get(kind, 0) + 1
        else:
            self.unknown[kind] = self.unknown.get(kind, 0) + 1

    def _comment(self, text: str) -> None:
        key, separator, value = text.partition(":")
        name = {"Date of creation": "date", "Manufacturer": "manufacturer", "Model": "model"}.get(key.strip())
        if separator and name and name not in self.header:
            self.header[name] = value.strip()

    def _count(self, number: int, kind: str, values: list[str], expected: int, at_least: bool = False) -> bool:
        if len(values) == expected or (at_least and len(values) > expected):
            return True
        wanted = f"at least {expected}" if at_least else str(expected)
        self.skip(number, f"{kind}: wrong field count",
                  f"{kind} has {len(values)} fields after the type, expected {wanted}: {_show(';'.join(values))}")
        return False

    def _numbers(self, number: int, kind: str, values: list[str], positions: range | tuple[int, ...]) -> list[float] | None:
        numbers = []
        for position in positions:
            try:
                value = float(values[position])
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                self.skip(number, f"{kind}: not a finite number",
                          f"{kind} field {position + 2} {_show(values[position])} is not a finite number")
                return None
            numbers.append(value)
        return numbers

    def _sensor(self, number: int, kind: str, values: list[str]) -> None:
        expected = SENSOR_FIELDS[kind]
        if not self._count(number, kind, values, expected):
            return
        numbers = self._numbers(number, kind, values, range(expected))
        if numbers is None:
            return
        app, sensor, flat, lines = self.tables[kind]
        app.append(numbers[0])
        sensor.append(numbers[1])
        flat.extend(numbers[2:-1])  # the values without the accuracy
        lines.append(number)

    def _posi(self, number: int, values: list[str]) -> None:
        if not self._count(number, "POSI", values, POSI_FIELDS):
            return
        numbers = self._numbers(number, "POSI", values, range(4))
        if numbers is None:
            return
        app_s, counter, latitude_deg, longitude_deg = numbers
        if not (-90.0 <= latitude_deg <= 90.0 and -180.0 <= longitude_deg <= 180.0):
            self.skip(number, "POSI: latitude/longitude out of range",
                      f"POSI at ({latitude_deg}, {longitude_deg}) is not a latitude in [-90, 90] and a longitude "
                      "in [-180, 180]")
            return
        self.references.append(Reference(number, app_s, counter, latitude_deg, longitude_deg, values[4], values[5]))

    def _ble(self, number: int, values: list[str]) -> None:
        kind = values[1].lower() if len(values) > 1 else ""
        if kind == "ibeacon":
            if not self._count(number, "BLE4 iBeacon", values, IBEACON_FIELDS):
                return
            numbers = self._numbers(number, "BLE4 iBeacon", values, (0, 3, 4, 5, 6))
            if numbers is None:
                return
            uuid = values[7].lower()
            if _HEX32.fullmatch(uuid):  # written without dashes
                uuid = f"{uuid[:8]}-{uuid[8:12]}-{uuid[12:16]}-{uuid[16:20]}-{uuid[20:]}"
            text = f"ibeacon:{uuid}:{values[5]}:{values[6]}"
            try:
                key = beacon_identity(text, "BLE4 iBeacon")
            except ConfigError:
                self.skip(number, "BLE4 iBeacon: malformed identity",
                          f"UUID {_show(values[7])}, major {values[5]!r}, minor {values[6]!r} is not an iBeacon identity")
                return
        elif kind == "eddystone":
            if not self._count(number, "BLE4 Eddystone", values, EDDYSTONE_MIN_FIELDS, at_least=True):
                return
            numbers = self._numbers(number, "BLE4 Eddystone", values, (0, 3))
            if numbers is None:
                return
            key = values[4].lower().removeprefix("0x")
            if not _HEX12.fullmatch(key):
                self.skip(number, "BLE4 Eddystone: malformed instance",
                          f"instance {_show(values[4])} is not 12 hex digits")
                return
        else:
            self.skip(number, "BLE4: not iBeacon or Eddystone",
                      f"BLE4 beacon kind {_show(values[1] if len(values) > 1 else '')} is neither iBeacon nor Eddystone")
            return
        self.sightings.append(Sighting(number, numbers[0], kind, key, numbers[1]))

    def result(self, source: str) -> GetSensorDataLog:
        sensors = {}
        for kind, (app, sensor, flat, lines) in self.tables.items():
            width = SENSOR_FIELDS[kind] - 3  # less the two timestamps and the accuracy
            sensors[kind] = SensorTable(np.frombuffer(app, dtype=float).copy(), np.frombuffer(sensor, dtype=float).copy(),
                                        np.frombuffer(flat, dtype=float).reshape(-1, width).copy(),
                                        np.frombuffer(lines, dtype=np.int64).copy())
        return GetSensorDataLog(source, sensors, tuple(self.references), tuple(self.sightings), dict(self.not_used),
                                dict(self.unknown), dict(self.header))
