"""The two built-in buildings: the paper's 12-point corridor map and a synthetic office floor.

A `Layout` is what a preset gives the simulator: the venue's map points or floor plan, its
calibration stands, and one route per walker, each a polyline of named nodes. Every route is
checked against the walkable area with shapely (a body-wide strip along it must lie inside);
`walkable_geometry` is that area.

- `paper`: the map of the paper's table 5 (building 2, floor 1 of Chiba Institute of Technology;
  coordinates in cm, here in m) and its route I-J-G-H-L-K-E-F-B-C-G-H-D-A-E-F-I (sec. 4.2; 280 m,
  15 corners of 90 deg; the paper counts 7 left and 7 right, the table's geometry gives 8 left and
  7 right). Corridors 2 m wide (hub.pedestrian.walkable's corridors for a map without a plan).
- `floorplan`: a 46 m x 24 m floor drawn here (no file is read): a loop corridor 2.4 m wide around
  a block of six rooms with 1 m doors (and a walled-off store room), and a 10 m x 20 m hall with
  two pillars at its east end. The walkable area is one polygon with holes (the block's walls, the
  pillars) plus the store room; three tours visit rooms and the hall. No map points: the plan is
  the map.
- `floors`: the office on two floors joined by a straight staircase with a half landing
  (sim_devices/pedestrian/floors.py); each floor has its own plan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import shapely
from shapely.geometry.base import BaseGeometry

from hub.pedestrian.walkable import WalkableSettings, corridor_graph, corridors_geometry, plan_area

from protocol.errors import ConfigError
from protocol.session import MapPoint, Stand

PRESETS = ("paper", "floorplan", "floors")
BODY_HALF_WIDTH_M = 0.25  # half a shoulder width: the strip along a route that must be walkable

# The paper's table 5: point, x cm, y cm, unit vectors of the corridors leaving it.
PAPER_TABLE_5 = (
    ("A", 0.0, 0.0, ((1, 0), (0, 1))),
    ("B", 330.0, 0.0, ((1, 0), (-1, 0), (0, 1))),
    ("C", 1270.5, 0.0, ((1, 0), (-1, 0), (0, 1))),
    ("D", 3217.5, 0.0, ((-1, 0), (0, 1))),
    ("E", 0.0, 2351.8, ((1, 0), (0, 1), (0, -1))),
    ("F", 330.0, 2351.8, ((1, 0), (-1, 0), (0, 1), (0, -1))),
    ("G", 1270.5, 2351.8, ((1, 0), (-1, 0), (0, 1), (0, -1))),
    ("H", 3217.5, 2351.8, ((1, 0), (-1, 0), (0, 1), (0, -1))),
    ("I", 330.0, 3355.0, ((1, 0), (0, -1))),
    ("J", 1270.5, 3355.0, ((-1, 0), (0, -1))),
    ("K", 0.0, 4207.5, ((1, 0), (0, -1))),
    ("L", 3217.5, 4207.5, ((-1, 0), (0, -1))),
)
PAPER_ROUTE = tuple("IJGHLKEFBCGHDAEFI")  # sec. 4.2
PAPER_STAND_NODES = (9, 13)  # extra stands where the route leaves C (to G) and A (to E): mid-walk re-calibration
# A walker stops at a stand where its route first passes the stand's place facing the stand's way
# (timeline.stand_stops); a route that never does so skips that stand.


@dataclass(frozen=True)
class Route:
    """A walker's planned path: node names and their (x, y) in metres; consecutive nodes differ."""

    nodes: tuple[str, ...]
    xy_m: tuple[tuple[float, float], ...]
    z_m: tuple[float, ...] = ()  # floor height under each node (m above floor 0); empty: all on floor 0

    def length_m(self) -> float:
        return sum(math.dist(a, b) for a, b in zip(self.xy_m, self.xy_m[1:]))


@dataclass(frozen=True)
class Layout:
    preset: str
    venue_name: str
    map_points: tuple[MapPoint, ...]
    floor_plan: tuple[list[list[list[float]]], ...]  # polygons: [outer ring, hole, ...]
    stands: tuple[Stand, ...]
    routes: tuple[Route, ...]
    size_m: tuple[float, float]  # bounding box of the walkable area (venue court length, width)
    floor_plans: tuple[tuple[int, tuple[list[list[list[float]]], ...]], ...] = ()  # per floor, when they differ
    beacon_places: tuple[tuple[int, float, float], ...] = ()  # (floor, x, y) where beacons may go, spread first
    floor_height_m: float = 0.0  # floor-to-floor height (0: one floor)


