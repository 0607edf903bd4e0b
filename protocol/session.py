"""Session description: the venue and its agents, with strict loading from TOML/JSON dicts.

A session log (MCAP) stores this description as metadata record `reckon.session` (JSON), and the
CSV importer reads it from a TOML file. Every key is documented in docs/session-format.md.
Unknown keys and out-of-range values fail with the key path, e.g.
`venue.toml: agents[2].sensors[0].mount: 'wheel' is not one of left_wheel, right_wheel, seat`.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from protocol.errors import ConfigError
from protocol.keys import RESERVED, check_id

FORMAT_VERSION = 1
AXES = ("+x", "-x", "+y", "-y", "+z", "-z")
# A beacon's advertisement identity, as edge.decoders.ble_adverts produces it from the air (that
# module's normalize_identity is the same rule; protocol imports nothing from edge).
_IDENTITY = re.compile(
    r"ibeacon:(?P<uuid>[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12})"
    r":(?P<major>\d{1,5}):(?P<minor>\d{1,5})"
    r"|eddystone:[0-9a-f]{20}:[0-9a-f]{12}")


class Mount(str, enum.Enum):
    LEFT_WHEEL = "left_wheel"
    RIGHT_WHEEL = "right_wheel"
    SEAT = "seat"
    # A swimmer's sensor (the swimming paper's placements) and a kickboard pushed by hand.
    WAIST = "waist"
    BACK = "back"
    HEAD = "head"
    KICKBOARD = "kickboard"
    # A phone: held flat in front (the indoor-navigation paper's hold) or in a trouser pocket.
    HAND = "hand"
    POCKET = "pocket"

    @property
    def on_wheel(self) -> bool:
        return self in (Mount.LEFT_WHEEL, Mount.RIGHT_WHEEL)


class AgentKind(str, enum.Enum):
    WHEELCHAIR = "wheelchair"
    SWIMMER = "swimmer"
    PEDESTRIAN = "pedestrian"  # a person on foot: a waist sensor (the camera-identity paper) or a phone


class Route(str, enum.Enum):
    """A swimmer's planned path over each length: along the lane, or the swimming paper's diagonal
    (straight to half the pool length, then a right turn of DIAGONAL_TURN_DEG to the far wall)."""

    STRAIGHT = "straight"
    DIAGONAL = "diagonal"


# The swimming paper's diagonal route: 12.5 m, turn right 35.75 deg, 15.40 m: 27.90 m in a 25 m pool.
DIAGONAL_TURN_DEG = 35.75


def route_end_heading_rad(route: "Route") -> float:
    """Heading at the wall relative to the length's start heading (left positive, rad)."""
    return -math.radians(DIAGONAL_TURN_DEG) if route is Route.DIAGONAL else 0.0


@dataclass(frozen=True)
class Beacon:
    """A BLE beacon at a fixed place (under a goal)."""

    id: str
    x_m: float
    y_m: float
    radius_m: float = 1.0  # reception zone the paper assumes (its simulation, sec. 4.4.1)
    tx_power_dbm: float = -59.0  # RSSI at 1 m, the iBeacon calibration figure
    height_m: float = 2.9  # under the backboard (3.05 m rim), out of play; a floor beacon would be in play
    # What the beacon advertises, canonical: "ibeacon:<uuid>:<major>:<minor>" or
    # "eddystone:<namespace, 20 hex>:<instance, 12 hex>". None: not heard by `ble://scan`.
    identity: str | None = None
    floor: int = 0  # a building's floor; a phone on another floor does not take a fix from it


@dataclass(frozen=True)
class Stand:
    """A QR calibration stand (the indoor-navigation paper's): a phone placed in its corner is at
    (x, y) on `floor`, facing `heading_deg` (counter-clockwise from +x), tilted `tilt_deg` up."""

    id: str
    x_m: float
    y_m: float
    floor: int = 0
    heading_deg: float = 0.0
    tilt_deg: float = 0.0


@dataclass(frozen=True)
class MapPoint:
    """A corridor junction of the paper's map (its tables 4-5): where corridors meet, and the
    directions (deg, counter-clockwise from +x) in which a corridor leaves it."""

    id: str
    x_m: float
    y_m: float
    directions_deg: tuple[float, ...]
    floor: int = 0


