"""A fixed-lag smoother for the particle matcher (hub/pedestrian/particles.py): each particle's last
`lag_steps` positions, so a later wall that kills a particle also removes the past it walked.

The refined pose for a step is the weighted mean, with the weights of `lag_steps` steps later,
of the surviving particles' positions at that step: the walls met since then have pruned the
ancestries that could not have led here. When the matcher resamples, the histories are copied with
their particles; when it re-seeds (a stand reset, or every particle died) the ancestry is broken,
so every step still waiting is finished at once with the current weights. A refined pose's
covariance is its particles' spread plus what the live pose added to the cloud's (the dead
reckoning's share: hub/pedestrian/particles.py). Memory: two (lag_steps x particles) arrays,
a few rows of scalars and 3x3s; work per step O(particles), O(lag x particles)
per resample.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from hub.pedestrian.matching import MatchedPose


class LagHistory:
    def __init__(self, lag_steps: int, particles: int, is_walkable: Callable[[np.ndarray, np.ndarray], np.ndarray]):
        """`is_walkable(x, y) -> bool array`: a refined mean that lands in a wall (a cloud split
        around a corner) is replaced by the surviving particle nearest to it, whose past is
        walkable by construction."""
        if lag_steps < 1:
            raise ValueError(f"lag_steps {lag_steps} is below 1")
        self.lag_steps = lag_steps
        self.is_walkable = is_walkable
        self.x_m = np.zeros((lag_steps, particles))
        self.y_m = np.zeros((lag_steps, particles))
        self.time_ns = np.zeros(lag_steps, dtype=np.int64)
        self.heading_rad = np.zeros(lag_steps)
        self.added = np.zeros((lag_steps, 3, 3))  # covariance the live pose added to its cloud's
        self.start = 0  # ring index of the oldest step waiting
        self.waiting = 0

    def record(self, time_ns: int, heading_rad: float, x_m: np.ndarray, y_m: np.ndarray,
               weight: np.ndarray, added_covariance: np.ndarray | None = None) -> list[MatchedPose]:
        """Add a step (the particles after it, the live heading, the covariance the live pose added
        to its cloud's); returns the step that leaves the window, refined, when the window was full."""
        out = [self._finish(self.start, weight)] if self.waiting == self.lag_steps else []
        if out:
            self.start = (self.start + 1) % self.lag_steps
            self.waiting -= 1
        row = (self.start + self.waiting) % self.lag_steps
        self.x_m[row], self.y_m[row] = x_m, y_m
        self.time_ns[row], self.heading_rad[row] = time_ns, heading_rad
        self.added[row] = 0.0 if added_covariance is None else added_covariance
        self.waiting += 1
        return out

    def reindex(self, chosen: np.ndarray) -> None:
        """Resampling: particle i is now a copy of old particle chosen[i], its past too."""
        self.x_m = self.x_m[:, chosen]
        self.y_m = self.y_m[:, chosen]

    def flush(self, weight: np.ndarray) -> list[MatchedPose]:
        """Every step waiting, refined with these weights (the ancestry ends here)."""
        out = [self._finish((self.start + i) % self.lag_steps, weight) for i in range(self.waiting)]
        self.start = self.waiting = 0
        return out

    def _finish(self, row: int, weight: np.ndarray) -> MatchedPose:
        x_m, y_m = self.x_m[row], self.y_m[row]
        total = float(weight.sum())
        # every particle has just died (the matcher re-seeds): their past was walkable, weigh it evenly
        weight = weight / total if total > 0.0 else np.full(len(weight), 1.0 / len(weight))
        mean_x, mean_y = float(weight @ x_m), float(weight @ y_m)
        if not self.is_walkable(np.array([mean_x]), np.array([mean_y]))[0]:
            alive = np.flatnonzero(weight > 0.0)
            if alive.size:
                nearest = alive[np.argmin(np.hypot(x_m[alive] - mean_x, y_m[alive] - mean_y))]
                mean_x, mean_y = float(x_m[nearest]), float(y_m[nearest])
        deviations = np.stack([x_m - mean_x, y_m - mean_y])
        covariance = self.added[row].copy()
        covariance[:2, :2] += (deviations * weight) @ deviations.T
        return MatchedPose(int(self.time_ns[row]), mean_x, mean_y, float(self.heading_rad[row]), covariance)