def _direction_deg(x: float, y: float) -> float:
    return math.degrees(math.atan2(y, x))


def paper_points() -> tuple[MapPoint, ...]:
    """The paper's table 5 in metres, directions in degrees counter-clockwise from +x."""
    return tuple(MapPoint(name, x / 100.0, y / 100.0, tuple(_direction_deg(dx, dy) for dx, dy in vectors))
                 for name, x, y, vectors in PAPER_TABLE_5)


def _stand_after(route: Route, index: int, stand_id: str, offset_m: float) -> Stand:
    """A stand `offset_m` along the route's segment that leaves node `index`, facing along it."""
    (x0, y0), (x1, y1) = route.xy_m[index], route.xy_m[index + 1]
    length = math.dist((x0, y0), (x1, y1))
    share = min(offset_m, 0.4 * length) / length
    return Stand(stand_id, round(x0 + share * (x1 - x0), 2), round(y0 + share * (y1 - y0), 2),
                 heading_deg=round(_direction_deg(x1 - x0, y1 - y0), 2))


def _paper(offset_m: float, people: int) -> Layout:
    points = paper_points()
    where = {p.id: (p.x_m, p.y_m) for p in points}
    route = Route(PAPER_ROUTE, tuple(where[n] for n in PAPER_ROUTE))
    stands = [_stand_after(route, 0, "stand-I", 0.0)]
    stands += [_stand_after(route, i, f"stand-{PAPER_ROUTE[i]}", offset_m) for i in PAPER_STAND_NODES]
    geometry = area_of((), points)
    min_x, min_y, max_x, max_y = geometry.bounds
    return Layout("paper", "pdr-paper", points, (), tuple(stands), (route,) * people,
                  (max_x - min_x, max_y - min_y))


# ---------------------------------------------------------------------------------------------
# The synthetic office floor (metres). Walkable pieces are rectangles (x0, y0, x1, y1); their union
# has holes where walls enclose non-walkable space.

CORRIDOR = (4.0, 4.0, 36.0, 20.0)  # outer edge of the loop corridor
BLOCK = (6.4, 6.4, 33.6, 17.6)  # the block inside the loop (2.4 m corridor)
HALL = (36.0, 2.0, 46.0, 22.0)
PILLARS = ((40.6, 7.6, 41.4, 8.4), (40.6, 15.6, 41.4, 16.4))
NORTH_ROOMS = ((6.9, 12.0, 13.9, 17.1), (14.2, 12.0, 21.2, 17.1), (21.5, 12.0, 28.5, 17.1))
NORTH_DOORS_X = (10.4, 17.7, 25.0)  # door centres, opening onto the north corridor
STORE_ROOM = (28.8, 12.0, 33.1, 17.1)
SOUTH_ROOMS = ((6.9, 6.9, 15.0, 11.7), (15.3, 6.9, 24.0, 11.7), (24.3, 6.9, 33.1, 11.7))
SOUTH_DOORS_X = (11.0, 19.6, 28.6)
DOOR_M = 1.0
WALL_M = 0.5  # corridor-side wall of a room

