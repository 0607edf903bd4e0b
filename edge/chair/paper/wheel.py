"""Wheel-gyro travel (the wheelchair paper, eq. 3-5), pure functions on arrays."""

from __future__ import annotations

import numpy as np


def wheel_rotation_deg(time_ns: np.ndarray, spin_dps: np.ndarray) -> np.ndarray:
    """Cumulative wheel rotation (deg) at each sample: trapezoid integral of the spin rate (eq. 3).

    `spin_dps` is positive when the chair rolls forward. A gap in the samples is bridged by the
    trapezoid across it (linear interpolation of the rate), as the paper's integral would.
    """
    if len(time_ns) == 0:
        return np.zeros(0)
    dt_s = np.diff(time_ns).astype(np.float64) * 1e-9
    steps = 0.5 * (spin_dps[1:] + spin_dps[:-1]) * dt_s
    return np.concatenate([[0.0], np.cumsum(steps)])


def travel_from_rotation_m(rotation_deg: np.ndarray, diameter_m: float) -> np.ndarray:
    """Wheel travel (m) for a rotation (deg): pi * D * Theta / 360.

    Erratum (paper eq. 4): the paper prints d = R * Theta / 360 with R the wheel *diameter*,
    which drops pi; one turn of a wheel of diameter D rolls pi * D.
    """
    return np.pi * diameter_m * rotation_deg / 360.0


def chair_travel_m(left_travel_m: np.ndarray, right_travel_m: np.ndarray) -> np.ndarray:
    """Chair travel as the mean of both wheels (eq. 5)."""
    return 0.5 * (left_travel_m + right_travel_m)
