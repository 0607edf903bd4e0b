"""`reckon import ilc WALK.txt[.gz]...`: Indoor Location Competition 2.0 walks as session logs.

One session per walk (each walk is its own recording): the phone's accelerometer, gyroscope and
magnetometer as ImuBatch messages (converted to protocol units: g, deg/s, gauss), every
TYPE_WAYPOINT as a TruthPose (heading unknown: NaN), and the floor plan, when the walk lies in the
competition's folder layout (`<site>/<floor>/path_data_files/<walk>.txt` beside `geojson_map.json`
and `floor_info.json`), as the venue's walkable area in metres, with the Earth's field there
(reckon/importers/geomagnetic.py: the plan is in longitude/latitude, north up) for the magnetometer.
How the plan is read (which feature is the outline, the frame): reckon/importers/ilc_plan.py.

The report (`str` of each IlcImport; the CLI prints them) gives per walk how many truth waypoints
lie in the walkable area as the hub builds it from the session (hub/pedestrian/walkable.py, the
one definition of walkable) and how far each other one lies outside it; after a floor's last walk,
that floor's block: the rule that found the outline, the shops, the frame and the floor's
waypoints pooled, against the hub's area and against it without the plan tolerance (NO_TOLERANCE).
A waypoint outside is a map problem to report, not an error. The report is printed, not stored:
the session logs are the same with or without it.

The walks have no calibration stand. The first waypoint stands in for one, as the issue asks: a
StandScan at the first waypoint's time and place, heading the bearing to the second waypoint.
That heading is an approximation (the surveyor need not walk straight between waypoints); the
session's `source.start` says so. Errors are then measured at every later waypoint.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hub.pedestrian.walkable import WalkableArea, WalkableSettings
from protocol import keys, messages
from protocol.errors import InputError
from protocol.messages import STANDARD_GRAVITY_MS2
from protocol.session import Venue, session_from_dict
from reckon.importers.geomagnetic import venue_field
from reckon.importers.ilc import IlcWalk, read_ilc
from reckon.importers.ilc_plan import FloorPlan, read_floor_plan
from reckon.importers.tables import ImuArrays
from reckon.importers.report import SensorCount, WalkableCheck
from reckon.importers.writing import Stamped, imu_messages, truth_message, write_messages

AGENT_ID = "walker"
SENSOR_ID = "phone"
# How far the bearing to the second waypoint may be from where the phone points: the surveyor's
# path between waypoints 5-15 m apart curves, and a hand-held phone points up to about 10 deg off
# the walking direction. An assumption, not a measurement; a real stand is known to about 3 deg.
START_HEADING_SD_RAD = math.radians(15.0)
START_NOTE = ("the first waypoint stands in for a calibration stand: position exact, heading the bearing to the "
              "second waypoint (an approximation)")
# The hub's area without its plan tolerance (hub/pedestrian/walkable.py: the plan's own area, less
# the grid's 0.12 m strip along every line). A waypoint outside this but inside the hub's area
# stands in a doorway or by a line drawn a little off: the map problem the tolerance absorbs.
# The floor report gives both.
NO_TOLERANCE = WalkableSettings(plan_tolerance_m=0.0)


@dataclass(frozen=True)
class IlcImport:
    output: Path
    samples: int
    waypoints: int
    floor_plan: bool
    skipped_lines: int
    walk: str = ""  # the walk's name (its file name without suffixes)
    walkable: WalkableCheck | None = None  # against the hub's walkable area; None without a floor plan
    walkable_no_tolerance: WalkableCheck | None = None  # the same with NO_TOLERANCE: in the floor report
    floor_folder: Path | None = None
    floor_report: tuple[str, ...] = ()  # set on a floor's last walk by import_walks, printed after it

    def __str__(self) -> str:
        plan = "with the floor plan" if self.floor_plan else "no floor plan found beside it"
        lines = [f"{self.output}: {self.samples} phone samples, {self.waypoints} waypoints, {plan}"
                 + (f"; {self.skipped_lines} lines skipped" if self.skipped_lines else "")]
        if self.walkable is not None:
            lines.append(f"  {self.walkable}")
        return "\n".join(lines + list(self.floor_report))


class IlcFloor:
    """One floor folder's plan, read once for all its walks, and the hub's walkable areas of it."""

    def __init__(self, folder: Path, plan: FloorPlan, width_m: float, height_m: float) -> None:
        self.folder, self.plan, self.width_m, self.height_m = folder, plan, width_m, height_m
        self._areas: dict[bool, WalkableArea | str] = {}  # no tolerance? -> the area, or why there is none

    def check(self, venue: Venue, walk: IlcWalk, no_tolerance: bool = False) -> WalkableCheck:
        """The walk's waypoints against the walkable area the hub builds from `venue` (the
        session's; its floor plan is this floor's, the same for every walk, so it is built once):
        with the hub's settings, or `no_tolerance` (NO_TOLERANCE: without the plan tolerance)."""
        if no_tolerance not in self._areas:
            try:
                settings = NO_TOLERANCE if no_tolerance else WalkableSettings()
                self._areas[no_tolerance] = WalkableArea.from_venue(venue, settings)
            except ValueError as error:
                self._areas[no_tolerance] = f"the hub finds no walkable area in the plan: {error}"
        area = self._areas[no_tolerance]
        if isinstance(area, str):
            return WalkableCheck(len(walk.waypoint_xy), problem=area)
        distances_m = area.outside_by_m(walk.waypoint_xy[:, 0], walk.waypoint_xy[:, 1])
        return WalkableCheck(len(distances_m), tuple((f"wp {number}", float(distance_m))
                                                     for number, distance_m in enumerate(distances_m, start=1)
                                                     if distance_m > 0.0))


