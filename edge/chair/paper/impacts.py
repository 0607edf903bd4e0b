"""Impact detection from the seat accelerometer (the wheelchair paper, eq. 7)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PAPER_THRESHOLD_G = 8.0  # chosen in the paper for high precision (its Fig. 5)
MERGE_GAP_S = 0.2  # exceedances closer than this are one impact (impacts last a few ms)


@dataclass(frozen=True)
class Impact:
    time_ns: int  # time of the peak
    peak_g: float


def vibration_g(accel_g: np.ndarray) -> np.ndarray:
    """Z = | |a| - 1 g | for (N, 3) accelerations in g (eq. 7)."""
    return np.abs(np.linalg.norm(accel_g, axis=-1) - 1.0)


def detect_impacts(time_ns: np.ndarray, accel_g: np.ndarray, threshold_g: float = PAPER_THRESHOLD_G) -> list[Impact]:
    """Impacts where Z exceeds `threshold_g`; exceedances within MERGE_GAP_S form one impact."""
    z = vibration_g(accel_g)
    above = np.flatnonzero(z > threshold_g)
    if len(above) == 0:
        return []
    breaks = np.flatnonzero(np.diff(time_ns[above]) > MERGE_GAP_S * 1e9) + 1
    impacts = []
    for group in np.split(above, breaks):
        peak = group[np.argmax(z[group])]
        impacts.append(Impact(int(time_ns[peak]), float(z[peak])))
    return impacts
