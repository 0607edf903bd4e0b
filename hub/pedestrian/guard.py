"""Map matching that is never much worse than dead reckoning: a consistency check on the particle
filter (hub/pedestrian/particles.py) and a fall-back to the edge's own track.

A floor plan can contradict a walk: a wall drawn across a corridor, a plan shifted, turned or
mirrored against the stands, a floor whose walkable area misses the walk altogether. A filter
that trusts such a map kills every particle that follows the track, re-seeds, and ends up where
nobody walked (issue 20: walks of p75 1.4-8.7 m made 17-34 m). `MapGuard` wraps the filter and
watches two signs, per pose:
- re-seeds: the filter lost every particle (`recoveries`) more than `max_recoveries` times within
  `recovery_window_steps` poses. One is a wrong turn recovered; more, a map that disagrees.
- the map itself: a stand or fix that is not walkable (`WalkableArea.is_walkable`) is a map
  problem, counted (`fixes_off_map`); the cloud is drawn only within `reacquire_radius_m` of it,
  never re-seeded away from it.
Two other signs were measured and left out (docs/pdr-estimator.md, "The map guard"): the
distance between the filter and the edge in the edge's covariance (with the edge's covariance
overconfident it fired where the filter was right, pooled p75 3.13 -> 3.65 m; now that it is
honest the filter's losses on the ILC walks lie inside it, so it catches nothing there and still
costs where the filter helps), and the share of weight walls kill per step
(a wall across a corridor kills many particles of a right cloud too; every contradicting plan
tried that it caught, re-seeds caught as well).

On contradiction the published pose is the edge's own track shifted by the offset the two had
`offset_delay_steps` agreeing poses before (the cloud goes astray some poses before the
re-seeds say so), with `fallback` set on the pose. The filter goes on in the shadow, its cloud
drawn within `reacquire_radius_m` of the fall-back track whenever it dies or strays further than
`return_distance_m` from it; once it has followed the fall-back track within `return_distance_m`
without a re-seed for `agree_steps` poses, the matched track comes back. Refined poses of
fall-back steps are the fall-back poses. State: fixed fields and deques of bounded length, so
memory is constant per agent.

A plan turned by a few tens of degrees about the stand is not caught: the filter then follows
the turned corridors without losing its cloud, and nothing in the track tells the two apart
(only a heading the edge trusts more than the stand's would).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from hub.pedestrian.matching import DeadReckonedPose, MatchedPose
from hub.pedestrian.particles import ParticleMatcher


@dataclass(frozen=True)
class GuardSettings:
    recovery_window_steps: int = 30  # about 15 s of walking
    max_recoveries: int = 1  # one re-seed in the window is a wrong turn recovered; two, a map that disagrees
    agree_steps: int = 20  # about 10 s of agreement before the matched track comes back
    return_distance_m: float = 2.0  # the shadow cloud agrees with the fall-back track within this
    reacquire_radius_m: float = 2.0  # a cloud is drawn no further than this from the track or a fix
    reacquire_sd_m: float = 1.0
    # Chosen on crafted plans (tests/hub/test_map_guard.py: a plan turned 90 deg: 0 -> 2.6 x the edge's
    # error, 4 -> 1.03 x, 10 -> 0.98 x); on the ILC tune half 0, 4 and 10 give the same p75.
    offset_delay_steps: int = 4
    position_floor_sd_m: float = 1.0  # a fall-back pose's covariance when the edge sends none


@dataclass
class GuardDiagnostics:
    fallback_steps: int = 0  # poses published from the edge's track
    fallback_episodes: int = 0
    fixes_off_map: int = 0  # stands or fixes on a cell that is not walkable
    reacquisitions: int = 0  # shadow clouds drawn near the fall-back track
    last_reason: str = ""  # why the last fall-back began: "recoveries" or "fix off map"


class MapGuard:
    """A MapMatcher: the particle filter, or the edge's own track where the map contradicts it."""

    def __init__(self, matcher: ParticleMatcher, settings: GuardSettings = GuardSettings()) -> None:
        self.matcher = matcher
        self.area = matcher.area
        self.settings = settings
        self.diagnostics = GuardDiagnostics()
        self.fallback = False
        self.offset_xy_m = (0.0, 0.0)  # filter minus edge where the fall-back track starts
        # filter minus edge at the last agreeing poses, oldest first
        self.agreed: deque[tuple[float, float]] = deque([(0.0, 0.0)], maxlen=settings.offset_delay_steps + 1)
        self.agreeing = 0  # consecutive poses of agreement while falling back
        self.recoveries_seen = matcher.diagnostics.recoveries
        self.recent_recoveries: deque[int] = deque(maxlen=max(1, settings.max_recoveries + 1))
        self.steps = 0
        self.last_pose: DeadReckonedPose | None = None
        # (time ns, fall-back pose or None) of the last poses, for refined poses that come out later
        self.recent: deque[tuple[int, MatchedPose | None]] = deque(maxlen=matcher.refined_lag_steps + 2)

    @property
    def refined_lag_steps(self) -> int:
        return self.matcher.refined_lag_steps

    def reset(self, time_ns: int, x_m: float, y_m: float, heading_rad: float) -> None:
        """A fix: the filter restarts there; a fix the map does not allow starts a fall-back at it."""
        self.offset_xy_m = (0.0, 0.0)
        self.agreed.clear()
        self.agreed.append((0.0, 0.0))
        self.agreeing = 0
        self.recent_recoveries.clear()
        if self.area.is_walkable(np.array([x_m]), np.array([y_m]))[0]:
            self.matcher.reset(time_ns, x_m, y_m, heading_rad)
            self.fallback = False
        else:
            self.diagnostics.fixes_off_map += 1
            self.matcher.restart_at(time_ns, x_m, y_m, heading_rad)
            self._reacquire(x_m, y_m)
            self._begin_fallback("fix off map")
        self.recoveries_seen = self.matcher.diagnostics.recoveries

    def update(self, pose: DeadReckonedPose) -> MatchedPose:
        settings = self.settings
        self.last_pose = pose
        matched = self.matcher.update(pose)
        self.steps += 1
        diagnostics = self.matcher.diagnostics
        recovered = diagnostics.recoveries > self.recoveries_seen
        self.recoveries_seen = diagnostics.recoveries
        if recovered:
            self.recent_recoveries.append(self.steps)
        if not self.fallback:
            if not self._contradicted():
                self.agreed.append((matched.x_m - pose.x_m, matched.y_m - pose.y_m))
                self.recent.append((pose.time_ns, None))
                return matched
            self.offset_xy_m = self.agreed[0]
            self._begin_fallback("recoveries")
            out = self._fallback_pose(pose)
            self._reacquire(out.x_m, out.y_m)
        else:
            out = self._fallback_pose(pose)
            distance_m = math.hypot(matched.x_m - out.x_m, matched.y_m - out.y_m)
            if recovered or distance_m > settings.return_distance_m:
                self.agreeing = 0
                self._reacquire(out.x_m, out.y_m)
            else:
                self.agreeing += 1
            if self.agreeing >= settings.agree_steps:
                self.fallback = False
                self.recent_recoveries.clear()
                self.agreed.clear()
                self.agreed.append((matched.x_m - pose.x_m, matched.y_m - pose.y_m))
                self.recent.append((pose.time_ns, None))
                return matched
        self.diagnostics.fallback_steps += 1
        self.recent.append((pose.time_ns, out))
        return out

    def observe(self, x_m: float, y_m: float, sd_m: float, covariance_xy: np.ndarray) -> None:
        """A position fix now: the filter weighs it (in the shadow while falling back), and the
        fall-back track's offset moves towards it as a Kalman update with the track's covariance."""
        self.matcher.observe(x_m, y_m, sd_m)
        if self.fallback and self.last_pose is not None:
            prior = np.asarray(covariance_xy, dtype=float)
            gain = prior @ np.linalg.inv(prior + np.eye(2) * sd_m * sd_m)
            here = np.array([self.last_pose.x_m + self.offset_xy_m[0], self.last_pose.y_m + self.offset_xy_m[1]])
            shift = gain @ (np.array([x_m, y_m]) - here)
            self.offset_xy_m = (self.offset_xy_m[0] + float(shift[0]), self.offset_xy_m[1] + float(shift[1]))

    def refined(self) -> list[MatchedPose]:
        return [self._refined(pose) for pose in self.matcher.refined()]

    def flush(self) -> list[MatchedPose]:
        return [self._refined(pose) for pose in self.matcher.flush()]

    def _refined(self, pose: MatchedPose) -> MatchedPose:
        """A refined pose of a fall-back step is the fall-back pose."""
        for time_ns, fallback in self.recent:
            if time_ns == pose.time_ns:
                return fallback if fallback is not None else pose
        return pose

    def _contradicted(self) -> bool:
        """Did the filter lose its cloud more often than a wrong turn explains?"""
        window_start = self.steps - self.settings.recovery_window_steps
        return sum(1 for step in self.recent_recoveries if step > window_start) > self.settings.max_recoveries

    def _begin_fallback(self, reason: str) -> None:
        if not self.fallback:
            self.diagnostics.fallback_episodes += 1
        self.fallback, self.agreeing = True, 0
        self.diagnostics.last_reason = reason

    def _fallback_pose(self, pose: DeadReckonedPose) -> MatchedPose:
        covariance = (np.asarray(pose.covariance, dtype=float) if pose.covariance is not None
                      else np.diag([self.settings.position_floor_sd_m ** 2] * 2 + [0.0]))
        return MatchedPose(pose.time_ns, pose.x_m + self.offset_xy_m[0], pose.y_m + self.offset_xy_m[1],
                           pose.heading_rad, covariance, fallback=True)

    def _reacquire(self, x_m: float, y_m: float) -> None:
        if self.matcher.seed_near(x_m, y_m, self.settings.reacquire_sd_m, self.settings.reacquire_radius_m):
            self.diagnostics.reacquisitions += 1

