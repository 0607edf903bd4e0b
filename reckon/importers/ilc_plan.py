"""Indoor Location Competition 2.0 floor plans (`geojson_map.json`, `floor_info.json`) in metres.

A floor's walkable area is its outline less every shop, room or obstacle drawn on it, written as
polygons `[outer ring, hole, ...]` in the floor-plan frame (metres): the venue's `floor_plan`
(protocol/session.py), which hub/pedestrian/walkable.py reads as the union of the outer rings
less the union of all holes.

**The outline.** The data set does not mark the floor in one way across buildings, so these rules
are tried in order and the first that finds a polygon decides (`FloorPlan.found_by` says which):
  (a) type: features whose `properties.type` is "floor" (site 1: feature 0, a MultiPolygon);
  (b) floor property: features with a `floor` property and none of a shop's label keys
      (`SHOP_KEYS`: every shop and room on site 1 carries its label `display` and the label's
      anchor `point`/`points`; an outline has no label). Another building of the set draws its
      outline as feature 0 with `{"floor": "F1", "center": [lon, lat], ...}` and no type;
  (c) containing polygon: the largest polygon feature that holds at least `CONTAINS_FRACTION`
      of the other polygon features' centroids.
Every feature that rule (a) or (b) finds is part of the outline (a floor may be drawn as two
wings). When none fits, InputError names the file, each rule and what it found.

**Holes.** The outline's own holes (a courtyard, an atrium void) are holes of the plan. Every
other Polygon or MultiPolygon part is a shop or obstacle: its outer ring becomes a hole of the
outline part holding most of its vertices. Shops along the outer wall straddle the outline (20 of
172 on site 1 F1), so a hole may cross its outline's edge; walkable.py subtracts it all the same.
A part wholly outside every outline part is left out (the report lists it). A shop's own inner
rings are not read: the whole shop is not walkable. Points and lines are not read.

**The frame.** ILC's waypoints are metres on the floor image: the outline's bounding box
(longitude, latitude) maps linearly onto [0, width] x [0, height] of floor_info.json's
`map_info`, east to +x, north to +y. On site 1's five floors those extents are the box's size on
the ground (spherical Earth) to 0.0004 %. A plan whose extents fit the bounds of all its polygons
better (shops drawn beyond the outline, the image made from all of them) is mapped from those
bounds instead, and the report says so. When neither fits within `EXTENT_TOLERANCE` the better is
stretched onto the extents all the same (the waypoints were drawn on that image) and
`FloorPlan.warnings` says so: the report's waypoint check then shows whether the walks fit the map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from protocol.errors import InputError

SHOP_KEYS = ("display", "point", "points")  # a shop's or room's label and its anchor (site 1)
FLOOR_KEY = "floor"
CONTAINS_FRACTION = 0.9  # rule (c): "nearly all": a shop along the wall may have its centroid outside
EXTENT_TOLERANCE = 0.02  # floor_info's extents against the bounds' ground size, either axis
EARTH_RADIUS_M = 6_378_137.0  # WGS 84 equatorial radius; site 1's extents follow it to 0.0004 %

Ring = list[list[float]]
Polygon = list[Ring]  # [outer ring, hole, ...]


@dataclass(frozen=True)
class FloorPlan:
    """A floor read from its GeoJSON: `polygons` in metres and how the outline was found."""

    polygons: list[Polygon]
    outline: tuple[int, ...]  # feature indices of the outline
    rule: str  # "type", "floor" or "contains": rules (a), (b), (c) of the module docstring
    found_by: str  # e.g. "feature 0, by its type 'floor'"
    centre_lonlat: tuple[float, float]  # centre of the outline's bounding box, degrees
    outline_parts: int
    outline_holes: int
    obstacles: int  # polygon parts made holes
    left_out: tuple[int, ...]  # features with a part wholly outside every outline part
    frame: str
    warnings: tuple[str, ...] = ()

    def describe(self) -> list[str]:
        """The lines the import report prints about this floor."""
        parts = f"{self.outline_parts} part{'s' if self.outline_parts != 1 else ''}"
        holes = f"{self.outline_holes} hole{'s' if self.outline_holes != 1 else ''}"
        left_out = (f"; left out, wholly outside the outline: feature{'s' if len(self.left_out) > 1 else ''} "
                    f"{_indices(self.left_out)}" if self.left_out else "")
        return ([f"floor outline: {self.found_by} ({parts}, {holes})",
                 f"shops and obstacles: {self.obstacles} polygons, not walkable{left_out}",
                 self.frame]
                + [f"warning: {warning}" for warning in self.warnings])


@dataclass(frozen=True)
class _Feature:
    index: int
    properties: dict[str, Any]
    polygons: list[Polygon]  # degrees (longitude, latitude) as the file has them


def read_floor_plan(geojson: Any, width_m: float, height_m: float, where: str = "floor plan") -> FloorPlan:
    """The floor plan in metres (see the module docstring). `where` names the file in errors.
    InputError on a GeoJSON without features, malformed coordinates, a degenerate frame, or no
    feature that any rule takes for the outline."""
    features = _features(geojson, where)
    with_polygons = [feature for feature in features if feature.polygons]
    if not with_polygons:
        raise InputError(f"{where}: no Polygon or MultiPolygon feature among its {len(features)} features: "
                         "no floor outline")
    if not (width_m > 0 and height_m > 0):
        raise InputError(f"{where}: floor_info map size {width_m} x {height_m} m (both must be > 0)")
    all_bounds = _bounds(with_polygons, where)

    def in_metres(low: np.ndarray, scale: np.ndarray) -> dict[int, list[Polygon]]:
        return {feature.index: [[((np.array(ring, dtype=float) - low) * scale).tolist() for ring in polygon]
                                for polygon in feature.polygons] for feature in with_polygons}

    # Rule (c) compares areas and containment, which any linear frame keeps: the ground's, so that
    # the areas it reports are square metres whatever floor_info says (floor_info's without lon/lat).
    ground_scale = (np.array(_ground_size_m(*all_bounds)) if _is_lonlat(all_bounds)
                    else np.array([width_m, height_m])) / (all_bounds[1] - all_bounds[0])
    outline, rule, found_by = _find_outline(features, lambda: in_metres(all_bounds[0], ground_scale), where)
    outline_bounds = _bounds([features[index] for index in outline], where)
    (low, high), frame, warnings = _frame(outline_bounds, all_bounds, width_m, height_m)
    metres = in_metres(low, np.array([width_m, height_m]) / (high - low))
    plan = [list(polygon) for index in outline for polygon in metres[index]]
    outline_holes = sum(len(polygon) - 1 for polygon in plan)
    obstacles, left_out = 0, []
    for feature in with_polygons:
        if feature.index in outline:
            continue
        for polygon in metres[feature.index]:
            hole = polygon[0]
            inside = [sum(point_in_ring(point, part[0]) for point in hole) for part in plan]
            if max(inside) > 0:
                plan[inside.index(max(inside))].append(hole)
                obstacles += 1
            elif feature.index not in left_out:
                left_out.append(feature.index)
    centre = (float(outline_bounds[0][0] + outline_bounds[1][0]) / 2.0,
              float(outline_bounds[0][1] + outline_bounds[1][1]) / 2.0)
    return FloorPlan(plan, tuple(outline), rule, found_by, centre, len(plan), outline_holes, obstacles,
                     tuple(left_out), frame, warnings)


def _bounds(features: list[_Feature], where: str) -> tuple[np.ndarray, np.ndarray]:
    corners = np.concatenate([np.array(ring) for feature in features for polygon in feature.polygons
                              for ring in polygon])
    low, high = corners.min(axis=0), corners.max(axis=0)
    if not np.all(high > low):
        raise InputError(f"{where}: feature{'s' if len(features) > 1 else ''} "
                         f"{_indices([f.index for f in features])}: degenerate bounds {low.tolist()}-{high.tolist()} "
                         "(no extent to map onto floor_info's)")
    return low, high


def _find_outline(features: list[_Feature], metres: Callable[[], dict[int, list[Polygon]]], where: str
                  ) -> tuple[list[int], str, str]:
    """(outline feature indices, rule, how it was found) by rules (a), (b), (c); InputError if none fits."""
    typed = [f for f in features if str(f.properties.get("type", "")).strip().lower() == "floor"]
    found = [f.index for f in typed if f.polygons]
    if found:
        return found, "type", f"{_features_text(found)}, by {_its(found)} type 'floor'"
    named = [f for f in features if f.properties.get(FLOOR_KEY) not in (None, "") and f.polygons]
    shops = [f.index for f in named if any(key in f.properties for key in SHOP_KEYS)]
    found = [f.index for f in named if f.index not in shops]
    if found:
        values = sorted({repr(features[i].properties[FLOOR_KEY]) for i in found})
        return found, "floor", f"{_features_text(found)}, by {_its(found)} 'floor' property ({', '.join(values)})"
    container = _container(metres())
    if container.index is not None:
        return [container.index], "contains", container.text
    types = sorted({repr(f.properties["type"]) for f in features if "type" in f.properties})
    typed_found = (f"{_features_text([f.index for f in typed])} {_has(typed)} it but no polygon" if typed
                   else "none" + (f" (types found: {', '.join(types)})" if types else ""))
    shops_found = (f"none; {_features_text(shops)} {_has(shops)} one but "
                   f"{'is a shop' if len(shops) == 1 else 'are shops'}" if shops else "none")
    raise InputError(f"{where}: no floor outline among its {len(features)} features. Looked for, in order: "
                     f"(a) a polygon feature with properties.type 'floor': {typed_found}; "
                     f"(b) a polygon feature with a 'floor' property and none of a shop's keys "
                     f"({', '.join(SHOP_KEYS)}): {shops_found}; "
                     f"(c) a polygon holding at least {CONTAINS_FRACTION:.0%} of the other polygons' centroids: "
                     f"{container.text}")


@dataclass(frozen=True)
class _Container:
    index: int | None
    text: str


def _container(metres: dict[int, list[Polygon]]) -> _Container:
    """Rule (c): the largest polygon feature holding CONTAINS_FRACTION of the others' centroids."""
    shapes = {index: _shape(polygons) for index, polygons in metres.items()}
    if len(shapes) == 1:
        (index,) = shapes
        return _Container(index, f"feature {index}, the only polygon")
    order = sorted(shapes, key=lambda index: (-shapes[index].area, index))
    centroids = {index: shape.centroid for index, shape in shapes.items()}
    for index in order:  # the largest first; a larger polygon that holds too few is passed over
        others = [centroids[other] for other in order if other != index and not centroids[other].is_empty]
        held = int(np.count_nonzero(shapely.covers(shapes[index], others))) if others else 0
        if others and held >= CONTAINS_FRACTION * len(others):
            return _Container(index, f"feature {index}, the largest polygon holding nearly all the others "
                                     f"({held} of {len(others)} centroids; {shapes[index].area:,.0f} m^2)")
        if index == order[0]:
            largest_text = (f"none; the largest, feature {index} ({shapes[index].area:,.0f} m^2), holds "
                            f"{held} of the other {len(others)} ({held / max(len(others), 1):.0%})")
    return _Container(None, largest_text)


