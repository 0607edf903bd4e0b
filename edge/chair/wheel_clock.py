"""A wheel device's clock offset from the seat's, learned from the chair's yaw that both see.

The three IMUs of a chair are three devices with three clocks; after a sync their offsets still
differ by tens of milliseconds (docs/simulator.md: SD 1-50 ms per device in the world population)
and drift apart at crystal rates (tens of ppm). For distance that hardly matters, but the axle
IMUs' yaw bridges a silent seat through pivots at 300+ deg/s, where 100 ms is 30 deg, and a turn
reversing inside the misalignment is bridged the wrong way.

Both the seat gyro and each axle IMU measure the chair's yaw rate (the axle's times cos camber):
g(t) = a w(t + offset). Regressing the seat's rate g on the wheel's rate w and its time derivative
w', both read at the current offset, gives g ~ a w + b w' ~ a w(t + b / a): the offset is off by
b / a. The offset moves by that (clipped) once the evidence is strong enough to pin it, then the
sums start over at the new offset (Gauss-Newton in constant memory; a turn reversal is what pins
it, a straight run tells nothing and moves nothing).

The edge runs the compiled twin of `add` and `_move` (edge/chair/merge_kernel.py's `_clock_add`,
`_clock_move`); change them here first, then there.
"""

from __future__ import annotations

import math

UPDATE_S = 1.0  # evidence collected at least this long before the offset moves
MAX_WINDOW_S = 20.0  # evidence older than this is dropped unused (a chair that never turns)
MAX_STEP_NS = 20_000_000  # one move at most (the regression is linear only near the true offset)
SETTLED_SE_NS = 3_000_000  # the estimate's standard error must be below this for it to move
GAIN = 0.5  # share of the estimate moved: successive windows' errors average out instead of jittering the offset
MAX_OFFSET_NS = 500_000_000  # never beyond (docs: device clocks are synced well inside 0.5 s)


class WheelClock:
    """`add(seat_dps, wheel_dps, dt)` for consecutive samples; `offset_ns`: wheel clock minus seat clock."""

    def __init__(self) -> None:
        self.offset_ns = 0
        self.updates = 0  # moves made (diagnostic)
        self._previous = (math.nan, math.nan, math.nan)  # (w[k-2], w[k-1], g[k-1])
        self._sums = [0.0] * 6  # ww, wd, dd, gw, gd, gg
        self._count = 0
        self._span_s = 0.0

    def restart(self) -> None:
        """The samples stop being consecutive (a gap): the derivative needs three in a row."""
        self._previous = (math.nan, math.nan, math.nan)

    def add(self, seat_dps: float, wheel_dps: float, dt: float) -> None:
        """Mid-step rates of one step, seat and wheel (the wheel read at the current offset)."""
        w2, w1, g1 = self._previous
        self._previous = (w1, wheel_dps, seat_dps)
        if not math.isfinite(w2):
            return
        derivative = (wheel_dps - w2) / (2.0 * dt)  # at the previous step, as w1 and g1
        s = self._sums
        s[0] += w1 * w1
        s[1] += w1 * derivative
        s[2] += derivative * derivative
        s[3] += g1 * w1
        s[4] += g1 * derivative
        s[5] += g1 * g1
        self._count += 1
        self._span_s += dt
        if self._span_s >= UPDATE_S:
            self._move()

    def _move(self) -> None:
        ww, wd, dd, gw, gd, gg = self._sums
        det = ww * dd - wd * wd
        done = self._span_s >= MAX_WINDOW_S
        if det > 0.0 and ww > 0.0:
            a = (gw * dd - gd * wd) / det
            b = (gd * ww - gw * wd) / det
            residual = max(gg - a * gw - b * gd, 0.0)
            # the variance of b: the residual's per sample times the (b, b) entry of the inverse normal matrix
            b_var = residual / max(self._count - 2, 1) * ww / det
            if a > 0.0 and math.sqrt(b_var) / a * 1e9 < SETTLED_SE_NS:
                step = max(-MAX_STEP_NS, min(MAX_STEP_NS, int(GAIN * b / a * 1e9)))
                self.offset_ns = max(-MAX_OFFSET_NS, min(MAX_OFFSET_NS, self.offset_ns + step))
                self.updates += 1
                done = True
        if done:
            self._sums = [0.0] * 6
            self._count = 0
            self._span_s = 0.0
