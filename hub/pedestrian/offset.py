"""A matcher for a venue with beacons but no map: the edge's own track, shifted by the fixes.

The edge's pose after a stand is right at the stand and drifts from it; its covariance says how
far. A position fix (a beacon pass) moves an offset added to every later pose, as a Kalman
update: the prior is the edge's covariance grown since the last fix (what the dead reckoning
added since), the fix's own sd the measurement. The edge's covariance need not be honest (the
phone edge's is overconfident on real walks: docs/pdr-estimator.md, the map guard), so the growth
is scaled by a factor learned from the fixes themselves: the method of moments on the
innovations, (|innovation|^2 - 2 sd^2) / trace(growth), smoothed over INFLATION_SMOOTHING of the
fixes and held in INFLATION_LIMITS. A stand resets the offset (the edge restarted there), not
the factor. No lag: the refined track is the live one. State: a few fixed fields.
"""

from __future__ import annotations

import numpy as np

from hub.pedestrian.matching import DeadReckonedPose, MatchedPose


INFLATION_LIMITS = (1.0, 50.0)
INFLATION_SMOOTHING = 0.2  # weight of each fix's estimate


class OffsetMatcher:
    """A MapMatcher without a map: `update`, `reset`, `observe` (a fix now)."""

    refined_lag_steps = 0

    def __init__(self) -> None:
        self.offset_xy_m = np.zeros(2)
        self.offset_covariance = np.zeros((2, 2))  # of the offset itself, after the last fix
        self.covariance_at_fix = np.zeros((2, 2))  # the edge's position covariance then
        self.last: DeadReckonedPose | None = None
        self.fixes = 0
        self.inflation = INFLATION_LIMITS[0]  # the edge covariance's growth times this

    def reset(self, time_ns: int, x_m: float, y_m: float, heading_rad: float) -> None:
        self.offset_xy_m = np.zeros(2)
        self.offset_covariance = np.zeros((2, 2))
        self.covariance_at_fix = np.zeros((2, 2))
        self.last = DeadReckonedPose(time_ns, x_m, y_m, heading_rad)

    def update(self, pose: DeadReckonedPose) -> MatchedPose:
        self.last = pose
        covariance = self._covariance(pose)
        full = np.zeros((3, 3)) if pose.covariance is None else np.array(pose.covariance, dtype=float)
        full[:2, :2] = covariance
        return MatchedPose(pose.time_ns, pose.x_m + float(self.offset_xy_m[0]), pose.y_m + float(self.offset_xy_m[1]),
                           pose.heading_rad, full)

    def observe(self, x_m: float, y_m: float, sd_m: float, covariance_xy: np.ndarray | None = None) -> None:
        """A position fix now."""
        if self.last is None:
            return
        prior = self._covariance(self.last)
        gain = prior @ np.linalg.inv(prior + np.eye(2) * sd_m * sd_m)
        here = np.array([self.last.x_m, self.last.y_m]) + self.offset_xy_m
        innovation = np.array([x_m, y_m]) - here
        growth = float(np.trace(self._grown(self.last)))
        if growth > 1e-6:
            estimate = (float(innovation @ innovation) - 2.0 * sd_m * sd_m - float(np.trace(self.offset_covariance))) / growth
            blended = self.inflation + INFLATION_SMOOTHING * (estimate - self.inflation)
            self.inflation = float(np.clip(blended, *INFLATION_LIMITS))
        self.offset_xy_m = self.offset_xy_m + gain @ innovation
        self.offset_covariance = (np.eye(2) - gain) @ prior
        self.covariance_at_fix = self._edge_covariance(self.last)
        self.fixes += 1

    def refined(self) -> list[MatchedPose]:
        return []

    def flush(self) -> list[MatchedPose]:
        return []

    def _edge_covariance(self, pose: DeadReckonedPose) -> np.ndarray:
        return np.zeros((2, 2)) if pose.covariance is None else np.array(pose.covariance, dtype=float)[:2, :2]

    def _grown(self, pose: DeadReckonedPose) -> np.ndarray:
        """What the dead reckoning's covariance added since the last fix (its symmetric, PSD part)."""
        grown = self._edge_covariance(pose) - self.covariance_at_fix
        values, vectors = np.linalg.eigh(0.5 * (grown + grown.T))
        return (vectors * np.maximum(values, 0.0)) @ vectors.T

    def _covariance(self, pose: DeadReckonedPose) -> np.ndarray:
        """The offset's covariance plus the dead reckoning's growth since the last fix, inflated."""
        return self.offset_covariance + self.inflation * self._grown(pose)