@dataclass(frozen=True)
class Venue:
    name: str
    court_length_m: float = 28.0  # FIBA / IWBF court; for a pool, the lane length (wall to wall, along x)
    court_width_m: float = 15.0
    beacons: tuple[Beacon, ...] = ()
    stands: tuple[Stand, ...] = ()
    map_points: tuple[MapPoint, ...] = ()
    # Walkable floor area: outer polygons with holes, in metres of the venue frame. Loaded from a
    # GeoJSON file named in the venue file (path relative to it) or given inline; stored inline in
    # a session log so the log stands alone. Each polygon is [outer ring, hole, hole, ...], a ring
    # a list of [x, y].
    floor_plan: tuple[Any, ...] = ()
    # A building with floors that differ: (floor, polygons) per floor, each as floor_plan. A floor
    # not listed has floor_plan (the plan of every floor, or of the venue's one floor).
    floor_plans: tuple[tuple[int, tuple[Any, ...]], ...] = ()
    # The Earth's field at the venue, for phones' magnetometers (edge/pedestrian/magnetic.py): the direction
    # of magnetic north in the venue frame (deg, counter-clockwise from +x: true north's direction
    # minus the declination), and the undisturbed field's strength and dip, which tell a clean reading
    # from one bent by the building's steel. None: unknown, the magnetometer is not used.
    magnetic_north_deg: float | None = None
    magnetic_field_ut: float | None = None
    magnetic_dip_deg: float | None = None

    def plan_of(self, floor: int) -> tuple[Any, ...]:
        """The walkable polygons of one floor."""
        return next((plan for number, plan in self.floor_plans if number == floor), self.floor_plan)

    @property
    def floors(self) -> tuple[int, ...]:
        """The floors with a plan of their own, in order."""
        return tuple(sorted(number for number, _ in self.floor_plans))


@dataclass(frozen=True)
class Sensor:
    """One IMU of an agent.

    Chair frame: x forward, y left, z up. `spin_axis` (wheels) is the gyro axis, with sign, that
    reads positive when the chair rolls forward. `forward_axis`/`left_axis` (seat and body mounts)
    are the sensor axes that point to the chair's front and left, or for a swimmer lying prone,
    towards the head (the direction of travel) and to the swimmer's left.
    """

    id: str
    mount: Mount
    rate_hz: float = 200.0
    spin_axis: str | None = None
    forward_axis: str | None = None
    left_axis: str | None = None


@dataclass(frozen=True)
class Agent:
    id: str
    kind: AgentKind = AgentKind.WHEELCHAIR
    wheel_diameter_m: float = 0.61  # the paper's chairs: 610 mm (one 670 mm)
    camber_deg: float = 17.0  # sports chairs 15-20 deg (algorithms.md)
    sensors: tuple[Sensor, ...] = ()
    start_x_m: float = 0.0  # start pose, used when the session has no truth
    start_y_m: float = 0.0
    start_heading_rad: float = 0.0
    route: Route = Route.STRAIGHT  # swimmers: the planned path of every length
    height_m: float = 1.70  # pedestrians: body height, for the paper's cadence-to-speed model

    def sensor(self, mount: Mount) -> Sensor | None:
        """The agent's sensor at `mount`, or None when it has none there."""
        return next((s for s in self.sensors if s.mount is mount), None)


@dataclass(frozen=True)
class Session:
    venue: Venue
    agents: tuple[Agent, ...]
    source: dict[str, Any] = field(default_factory=dict)  # free-form provenance (sim seed, importer)

    def agent(self, agent_id: str) -> Agent:
        for agent in self.agents:
            if agent.id == agent_id:
                return agent
        raise KeyError(agent_id)

    def sensor_owner(self) -> dict[str, Agent]:
        return {s.id: a for a in self.agents for s in a.sensors}


# ---------------------------------------------------------------------------------------------
# Strict loading


def _check_keys(data: dict[str, Any], cls: type, where: str, nested: tuple[str, ...] = ()) -> None:
    allowed = {f.name for f in dataclasses.fields(cls)} | set(nested)
    for key in data:
        if key not in allowed:
            raise ConfigError(f"{where}.{key}: unknown key (allowed: {', '.join(sorted(allowed))})")


def _number(data: dict[str, Any], key: str, where: str, default: float, low: float, high: float) -> float:
    value = data.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{where}.{key}: {value!r} is not a finite number")
    if not low <= value <= high:
        raise ConfigError(f"{where}.{key}: {value} is outside [{low}, {high}]")
    return float(value)


