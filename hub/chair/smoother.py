"""Fixed-lag smoothing of one agent's corrected track, in fixed memory.

The hub sees each agent as its live poses (position and covariance) plus the corrections it has
applied. Between corrections the position error of dead reckoning behaves as a random walk whose
variance the edge reports, so the Rauch-Tung-Striebel recursion reduces to a scalar per pose:
with p_k the position variance after any correction at pose k and q_k the variance before it,

    delta_k = C_k * (delta_{k+1} + c_{k+1}),    C_k = p_k / q_{k+1}

where delta_k is the smoothing offset of pose k and c_{k+1} the shift applied at pose k+1. A
correction therefore moves earlier poses by its shift times the share of the variance they had
already accumulated: a fix after a long drift reaches back, one after a recent fix hardly does.
A correction that measured an earlier time (a beacon pass, a collision found after the pairing
window) is placed at the pose it measured, so poses in between take the whole shift.

A pose leaves as `refined` once it is `lag_s` old; the ring holds lag x pose rate entries.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np


@dataclass
class _Entry:
    time_ns: int
    xy: np.ndarray  # live (filtered) position
    heading_rad: float
    covariance: np.ndarray  # 3 x 3 live
    variance_before: float  # q: position variance before any correction at this pose
    variance_after: float  # p
    offset: np.ndarray  # delta: smoothing offset accumulated so far


class FixedLagSmoother:
    def __init__(self, lag_s: float, max_entries: int):
        self.lag_ns = int(lag_s * 1e9)
        self.entries: deque[_Entry] = deque(maxlen=max_entries)

    def add(self, time_ns: int, xy: np.ndarray, heading_rad: float, covariance: np.ndarray) -> list[tuple]:
        """A live pose; returns the (time_ns, x, y, heading, covariance) poses that reached the lag."""
        variance = 0.5 * float(covariance[0, 0] + covariance[1, 1])
        if self.entries and time_ns <= self.entries[-1].time_ns:
            return []  # out of order: the live pose was published, the refined track skips it
        out = []
        if len(self.entries) == self.entries.maxlen:
            out.append(self._emit(self.entries.popleft()))
        self.entries.append(_Entry(time_ns, np.array(xy, dtype=float), heading_rad, covariance, variance, variance,
                                   np.zeros(2)))
        while self.entries and time_ns - self.entries[0].time_ns >= self.lag_ns:
            out.append(self._emit(self.entries.popleft()))
        return out

    def correct(self, measured_ns: int, shift: np.ndarray, variance_after: float) -> None:
        """A correction `shift` applied now, measured at `measured_ns`; `variance_after` at the newest pose."""
        if not self.entries:
            return
        newest = self.entries[-1]
        newest.variance_after = min(variance_after, newest.variance_after)
        running = np.array(shift, dtype=float)
        # Poses from the measured one on shift with it: the dead reckoning since then is unchanged.
        k = len(self.entries) - 1
        while k > 0 and self.entries[k].time_ns > measured_ns:
            self.entries[k].offset += running
            k -= 1
        self.entries[k].offset += running
        # Earlier poses take their share of the variance accumulated up to the measured pose.
        for j in range(k - 1, -1, -1):
            before = self.entries[j + 1].variance_before
            running = min(self.entries[j].variance_after / before, 1.0) * running if before > 0 else 0.0 * running
            self.entries[j].offset += running

    def flush(self) -> list[tuple]:
        """Everything still held (end of session)."""
        out = [self._emit(entry) for entry in self.entries]
        self.entries.clear()
        return out

    @staticmethod
    def _emit(entry: _Entry) -> tuple:
        xy = entry.xy + entry.offset
        return entry.time_ns, float(xy[0]), float(xy[1]), entry.heading_rad, entry.covariance
