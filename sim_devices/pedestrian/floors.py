"""The `floors` preset: the office floor (venues.py) on two floors joined by a staircase.

Floor 0 is the `floorplan` office (loop corridor, six rooms, store room, the hall with two pillars)
plus a stairwell south of the south corridor. Floor 1 differs: the three north rooms are one
open-plan office (doors at x 10.4, 17.7 and 25.0 m), and it has no hall (the hall is double height,
a void on floor 1); the south rooms, the store room and the stairwell are as on floor 0.

The staircase (stairwell x 12.6-24.1 m, y 1.4-4.05 m, open to the south corridor): a straight run
along +x at y = 2.2 m, two flights of STAIR_FLIGHT_M with a half landing of STAIR_LANDING_M between;
floor 0 at its west foot (x 14.4 m), floor 1 at its east head (x 22.32 m). The horizontal track
follows this footprint, the height rises linearly along each flight (riser = floor height / the
treads of both flights). Walkers reach the foot from the south corridor at x 13.4 m and leave the
head at x 23.3 m, both by a 90 deg turn: going up the walker heads east, coming down west.

Routes (walker i takes tour i mod 2) start at `stand-s1` on floor 0, go up, walk floor 1 (through
the open-plan office, which floor 0's room walls would not allow), come down, and finish on floor
0: two floor changes per walk. Stands: `stand-s1` (floor 0, the start), `stand-hall` (floor 0),
`stand-f1` (floor 1, the north corridor 1 m west of its NE corner, facing west).
"""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from hub.pedestrian.walkable import plan_area
from protocol.session import Stand
from sim_devices.pedestrian.venues import (BLOCK, CORRIDOR, DOOR_M, FLOOR_NODES, NORTH_DOORS_X, SOUTH_DOORS_X,
                                           SOUTH_ROOMS, STORE_ROOM, BODY_HALF_WIDTH_M, Layout, Route, _rings,
                                           _stand_after, floor_geometry, route_problem)

STAIRWELL = (12.6, 1.4, 24.1, 4.05)  # overlaps the corridor's outer edge (y 4.0): open to it
STAIR_Y_M = 2.2
STAIR_FOOT_X_M = 14.4
STAIR_FLIGHT_M = 3.36  # 12 treads of 0.28 m
STAIR_LANDING_M = 1.2
OPEN_OFFICE = (6.9, 12.0, 28.5, 17.1)  # floor 1: the north rooms' block without their partitions
OPEN_OFFICE_BEACON = (17.7, 14.6)  # floor 1's beacon in the open office (instead of the hall's)


def stair_nodes(height_m: float) -> dict[str, tuple[float, float, float]]:
    """The staircase's nodes: (x, y, height above floor 0)."""
    landing = STAIR_FOOT_X_M + STAIR_FLIGHT_M
    head = landing + STAIR_LANDING_M + STAIR_FLIGHT_M
    return {"c0": (13.4, 5.2, 0.0), "sw": (13.4, STAIR_Y_M, 0.0), "foot": (STAIR_FOOT_X_M, STAIR_Y_M, 0.0),
            "land1": (landing, STAIR_Y_M, height_m / 2), "land2": (landing + STAIR_LANDING_M, STAIR_Y_M, height_m / 2),
            "head": (head, STAIR_Y_M, height_m), "se": (23.3, STAIR_Y_M, height_m), "c1": (23.3, 5.2, height_m)}


UP = ("c0", "sw", "foot", "land1", "land2", "head", "se", "c1")
DOWN = tuple(reversed(UP))
FLOOR_1_NODES = {"o1": (10.4, 14.6), "o3": (25.0, 14.6), "NEw": (33.8, 18.8)}
# (node, floor) sequences; stair nodes carry their own height
FLOORS_TOURS = (
    (("s1", 0), *UP, ("SE", 1), ("NE", 1), ("dN3", 1), ("o3", 1), ("o1", 1), ("dN1", 1), ("NW", 1), ("SW", 1),
     *DOWN, ("SE", 0), ("E1", 0), ("h1", 0), ("h2", 0), ("h3", 0), ("h4", 0), ("h5", 0), ("h6", 0), ("E1", 0),
     ("NE", 0), ("NW", 0), ("SW", 0), ("s1", 0)),
    (("s1", 0), ("SE", 0), ("NE", 0), ("NW", 0), ("SW", 0), *UP, ("SW", 1), ("NW", 1), ("dN1", 1), ("o1", 1),
     ("o3", 1), ("dN3", 1), ("NE", 1), ("SE", 1), *DOWN, ("SE", 0), ("NE", 0), ("NW", 0), ("SW", 0), ("s1", 0)),
)


def _box(rect: tuple[float, float, float, float]) -> BaseGeometry:
    return shapely.box(*rect)