FLOOR_NODES: dict[str, tuple[float, float]] = {
    # loop corridor centre line (corners and door fronts)
    "SW": (5.2, 5.2), "SE": (34.8, 5.2), "NE": (34.8, 18.8), "NW": (5.2, 18.8),
    "s1": (8.0, 5.2), "dS1": (11.0, 5.2), "dS2": (19.6, 5.2), "dS3": (28.6, 5.2),
    "dN1": (10.4, 18.8), "dN2": (17.7, 18.8), "dN3": (25.0, 18.8), "E1": (34.8, 12.0),
    # inside rooms
    "S1a": (11.0, 9.3), "S1b": (13.5, 9.3), "S1c": (13.5, 8.0), "S1d": (9.0, 8.0), "S1e": (9.0, 9.3),
    "N2a": (17.7, 14.6), "N2b": (19.8, 14.6), "N2c": (19.8, 13.2), "N2d": (15.6, 13.2), "N2e": (15.6, 14.6),
    "S3a": (28.6, 9.3), "S3b": (31.5, 9.3), "S3c": (31.5, 8.0), "S3d": (26.0, 8.0), "S3e": (26.0, 9.3),
    # hall, around the pillars
    "h1": (38.5, 12.0), "h2": (38.5, 4.5), "h3": (43.5, 4.5), "h4": (43.5, 19.5), "h5": (38.5, 19.5),
    "h6": (38.5, 14.0),
}
FLOOR_TOURS = (
    ("s1", "dS1", "S1a", "S1b", "S1c", "S1d", "S1e", "S1a", "dS1", "SE", "E1", "h1", "h2", "h3", "h4", "h5", "h6",
     "E1", "NE", "dN2", "N2a", "N2b", "N2c", "N2d", "N2e", "N2a", "dN2", "NW", "SW", "s1"),
    ("s1", "SE", "NE", "dN2", "N2a", "N2b", "N2c", "N2d", "N2e", "N2a", "dN2", "NW", "SW", "s1", "dS3", "S3a", "S3b", "S3c", "S3d", "S3e", "S3a", "dS3", "SE", "E1", "h1", "h2", "h3", "h4", "h5", "h6", "E1",
     "NE", "NW", "SW", "s1"),
    ("s1", "dS3", "S3a", "S3b", "S3c", "S3d", "S3e", "S3a", "dS3", "SE", "NE", "dN3", "dN1", "NW", "SW", "dS1",
     "S1a", "S1b", "S1c", "S1d", "S1e", "S1a", "dS1", "s1"),
)
FLOOR_STANDS = (("stand-s1", "s1", 0.0), ("stand-hall", "h1", 1.0), ("stand-north", "NW", 1.0))


def floor_geometry() -> BaseGeometry:
    """The office floor's walkable area: one polygon with holes."""
    def box(rect: tuple[float, float, float, float]) -> BaseGeometry:
        return shapely.box(*rect)  # type: ignore[no-any-return]

    loop = box(CORRIDOR).difference(box(BLOCK))
    pieces = [loop, box(HALL).difference(shapely.union_all([box(p) for p in PILLARS]))]
    for (x0, y0, x1, y1), middle in zip(NORTH_ROOMS, NORTH_DOORS_X):
        pieces.append(box((x0, y0, x1, y1)))
        pieces.append(box((middle - DOOR_M / 2, y1 - 0.01, middle + DOOR_M / 2, BLOCK[3] + 0.01)))
    for (x0, y0, x1, y1), middle in zip(SOUTH_ROOMS, SOUTH_DOORS_X):
        pieces.append(box((x0, y0, x1, y1)))
        pieces.append(box((middle - DOOR_M / 2, BLOCK[1] - 0.01, middle + DOOR_M / 2, y0 + 0.01)))
    pieces.append(box(STORE_ROOM))  # a store room without a door: walled off, never reached
    area = shapely.union_all(pieces)
    return shapely.normalize(area)


def _rings(polygon: shapely.Polygon) -> list[list[list[float]]]:
    rings = [polygon.exterior, *polygon.interiors]
    return [[[round(x, 3), round(y, 3)] for x, y in ring.coords[:-1]] for ring in rings]


def _floorplan(offset_m: float, people: int) -> Layout:
    area = floor_geometry()
    parts = list(shapely.get_parts(area))
    plan = tuple(_rings(part) for part in parts)
    routes = tuple(Route(FLOOR_TOURS[i % len(FLOOR_TOURS)], tuple(FLOOR_NODES[n] for n in FLOOR_TOURS[i % len(FLOOR_TOURS)]))
                   for i in range(people))
    tour = Route(FLOOR_TOURS[0], tuple(FLOOR_NODES[n] for n in FLOOR_TOURS[0]))
    stands = [_stand_after(tour, tour.nodes.index(node), stand_id, share * offset_m)
              for stand_id, node, share in FLOOR_STANDS]
    min_x, min_y, max_x, max_y = area.bounds
    # No map points: the floor plan is the map (the paper's snap has no junction table here).
    return Layout("floorplan", "pdr-office", (), plan, tuple(stands), routes,
                  (max_x - min_x, max_y - min_y))


