"""`reckon import ngimu DIR -o session.mcap`: an x-io NGIMU recording folder -> one session MCAP.

DIR holds one subfolder per device as the NGIMU software saves them, e.g.
`NGIMU - 1 Frame - 00337909/sensors.csv` (Time (s), Gyroscope X (deg/s) .., Accelerometer X (g) ..,
Magnetometer X (uT) .., Barometer (hPa)) and `Settings.txt` (`/rate/sensors, 400f`).

- Mounts come from the folder label (Frame/Seat -> seat, Left -> left_wheel, Right -> right_wheel)
  unless `mounts` names them.
- Each device keeps its own clock: times are device seconds, as recorded, not aligned. NGIMU
  sample intervals vary (2.5 ms nominal, gaps of 15 ms); they are kept as given. The logger
  writes some samples twice (same values, same or a 4 us earlier time): skipped and counted.
- Unless given, a wheel's spin axis is the gyro axis with the largest net rotation, signed so the
  net rotation is positive. This ASSUMES THE RECORDING IS MOSTLY FORWARD PUSHING: a recording
  that is mostly backward gets both wheels' signs wrong; pass `spin_axes` then.
- Unless given, the seat's up axis is the one gravity reads along, and its forward axis is the
  horizontal axis whose acceleration follows the wheels' acceleration best (same clocks assumed
  within ~0.1 s); left = up x forward.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from edge.mounting import signed_axis
from edge.chair.paper.wheel import wheel_rotation_deg
from protocol.errors import ConfigError, InputError
from protocol.session import AXES, Mount, Session, session_from_dict
from reckon.importers.report import ImportReport
from reckon.importers.tables import (STANDARD_GRAVITY_MPS2, HeaderName, ImuArrays, csv_rows, layout_from_header,
                                     read_imu_rows)
from reckon.importers.writing import imu_messages, sensor_count, write_messages

log = logging.getLogger(__name__)

# Wheel diameter when none is given: worklab's `process_imu` default, wsize = 0.31 m *radius*, in the
# version its NGIMU example notebook (docs/chapters/examples/ex_move_imu.ipynb, the source of the
# recording in shared/data/wheelchair/worklab-ngimu) called with defaults; later worklab versions use
# 0.32 m. A library default, not a measurement of that chair: pass the measured diameter when known.
DEFAULT_WHEEL_DIAMETER_M = 0.62
SENSORS_FILE = "sensors.csv"
SETTINGS_FILE = "Settings.txt"
BAROMETER_COLUMN = "Barometer (hPa)"
SEAT_CORRELATION_MIN = 0.5  # below this the forward-axis guess is no better than the default
SPIN_AMBIGUITY = 0.5  # warn when the second axis turned more than half as much as the spin axis
_FOLDER = re.compile(r"^NGIMU - (?P<label>.+?) - (?P<serial>[0-9A-Fa-f]{4,})$")
_MOUNT_WORDS = {"frame": Mount.SEAT, "seat": Mount.SEAT, "left": Mount.LEFT_WHEEL, "right": Mount.RIGHT_WHEEL}
_COLUMN = re.compile(r"^(gyroscope|accelerometer|magnetometer) ([xyz]) \((.+)\)$")
_TIME = re.compile(r"^time \((.+)\)$")
_QUANTITY = {"gyroscope": "gyro", "accelerometer": "accel", "magnetometer": "mag"}
_RATE = re.compile(r"^/rate/sensors\s*,\s*([0-9.]+)f?\s*$", re.M)
_UNIT_VECTOR = {f"{sign}{name}": (1.0 if sign == "+" else -1.0) * np.eye(3)[index]
                for index, name in enumerate("xyz") for sign in "+-"}


@dataclass
class Device:
    folder: Path
    sensor_id: str
    mount: Mount
    rate_hz: float
    data: ImuArrays


def import_ngimu_folder(folder: Path, output: Path, *, mounts: Mapping[str, str] | None = None,
                        spin_axes: Mapping[str, str] | None = None, seat_axes: tuple[str, str] | None = None,
                        wheel_diameter_m: float = DEFAULT_WHEEL_DIAMETER_M, agent_id: str = "chair",
                        venue: str = "lab") -> ImportReport:
    """Import an NGIMU recording folder as one agent in venue `venue`.

    `mounts`: device folder name, serial number or sensor id -> "seat" | "left_wheel" | "right_wheel".
    `spin_axes`: "left_wheel"/"right_wheel" -> gyro axis ("+x".."-z") reading positive forward.
    `seat_axes`: (forward_axis, left_axis) of the seat/frame sensor. Unset: found from the data.
    ConfigError for a bad option, InputError for an unusable folder or file.
    """
    folder, output = Path(folder), Path(output)
    report = ImportReport(output)
    devices = _read_devices(folder, dict(mounts or {}), report)
    session = _session(devices, dict(spin_axes or {}), seat_axes, wheel_diameter_m, agent_id, venue, folder, report)
    starts = {device.sensor_id: float(device.data.time_ns[0]) * 1e-9 for device in devices}
    if len(set(starts.values())) > 1:
        spread_ms = (max(starts.values()) - min(starts.values())) * 1e3
        report.warn("device clocks start at " + ", ".join(f"{sid} {start:.6f} s" for sid, start in starts.items())
                    + f" (spread {spread_ms:.1f} ms); each sensor keeps its own clock, not aligned")
    streams = []
    for device in devices:
        report.sensors[device.sensor_id] = sensor_count(agent_id, device.data)
        streams.append(imu_messages(venue, agent_id, device.sensor_id, device.data, report.sensors[device.sensor_id]))
    write_messages(output, session, streams)
    log.info("imported NGIMU %s: %d devices", folder, len(devices))
    return report


def _read_devices(folder: Path, mounts: dict[str, str], report: ImportReport) -> list[Device]:
    if not folder.is_dir():
        raise InputError(f"{folder}: not a folder (expected one subfolder per NGIMU device)")
    subfolders = sorted(path for path in folder.iterdir() if path.is_dir())
    for path in subfolders:
        if not (path / SENSORS_FILE).is_file():
            report.warn(f"{path}: no {SENSORS_FILE}, not a device folder; ignored")
    subfolders = [path for path in subfolders if (path / SENSORS_FILE).is_file()]
    if not subfolders:
        raise InputError(f"{folder}: no NGIMU device folders (subfolders holding {SENSORS_FILE})")
    names = [(path, _sensor_id(path.name), _FOLDER.match(path.name)) for path in subfolders]
    used: set[Mount] = set()
    for key in mounts:
        if not any(key in (path.name, sensor_id, match and match["serial"]) for path, sensor_id, match in names):
            raise ConfigError(f"mounts.{key}: matches no device folder "
                              f"(folders: {', '.join(path.name for path in subfolders)})")
    devices = []
    for path, sensor_id, match in names:
        mount = _mount(path, sensor_id, match, mounts)
        if mount in used:
            other = next(device.folder.name for device in devices if device.mount is mount)
            raise InputError(f"{folder}: folders {other!r} and {path.name!r} are both at mount {mount.value!r}; "
                             "give the mounts explicitly")
        if sensor_id in {device.sensor_id for device in devices}:
            raise InputError(f"{path}: two device folders give sensor id {sensor_id!r}")
        used.add(mount)
        data = read_sensors_csv(path / SENSORS_FILE, report)
        devices.append(Device(path, sensor_id, mount, _rate_hz(path, data), data))
    return devices


def read_sensors_csv(path: Path, report: ImportReport) -> ImuArrays:
    """One NGIMU `sensors.csv` -> arrays in g, deg/s, gauss (uT / 100); barometer ignored."""
    display = f"{path.parent.name}/{path.name}"
    with csv_rows(path, display) as (header, rows):
        layout = layout_from_header(header, _parse_name, _name_hint, display, report, known_extra=(BAROMETER_COLUMN,))
        return read_imu_rows(rows, layout, display, report)


def _parse_name(cell: str) -> HeaderName | None:
    name = cell.strip().lower()
    if match := _TIME.match(name):
        return HeaderName("time", "", match.group(1))
    if match := _COLUMN.match(name):
        return HeaderName(_QUANTITY[match.group(1)], match.group(2), match.group(3))
    return None


def _name_hint(quantity: str, axis: str) -> str:
    names = {"time": "Time (s)", "gyro": "Gyroscope {} (deg/s)", "accel": "Accelerometer {} (g)",
             "mag": "Magnetometer {} (uT)"}
    return repr(names[quantity].format(axis.upper()))


def _sensor_id(folder_name: str) -> str:
    match = _FOLDER.match(folder_name)
    if match:
        return f"ngimu-{match['serial'].lower()}"
    return re.sub(r"[^A-Za-z0-9_-]+", "-", folder_name).strip("-")[:64] or "ngimu"


def _mount(path: Path, sensor_id: str, match: re.Match[str] | None, mounts: dict[str, str]) -> Mount:
    for key in (path.name, sensor_id, match and match["serial"]):
        if key in mounts:
            try:
                return Mount(mounts[key])
            except ValueError:
                raise ConfigError(f"mounts.{key}: {mounts[key]!r} is not one of "
                                  f"{', '.join(m.value for m in Mount)}") from None
    label = match["label"] if match else path.name
    found = {_MOUNT_WORDS[word] for word in re.findall(r"[a-z]+", label.lower()) if word in _MOUNT_WORDS}
    if len(found) != 1:
        raise InputError(f"{path}: cannot tell the mount from the name {label!r} (expected one of the words "
                         f"Frame, Seat, Left, Right); give it, e.g. mounts {{{path.name!r}: 'seat'}}")
    return found.pop()


def _rate_hz(path: Path, data: ImuArrays) -> float:
    """The sensor rate set in Settings.txt, else the median sample rate."""
    try:
        match = _RATE.search((path / SETTINGS_FILE).read_text(encoding="utf-8", errors="replace"))
    except OSError:
        match = None
    if match and 1.0 <= float(match.group(1)) <= 10_000.0:
        return float(match.group(1))
    intervals = np.diff(data.time_ns)
    return float(1e9 / np.median(intervals)) if len(intervals) else 1.0


# ---------------------------------------------------------------------------------------------
# Finding the mounting from the data


def detect_spin_axis(data: ImuArrays) -> tuple[str, np.ndarray]:
    """(axis, net rotation deg per gyro axis): the axis that turned most, signed to read positive.

    Positive means forward only if the recording is mostly forward pushing (module docstring).
    """
    rotation = np.array([wheel_rotation_deg(data.time_ns, data.gyro_dps[:, i])[-1] for i in range(3)])
    index = int(np.argmax(np.abs(rotation)))
    return ("+" if rotation[index] >= 0 else "-") + "xyz"[index], rotation


def gravity_up_axis(accel_g: np.ndarray) -> str:
    """The sensor axis pointing up: at rest an accelerometer reads +1 g along up (mean over the data)."""
    mean = np.mean(accel_g, axis=0)
    index = int(np.argmax(np.abs(mean)))
    return ("+" if mean[index] >= 0 else "-") + "xyz"[index]


def detect_seat_axes(seat: ImuArrays, wheels: list[tuple[ImuArrays, str]],
                     wheel_diameter_m: float) -> tuple[str, str, float]:
    """(forward_axis, left_axis, correlation): forward = the horizontal seat axis whose acceleration
    follows the chair's acceleration from the wheel gyros best, in a 10 ms grid smoothed over 0.1 s.
    Below SEAT_CORRELATION_MIN (or with no wheels, no overlap: correlation 0) forward is the first
    horizontal axis, positive, as a default. Left = up x forward either way.
    """
    up = gravity_up_axis(seat.accel_g)
    horizontal = [axis for axis in "xyz" if axis != up[1]]
    start = max([seat.time_ns[0]] + [data.time_ns[0] for data, _ in wheels])
    end = min([seat.time_ns[-1]] + [data.time_ns[-1] for data, _ in wheels])
    grid = np.arange(start, end, 10_000_000)  # 10 ms
    default = "+" + horizontal[0]
    if not wheels or len(grid) < 100:  # under a second of overlap
        return default, _cross(up, default), 0.0
    speed_mps = np.mean([np.interp(grid, data.time_ns, np.radians(signed_axis(data.gyro_dps, axis)))
                         for data, axis in wheels], axis=0) * wheel_diameter_m / 2
    chair_accel_g = np.gradient(_smooth(speed_mps), _smooth(grid * 1e-9)) / STANDARD_GRAVITY_MPS2
    correlations = [_correlation(_smooth(np.interp(grid, seat.time_ns, seat.accel_g[:, "xyz".index(axis)])),
                                 chair_accel_g) for axis in horizontal]
    best = int(np.argmax(np.abs(correlations)))
    forward = ("+" if correlations[best] >= 0 else "-") + horizontal[best]
    if abs(correlations[best]) < SEAT_CORRELATION_MIN:
        forward = default
    return forward, _cross(up, forward), abs(correlations[best])


def _correlation(first: np.ndarray, second: np.ndarray) -> float:
    """Pearson correlation; 0 when either signal is constant."""
    spread = float(np.std(first) * np.std(second))
    return float(np.mean((first - first.mean()) * (second - second.mean()))) / spread if spread > 0 else 0.0


def _smooth(values: np.ndarray, samples: int = 10) -> np.ndarray:
    """Moving average over `samples`; only the fully covered part (len - samples + 1 values)."""
    return np.convolve(values, np.ones(samples) / samples, mode="valid")


def _cross(first: str, second: str) -> str:
    """Signed axis name of first x second (both signed axis names, perpendicular)."""
    vector = np.cross(_UNIT_VECTOR[first], _UNIT_VECTOR[second])
    return next(name for name, unit in _UNIT_VECTOR.items() if np.array_equal(unit, vector))


def _session(devices: list[Device], spin_axes: dict[str, str], seat_axes: tuple[str, str] | None,
             wheel_diameter_m: float, agent_id: str, venue: str, folder: Path, report: ImportReport) -> Session:
    for key, axis in spin_axes.items():
        if key not in (Mount.LEFT_WHEEL.value, Mount.RIGHT_WHEEL.value):
            raise ConfigError(f"spin_axes.{key}: not a wheel mount (left_wheel, right_wheel)")
        if axis not in AXES:
            raise ConfigError(f"spin_axes.{key}: {axis!r} is not one of {', '.join(AXES)}")
    sensors: list[dict[str, object]] = []
    detected: dict[str, str] = {}  # what was found from the data, kept in session.source
    wheels: list[tuple[ImuArrays, str]] = []
    for device in devices:
        entry: dict[str, object] = {"id": device.sensor_id, "mount": device.mount.value,
                                    "rate_hz": round(device.rate_hz, 3)}
        if device.mount is not Mount.SEAT:
            axis = spin_axes.get(device.mount.value)
            if axis is None:
                axis, rotation = detect_spin_axis(device.data)
                detected[device.sensor_id] = (f"spin_axis {axis} from net rotation (deg) "
                                              f"{np.round(rotation, 1).tolist()}")
                _check_spin(device, axis, rotation, report)
            entry["spin_axis"] = axis
            wheels.append((device.data, axis))
        sensors.append(entry)
    for device, entry in zip(devices, sensors):
        if device.mount is Mount.SEAT:
            entry["forward_axis"], entry["left_axis"] = seat_axes or _detected_seat_axes(
                device, wheels, wheel_diameter_m, detected, report)
    data = {"venue": {"name": venue},
            "agents": [{"id": agent_id, "wheel_diameter_m": wheel_diameter_m, "sensors": sensors}],
            "source": {"importer": "reckon import ngimu", "folder": folder.name,
                       "devices": {device.sensor_id: device.folder.name for device in devices},
                       "detected": detected}}
    return session_from_dict(data, where="ngimu import")


def _detected_seat_axes(device: Device, wheels: list[tuple[ImuArrays, str]], wheel_diameter_m: float,
                        detected: dict[str, str], report: ImportReport) -> tuple[str, str]:
    forward, left, correlation = detect_seat_axes(device.data, wheels, wheel_diameter_m)
    detected[device.sensor_id] = f"forward_axis {forward}, left_axis {left} (correlation {correlation:.2f})"
    if correlation < SEAT_CORRELATION_MIN:
        report.warn(f"{device.folder.name}: forward axis unclear from the data (correlation {correlation:.2f} "
                    f"< {SEAT_CORRELATION_MIN}); assumed {forward}, left {left}; give seat_axes")
    return forward, left


def _check_spin(device: Device, axis: str, rotation: np.ndarray, report: ImportReport) -> None:
    ordered = np.sort(np.abs(rotation))
    turns = ordered[-1] / 360.0
    if turns < 1.0:
        report.warn(f"{device.folder.name}: the wheel turned only {turns:.2f} revolutions; "
                    f"spin axis {axis} is a weak guess")
    elif ordered[-2] > SPIN_AMBIGUITY * ordered[-1]:
        report.warn(f"{device.folder.name}: spin axis unclear (net rotation per axis "
                    f"{np.round(rotation).tolist()} deg); took {axis}")
