"""`reckon import ilc WALK.txt[.gz]...`: Indoor Location Competition 2.0 walks as session logs.

One session per walk (each walk is its own recording): the phone's accelerometer, gyroscope and
magnetometer as ImuBatch messages (converted to protocol units: g, deg/s, gauss), every
TYPE_WAYPOINT as a TruthPose (heading unknown: NaN), and the floor plan, when the walk lies in the
competition's folder layout (`<site>/<floor>/path_data_files/<walk>.txt` beside `geojson_map.json`
and `floor_info.json`), as the venue's walkable area in metres, with the Earth's field there
(reckon/importers/geomagnetic.py: the plan is in longitude/latitude, north up) for the magnetometer.

The walks have no calibration stand. The first waypoint stands in for one, as the issue asks: a
StandScan at the first waypoint's time and place, heading the bearing to the second waypoint.
That heading is an approximation (the surveyor need not walk straight between waypoints); the
session's `source.start` says so. Errors are then measured at every later waypoint.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from protocol import keys, messages
from protocol.errors import InputError
from protocol.messages import STANDARD_GRAVITY_MS2
from protocol.session import session_from_dict
from reckon.importers.geomagnetic import venue_field
from reckon.importers.ilc import IlcWalk, floor_centre_lonlat, floor_plan_metres, read_ilc
from reckon.importers.tables import ImuArrays
from reckon.importers.report import SensorCount
from reckon.importers.writing import Stamped, imu_messages, truth_message, write_messages

AGENT_ID = "walker"
SENSOR_ID = "phone"
# How far the bearing to the second waypoint may be from where the phone points: the surveyor's
# path between waypoints 5-15 m apart curves, and a hand-held phone points up to about 10 deg off
# the walking direction. An assumption, not a measurement; a real stand is known to about 3 deg.
START_HEADING_SD_RAD = math.radians(15.0)
START_NOTE = ("the first waypoint stands in for a calibration stand: position exact, heading the bearing to the "
              "second waypoint (an approximation)")


@dataclass(frozen=True)
class IlcImport:
    output: Path
    samples: int
    waypoints: int
    floor_plan: bool
    skipped_lines: int

    def __str__(self) -> str:
        plan = "with the floor plan" if self.floor_plan else "no floor plan found beside it"
        return (f"{self.output}: {self.samples} phone samples, {self.waypoints} waypoints, {plan}"
                + (f"; {self.skipped_lines} lines skipped" if self.skipped_lines else ""))


def find_floor(walk_path: Path) -> tuple[dict, float, float] | None:
    """(GeoJSON, width m, height m) of the floor a walk belongs to, from the competition's layout."""
    floor = walk_path.resolve().parent.parent
    geojson, info = floor / "geojson_map.json", floor / "floor_info.json"
    if not (geojson.is_file() and info.is_file()):
        return None
    try:
        size = json.loads(info.read_text(encoding="utf-8"))["map_info"]
        return json.loads(geojson.read_text(encoding="utf-8")), float(size["width"]), float(size["height"])
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise InputError(f"{floor}: floor_info.json or geojson_map.json unreadable ({error})") from None


def walk_session(walk: IlcWalk, name: str, floor: tuple[dict, float, float] | None) -> dict:
    """The session description (a plain dict, validated by session_from_dict) of one walk."""
    venue: dict = {"name": name}
    if floor is not None:
        geojson, width_m, height_m = floor
        longitude_deg, latitude_deg = floor_centre_lonlat(geojson)
        venue.update(court_length_m=width_m, court_width_m=height_m,
                     floor_plan=floor_plan_metres(geojson, width_m, height_m),
                     **venue_field(latitude_deg, longitude_deg, int(walk.time_ns[0])))
    return {
        "venue": venue,
        "agents": [{"id": AGENT_ID, "kind": "pedestrian",
                    # Held flat in front (ILC's surveyors): the screen's top (+y) points where they walk.
                    "sensors": [{"id": SENSOR_ID, "mount": "hand", "rate_hz": 50.0,
                                 "forward_axis": "+y", "left_axis": "-x"}]}],
        "source": {"importer": "ilc", "walk": name, "phone": walk.phone, "start": START_NOTE,
                   "height": "the surveyor's height is not recorded: the default 1.70 m is used"},
    }


def start_scan(walk: IlcWalk, venue: str) -> Stamped:
    (x0, y0), (x1, y1) = walk.waypoint_xy[0], walk.waypoint_xy[1]
    time_ns = int(walk.waypoint_time_ns[0])
    message = messages.new("StandScan", timestamp_ns=time_ns, agent_id=AGENT_ID, sensor_id=SENSOR_ID,
                           stand_id="waypoint-1", x_m=float(x0), y_m=float(y0), floor=0,
                           heading_rad=math.atan2(y1 - y0, x1 - x0), heading_sd_rad=START_HEADING_SD_RAD,
                           tilt_rad=0.0, payload=START_NOTE,
                           accepted=True, reason="")
    return time_ns, keys.scan(venue, AGENT_ID), message


def import_ilc(path: Path, output: Path) -> IlcImport:
    """Write one ILC walk as a session log at `output`; InputError naming the file on bad input."""
    walk = read_ilc(path)
    if len(walk.waypoint_xy) < 2:
        raise InputError(f"{path}: {len(walk.waypoint_xy)} waypoints; a walk needs at least 2 "
                         "(the first stands in for a calibration stand, the rest are scored)")
    if len(walk.time_ns) < 2:
        raise InputError(f"{path}: no phone samples (TYPE_ACCELEROMETER with TYPE_GYROSCOPE)")
    name = path.name.split(".")[0]
    floor = find_floor(path)
    session = session_from_dict(walk_session(walk, name, floor), where=f"{path} (import)")
    phone = ImuArrays(walk.time_ns, walk.accel_ms2 / STANDARD_GRAVITY_MS2, np.degrees(walk.gyro_rads),
                      None if walk.mag_ut is None else walk.mag_ut / 100.0)  # 1 gauss = 100 uT
    count = SensorCount(AGENT_ID)
    truth = [truth_message(name, AGENT_ID, int(t), float(x), float(y), math.nan)
             for t, (x, y) in zip(walk.waypoint_time_ns, walk.waypoint_xy)]
    write_messages(output, session, [imu_messages(name, AGENT_ID, SENSOR_ID, phone, count), truth,
                                     [start_scan(walk, name)]])
    return IlcImport(output, len(walk.time_ns), len(truth), floor is not None, walk.skipped_lines)


def import_walks(paths: list[Path], output: Path) -> list[IlcImport]:
    """Several walks: `output` is a folder (one `<walk>.mcap` each); one walk may name a file."""
    if len(paths) == 1 and output.suffix == ".mcap":
        return [import_ilc(paths[0], output)]
    if output.exists() and not output.is_dir():
        raise InputError(f"{output}: not a folder; with several walks, -o names the folder for their logs")
    output.mkdir(parents=True, exist_ok=True)
    return [import_ilc(path, output / f"{path.name.split('.')[0]}.mcap") for path in paths]
