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

Storage: arrays over the entries, not an object per pose (500 chairs x 30 s at 50 Hz are 750,000
poses: objects of a few arrays each held half a gigabyte), twice the ring's length so the held
entries are always one contiguous slice [start, end): when `end` reaches the arrays' end the held
part moves to the front, one copy per `max_entries` poses. A correction is then a few array
operations over that slice instead of a Python loop over up to 1,500 poses.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import numpy as np

# Columns of `rows`: the live pose, its covariance, q and p of the recursion above, delta.
X, Y, HEADING, COV, BEFORE, AFTER, OFFSET = 0, 1, 2, 3, 12, 13, 14  # COV: 9 columns; OFFSET: 2
_COLUMNS = 16
_ROW = struct.Struct(f"{_COLUMNS}d")  # a row written straight into `rows`' memory: half a numpy row assignment's time


class FixedLagSmoother:
    def __init__(self, lag_s: float, max_entries: int):
        if max_entries < 1:
            raise ValueError(f"smoother max_entries {max_entries} must be at least 1")
        self.lag_ns = int(lag_s * 1e9)
        self.max_entries = max_entries
        self.time_ns = np.zeros(2 * max_entries, dtype=np.int64)
        self.rows = np.zeros((2 * max_entries, _COLUMNS))
        self.start = self.end = 0
        self.newest_ns = 0  # time_ns[end - 1] while any is held, as an int (a numpy read per pose less)

    def __len__(self) -> int:
        return self.end - self.start

    def add(self, time_ns: int, x: float, y: float, heading_rad: float, covariance: Sequence[float],
            build: bool = True) -> list[tuple | None]:
        """A live pose (`covariance` its 3 x 3, row-major: 9 floats); returns the poses that reached the
        lag, each as (time_ns, x, y, heading, covariance 9 floats), or as None when not `build` (nobody
        takes the refined track: they are only counted)."""
        if self.end > self.start and time_ns <= self.newest_ns:
            return []  # out of order: the live pose was published, the refined track skips it
        out = []
        if self.end - self.start == self.max_entries:
            out.append(self._emit(self.start) if build else None)
            self.start += 1
        if self.end == len(self.time_ns):
            held = slice(self.start, self.end)
            count = self.end - self.start
            self.time_ns[:count] = self.time_ns[held]
            self.rows[:count] = self.rows[held]
            self.start, self.end = 0, count
        variance = 0.5 * (covariance[0] + covariance[4])
        k = self.end
        self.time_ns[k] = self.newest_ns = time_ns
        _ROW.pack_into(self.rows, k * _ROW.size, x, y, heading_rad, *covariance, variance, variance, 0.0, 0.0)
        self.end += 1
        while self.end > self.start and time_ns - int(self.time_ns[self.start]) >= self.lag_ns:
            out.append(self._emit(self.start) if build else None)
            self.start += 1
        return out

    def correct(self, measured_ns: int, shift: np.ndarray, variance_after: float) -> None:
        """A correction `shift` applied now, measured at `measured_ns`; `variance_after` at the newest pose."""
        if self.end == self.start:
            return
        rows = self.rows[self.start:self.end]
        rows[-1, AFTER] = min(variance_after, rows[-1, AFTER])
        # Poses from the measured one on (the last not after it, else the oldest) shift with it: the
        # dead reckoning since then is unchanged.
        k = max(int(np.searchsorted(self.time_ns[self.start:self.end], measured_ns, side="right")) - 1, 0)
        shift = np.asarray(shift, dtype=float)
        rows[k:, OFFSET:OFFSET + 2] += shift
        if k == 0:
            return
        # Earlier poses take their share of the variance accumulated up to the measured pose: pose j
        # moves by the shift times the product of min(p_i / q_{i+1}, 1) from j to k - 1, multiplied
        # on in that order from the shift (multiply.accumulate), as a loop from k - 1 down would.
        before = rows[1:k + 1, BEFORE]
        ratio = np.where(before > 0, np.minimum(rows[:k, AFTER] / np.where(before > 0, before, 1.0), 1.0), 0.0)
        factors = np.empty((k + 1, 2))
        factors[0] = shift
        factors[1:] = ratio[::-1, None]
        rows[:k, OFFSET:OFFSET + 2] += np.multiply.accumulate(factors, axis=0)[1:][::-1]

    def flush(self) -> list[tuple]:
        """Everything still held (end of session)."""
        out = [self._emit(k) for k in range(self.start, self.end)]
        self.start = self.end = 0
        return out

    def _emit(self, k: int) -> tuple:
        row = self.rows[k].tolist()  # one conversion, then float arithmetic (the same bits as numpy's)
        return (int(self.time_ns[k]), row[X] + row[OFFSET], row[Y] + row[OFFSET + 1], row[HEADING], row[COV:COV + 9])
