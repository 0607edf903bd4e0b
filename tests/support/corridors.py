"""The indoor-navigation paper's corridor map (its table 5) and a dead-reckoned walk over it, for
the map matchers' tests (tests/hub/test_map_matching.py, test_map_guard.py)."""

from __future__ import annotations

import math

import numpy as np

from hub.pedestrian.matching import DeadReckonedPose
from hub.pedestrian.walkable import WalkableArea
from protocol.session import MapPoint, Venue


def _directions(*vectors: tuple[int, int]) -> tuple[float, ...]:
    return tuple(math.degrees(math.atan2(y, x)) % 360.0 for x, y in vectors)


TABLE_5_CM = {  # point: x, y (cm), unit vectors of the corridors leaving it
    "A": (0, 0, [(1, 0), (0, 1)]), "B": (330, 0, [(1, 0), (-1, 0), (0, 1)]),
    "C": (1270.5, 0, [(1, 0), (-1, 0), (0, 1)]), "D": (3217.5, 0, [(-1, 0), (0, 1)]),
    "E": (0, 2351.8, [(1, 0), (0, 1), (0, -1)]), "F": (330, 2351.8, [(1, 0), (-1, 0), (0, 1), (0, -1)]),
    "G": (1270.5, 2351.8, [(1, 0), (-1, 0), (0, 1), (0, -1)]),
    "H": (3217.5, 2351.8, [(1, 0), (-1, 0), (0, 1), (0, -1)]),
    "I": (330, 3355, [(1, 0), (0, -1)]), "J": (1270.5, 3355, [(-1, 0), (0, -1)]),
    "K": (0, 4207.5, [(1, 0), (0, -1)]), "L": (3217.5, 4207.5, [(-1, 0), (0, -1)])}
PAPER_POINTS = tuple(MapPoint(name, x / 100.0, y / 100.0, _directions(*vectors))
                     for name, (x, y, vectors) in TABLE_5_CM.items())
PAPER_ROUTE = "IJGHLKEFBCGHDAEFI"
PAPER_AREA = WalkableArea.from_venue(Venue("chiba", map_points=PAPER_POINTS))


def truth_walk(points: tuple[MapPoint, ...], route: str, step_m: float = 0.7, cadence_hz: float = 1.8
               ) -> tuple[np.ndarray, np.ndarray]:
    """(time_ns, [x, y, heading]) of steps along the route's centre lines; heading = step direction."""
    where = {p.id: (p.x_m, p.y_m) for p in points}
    corners = np.array([where[name] for name in route])
    legs = np.diff(corners, axis=0)
    ends_m = np.concatenate([[0.0], np.cumsum(np.hypot(*legs.T))])
    travelled_m = np.append(np.arange(0.0, ends_m[-1], step_m), ends_m[-1])
    leg = np.clip(np.searchsorted(ends_m, travelled_m, side="right") - 1, 0, len(legs) - 1)
    xy = corners[leg] + legs[leg] * ((travelled_m - ends_m[leg]) / np.hypot(*legs[leg].T))[:, None]
    steps = np.diff(xy, axis=0)
    heading = np.concatenate([[math.atan2(legs[0, 1], legs[0, 0])], np.arctan2(steps[:, 1], steps[:, 0])])
    return (np.arange(len(xy)) / cadence_hz * 1e9).astype(np.int64), np.column_stack([xy, heading])


def dead_reckon(time_ns: np.ndarray, truth: np.ndarray, bias_deg: float = 3.0, drift_deg_per_s: float = 0.1,
                scale: float = 1.08, seed: int = 1) -> list[DeadReckonedPose]:
    """Step-wise dead reckoning of `truth` with a heading bias and drift and a step-length scale."""
    random = np.random.default_rng(seed)
    heading = (truth[:, 2] + math.radians(bias_deg) + math.radians(drift_deg_per_s) * time_ns * 1e-9
               + random.normal(0.0, math.radians(2.0), len(truth)))
    heading[0] = truth[0, 2]  # starts from the reset's pose
    lengths_m = np.concatenate([[0.0], np.hypot(*np.diff(truth[:, :2], axis=0).T)])
    lengths_m *= scale * (1.0 + random.normal(0.0, 0.03, len(truth)))
    xy = truth[0, :2] + np.cumsum(np.column_stack([lengths_m * np.cos(heading), lengths_m * np.sin(heading)]), axis=0)
    return [DeadReckonedPose(int(t), float(x), float(y), float(h), np.diag([0.1 + 0.01 * k, 0.1 + 0.01 * k, 0.01]))
            for k, (t, x, y, h) in enumerate(zip(time_ns, xy[:, 0], xy[:, 1], heading))]
