"""The magnetometer as a gated aid to a phone's heading (edge/pedestrian/estimator.py).

The indoor-navigation paper found magnetic heading unusable on an upper floor (the field halved
by the building's steel), so the gyro carries the heading and the magnetometer only nudges the
offset between the gyro's frame and the venue's, and only while its readings look like the
undisturbed Earth field the venue file states (`magnetic_field_ut`, `magnetic_dip_deg`):
1. per sample, the reading is turned into the earth frame by the AHRS attitude; it passes the
   gate when its strength is within `field_tolerance` of the venue's and its dip within
   `dip_tolerance_deg` (steel bends the field's direction and changes its strength together);
2. a passing sample measures the offset: magnetic north's direction in the venue frame
   (`magnetic_north_deg`) minus its direction in the gyro frame;
3. per step, when at least `min_clean_fraction` of the step's samples passed, their circular mean
   is one measurement with `heading_sd_rad`: the caller applies it as a Kalman update of
   (x, y, heading), gated at `gate_sigma` (a disturbance that slipped through the field gate).
Per-step measurements, not per-sample: neighbouring samples see the same disturbance, so 50 of
them carry little more than one. State: two sums and two counts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MagneticSettings:
    # Field gate: a mall's ground floor (ILC site 1) reads 38-56 uT against WMM's 48.8 uT; the
    # paper's 12th floor about half the field. 15 % passes the cleaner half of the readings there.
    field_tolerance: float = 0.15
    dip_tolerance_deg: float = 10.0
    # One step's measurement: indoor disturbances that pass the gate still bend the heading by
    # 10-30 deg (ILC site 1, per 5-15 m stretch: docs/pdr-estimator.md), and the same disturbance
    # lasts over the 5-15 m, i.e. 7-20 steps: the per-step measurements are not independent. 40 deg
    # per step is a 20 deg disturbance shared by about 4 steps (chosen from 10-50 deg on ILC walks
    # 1-5: p75 4.35 m at 20 deg, 3.65 m at 40 deg).
    heading_sd_rad: float = math.radians(40.0)
    min_clean_fraction: float = 0.5
    gate_sigma: float = 3.0


@dataclass(frozen=True)
class VenueField:
    """The venue's undisturbed field (protocol/session.py Venue.magnetic_*)."""

    north_rad: float  # magnetic north's direction in the venue frame, counter-clockwise from +x
    field_ut: float
    dip_rad: float


class MagneticAid:
    """Accumulate a step's gated offset measurements; `measurement()` at the step's end."""

    def __init__(self, venue: VenueField, settings: MagneticSettings = MagneticSettings()):
        self.venue = venue
        self.settings = settings
        self.sum = np.zeros(2)  # unit vectors of the offsets measured in this step
        self.clean = 0
        self.seen = 0
        self.used = 0  # steps whose measurement went to the filter (counted by the caller's update)
        self.rejected = 0  # steps gated out: too few clean samples, or the innovation too large

    def add(self, earth_from_phone: np.ndarray, mag_ut: tuple[float, float, float]) -> None:
        """One sample: its reading in the earth frame of the AHRS (z up, heading counter-clockwise)."""
        self.seen += 1
        earth = earth_from_phone @ np.asarray(mag_ut, dtype=float)
        horizontal = math.hypot(earth[0], earth[1])
        strength = math.hypot(horizontal, earth[2])
        dip = math.atan2(-earth[2], horizontal)  # the field points down in the northern hemisphere
        if (abs(strength - self.venue.field_ut) > self.settings.field_tolerance * self.venue.field_ut
                or abs(dip - self.venue.dip_rad) > math.radians(self.settings.dip_tolerance_deg)):
            return
        offset = self.venue.north_rad - math.atan2(earth[1], earth[0])
        self.sum += (math.cos(offset), math.sin(offset))
        self.clean += 1

    def measurement(self) -> float | None:
        """The step's offset measurement (rad), or None; starts the next step either way."""
        enough = self.seen > 0 and self.clean >= self.settings.min_clean_fraction * self.seen
        value = math.atan2(self.sum[1], self.sum[0]) if enough else None
        if value is None and self.seen:
            self.rejected += 1
        self.sum[:] = 0.0
        self.clean = self.seen = 0
        return value
