"""An agent's recent live poses, for looking back to a measured time (a fix, a beacon pass, a contact).

Arrays over the poses, not a tuple of arrays per pose (500 chairs x 1,024 poses held a quarter of
a gigabyte that way), twice `capacity` long so the held poses are one contiguous slice
[start, end): when `end` reaches the arrays' end the newest `capacity` move to the front, one copy
per `capacity` poses. Poses are kept in arrival order, which is time order unless a clock offset
moved; a look-up takes the last pose not after the time, searching from the newest.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import numpy as np

_ROW = struct.Struct("7d")  # a row written straight into `rows`' memory: half a numpy row assignment's time
SCAN = 8  # poses looked at one by one from the newest before a vectorised search (most look-ups are recent)


class PoseHistory:
    def __init__(self, capacity: int):
        if capacity < 1:
            raise ValueError(f"pose history capacity {capacity} must be at least 1")
        self.capacity = capacity
        self.time_ns = np.zeros(2 * capacity, dtype=np.int64)
        self.rows = np.zeros((2 * capacity, 7))  # x, y, covariance 2 x 2 (row-major), heading
        self.start = self.end = 0

    def __len__(self) -> int:
        return self.end - self.start

    def append(self, time_ns: int, x: float, y: float, covariance: Sequence[float], heading_rad: float) -> None:
        """A live pose; `covariance` the edge's 3 x 3, row-major (its position block is kept)."""
        if self.end == len(self.time_ns):
            keep = slice(max(self.start, self.end - self.capacity + 1), self.end)
            count = keep.stop - keep.start
            self.time_ns[:count] = self.time_ns[keep]
            self.rows[:count] = self.rows[keep]
            self.start, self.end = 0, count
        elif self.end - self.start == self.capacity:
            self.start += 1
        self.time_ns[self.end] = time_ns
        _ROW.pack_into(self.rows, self.end * _ROW.size, x, y, covariance[0], covariance[1], covariance[3], covariance[4],
                       heading_rad)
        self.end += 1

    def clear(self) -> None:
        self.start = self.end = 0

    def last_at(self, time_ns: int) -> int | None:
        """Index (0 = oldest held) of the last pose not after `time_ns`; None if all are after it."""
        times = self.time_ns
        for k in range(self.end - 1, max(self.end - 1 - SCAN, self.start - 1), -1):
            if times[k] <= time_ns:
                return k - self.start
        if self.end - self.start <= SCAN:
            return None
        found = np.flatnonzero(times[self.start:self.end - SCAN] <= time_ns)
        return int(found[-1]) if len(found) else None

    def time_at(self, index: int) -> int:
        return int(self.time_ns[self.start + index])

    def position(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """(xy, covariance 2 x 2) of the pose at `index`: new arrays, the caller's to keep."""
        row = self.rows[self.start + index]
        return row[0:2].copy(), row[2:6].reshape(2, 2).copy()

    def heading(self, index: int) -> float:
        return float(self.rows[self.start + index, 6])