def _shape(polygons: list[Polygon]) -> BaseGeometry:
    parts = [shapely.make_valid(shapely.Polygon(polygon[0], polygon[1:])) for polygon in polygons]
    return shapely.union_all(parts)


def _frame(outline: tuple[np.ndarray, np.ndarray], everything: tuple[np.ndarray, np.ndarray], width_m: float,
           height_m: float) -> tuple[tuple[np.ndarray, np.ndarray], str, tuple[str, ...]]:
    """The bounds that map onto floor_info's extents, the report's line about it, and warnings.

    The outline's bounding box, unless the bounds of every polygon fit floor_info's extents
    better on the ground. Site 1 shows which one ILC used: F2's shops reach 0.06 m south of its
    outline, and floor_info's height fits the outline's box (to 0.0004 %; the bounds of all: 0.03 %
    off), as on the other four floors. Without longitude/latitude: the outline's box."""
    boxes = {"the outline's bounding box": outline, "the bounds of all polygons": everything}
    first = next(iter(boxes))
    if not all(_is_lonlat(box) for box in boxes.values()):
        low, high = outline
        return outline, (f"frame: {first} ({low[0]:.6g} to {high[0]:.6g}, {low[1]:.6g} to {high[1]:.6g}; "
                         f"not longitude/latitude, not checked on the ground) onto floor_info's "
                         f"{width_m:.1f} x {height_m:.1f} m"), ()
    ground = {name: _ground_size_m(*box) for name, box in boxes.items()}
    misfit = {name: max(abs(width_m / size[0] - 1.0), abs(height_m / size[1] - 1.0)) for name, size in ground.items()}
    chosen = min(boxes, key=lambda name: (misfit[name], name != first))
    (low, high), (ground_width_m, ground_height_m) = boxes[chosen], ground[chosen]
    text = (f"frame: {chosen} (lon {low[0]:.6f} to {high[0]:.6f}, lat {low[1]:.6f} to {high[1]:.6f}; "
            f"{ground_width_m:.1f} x {ground_height_m:.1f} m on the ground) onto floor_info's "
            f"{width_m:.1f} x {height_m:.1f} m")
    if chosen != first:
        text += (f" (the outline's box, {ground[first][0]:.1f} x {ground[first][1]:.1f} m on the ground, "
                 "fits floor_info less well)")
    if misfit[chosen] <= EXTENT_TOLERANCE:
        return boxes[chosen], text, ()
    return boxes[chosen], text, (
        f"floor_info's {width_m:.1f} x {height_m:.1f} m is not {chosen}'s {ground_width_m:.1f} x "
        f"{ground_height_m:.1f} m on the ground (x {width_m / ground_width_m:.3f}, y {height_m / ground_height_m:.3f}, "
        f"more than {EXTENT_TOLERANCE:.0%} off): the plan is stretched onto floor_info's extents, as ILC's "
        "waypoints are drawn on them; see whether the waypoints fit the map (walkable below)",)


