"""Telling a browser's rotation rate in rad/s from the W3C's deg/s, against DeviceOrientation
(docs/phone.md, "Bad input"). Pure: no socket, no clock."""

from __future__ import annotations

import math
from typing import Any

from edge.decoders.phone.parse import DEG_PER_RAD, Sample, epoch_ms_to_ns, as_number


def _orientation_quaternion(alpha_deg: float, beta_deg: float, gamma_deg: float) -> tuple[float, float, float, float]:
    """W3C DeviceOrientation (intrinsic Z-X'-Y'': alpha about z, beta about x, gamma about y) as a
    unit quaternion (w, x, y, z): qz(alpha) * qx(beta) * qy(gamma)."""
    a, b, g = (math.radians(v) / 2 for v in (alpha_deg, beta_deg, gamma_deg))
    ca, sa, cb, sb, cg, sg = math.cos(a), math.sin(a), math.cos(b), math.sin(b), math.cos(g), math.sin(g)
    # qz * qx = (ca cb, ca sb, sa sb, sa cb); then * qy(g)
    w, x, y, z = ca * cb, ca * sb, sa * sb, sa * cb
    return (w * cg - y * sg, x * cg - z * sg, w * sg + y * cg, z * cg + x * sg)


class RotationUnitCheck:
    """Tells a browser's rotationRate in rad/s from the spec's deg/s (some browsers got it wrong):
    the angle DeviceOrientation turned through, summed sample to sample, against the rotation rate
    integrated over the same time. Once the phone has turned MIN_TURN_DEG the ratio decides: about
    1 is deg/s; about 1/57.3 is rad/s, and `scale` becomes 57.3 (a problem says so once). Anything
    else is not decided and the sums start again. Steps longer than `gap_ns` are not summed."""

    MIN_TURN_DEG = 180.0  # half a turn: enough that the ratio is far from the 1-vs-57 ambiguity
    DEG_S_RATIO = (0.4, 2.5)
    RAD_S_RATIO = (1 / 150, 1 / 20)

    def __init__(self, gap_ns: int = 250_000_000):
        self.gap_ns = gap_ns
        self.scale = 1.0
        self.decided = False
        self._turned_deg = 0.0
        self._integrated = 0.0  # of |rotation rate| in reported units x s
        self._last_q: tuple[int, tuple[float, float, float, float]] | None = None
        self._last_gyro: tuple[int, float] | None = None

    def orientation(self, rows: list[list[Any]], problems: list[str]) -> None:
        """Rows [t_ms, alpha, beta, gamma, absolute] as the page sends them."""
        for row in rows:
            values = [as_number(v) for v in row[:4]]
            if self.decided or not all(math.isfinite(v) for v in values):
                continue
            time_ns, q = epoch_ms_to_ns(values[0]), _orientation_quaternion(*values[1:])
            if self._last_q is not None and 0 < time_ns - self._last_q[0] <= self.gap_ns:
                dot = min(1.0, abs(sum(u * v for u, v in zip(q, self._last_q[1]))))
                self._turned_deg += math.degrees(2 * math.acos(dot))
            self._last_q = (time_ns, q)
        self._decide(problems)

    def motion(self, samples: list[Sample]) -> None:
        for time_ns, _, gyro, _ in samples:
            if self.decided or not all(math.isfinite(v) for v in gyro):
                continue
            rate = math.sqrt(gyro[0] ** 2 + gyro[1] ** 2 + gyro[2] ** 2)
            if self._last_gyro is not None and 0 < time_ns - self._last_gyro[0] <= self.gap_ns:
                self._integrated += (rate + self._last_gyro[1]) / 2 * (time_ns - self._last_gyro[0]) * 1e-9
            self._last_gyro = (time_ns, rate)

    def _decide(self, problems: list[str]) -> None:
        if self._turned_deg < self.MIN_TURN_DEG:
            return
        ratio = self._integrated / self._turned_deg
        if self.DEG_S_RATIO[0] <= ratio <= self.DEG_S_RATIO[1]:
            self.decided = True
        elif self.RAD_S_RATIO[0] <= ratio <= self.RAD_S_RATIO[1]:
            self.decided, self.scale = True, DEG_PER_RAD
            problems.append(f"rotation rate looks like rad/s, not deg/s (it integrates to {ratio:.3f} of the "
                            f"{self._turned_deg:.0f} deg the orientation turned): converting from now on")
        else:
            problems.append(f"rotation rate and orientation disagree (ratio {ratio:.3f} over "
                            f"{self._turned_deg:.0f} deg): units not decided yet, rotation taken as deg/s")
        self._turned_deg = self._integrated = 0.0