def _integer(data: dict[str, Any], key: str, where: str, default: int, low: int, high: int) -> int:
    """A whole number within [low, high] (a floor); 1.5 is refused rather than truncated."""
    value = _number(data, key, where, default, low, high)
    if value != int(value):
        raise ConfigError(f"{where}.{key}: {data[key]!r} is not a whole number")
    return int(value)


def _optional_number(data: dict[str, Any], key: str, where: str, low: float, high: float) -> float | None:
    """A number within [low, high], or None when the key is absent. (The Earth's field is 22-67 uT
    everywhere, so magnetic_field_ut's bounds catch a value given in gauss or nT.)"""
    return None if data.get(key) is None else _number(data, key, where, 0.0, low, high)


def _enum(data: dict[str, Any], key: str, where: str, enum_type: type[enum.Enum], default: Any = None) -> Any:
    value = data.get(key, default)
    try:
        return enum_type(value)
    except ValueError:
        choices = ", ".join(str(m.value) for m in enum_type)
        raise ConfigError(f"{where}.{key}: {value!r} is not one of {choices}") from None


def _axis(data: dict[str, Any], key: str, where: str) -> str | None:
    value = data.get(key)
    if value is not None and value not in AXES:
        raise ConfigError(f"{where}.{key}: {value!r} is not one of {', '.join(AXES)}")
    return value


def _required(data: dict[str, Any], key: str, where: str) -> Any:
    if key not in data:
        raise ConfigError(f"{where}: missing key {key!r}")
    return data[key]


def _list(data: dict[str, Any], key: str, where: str) -> list[Any]:
    value = data.get(key, [])
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise ConfigError(f"{where}.{key}: expected a list of tables")
    return value


def beacon_identity(text: Any, where: str) -> str:
    """A beacon identity in canonical form (lower case, iBeacon major/minor without leading zeros);
    ConfigError naming `where` when it is not one. Same rule as edge's normalize_identity."""
    folded = text.strip().lower() if isinstance(text, str) else ""
    match = _IDENTITY.fullmatch(folded)
    if match is None or (match["uuid"] and max(int(match["major"]), int(match["minor"])) > 0xFFFF):
        raise ConfigError(f"{where}: {text!r} is not ibeacon:<uuid>:<major 0-65535>:<minor 0-65535> "
                          "or eddystone:<namespace, 20 hex digits>:<instance, 12 hex digits>")
    if match["uuid"]:
        return f"ibeacon:{match['uuid']}:{int(match['major'])}:{int(match['minor'])}"
    return folded


def _beacon(data: dict[str, Any], where: str) -> Beacon:
    _check_keys(data, Beacon, where)
    return Beacon(
        id=check_id(_required(data, "id", where), f"{where}.id"),
        x_m=_number(data, "x_m", where, _required(data, "x_m", where), -1e3, 1e3),
        y_m=_number(data, "y_m", where, _required(data, "y_m", where), -1e3, 1e3),
        radius_m=_number(data, "radius_m", where, 1.0, 0.1, 50.0),
        tx_power_dbm=_number(data, "tx_power_dbm", where, -59.0, -120.0, 20.0),
        height_m=_number(data, "height_m", where, 2.9, 0.0, 20.0),
        identity=None if data.get("identity") is None else beacon_identity(data["identity"], f"{where}.identity"),
        floor=_integer(data, "floor", where, 0, -20, 200),
    )


def _check_beacon_reaches_court(beacon: Beacon, venue: Venue, where: str) -> None:
    """A beacon whose reception zone does not touch the court can never give a fix: almost always
    a coordinate in the wrong unit or from the wrong corner."""
    dx = max(-beacon.x_m, 0.0, beacon.x_m - venue.court_length_m)
    dy = max(-beacon.y_m, 0.0, beacon.y_m - venue.court_width_m)
    if math.hypot(dx, dy) > beacon.radius_m:
        raise ConfigError(f"{where}: ({beacon.x_m:g}, {beacon.y_m:g}) m is {math.hypot(dx, dy):.2f} m outside the "
                          f"{venue.court_length_m:g} x {venue.court_width_m:g} m court, beyond its radius_m "
                          f"{beacon.radius_m:g} (x_m runs 0..court_length_m, y_m 0..court_width_m from a corner)")