def _is_lonlat(bounds: tuple[np.ndarray, np.ndarray]) -> bool:
    low, high = bounds
    return bool(-180.0 <= low[0] and high[0] <= 180.0 and -80.0 <= low[1] and high[1] <= 80.0)


def _ground_size_m(low: np.ndarray, high: np.ndarray) -> tuple[float, float]:
    """(east-west, north-south) size in metres of a longitude/latitude box on a spherical Earth."""
    metres_per_degree = math.radians(1.0) * EARTH_RADIUS_M
    return (float(high[0] - low[0]) * metres_per_degree * math.cos(math.radians(float(low[1] + high[1]) / 2.0)),
            float(high[1] - low[1]) * metres_per_degree)


def _features(geojson: Any, where: str) -> list[_Feature]:
    features = geojson.get("features") if isinstance(geojson, dict) else None
    if not isinstance(features, list):
        raise InputError(f"{where}: the GeoJSON has no 'features' list")
    read = []
    for index, feature in enumerate(features):
        properties = feature.get("properties") if isinstance(feature, dict) else None
        read.append(_Feature(index, properties if isinstance(properties, dict) else {},
                             _polygons(feature, f"{where}: feature {index}")))
    return read


def _polygons(feature: Any, where: str) -> list[Polygon]:
    """The feature's polygons as [outer, hole, ...] of [lon, lat] points; [] for other geometries
    and empty polygons; InputError naming `where` on malformed coordinates."""
    geometry = feature.get("geometry") if isinstance(feature, dict) else None
    kind = geometry.get("type") if isinstance(geometry, dict) else None
    if kind not in ("Polygon", "MultiPolygon"):
        return []
    coordinates = geometry.get("coordinates")
    polygons = [coordinates] if kind == "Polygon" else coordinates
    if not isinstance(polygons, list) or not all(isinstance(polygon, list) for polygon in polygons):
        raise InputError(f"{where}: {kind} coordinates are not a list of polygons (lists of rings)")
    for part, polygon in enumerate(polygons):
        for number, ring in enumerate(polygon):
            if (not isinstance(ring, list) or len(ring) < 3
                    or not all(isinstance(p, list) and len(p) >= 2 and all(map(_is_number, p[:2])) for p in ring)):
                raise InputError(f"{where}: {kind} part {part} ring {number} is not a list of >= 3 [lon, lat] points")
    return [[[point[:2] for point in ring] for ring in polygon] for polygon in polygons if polygon]


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _indices(indices: tuple[int, ...] | list[int]) -> str:
    return ", ".join(map(str, indices))


def _features_text(indices: list[int]) -> str:
    return f"feature{'s' if len(indices) > 1 else ''} {_indices(indices)}"


def _its(indices: list[int]) -> str:
    return "its" if len(indices) == 1 else "their"


def _has(items: list) -> str:
    return "has" if len(items) == 1 else "have"


def point_in_ring(point: list[float] | tuple[float, float], ring: Ring) -> bool:
    """Even-odd rule: is (x, y) inside the closed ring (first point need not repeat)?"""
    x, y = point
    inside = False
    previous_x, previous_y = ring[-1]
    for current_x, current_y in ring:
        if (current_y > y) != (previous_y > y):
            crossing_x = previous_x + (y - previous_y) * (current_x - previous_x) / (current_y - previous_y)
            if x < crossing_x:
                inside = not inside
        previous_x, previous_y = current_x, current_y
    return inside
