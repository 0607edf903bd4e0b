"""A route as a smooth path: straight segments joined by circular arcs, sampled by arc length.

People cut corners: each corner of the route's polyline becomes an arc of `radius_m` tangent to
both segments (smaller when a segment is too short to hold it: the tangent length is at most 45 %
of either neighbour). Heading is continuous, so the simulated accelerometer sees a centripetal
pull through the turn and no impulse. `Corner` records where each corner lies along the path,
for the truth of junction passages and for slowing down.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim_devices.pedestrian.venues import Route

TANGENT_SHARE_MAX = 0.45  # an arc may use at most this share of either neighbouring segment
STRAIGHT_DEG = 1.0  # a node with a smaller heading change is a straight passage


@dataclass(frozen=True)
class Corner:
    """A route node passed: arc length of its middle, where the arc starts and ends, headings."""

    node: str
    s_m: float  # arc length at the middle of the turn (the node itself for a straight passage)
    start_m: float
    end_m: float
    heading_before_rad: float
    heading_after_rad: float

    @property
    def turn_rad(self) -> float:
        return math.remainder(self.heading_after_rad - self.heading_before_rad, 2.0 * math.pi)


@dataclass(frozen=True)
class SmoothPath:
    """The path sampled every `spacing_m`: arc length, position, heading (rad, counter-clockwise from +x)."""

    s_m: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    heading_rad: np.ndarray  # unwrapped
    corners: tuple[Corner, ...]
    # height above floor 0 at the route's nodes: (arc length, height) knots, linear between
    # (stairs); None on one floor
    height_knots: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def length_m(self) -> float:
        return float(self.s_m[-1])

    def at(self, s_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, y, unwrapped heading) at arc lengths `s_m` (clipped to the path), linear between samples."""
        s = np.clip(s_m, 0.0, self.length_m)
        return (np.interp(s, self.s_m, self.x_m), np.interp(s, self.s_m, self.y_m),
                np.interp(s, self.s_m, self.heading_rad))

    def height_at(self, s_m: np.ndarray) -> np.ndarray:
        """Height (m) of the floor or stair under the walker above floor 0 at arc lengths `s_m`."""
        if self.height_knots is None:
            return np.zeros(np.shape(s_m))
        return np.interp(np.clip(s_m, 0.0, self.length_m), *self.height_knots)


def smooth_path(route: Route, radius_m: float, spacing_m: float = 0.01,
                passes: tuple[tuple[str, float, float], ...] = ()) -> SmoothPath:
    """The route with rounded corners, sampled every `spacing_m`. `passes` (name, x, y) are extra
    points (map points the route walks straight through) recorded as straight Corners."""
    points = np.asarray(route.xy_m, dtype=float)
    headings = np.arctan2(np.diff(points[:, 1]), np.diff(points[:, 0]))
    lengths = np.hypot(np.diff(points[:, 0]), np.diff(points[:, 1]))
    pieces_s, pieces_x, pieces_y, pieces_h = [], [], [], []
    corners = []
    position = points[0].copy()
    s_total = 0.0
    heading = float(headings[0])
    turns = [math.remainder(float(headings[i] - headings[i - 1]), 2 * math.pi) for i in range(1, len(headings))]
    tangents = [0.0] + [min(radius_m * math.tan(abs(t) / 2), TANGENT_SHARE_MAX * min(lengths[i], lengths[i + 1]))
                        for i, t in enumerate(turns)] + [0.0]

    def emit(s: np.ndarray, x: np.ndarray, y: np.ndarray, h: np.ndarray) -> None:
        pieces_s.append(s), pieces_x.append(x), pieces_y.append(y), pieces_h.append(h)

    for i, length in enumerate(lengths):
        straight = length - tangents[i] - tangents[i + 1]
        direction = np.array([math.cos(headings[i]), math.sin(headings[i])])
        count = max(2, int(math.ceil(straight / spacing_m)) + 1)
        t = np.linspace(0.0, straight, count)
        emit(s_total + t, position[0] + t * direction[0], position[1] + t * direction[1], np.full(count, heading))
        for name, px, py in passes:
            offset = np.array([px, py]) - points[i]
            along = float(np.dot(offset, direction))
            lateral = abs(float(direction[0] * offset[1] - direction[1] * offset[0]))
            if lateral < 0.05 and tangents[i] < along < length - tangents[i + 1]:
                s_pass = s_total + along - tangents[i]
                corners.append(Corner(name, s_pass, s_pass, s_pass, heading, heading))
        position = position + straight * direction
        s_total += straight
        if i == len(lengths) - 1:
            break
        turn = turns[i]
        tangent = tangents[i + 1]
        if abs(math.degrees(turn)) < STRAIGHT_DEG or tangent <= 0.0:
            corners.append(Corner(route.nodes[i + 1], s_total, s_total, s_total, heading, heading + turn))
            heading += turn
            continue
        radius = tangent / math.tan(abs(turn) / 2)
        arc = radius * abs(turn)
        count = max(3, int(math.ceil(arc / spacing_m)) + 1)
        t = np.linspace(0.0, arc, count)
        side = math.copysign(1.0, turn)  # left turn: centre to the left
        centre = position + radius * np.array([-math.sin(heading), math.cos(heading)]) * side
        angle = heading + side * t / radius
        x = centre[0] + radius * np.sin(angle) * side
        y = centre[1] - radius * np.cos(angle) * side
        corners.append(Corner(route.nodes[i + 1], s_total + arc / 2, s_total, s_total + arc, heading, heading + turn))
        emit(s_total + t[1:], x[1:], y[1:], angle[1:])
        position = np.array([x[-1], y[-1]])
        s_total += arc
        heading += turn
    s = np.concatenate(pieces_s)
    keep = np.concatenate([[True], np.diff(s) > 1e-9])
    corners.sort(key=lambda c: c.s_m)
    knots = None
    if route.z_m and any(route.z_m):  # the route's own nodes are the corners (no map-point passes here)
        knot_s = np.array([0.0] + [c.s_m for c in corners] + [float(s[keep][-1])])
        knots = (knot_s, np.asarray(route.z_m, dtype=float))
    return SmoothPath(s[keep], np.concatenate(pieces_x)[keep], np.concatenate(pieces_y)[keep],
                      np.concatenate(pieces_h)[keep], tuple(corners), knots)
