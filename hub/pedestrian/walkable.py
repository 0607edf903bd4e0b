"""Where a pedestrian can walk: the venue's floor plan, or corridors drawn between its map points.

This is the one definition of walkable: the hub's particle filter, `reckon eval`'s check of the
truth positions, the ILC importer's report and the simulator's route check all go through it
(`WalkableArea.from_venue`, `WalkableArea.from_floor_plan`, `floor_plan_geometry`).

Two sources (protocol/session.py `Venue`):
- `floor_plan`: polygons in metres, each [outer ring, hole, ...]. Walkable is the union of the
  outer rings less the union of every hole (set semantics, each ring repaired on its own). Not
  shapely's `make_valid` of the whole polygon: that reads the rings by parity, so a shop whose edge
  lies along the outline (ILC site 1: 11-39 shops per floor cross it) vanishes, or is read inside
  out: 5,300-9,400 m^2 of shops per floor came out walkable (F2's east wing: a 6,200 m^2 store
  sharing 150 m of edge with its outline, walkable entire), and a floor whose rings pair up the
  other way loses its corridors.
  Then the plan tolerance (`plan_tolerance_m`, 0.5 m): a drawn line is not a wall to the
  centimetre. Storefronts are open and drawn about half a metre either way, and a surveyor
  stands in a shop's doorway (site 1: truth waypoints 0.03 and 0.16 m inside shop polygons), so
  every obstacle wider than twice the tolerance gives up a strip of that width; thinner ones
  (walls, pillars, kiosks under 1 m) are kept whole, so no partition disappears. Gaps narrower
  than `plan_gap_m` between two obstacles (shops drawn a few cm apart) are closed first, so the
  strip does not open a passage through a block of shops.
- `map_points` only (the indoor-navigation paper's map, its tables 4-5): a corridor leaves point P
  in each of its directions and ends at the nearest point Q lying along that direction (within
  `lateral_tolerance_m` of the ray); the corridor is the segment PQ widened to
  `corridor_half_width_m` each side, with square ends so that junctions are filled. The width is
  the model; no tolerance is added.

Queries for many particles at once go through an occupancy grid (`cell_m`). A cell is walkable
only when its centre lies deeper than `clearance_m` inside the area, with clearance = half the
cell diagonal + half the sample spacing along a move: then every point where a move crosses a wall
is within reach of a sampled cell that is marked blocked, so no wall, however thin, is jumped.
The price is that the strip of about 1.2 cells (0.12 m at 0.1 m cells) along every wall counts
as wall; on a floor plan the tolerance is wider than that strip, so every point of the plan's
own walkable area is walkable on the grid (a thin wall's 0.12 m excepted). Measured on the ILC plan:
this grid check costs 0.12 ms for 500 moves of 0.7 m against 2.2 ms for shapely's vectorised
`covered_by` on the same moves, and its cost does not grow with the number of holes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from protocol.session import MapPoint, Venue


PLAN_TOLERANCE_M = 0.5  # see the module docstring: how far a true position may lie across a drawn line
RASTER_BAND_ROWS = 32  # rows rasterised against one clipped piece of the area (see _rasterise)
ROUND_SEGMENTS = 4  # segments per quarter circle of a buffer's rounded corners (shapely: 8); a 0.5 m arc, 1 cm off
PLAN_GAP_M = 0.45  # slots between obstacles narrower than this are drawing gaps (a door is 0.7 m or more)


@dataclass(frozen=True)
class WalkableSettings:
    cell_m: float = 0.1  # grid resolution; 0.2 m halves the grid's memory four times, still finer than a step
    corridor_half_width_m: float = 1.0  # map points only: a 2 m corridor (a university corridor is 1.8-2.5 m)
    lateral_tolerance_m: float = 0.5  # map points only: how far off a direction's ray the next point may lie
    max_samples_per_check: int = 64  # bounds the scratch memory of one move check (longer moves loop)
    # Floor plans only. 0 gives the plan's own area (then the grid's 0.12 m strip along every
    # wall is not walkable); more than 0.2 m covers that strip, 0.5 m the site 1 waypoints in shops.
    plan_tolerance_m: float = PLAN_TOLERANCE_M
    plan_gap_m: float = PLAN_GAP_M


@dataclass(frozen=True)
class Corridor:
    """A straight corridor between two map points (metres, venue frame)."""

    start_id: str
    end_id: str
    start_x_m: float
    start_y_m: float
    end_x_m: float
    end_y_m: float


def corridor_graph(points: tuple[MapPoint, ...], lateral_tolerance_m: float = 0.5
                   ) -> tuple[tuple[Corridor, ...], tuple[tuple[str, float], ...]]:
    """The paper's graph: for each point and direction, the nearest point ahead along it.

    Returns the corridors (each pair once) and the dangling directions (point id, direction deg)
    that reach no point, e.g. H's [1, 0] in the paper's table 5 (nothing lies east of H).
    Only points on the same floor are joined.
    """
    corridors: dict[frozenset[str], Corridor] = {}
    dangling = []
    for point in points:
        for direction_deg in point.directions_deg:
            unit_x, unit_y = math.cos(math.radians(direction_deg)), math.sin(math.radians(direction_deg))
            best: MapPoint | None = None
            best_ahead_m = math.inf
            for other in points:
                if other is point or other.floor != point.floor:
                    continue
                offset_x, offset_y = other.x_m - point.x_m, other.y_m - point.y_m
                ahead_m = offset_x * unit_x + offset_y * unit_y
                lateral_m = abs(-offset_x * unit_y + offset_y * unit_x)
                if ahead_m > 0.0 and lateral_m <= lateral_tolerance_m and ahead_m < best_ahead_m:
                    best, best_ahead_m = other, ahead_m
            if best is None:
                dangling.append((point.id, direction_deg))
                continue
            key = frozenset((point.id, best.id))
            if key not in corridors:
                corridors[key] = Corridor(point.id, best.id, point.x_m, point.y_m, best.x_m, best.y_m)
    return tuple(corridors.values()), tuple(dangling)


def corridors_geometry(corridors: tuple[Corridor, ...], half_width_m: float) -> BaseGeometry:
    """The union of the corridors, each widened by `half_width_m` with square ends (fills corners)."""
    lines = [shapely.LineString([(c.start_x_m, c.start_y_m), (c.end_x_m, c.end_y_m)]) for c in corridors]
    return shapely.union_all([line.buffer(half_width_m, cap_style="square") for line in lines])


def plan_area(floor_plan: tuple[list[list[list[float]]], ...] | list) -> BaseGeometry:
    """A floor plan's own walkable area: the union of its outer rings less the union of all its
    holes (set semantics, see the module docstring). A self-intersecting ring from a hand-drawn
    plan is repaired on its own (shapely.make_valid) rather than rejected; rings of fewer than
    3 points are skipped."""
    def areas(rings: list) -> BaseGeometry:
        shapes = [shapely.make_valid(shapely.Polygon(ring)) for ring in rings if len(ring) >= 3]
        # make_valid may split a ring into polygons plus stray lines; only areas count
        return shapely.union_all([part for shape in shapes for part in shapely.get_parts(shape)
                                  if isinstance(part, (shapely.Polygon, shapely.MultiPolygon))])

    outlines = areas([rings[0] for rings in floor_plan if rings])
    holes = areas([ring for rings in floor_plan for ring in rings[1:]])
    return outlines.difference(holes) if not holes.is_empty else outlines


def with_tolerance(area: BaseGeometry, tolerance_m: float, gap_m: float = PLAN_GAP_M) -> BaseGeometry:
    """`area` with every obstacle (what is not walkable, the outside included) wider than
    2 x `tolerance_m` pulled back by `tolerance_m`, thinner obstacles kept whole, after closing
    the gaps between obstacles narrower than `gap_m`. 0 gives `area` unchanged."""
    if tolerance_m <= 0.0 or area.is_empty:
        return area
    min_x, min_y, max_x, max_y = area.bounds
    frame = shapely.box(min_x, min_y, max_x, max_y).buffer(2.0 * tolerance_m + gap_m + 1.0, join_style="mitre")
    obstacles = frame.difference(area)
    if gap_m > 0.0:  # closing: a slot between two shops drawn apart is filled, wider passages are kept
        obstacles = obstacles.buffer(gap_m / 2.0, join_style="mitre").buffer(-gap_m / 2.0, join_style="mitre")
    cores = obstacles.buffer(-tolerance_m, quad_segs=ROUND_SEGMENTS)  # what is left of the wide obstacles
    thin = obstacles.difference(cores.buffer(tolerance_m, quad_segs=ROUND_SEGMENTS))  # walls, pillars, corner tips
    walkable = frame.difference(shapely.union_all([cores, thin]))
    return walkable.intersection(area.buffer(tolerance_m, quad_segs=ROUND_SEGMENTS))  # the frame's own margin is not walkable


def floor_plan_geometry(floor_plan: tuple[list[list[list[float]]], ...] | list,
                        tolerance_m: float = PLAN_TOLERANCE_M, gap_m: float = PLAN_GAP_M) -> BaseGeometry:
    """The walkable area of a floor plan (polygons [outer ring, hole, ...] in metres): its own area
    (`plan_area`) with the plan tolerance (`with_tolerance`). This is what the hub matches on."""
    return with_tolerance(plan_area(floor_plan), tolerance_m, gap_m)


class WalkableArea:
    """The walkable area as exact geometry (`geometry`) and as a grid for fast particle queries."""

    def __init__(self, geometry: BaseGeometry, cell_m: float = 0.1, max_samples_per_check: int = 64) -> None:
        if geometry.is_empty:
            raise ValueError("walkable area is empty (no floor plan polygons and no corridors)")
        if not 0.01 <= cell_m <= 1.0:
            raise ValueError(f"cell_m {cell_m} is outside [0.01, 1.0]")
        self.geometry = geometry
        self.cell_m = cell_m
        self.sample_spacing_m = cell_m  # see the module docstring: clearance depends on it
        self.clearance_m = 1.01 * (cell_m * math.sqrt(2.0) / 2.0 + self.sample_spacing_m / 2.0)  # 1 % for rounding
        self.max_samples_per_check = max(2, max_samples_per_check)
        min_x, min_y, max_x, max_y = geometry.bounds
        self.origin_x_m, self.origin_y_m = min_x, min_y
        self.columns = int(math.ceil((max_x - min_x) / cell_m)) + 1
        self.rows = int(math.ceil((max_y - min_y) / cell_m)) + 1
        self.cells_geometry = geometry.buffer(-self.clearance_m, quad_segs=ROUND_SEGMENTS)  # where a walkable cell's centre may lie
        self.grid = self._rasterise(self.cells_geometry)

    @classmethod
    def from_venue(cls, venue: Venue, settings: WalkableSettings = WalkableSettings(), floor: int = 0
                   ) -> "WalkableArea":
        """From the plan of `floor` when the venue has one (`Venue.plan_of`), else from corridors
        between its map points on `floor`; ValueError when it has neither."""
        plan = venue.plan_of(floor)
        if plan:
            return cls.from_floor_plan(plan, settings)
        else:
            points = tuple(p for p in venue.map_points if p.floor == floor)
            corridors, _ = corridor_graph(points, settings.lateral_tolerance_m)
            if not corridors:
                raise ValueError(f"venue {venue.name!r} has no floor plan and no corridors on floor {floor}")
            geometry = corridors_geometry(corridors, settings.corridor_half_width_m)
        return cls(geometry, settings.cell_m, settings.max_samples_per_check)

    @classmethod
    def from_floor_plan(cls, floor_plan: tuple[list[list[list[float]]], ...] | list,
                        settings: WalkableSettings = WalkableSettings()) -> "WalkableArea":
        """From floor plan polygons ([outer ring, hole, ...] in metres), as `from_venue` reads them;
        ValueError when they enclose no area."""
        return cls(floor_plan_geometry(floor_plan, settings.plan_tolerance_m, settings.plan_gap_m),
                   settings.cell_m, settings.max_samples_per_check)

    def _rasterise(self, eroded: BaseGeometry) -> np.ndarray:
        """Cells whose centre lies in `eroded`, one horizontal scan line per row: intersecting a
        line with the area gives the walkable runs directly (ILC plan at 0.1 m: 0.27 s against
        0.73 s for testing every cell centre with shapely.contains_xy, same cells). The lines go
        in bands of rows, each against the area clipped to its band: a plan with the tolerance has
        10-50 times the vertices, and a line against all of them took 18 s on site 1 B1 (0.8 s in bands)."""
        grid = np.zeros((self.rows, self.columns), dtype=bool)
        if eroded.is_empty:
            return grid
        centres_y = self.origin_y_m + (np.arange(self.rows) + 0.5) * self.cell_m
        left_m, right_m = self.origin_x_m - self.cell_m, self.origin_x_m + (self.columns + 1) * self.cell_m
        lines = shapely.linestrings(np.stack([np.full(self.rows, left_m), centres_y,
                                              np.full(self.rows, right_m), centres_y], axis=1).reshape(-1, 2, 2))
        runs = np.empty(self.rows, dtype=object)
        for first in range(0, self.rows, RASTER_BAND_ROWS):
            last = min(first + RASTER_BAND_ROWS, self.rows)
            band = shapely.clip_by_rect(eroded, left_m, centres_y[first] - self.cell_m / 4.0, right_m,
                                        centres_y[last - 1] + self.cell_m / 4.0)
            runs[first:last] = shapely.intersection(lines[first:last], band)
        for row, run in enumerate(runs):
            for part in shapely.get_parts(run):
                if not isinstance(part, shapely.LineString) or part.is_empty:
                    continue  # a line touching a vertex gives a point: no cell centre to mark
                xs = shapely.get_coordinates(part)[:, 0]
                first = int(math.ceil((xs.min() - self.origin_x_m) / self.cell_m - 0.5))
                last = int(math.floor((xs.max() - self.origin_x_m) / self.cell_m - 0.5))
                grid[row, max(first, 0):min(last, self.columns - 1) + 1] = True
        return grid

    def is_walkable(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Per point, True when its grid cell is walkable; points off the grid are not."""
        column = np.floor((np.asarray(x_m) - self.origin_x_m) / self.cell_m)
        row = np.floor((np.asarray(y_m) - self.origin_y_m) / self.cell_m)
        inside = (column >= 0) & (column < self.columns) & (row >= 0) & (row < self.rows)
        result = np.zeros(np.shape(column), dtype=bool)
        result[inside] = self.grid[row[inside].astype(np.intp), column[inside].astype(np.intp)]
        return result

    def move_allowed(self, start_x_m: np.ndarray, start_y_m: np.ndarray, end_x_m: np.ndarray,
                     end_y_m: np.ndarray) -> np.ndarray:
        """Per move, True when the straight segment from start to end stays walkable (no wall
        crossed, never outside). Work is O(moves x length / cell); scratch memory at most
        moves x max_samples_per_check, longer moves are checked in pieces."""
        start_x_m, start_y_m = np.asarray(start_x_m, dtype=float), np.asarray(start_y_m, dtype=float)
        delta_x_m, delta_y_m = np.asarray(end_x_m) - start_x_m, np.asarray(end_y_m) - start_y_m
        longest_m = float(np.max(np.hypot(delta_x_m, delta_y_m), initial=0.0))
        pieces = max(1, int(math.ceil(longest_m / self.sample_spacing_m)))  # sample intervals in all
        allowed = self.is_walkable(start_x_m, start_y_m)
        per_check = self.max_samples_per_check - 1
        for first in range(0, pieces, per_check):
            fractions = np.arange(first + 1, min(first + per_check, pieces) + 1) / pieces
            xs = start_x_m[:, None] + delta_x_m[:, None] * fractions
            ys = start_y_m[:, None] + delta_y_m[:, None] * fractions
            allowed &= self.is_walkable(xs, ys).all(axis=1)
        return allowed

    def nearest_walkable(self, x_m: float, y_m: float, search_m: float) -> tuple[float, float] | None:
        """The centre of the walkable cell nearest (x, y) within `search_m`, or None."""
        reach = int(math.ceil(search_m / self.cell_m))
        column = int(math.floor((x_m - self.origin_x_m) / self.cell_m))
        row = int(math.floor((y_m - self.origin_y_m) / self.cell_m))
        row_low, row_high = max(row - reach, 0), min(row + reach + 1, self.rows)
        column_low, column_high = max(column - reach, 0), min(column + reach + 1, self.columns)
        if row_low >= row_high or column_low >= column_high:
            return None
        rows, columns = np.nonzero(self.grid[row_low:row_high, column_low:column_high])
        if rows.size == 0:
            return None
        centres_x = self.origin_x_m + (columns + column_low + 0.5) * self.cell_m
        centres_y = self.origin_y_m + (rows + row_low + 0.5) * self.cell_m
        distances = np.hypot(centres_x - x_m, centres_y - y_m)
        best = int(np.argmin(distances))
        if distances[best] > search_m:
            return None
        return float(centres_x[best]), float(centres_y[best])

    def outside_by_m(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Per point, 0 where it is walkable, else how far it lies from the walkable cells (m): for
        reporting truth positions or a fix that the map does not allow (exact distance to the area
        the cells cover; a point next to a walkable cell, one cell at most)."""
        x_m, y_m = np.atleast_1d(np.asarray(x_m, dtype=float)), np.atleast_1d(np.asarray(y_m, dtype=float))
        walkable = self.is_walkable(x_m, y_m)
        distance = np.zeros(x_m.shape)
        outside = np.flatnonzero(~walkable)
        if outside.size:
            exact = shapely.distance(self.cells_geometry, shapely.points(x_m[outside], y_m[outside]))
            distance[outside] = np.maximum(np.nan_to_num(exact, nan=math.inf), 0.01)  # 0: between cell centres
        return distance