def _sensor(data: dict[str, Any], where: str) -> Sensor:
    _check_keys(data, Sensor, where)
    sensor = Sensor(
        id=check_id(_required(data, "id", where), f"{where}.id"),
        mount=_enum(data, "mount", where, Mount, _required(data, "mount", where)),
        rate_hz=_number(data, "rate_hz", where, 200.0, 1.0, 10_000.0),
        spin_axis=_axis(data, "spin_axis", where),
        forward_axis=_axis(data, "forward_axis", where),
        left_axis=_axis(data, "left_axis", where),
    )
    if sensor.mount.on_wheel and sensor.spin_axis is None:
        raise ConfigError(f"{where}: a {sensor.mount.value} sensor needs spin_axis (one of {', '.join(AXES)})")
    if not sensor.mount.on_wheel:
        # A phone's own axes (Android: x right, y to the top of the screen, z out of it): held flat
        # in front, the top points where its holder walks. Other mounts name their axes, or x/y.
        phone = sensor.mount in (Mount.HAND, Mount.POCKET)
        forward = sensor.forward_axis or ("+y" if phone else "+x")
        left = sensor.left_axis or ("-x" if phone else "+y")
        if forward[1] == left[1]:
            raise ConfigError(f"{where}: forward_axis {forward} and left_axis {left} must be different axes")
        sensor = dataclasses.replace(sensor, forward_axis=forward, left_axis=left)
    return sensor


def _agent(data: dict[str, Any], where: str) -> Agent:
    _check_keys(data, Agent, where)
    sensors = tuple(_sensor(s, f"{where}.sensors[{i}]") for i, s in enumerate(_list(data, "sensors", where)))
    mounts = [s.mount for s in sensors]
    for mount in set(mounts):
        if mounts.count(mount) > 1:
            raise ConfigError(f"{where}.sensors: two sensors at mount {mount.value!r}")
    agent_id = check_id(_required(data, "id", where), f"{where}.id")
    if agent_id in RESERVED:
        raise ConfigError(f"{where}.id: {agent_id!r} is reserved for the {agent_id}'s keys; choose another agent id")
    return Agent(
        id=agent_id,
        kind=_enum(data, "kind", where, AgentKind, "wheelchair"),
        wheel_diameter_m=_number(data, "wheel_diameter_m", where, 0.61, 0.2, 1.0),
        camber_deg=_number(data, "camber_deg", where, 17.0, 0.0, 30.0),
        sensors=sensors,
        start_x_m=_number(data, "start_x_m", where, 0.0, -1e3, 1e3),
        start_y_m=_number(data, "start_y_m", where, 0.0, -1e3, 1e3),
        start_heading_rad=_number(data, "start_heading_rad", where, 0.0, -10.0, 10.0),
        route=_enum(data, "route", where, Route, "straight"),
        height_m=_number(data, "height_m", where, 1.70, 0.5, 2.5),
    )


def _stand(data: dict[str, Any], where: str) -> Stand:
    _check_keys(data, Stand, where)
    return Stand(
        id=check_id(_required(data, "id", where), f"{where}.id"),
        x_m=_number(data, "x_m", where, _required(data, "x_m", where), -1e4, 1e4),
        y_m=_number(data, "y_m", where, _required(data, "y_m", where), -1e4, 1e4),
        floor=_integer(data, "floor", where, 0, -20, 200),
        heading_deg=_number(data, "heading_deg", where, 0.0, -360.0, 360.0),
        tilt_deg=_number(data, "tilt_deg", where, 0.0, -90.0, 90.0),
    )


def _map_point(data: dict[str, Any], where: str) -> MapPoint:
    _check_keys(data, MapPoint, where)
    directions = _required(data, "directions_deg", where)
    if not isinstance(directions, list) or not directions:
        raise ConfigError(f"{where}.directions_deg: expected a non-empty list of angles in degrees")
    angles = tuple(_number({f"directions_deg[{i}]": d}, f"directions_deg[{i}]", where, 0.0, -360.0, 360.0)
                   for i, d in enumerate(directions))
    return MapPoint(
        id=check_id(_required(data, "id", where), f"{where}.id"),
        x_m=_number(data, "x_m", where, _required(data, "x_m", where), -1e4, 1e4),
        y_m=_number(data, "y_m", where, _required(data, "y_m", where), -1e4, 1e4),
        directions_deg=angles,
        floor=_integer(data, "floor", where, 0, -20, 200),
    )