def find_floor(walk_path: Path, floors: dict[Path, IlcFloor | None] | None = None) -> IlcFloor | None:
    """The floor a walk belongs to, from the competition's layout (`<floor>/path_data_files/<walk>`
    beside `geojson_map.json` and `floor_info.json`); None when they are not there. `floors`
    caches floors by folder across walks. InputError naming the file when they cannot be read or
    no feature of the GeoJSON is a floor outline (reckon/importers/ilc_plan.py)."""
    folder = walk_path.resolve().parent.parent
    if floors is not None and folder in floors:
        return floors[folder]
    geojson, info = folder / "geojson_map.json", folder / "floor_info.json"
    floor = None
    if geojson.is_file() and info.is_file():
        try:
            size = json.loads(info.read_text(encoding="utf-8"))["map_info"]
            data, width_m, height_m = (json.loads(geojson.read_text(encoding="utf-8")), float(size["width"]),
                                       float(size["height"]))
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise InputError(f"{folder}: floor_info.json or geojson_map.json unreadable ({error})") from None
        floor = IlcFloor(folder, read_floor_plan(data, width_m, height_m, where=str(geojson)), width_m, height_m)
    if floors is not None:
        floors[folder] = floor
    return floor


def walk_session(walk: IlcWalk, name: str, floor: IlcFloor | None) -> dict:
    """The session description (a plain dict, validated by session_from_dict) of one walk."""
    venue: dict = {"name": name}
    if floor is not None:
        longitude_deg, latitude_deg = floor.plan.centre_lonlat
        venue.update(court_length_m=floor.width_m, court_width_m=floor.height_m, floor_plan=floor.plan.polygons,
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


def import_ilc(path: Path, output: Path, floors: dict[Path, IlcFloor | None] | None = None) -> IlcImport:
    """Write one ILC walk as a session log at `output`; InputError naming the file on bad input.
    `floors`: floors already read (by folder), shared across the walks of one import."""
    walk = read_ilc(path)
    if len(walk.waypoint_xy) < 2:
        raise InputError(f"{path}: {len(walk.waypoint_xy)} waypoints; a walk needs at least 2 "
                         "(the first stands in for a calibration stand, the rest are scored)")
    if len(walk.time_ns) < 2:
        raise InputError(f"{path}: no phone samples (TYPE_ACCELEROMETER with TYPE_GYROSCOPE)")
    name = path.name.split(".")[0]
    floor = find_floor(path, floors)
    session = session_from_dict(walk_session(walk, name, floor), where=f"{path} (import)")
    phone = ImuArrays(walk.time_ns, walk.accel_ms2 / STANDARD_GRAVITY_MS2, np.degrees(walk.gyro_rads),
                      None if walk.mag_ut is None else walk.mag_ut / 100.0)  # 1 gauss = 100 uT
    count = SensorCount(AGENT_ID)
    truth = [truth_message(name, AGENT_ID, int(t), float(x), float(y), math.nan)
             for t, (x, y) in zip(walk.waypoint_time_ns, walk.waypoint_xy)]
    write_messages(output, session, [imu_messages(name, AGENT_ID, SENSOR_ID, phone, count), truth,
                                     [start_scan(walk, name)]])
    if floor is None:
        return IlcImport(output, len(walk.time_ns), len(truth), False, walk.skipped_lines, name)
    return IlcImport(output, len(walk.time_ns), len(truth), True, walk.skipped_lines, name,
                     floor.check(session.venue, walk), floor.check(session.venue, walk, no_tolerance=True),
                     floor.folder)


def import_walks(paths: list[Path], output: Path) -> list[IlcImport]:
    """Several walks: `output` is a folder (one `<walk>.mcap` each); one walk may name a file.
    The last walk of each floor carries the floor's report (`floor_report`)."""
    floors: dict[Path, IlcFloor | None] = {}
    if len(paths) == 1 and output.suffix == ".mcap":
        return with_floor_reports([import_ilc(paths[0], output, floors)], floors)
    if output.exists() and not output.is_dir():
        raise InputError(f"{output}: not a folder; with several walks, -o names the folder for their logs")
    output.mkdir(parents=True, exist_ok=True)
    return with_floor_reports([import_ilc(path, output / f"{path.name.split('.')[0]}.mcap", floors)
                               for path in paths], floors)


def with_floor_reports(imports: list[IlcImport], floors: dict[Path, IlcFloor | None]) -> list[IlcImport]:
    """`imports` with each floor's report on its last walk: how the plan was read and the floor's
    waypoints against the walkable area, pooled over its walks."""
    result = list(imports)
    for folder, floor in floors.items():
        walks = [number for number, item in enumerate(result) if item.floor_folder == folder]
        if floor is None or not walks:
            continue
        pooled = WalkableCheck.combine([(result[number].walk, result[number].walkable) for number in walks
                                        if result[number].walkable is not None])
        strict = WalkableCheck.combine([(result[number].walk, result[number].walkable_no_tolerance)
                                        for number in walks if result[number].walkable_no_tolerance is not None])
        lines = ([f"floor {folder} ({len(walks)} walk{'s' if len(walks) > 1 else ''}):"]
                 + [f"  {line}" for line in floor.plan.describe()]
                 + ["  " + pooled.text("walkable (the hub's area)"),
                    "  " + strict.text("walkable with plan_tolerance_m 0")])
        result[walks[-1]] = dataclasses.replace(result[walks[-1]], floor_report=tuple(lines))
    return result