def floor_one_geometry() -> BaseGeometry:
    """Floor 1's walkable area: the loop, the open-plan office, the south rooms, the store room."""
    pieces = [_box(CORRIDOR).difference(_box(BLOCK)), _box(OPEN_OFFICE), _box(STORE_ROOM)]
    for middle in NORTH_DOORS_X:
        pieces.append(_box((middle - DOOR_M / 2, OPEN_OFFICE[3] - 0.01, middle + DOOR_M / 2, BLOCK[3] + 0.01)))
    for (x0, y0, x1, y1), middle in zip(SOUTH_ROOMS, SOUTH_DOORS_X):
        pieces.append(_box((x0, y0, x1, y1)))
        pieces.append(_box((middle - DOOR_M / 2, BLOCK[1] - 0.01, middle + DOOR_M / 2, y0 + 0.01)))
    return shapely.normalize(shapely.union_all(pieces))


def floor_geometries() -> dict[int, BaseGeometry]:
    stair = _box(STAIRWELL)
    return {0: shapely.normalize(shapely.union_all([floor_geometry(), stair])),
            1: shapely.normalize(shapely.union_all([floor_one_geometry(), stair]))}


def _route(tour: tuple, height_m: float) -> Route:
    stairs = stair_nodes(height_m)
    names, xy, z = [], [], []
    for item in tour:
        if isinstance(item, str):
            x, y, level = stairs[item]
            names.append(item)
        else:
            name, floor = item
            x, y = FLOOR_NODES.get(name) or FLOOR_1_NODES[name]
            level = floor * height_m
            names.append(f"{name}@{floor}")
        xy.append((x, y))
        z.append(level)
    return Route(tuple(names), tuple(xy), tuple(z))


def floors_layout(offset_m: float, people: int, height_m: float) -> Layout:
    geometries = floor_geometries()
    plans = tuple((floor, tuple(_rings(part) for part in shapely.get_parts(area)))
                  for floor, area in sorted(geometries.items()))
    routes = tuple(_route(FLOORS_TOURS[i % len(FLOORS_TOURS)], height_m) for i in range(people))
    tour = _route(FLOORS_TOURS[0], height_m)
    start = _stand_after(tour, 0, "stand-s1", 0.0)
    hall = _stand_after(tour, tour.nodes.index("h1@0"), "stand-hall", offset_m)
    upper = _stand_after(tour, tour.nodes.index("NE@1"), "stand-f1", offset_m)
    stands = (start, hall, Stand(upper.id, upper.x_m, upper.y_m, floor=1, heading_deg=upper.heading_deg))
    places = [(0, x, y) for x, y in ((11.0, 5.2), (28.6, 5.2), (34.8, 12.0), (25.0, 18.8), (10.4, 18.8),
                                     (5.2, 12.0), (41.0, 12.0), (18.4, 2.6))]
    places += [(1, x, y) for x, y in ((11.0, 5.2), (28.6, 5.2), (34.8, 12.0), (25.0, 18.8), (10.4, 18.8),
                                      (5.2, 12.0), OPEN_OFFICE_BEACON, (18.4, 2.6))]
    min_x, min_y, max_x, max_y = shapely.union_all(list(geometries.values())).bounds
    return Layout("floors", "pdr-office-2f", (), plans[0][1], stands, routes, (max_x - min_x, max_y - min_y),
                  floor_plans=plans, beacon_places=tuple(places), floor_height_m=height_m)


def route_problem_by_floor(route: Route, result: Layout) -> str:
    """route_problem for each segment on its own floor's plan (a segment whose ends are not both on one
    floor, a stair segment, must lie in the stairwell)."""
    areas = {floor: plan_area(plan) for floor, plan in result.floor_plans}
    stair = _box(STAIRWELL)
    height = result.floor_height_m
    for i in range(len(route.xy_m) - 1):
        z0, z1 = route.z_m[i], route.z_m[i + 1]
        segment = Route(route.nodes[i:i + 2], route.xy_m[i:i + 2])
        level = z0 / height
        on_floor = z0 == z1 and abs(level - round(level)) < 1e-9
        area = areas[int(round(level))] if on_floor else stair
        problem = route_problem(segment, area)
        if problem:
            return problem
        if not on_floor and not stair.covers(shapely.LineString(segment.xy_m).buffer(BODY_HALF_WIDTH_M)):
            return f"stair segment {segment.nodes[0]}-{segment.nodes[1]} leaves the stairwell"
    whole = route_problem(Route(route.nodes, route.xy_m), shapely.union_all(list(areas.values())))
    return whole if "turns back" in whole else ""


def height_floor(height_m: np.ndarray, floor_height_m: float) -> np.ndarray:
    """The floor number (int64) at heights above floor 0: the nearer floor, so on a stair the floor
    being left until half-way; the half landing itself counts as the upper floor."""
    return np.floor(np.asarray(height_m, dtype=np.float64) / floor_height_m + 0.5).astype(np.int64)