def _ring(ring: Any, where: str) -> list[list[float]]:
    if not isinstance(ring, list) or len(ring) < 3:
        raise ConfigError(f"{where}: a ring needs at least 3 [x, y] points")
    points = []
    for i, point in enumerate(ring):
        if (not isinstance(point, list) or len(point) != 2
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in point)):
            raise ConfigError(f"{where}[{i}]: {point!r} is not a finite [x, y]")
        points.append([float(point[0]), float(point[1])])
    return points


def floor_plan_from(value: Any, where: str, base: Path | None = None) -> tuple[Any, ...]:
    """The venue's walkable polygons from a GeoJSON path (relative to `base`, the venue file's
    folder) or an inline list of polygons; ConfigError naming `where` on any mistake. A GeoJSON
    file's Polygon/MultiPolygon features are taken as walkable areas (their holes as obstacles);
    its coordinates must already be metres in the venue frame (reckon import ilc converts)."""
    if isinstance(value, str):
        path = Path(value) if base is None or Path(value).is_absolute() else base / value
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except OSError as error:
            raise ConfigError(f"{where}: cannot read {path} ({error.strerror})") from None
        except json.JSONDecodeError as error:
            raise ConfigError(f"{where}: {path} is not JSON ({error})") from None
        polygons = []
        for i, feature in enumerate(data.get("features", []) if isinstance(data, dict) else []):
            geometry = feature.get("geometry") or {}
            if geometry.get("type") == "Polygon":
                polygons.append(geometry["coordinates"])
            elif geometry.get("type") == "MultiPolygon":
                polygons.extend(geometry["coordinates"])
        if not polygons:
            raise ConfigError(f"{where}: {path} has no Polygon or MultiPolygon features")
        value, where = polygons, f"{where} ({path})"
    if not isinstance(value, list):
        raise ConfigError(f"{where}: expected a GeoJSON file path or a list of polygons")
    plan = []
    for i, polygon in enumerate(value):
        if not isinstance(polygon, list) or not polygon:
            raise ConfigError(f"{where}[{i}]: a polygon is a list of rings (outer first, then holes)")
        plan.append([_ring(ring, f"{where}[{i}][{j}]") for j, ring in enumerate(polygon)])
    return tuple(plan)


def floor_plans_from(value: Any, where: str, base: Path | None = None) -> tuple[tuple[int, tuple[Any, ...]], ...]:
    """Per-floor plans from a table {floor: plan} (venue file: keys are strings, "1" or "-1") or
    the session log's list of [floor, plan] pairs; each plan as `floor_plan_from` reads it."""
    if isinstance(value, dict):
        pairs = list(value.items())
    elif isinstance(value, list) and all(isinstance(pair, list) and len(pair) == 2 for pair in value):
        pairs = [(str(number), plan) for number, plan in value]
    else:
        raise ConfigError(f"{where}: expected a table of floor = plan (\"1\" = \"floor1.geojson\")")
    plans = {}
    for key, plan in pairs:
        try:
            number = int(key)
        except (TypeError, ValueError):
            number = None
        if number is None or not -20 <= number <= 200:
            raise ConfigError(f"{where}: floor {key!r} is not a whole number in -20..200")
        if number in plans:
            raise ConfigError(f"{where}: floor {number} given twice")
        plans[number] = floor_plan_from(plan, f"{where}.{key}", base)
    return tuple(sorted(plans.items()))


