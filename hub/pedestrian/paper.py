"""The indoor-navigation paper's map matching (sec. 3.4-3.5, tables 4-5), the baseline.

The map is the venue's `map_points`: corridor junctions with the directions of the corridors
leaving each. Dead reckoning runs untouched until a turn is detected, i.e. the heading changed by
at least `turn_threshold_deg` within `turn_window_s`. Then (sec. 3.4):
1. position: the current (corrected) position moves to the nearest map point;
2. heading: when the turn has ended, the heading snaps to the nearest direction allowed at that
   point.
Sec. 3.5: the snap is valid only when no other point lies within X tan(3 deg) of the target point,
X the distance from the previous point (the last snapped point; after a reset, the reset pose).

The paper gives neither the threshold nor the window. Chosen here:
- 45 deg within 2.0 s: half of the 90 deg corridor turns of its maps, well above a hand-held
  phone's sway (about +-10 deg per step) and its drift (table 3: at most 3 deg over 40 m); a walking
  90 deg turn takes 1-2 s (2-3 steps), so the window holds the whole turn.
- the turn has ended when the heading moved less than 15 deg over the last 1.0 s (2 steps).

Departures, flagged in settings: the paper states the sec. 3.5 rule as a condition of use but
would snap anyway; here a snap that breaks it is refused (recorded with valid=False, no move),
which is the paper's own suggested fix (sec. 5) carried over. `max_snap_distance_m` is the other
fix sec. 5 suggests (no snap when the nearest point is far: a turn in an open hall); off by default.

Applied as a rigid correction of the dead-reckoned stream: output = R(rotation) (p - anchor_dr)
+ anchor_out, heading + rotation; a position snap moves the anchor, a heading snap turns about the
current corrected position. State is fixed-size: the heading history is a ring of
`history_capacity` samples (enough for the windows at 100 Hz).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from hub.pedestrian.matching import DeadReckonedPose, MatchedPose, SnapRecord, SnapStage, wrap_angle_rad
from protocol.session import MapPoint

VALIDITY_ANGLE_DEG = 3.0  # sec. 3.5: table 3's worst heading error after calibration, rounded


@dataclass(frozen=True)
class PaperSnapSettings:
    turn_threshold_deg: float = 45.0
    turn_window_s: float = 2.0
    settle_threshold_deg: float = 15.0
    settle_window_s: float = 1.0
    enforce_validity_rule: bool = True  # departure: the paper snaps regardless (see module docstring)
    max_snap_distance_m: float | None = None  # sec. 5's suggested fix; None: off, as in the paper
    unknown_position_sd_m: float = 1.0  # reported covariance when the dead reckoning gives none
    unknown_heading_sd_rad: float = math.radians(5.0)
    history_capacity: int = 256  # (time, heading) samples kept; 2 s at 100 Hz fits with margin


class PaperSnapMatcher:
    """Turn-triggered snap to the nearest map point and corridor direction (the paper's)."""

    def __init__(self, points: tuple[MapPoint, ...], settings: PaperSnapSettings = PaperSnapSettings(),
                 floor: int = 0) -> None:
        self.settings = settings
        self.points = tuple(p for p in points if p.floor == floor)
        if not self.points:
            raise ValueError(f"no map points on floor {floor}")
        self.point_xy_m = np.array([[p.x_m, p.y_m] for p in self.points])
        self.history: deque[tuple[int, float]] = deque(maxlen=settings.history_capacity)
        self.rotation_rad = 0.0
        self.anchor_dead_reckoned = np.zeros(2)
        self.anchor_output = np.zeros(2)
        self.previous_point_xy_m: np.ndarray | None = None  # None: take the first pose seen
        self.in_turn = False
        self.turn_point: int | None = None  # index of the point snapped at the turn's start
        self.last_heading_rad: float | None = None
        self.unwrapped_heading_rad = 0.0

    def reset(self, time_ns: int, x_m: float, y_m: float, heading_rad: float) -> None:
        self.rotation_rad = 0.0
        self.anchor_dead_reckoned = np.array([x_m, y_m])
        self.anchor_output = np.array([x_m, y_m])
        self.previous_point_xy_m = np.array([x_m, y_m])
        self.history.clear()
        self.in_turn, self.turn_point = False, None
        self.last_heading_rad = None

    def _corrected_xy(self, pose: DeadReckonedPose) -> np.ndarray:
        cos_r, sin_r = math.cos(self.rotation_rad), math.sin(self.rotation_rad)
        offset = np.array([pose.x_m, pose.y_m]) - self.anchor_dead_reckoned
        return self.anchor_output + np.array([cos_r * offset[0] - sin_r * offset[1],
                                              sin_r * offset[0] + cos_r * offset[1]])

    def _largest_change_rad(self, time_ns: int, window_s: float) -> float:
        """Largest |heading now - heading then| over the samples within `window_s` (unwrapped)."""
        oldest_ns = time_ns - int(window_s * 1e9)
        now = self.history[-1][1]
        return max((abs(now - heading) for sample_ns, heading in self.history if sample_ns >= oldest_ns),
                   default=0.0)

    refined_lag_steps = 0  # the paper's snap decides at once: it has no refined track

    def refined(self) -> list[MatchedPose]:
        return []

    def flush(self) -> list[MatchedPose]:
        return []

    def update(self, pose: DeadReckonedPose) -> MatchedPose:
        if self.last_heading_rad is None:
            self.unwrapped_heading_rad = pose.heading_rad
            if self.previous_point_xy_m is None:  # no reset yet: the walk starts where it is
                self.reset(pose.time_ns, pose.x_m, pose.y_m, pose.heading_rad)
        else:
            self.unwrapped_heading_rad += wrap_angle_rad(pose.heading_rad - self.last_heading_rad)
        self.last_heading_rad = pose.heading_rad
        self.history.append((pose.time_ns, self.unwrapped_heading_rad))
        snap = None
        if not self.in_turn:
            change_rad = self._largest_change_rad(pose.time_ns, self.settings.turn_window_s)
            if change_rad >= math.radians(self.settings.turn_threshold_deg):
                self.in_turn = True
                snap = self._snap_position(pose)
        elif self._largest_change_rad(pose.time_ns, self.settings.settle_window_s) < math.radians(
                self.settings.settle_threshold_deg):
            self.in_turn = False
            snap = self._snap_heading(pose)
            # the next turn is measured from here: headings from before this turn's end would
            # otherwise trigger it a second time within the window
            self.history.clear()
            self.history.append((pose.time_ns, self.unwrapped_heading_rad))
        return self._output(pose, snap)

    def _snap_position(self, pose: DeadReckonedPose) -> SnapRecord:
        here = self._corrected_xy(pose)
        distances_m = np.hypot(*(self.point_xy_m - here).T)
        target = int(np.argmin(distances_m))
        target_xy = self.point_xy_m[target]
        x_m = float(np.hypot(*(target_xy - self.previous_point_xy_m)))  # sec. 3.5's X
        rule_radius_m = x_m * math.tan(math.radians(VALIDITY_ANGLE_DEG))
        to_target_m = np.hypot(*(self.point_xy_m - target_xy).T)
        to_target_m[target] = math.inf
        conflict = int(np.argmin(to_target_m))
        valid = bool(to_target_m[conflict] > rule_radius_m)
        too_far = (self.settings.max_snap_distance_m is not None
                   and distances_m[target] > self.settings.max_snap_distance_m)
        applied = (valid or not self.settings.enforce_validity_rule) and not too_far
        if applied:
            self.anchor_dead_reckoned = np.array([pose.x_m, pose.y_m])
            self.anchor_output = target_xy.copy()
            self.previous_point_xy_m = target_xy.copy()
            self.turn_point = target
        else:
            self.turn_point = None
        return SnapRecord(time_ns=pose.time_ns, stage=SnapStage.POSITION, point_id=self.points[target].id,
                          valid=valid, applied=applied, distance_m=float(distances_m[target]),
                          rule_radius_m=rule_radius_m,
                          conflicting_point_id=None if valid else self.points[conflict].id)

    def _snap_heading(self, pose: DeadReckonedPose) -> SnapRecord | None:
        if self.turn_point is None:
            return None  # the position snap was refused: no point, so no allowed directions
        point = self.points[self.turn_point]
        heading_rad = pose.heading_rad + self.rotation_rad
        allowed_rad = np.radians(point.directions_deg)
        nearest = int(np.argmin(np.abs(wrap_angle_rad(allowed_rad - heading_rad))))
        here = self._corrected_xy(pose)
        distance_m = float(np.hypot(*(here - self.point_xy_m[self.turn_point])))
        self.rotation_rad = wrap_angle_rad(allowed_rad[nearest] - pose.heading_rad)
        self.anchor_dead_reckoned = np.array([pose.x_m, pose.y_m])
        self.anchor_output = here  # turn about where the walker is now: the position stays continuous
        self.turn_point = None
        return SnapRecord(time_ns=pose.time_ns, stage=SnapStage.HEADING, point_id=point.id, valid=True,
                          applied=True, distance_m=distance_m, rule_radius_m=0.0,
                          direction_deg=float(point.directions_deg[nearest]))

    def _output(self, pose: DeadReckonedPose, snap: SnapRecord | None) -> MatchedPose:
        if pose.covariance is None:
            position_variance = self.settings.unknown_position_sd_m ** 2
            covariance = np.diag([position_variance, position_variance, self.settings.unknown_heading_sd_rad ** 2])
        else:
            rotation = np.eye(3)
            cos_r, sin_r = math.cos(self.rotation_rad), math.sin(self.rotation_rad)
            rotation[:2, :2] = [[cos_r, -sin_r], [sin_r, cos_r]]
            covariance = rotation @ np.asarray(pose.covariance) @ rotation.T
        x_m, y_m = self._corrected_xy(pose)
        return MatchedPose(time_ns=pose.time_ns, x_m=float(x_m), y_m=float(y_m),
                           heading_rad=wrap_angle_rad(pose.heading_rad + self.rotation_rad),
                           covariance=covariance, snap=snap)
