"""Our hub's corrections for chairs: beacon closest approach and contacts as relative constraints.

Pure functions over `edge.chair.estimator.ChairState`; the hub (or `reckon eval`) decides when.
- A beacon is a *zone*, not a range: RSSI ranging is poor (path-loss exponent 1.8-4.3 in one
  building, body loss 3-5 dB; algorithms.md). A pass near the goal gives one fix at the moment of
  the strongest sighting, with an uncertainty that grows with the distance that RSSI suggests.
- A contact says the two chairs were about a chair-width apart (centres ~0.9 m), not on one
  point as the paper's eq. 8 has it: a range constraint on both, chi-square gated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from edge.chair.estimator import N, X, Y, ChairState
from protocol.session import Beacon

PATH_LOSS_EXPONENT = 2.0  # free space; the hub cannot know the hall's
RECEIVER_HEIGHT_M = 0.5
BEACON_BASE_SD_M = 2.0  # a pass peak is 4-8 dB above the mean (shadowing 4 dB, fading 2 dB): metres, not a zone
BEACON_MAX_HORIZONTAL_M = 2.5  # weaker peaks say too little to be worth a fix
CONTACT_DISTANCE_M = 0.9  # two chair discs of ~0.45 m radius touching
CONTACT_SD_M = 0.3  # centres 0.6-1.2 m apart in frontal and lateral contacts
CONTACT_GATE_CHI2 = 10.83  # 99.9 %, 1 dof


@dataclass(frozen=True)
class BeaconFix:
    xy: np.ndarray
    covariance: np.ndarray
    horizontal_m: float  # the distance the peak RSSI suggests


def beacon_fix(beacon: Beacon, peak_rssi_dbm: float) -> BeaconFix | None:
    """A position fix from the strongest sighting of one pass, or None when too weak."""
    slant = 10.0 ** ((beacon.tx_power_dbm - peak_rssi_dbm) / (10.0 * PATH_LOSS_EXPONENT))
    height = beacon.height_m - RECEIVER_HEIGHT_M
    horizontal = math.sqrt(max(slant * slant - height * height, 0.0))
    if horizontal > BEACON_MAX_HORIZONTAL_M:
        return None
    variance = horizontal**2 + BEACON_BASE_SD_M**2
    return BeaconFix(np.array([beacon.x_m, beacon.y_m]), np.eye(2) * variance, horizontal)


def contact_update(a: ChairState, b: ChairState, contact_m: float = CONTACT_DISTANCE_M,
                   sd_m: float = CONTACT_SD_M, gate_chi2: float = CONTACT_GATE_CHI2) -> tuple[ChairState, ChairState, bool]:
    """Pull two chairs to `contact_m` apart along the line between them (EKF on both; gated).

    The two filters are independent here (cross-covariance taken as zero), the approximation a
    per-chair hub makes; a joint filter would keep the correlation the contact creates.
    """
    delta = a.mean[:2] - b.mean[:2]
    distance = float(np.hypot(*delta))
    if distance < 1e-6:
        return a, b, False
    unit = delta / distance
    h = np.zeros(2 * N)
    h[X], h[Y] = unit
    h[N + X], h[N + Y] = -unit
    cov = np.zeros((2 * N, 2 * N))
    cov[:N, :N], cov[N:, N:] = a.cov, b.cov
    variance = float(h @ cov @ h) + sd_m**2
    innovation = contact_m - distance
    if innovation * innovation / variance > gate_chi2:
        return a, b, False
    gain = cov @ h / variance
    mean = np.concatenate([a.mean, b.mean]) + gain * innovation
    cov = cov - np.outer(gain, h @ cov)
    return (replace(a, mean=mean[:N], cov=cov[:N, :N]), replace(b, mean=mean[N:], cov=cov[N:, N:]), True)