def session_from_dict(data: dict[str, Any], where: str = "session", base: Path | None = None) -> Session:
    """Validate a plain dict (from TOML or JSON) into a Session; ConfigError names the key path.
    `base` is the folder that relative file names in it (the floor plan) are read from."""
    allowed = {f.name for f in dataclasses.fields(Session)} | {"format_version"}
    for key in data:
        if key not in allowed:
            raise ConfigError(f"{where}: unknown key {key!r} (allowed: {', '.join(sorted(allowed))})")
    version = data.get("format_version", FORMAT_VERSION)
    if isinstance(version, bool) or not isinstance(version, int) or not 1 <= version <= FORMAT_VERSION:
        raise ConfigError(f"{where}.format_version: {version!r} is not a format this reckon reads "
                          f"(1 to {FORMAT_VERSION}; a newer file needs a newer reckon)")
    venue_data = _required(data, "venue", where)
    if not isinstance(venue_data, dict):
        raise ConfigError(f"{where}.venue: expected a table")
    vwhere = f"{where}: venue"
    _check_keys(venue_data, Venue, vwhere)
    beacons = tuple(_beacon(b, f"{vwhere}.beacons[{i}]") for i, b in enumerate(_list(venue_data, "beacons", vwhere)))
    venue = Venue(
        name=check_id(_required(venue_data, "name", vwhere), f"{vwhere}.name"),
        court_length_m=_number(venue_data, "court_length_m", vwhere, 28.0, 1.0, 500.0),
        court_width_m=_number(venue_data, "court_width_m", vwhere, 15.0, 1.0, 500.0),
        beacons=beacons,
        stands=tuple(_stand(b, f"{vwhere}.stands[{i}]") for i, b in enumerate(_list(venue_data, "stands", vwhere))),
        map_points=tuple(_map_point(b, f"{vwhere}.map_points[{i}]")
                         for i, b in enumerate(_list(venue_data, "map_points", vwhere))),
        floor_plan=floor_plan_from(venue_data["floor_plan"], f"{vwhere}.floor_plan", base)
        if "floor_plan" in venue_data else (),
        floor_plans=floor_plans_from(venue_data.get("floor_plans", {}), f"{vwhere}.floor_plans", base),
        magnetic_north_deg=_optional_number(venue_data, "magnetic_north_deg", vwhere, -360.0, 360.0),
        magnetic_field_ut=_optional_number(venue_data, "magnetic_field_ut", vwhere, 20.0, 70.0),
        magnetic_dip_deg=_optional_number(venue_data, "magnetic_dip_deg", vwhere, -90.0, 90.0),
    )
    for i, beacon in enumerate(beacons):
        _check_beacon_reaches_court(beacon, venue, f"{vwhere}.beacons[{i}]")
    agents = tuple(_agent(a, f"{where}: agents[{i}]") for i, a in enumerate(_list(data, "agents", where)))
    if not agents:
        raise ConfigError(f"{where}: no agents (add at least one [[agents]] table)")
    for kind, ids in (("agent id", [a.id for a in agents]), ("sensor id", [s.id for a in agents for s in a.sensors]),
                      ("beacon id", [b.id for b in beacons]), ("stand id", [b.id for b in venue.stands]),
                      ("map point id", [p.id for p in venue.map_points]),
                      ("beacon identity", [b.identity for b in beacons if b.identity])):
        duplicates = sorted({item for item in ids if ids.count(item) > 1})
        if duplicates:
            raise ConfigError(f"{where}: duplicate {kind} {duplicates[0]!r}")
    source = data.get("source", {})
    if not isinstance(source, dict):
        raise ConfigError(f"{where}.source: expected a table")
    return Session(venue=venue, agents=agents, source=dict(source))


def load_toml(path: Path) -> Session:
    """Read a session description TOML; ConfigError names the file and key on any mistake."""
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as error:
        raise ConfigError(f"{path}: cannot read ({error.strerror})") from None
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(f"{path}: not valid TOML ({error})") from None
    return session_from_dict(data, where=str(path), base=Path(path).parent)


def to_dict(session: Session) -> dict[str, Any]:
    """Plain-JSON form of a session (enums as their values)."""

    def plain(value: Any) -> Any:
        if isinstance(value, enum.Enum):
            return value.value
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            fields = {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
            if isinstance(value, Beacon):  # optional and newer: logs without them stay as they were
                for name, default in (("identity", None), ("floor", 0)):
                    if fields[name] == default:
                        del fields[name]
            if isinstance(value, Venue):  # newer and optional: older logs stay byte-identical
                for name in ("stands", "map_points", "floor_plan", "floor_plans"):
                    if not fields[name]:
                        del fields[name]
            if isinstance(value, Agent) and value.kind is not AgentKind.PEDESTRIAN:
                del fields["height_m"]
            return fields
        if isinstance(value, (list, tuple)):
            return [plain(v) for v in value]
        if isinstance(value, dict):
            return {k: plain(v) for k, v in value.items()}
        return value

    data = plain(session)
    data["format_version"] = FORMAT_VERSION
    return data


def to_json(session: Session) -> str:
    return json.dumps(to_dict(session), sort_keys=True)