# Beacon places (ceiling-mounted over the corridor centre line), spread first: paper = its junctions.
PAPER_BEACON_POINTS = ("I", "G", "H", "C", "A", "K", "L", "D")
FLOOR_BEACON_PLACES = ((11.0, 5.2), (28.6, 5.2), (34.8, 12.0), (25.0, 18.8), (10.4, 18.8), (5.2, 12.0),
                       (41.0, 12.0), (43.5, 19.5))


def layout(preset: str, people: int, stand_offset_m: float = 1.0, floor_height_m: float = 4.0) -> Layout:
    """The named preset's layout for `people` walkers; ConfigError for an unknown preset or a route
    that leaves the walkable area (of its floor; a stair segment: of the stairwell)."""
    if preset not in PRESETS:
        raise ConfigError(f"preset: {preset!r} is not one of {', '.join(PRESETS)}")
    if preset == "floors":
        from sim_devices.pedestrian.floors import floors_layout, route_problem_by_floor

        result = floors_layout(stand_offset_m, people, floor_height_m)
        for number, route in enumerate(result.routes):
            problem = route_problem_by_floor(route, result)
            if problem:
                raise ConfigError(f"preset {preset}: route {number + 1} {problem}")
        return result
    result = _paper(stand_offset_m, people) if preset == "paper" else _floorplan(stand_offset_m, people)
    area = walkable_geometry(result)
    for number, route in enumerate(result.routes):
        problem = route_problem(route, area)
        if problem:
            raise ConfigError(f"preset {preset}: route {number + 1} {problem}")
    return result


def beacon_places(result: Layout) -> tuple[tuple[int, float, float], ...]:
    """(floor, x, y) where beacons may go, spread first (the first N are used)."""
    if result.beacon_places:
        return result.beacon_places
    if result.map_points:
        where = {p.id: (p.x_m, p.y_m) for p in result.map_points}
        return tuple((0, *where[name]) for name in PAPER_BEACON_POINTS)
    return tuple((0, x, y) for x, y in FLOOR_BEACON_PLACES)


def walkable_geometry(result: Layout) -> BaseGeometry:
    """The walkable area; of a building with several floors, the union of its floors (a 2-D check
    only; `floors.route_problem_by_floor` checks each floor)."""
    if result.floor_plans:
        return shapely.union_all([plan_area(plan) for _, plan in result.floor_plans])
    return area_of(result.floor_plan, result.map_points)


def area_of(floor_plan: tuple[list[list[list[float]]], ...], map_points: tuple[MapPoint, ...]) -> BaseGeometry:
    """The walkable area by the hub's one definition (hub/pedestrian/walkable.py): the plan's own
    area, without the hub's tolerance for drawn lines (a simulated walker keeps out of the shops),
    or the corridors the hub draws between the map points."""
    if floor_plan:
        return plan_area(floor_plan)
    settings = WalkableSettings()
    corridors, _ = corridor_graph(map_points, settings.lateral_tolerance_m)
    return corridors_geometry(corridors, settings.corridor_half_width_m)


def route_problem(route: Route, area: BaseGeometry) -> str:
    """Why the route is not walkable (empty when it is): a body-wide strip along each segment must lie
    inside the area, consecutive nodes must differ, and no corner may turn back over 170 deg."""
    for i, (start, end) in enumerate(zip(route.xy_m, route.xy_m[1:])):
        if math.dist(start, end) < 0.5:
            raise ConfigError(f"route segment {route.nodes[i]}-{route.nodes[i + 1]} is shorter than 0.5 m")
        strip = shapely.LineString([start, end]).buffer(BODY_HALF_WIDTH_M)
        if not area.covers(strip):
            return f"segment {route.nodes[i]}-{route.nodes[i + 1]} crosses a wall"
    for i in range(1, len(route.xy_m) - 1):
        (ax, ay), (bx, by), (cx, cy) = route.xy_m[i - 1], route.xy_m[i], route.xy_m[i + 1]
        turn = math.degrees(math.remainder(math.atan2(cy - by, cx - bx) - math.atan2(by - ay, bx - ax), 2 * math.pi))
        if abs(turn) > 170.0:
            return f"turns back {turn:.0f} deg at {route.nodes[i]}"
    return ""
