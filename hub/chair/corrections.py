"""Our hub's corrections for chairs: beacon closest approach and contacts as relative constraints.

Pure functions over `edge.chair.estimator.ChairState`; the hub (or `reckon eval`) decides when.
- A beacon is a closest approach, not a range: RSSI ranging is poor (path-loss exponent 1.8-4.3
  in one building, body loss 3-5 dB; algorithms.md), and the venue file's figures may be wrong. A
  pass that peaks near the beacon's learned level gives one fix at the moment of its strongest
  sighting: where that beacon's close passes have put chairs, or, when the pose says the pass was
  more likely a far one, where its far passes have (`BeaconLevels`).
- A contact says the two chairs were about a chair-width apart (centres ~0.9 m), not on one
  point as the paper's eq. 8 has it: a range constraint on both, chi-square gated.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

from edge.chair.state import N, X, Y, ChairState
from protocol.session import Beacon

PATH_LOSS_EXPONENT = 2.0  # free space; the hub cannot know the hall's
RECEIVER_HEIGHT_M = 0.5
BEACON_BASE_SD_M = 3.0  # a close pass's peak: 1.3-2.4 m per axis about where its kind puts it, plus ~1 m of that
# offset still unlearned (worlds 2 and 3); chosen from 2 / 2.5 / 3 / 4 on worlds 1-10
BEACON_MAX_HORIZONTAL_M = 2.5  # weaker peaks (by the venue file's figures) say too little to be worth a fix
PASS_FLOOR_DBM = -72.0  # sightings above this (about 4 m from a goal, by the venue file) belong to a pass
CLOSE_M = 1.0  # a close pass: within about a metre of the spot under the beacon
LEVEL_PASSES = 16  # pass peaks kept per beacon (every chair's): its level is the second strongest
MIN_PASSES = 3  # until then, the venue file's level at CLOSE_M in free space
PASS_DB = 12.0  # ... and so do sightings this far below the learned level (a hall quieter than its file)
ACCEPT_DB = 3.0  # a pass peaking this close to the level was a close one
FIX_PRIOR_SD_M = 1.5  # a close pass's distance from the beacon, until the beacon's own are learned
FIX_PRIOR_WEIGHT = 3.0  # the prior counts as this many fixes
FIX_MEMORY = 30.0  # fixes: forgetting of the learned spread
COMPONENT_FLOOR_SD_M = 0.5  # RSSI puts a chair no closer than this to where a kind of pass puts it
FAR_PRIOR_SD_M = 5.0  # a candidate that was not close: somewhere in the beacon's end of the court
CLOSE_PRIOR_SHARE = 0.5  # of a beacon's candidate passes, the share that were close, until its own are counted
CLOSE_PRIOR_WEIGHT = 5.0  # the prior counts as this many candidates
# Of a beacon's candidates, the share that came from nowhere near it (a chair parked across the court,
# listening for seconds, keeps the strongest of many fades; a reflection), spread over the whole court.
# Chosen from 0.1 / 0.3 / learned per beacon (prior 0.1) on worlds 1-10 and 31-50: beacons alone worse than
# dead reckoning by > 5 % in 4 / 2 / 5 worlds (7 without), beacon + collision median 0.764 / 0.778 / 0.779 m.
STRAY_SHARE = 0.1
CONTACT_DISTANCE_M = 0.9  # two chair discs of ~0.45 m radius touching, until the venue's contacts teach it
CONTACT_SD_M = 0.3  # centres 0.6-1.2 m apart in frontal and lateral contacts
CONTACT_FLOOR_SD_M = 0.1  # never trusted closer than this (chairs meet at any angle)
CONTACT_PRIOR_WEIGHT = 5.0  # the prior counts as this many contacts
CONTACT_MEMORY = 50.0  # contacts: forgetting of the learned distance
CONTACT_GATE_CHI2 = 10.83  # 99.9 %, 1 dof
CONTACT_TIMING_FLOOR_SD_S = 0.003  # two 200 Hz samplings of one pulse differ by this much anyway
# The timing prior counts as one contact (5, as the distance's, kept the pairing window's looseness for
# a minute of play: worlds 1-10, false pairs 2 against 1 of 423, world 7 beacon + collision 0.54 against 0.48 m).
CONTACT_TIMING_PRIOR_WEIGHT = 1.0
FIX_GATE_CHI2 = 13.8  # 99.9 %, 2 dof


def free_space_level_dbm(beacon: Beacon, horizontal_m: float) -> float:
    """RSSI the venue file promises at `horizontal_m` from under the beacon, path-loss exponent 2."""
    slant_m = math.hypot(horizontal_m, beacon.height_m - RECEIVER_HEIGHT_M)
    return beacon.tx_power_dbm - 20.0 * math.log10(max(slant_m, 0.1))


@dataclass
class _Component:
    """One kind of candidate pass, learned by EM with forgetting: where the chair was against the beacon
    (mean offset) and how widely (per axis, beyond the poses' own variance), blended with a prior."""

    prior_sd_m: float
    offset_sum_m: np.ndarray = field(default_factory=lambda: np.zeros(2))
    spread_sum_m2: float = 0.0
    weight: float = 0.0

    def offset_m(self) -> np.ndarray:
        return self.offset_sum_m / (self.weight + FIX_PRIOR_WEIGHT)

    def variance_m2(self) -> float:
        """Never below COMPONENT_FLOOR_SD_M: poses that state more variance than they have would drive the
        spread beyond it negative."""
        learned = (self.spread_sum_m2 + FIX_PRIOR_WEIGHT * self.prior_sd_m**2) / (self.weight + FIX_PRIOR_WEIGHT)
        return max(learned, COMPONENT_FLOOR_SD_M**2)

    def learn(self, responsibility: float, from_beacon: np.ndarray, pose_covariance: np.ndarray) -> None:
        forget = 1.0 - 1.0 / FIX_MEMORY
        deviation = from_beacon - self.offset_m()
        self.offset_sum_m = forget * self.offset_sum_m + responsibility * from_beacon
        self.spread_sum_m2 = forget * self.spread_sum_m2 + responsibility * 0.5 * (
            float(deviation @ deviation) - float(np.trace(pose_covariance)))
        self.weight = forget * self.weight + responsibility


@dataclass
class BeaconLevel:
    """What the hub has learned of one beacon from every chair's passes (fixed size)."""

    peaks: deque = field(default_factory=lambda: deque(maxlen=LEVEL_PASSES))
    close: _Component = field(default_factory=lambda: _Component(FIX_PRIOR_SD_M))
    far: _Component = field(default_factory=lambda: _Component(FAR_PRIOR_SD_M))
    close_sum: float = 0.0  # responsibilities of every candidate pass, with forgetting
    close_weight: float = 0.0  # ... candidate passes counted
    close_fixes: int = 0
    far_fixes: int = 0
    stray: int = 0  # candidates whose pose put them where neither kind of pass does: no fix


class BeaconLevels:
    """Passes of the venue's beacons: the venue file's figures, checked by what each beacon shows.

    RSSI is a poor range, and the venue file's tx power and height may both be wrong (a beacon on
    the floor instead of hung, 6 dB off its label). A pass's peak is the moment of closest
    approach; whether it was close, two things say:
    - the venue file: the peak's distance h through its tx power and height in free space; a pass
      with h <= BEACON_MAX_HORIZONTAL_M is a candidate, with sigma sqrt(h^2 + BEACON_BASE_SD_M^2);
    - the beacon itself: its level, the second strongest of its last LEVEL_PASSES pass peaks over
      all chairs (the strongest alone would follow one lucky fade; most passes are not close, so
      a median would learn what far looks like); a pass peaking within ACCEPT_DB of it is a
      candidate too (a hall quieter than its file), and a sighting within PASS_DB of it is part of
      a pass.
    A candidate is still only probably close: with a low path-loss exponent and deep shadowing a
    pass 15 m away peaks as high as one under the beacon. So each beacon learns two kinds of
    candidate, by EM over every chair's (each candidate weighted by how likely it was of each kind,
    with forgetting): close passes, where the chair was at a learned offset from the beacon (a
    chair peaks in front of a goal, on the court side, not under it: 1-4 m in our worlds) within
    the venue file's sigma or the spread they have shown, whichever is larger; and far ones, in the
    beacon's end of the court (prior FAR_PRIOR_SD_M). A candidate's fix is the likelier kind's
    point, its covariance divided by that kind's probability. A single wide Gaussian was not
    robust: far passes widened the spread they were judged by until a fix 15 m off passed the gate,
    and in a hall whose chairs peak 3 m in front of the goal every fix pulled them under it.
    Neither kind is a catch-all: a candidate may have come from anywhere on the court (STRAY_SHARE
    of them, evenly over its area). One whose pose says so is no fix, and every fix's covariance is
    divided by the probability that it was a pass at all. The far kind's 5 m alone let a chair 20 m
    from the beacon, its pose good to half a metre, take a fix at the beacon (chi-square 7.7 < 13.8):
    the fix moved its position little, but through the position's correlation with the heading it
    turned the chair by tens of degrees (world 37: that chair 1.5 -> 4.3 m mean error).
    """

    def __init__(self, beacons: tuple[Beacon, ...], court_area_m2: float) -> None:
        if not court_area_m2 > 0.0:
            raise ValueError(f"court area {court_area_m2} m^2 must be positive")
        self.stray_density = STRAY_SHARE / court_area_m2
        self.beacons = {beacon.id: beacon for beacon in beacons}
        self.levels = {beacon.id: BeaconLevel() for beacon in beacons}
        self._floors: dict[str, float] = {}  # pass_floor_dbm's, until the beacon's peaks change (read per sighting)

    def level_dbm(self, beacon_id: str) -> float:
        record = self.levels[beacon_id]
        if len(record.peaks) >= MIN_PASSES:
            return float(sorted(record.peaks)[-2])
        return free_space_level_dbm(self.beacons[beacon_id], CLOSE_M)

    def pass_floor_dbm(self, beacon_id: str) -> float:
        """Sightings weaker than this are not part of a pass."""
        floor = self._floors.get(beacon_id)
        if floor is None:
            floor = self._floors[beacon_id] = min(PASS_FLOOR_DBM, self.level_dbm(beacon_id) - PASS_DB)
        return floor

    def close(self, beacon_id: str, peak_dbm: float) -> np.ndarray | None:
        """A pass ended at this peak: the covariance of its fix, were it close, if it is a candidate; else
        None. (The peak joins the beacon's record.)"""
        beacon, level = self.beacons[beacon_id], self.level_dbm(beacon_id)
        self.levels[beacon_id].peaks.append(peak_dbm)
        self._floors.pop(beacon_id, None)
        slant = 10.0 ** ((beacon.tx_power_dbm - peak_dbm) / (10.0 * PATH_LOSS_EXPONENT))
        horizontal = math.sqrt(max(slant * slant - (beacon.height_m - RECEIVER_HEIGHT_M) ** 2, 0.0))
        if horizontal > BEACON_MAX_HORIZONTAL_M and peak_dbm < level - ACCEPT_DB:
            return None
        stated = min(horizontal, BEACON_MAX_HORIZONTAL_M) ** 2 + BEACON_BASE_SD_M**2
        return np.eye(2) * max(stated, self.levels[beacon_id].close.variance_m2())

    def close_share(self, beacon_id: str) -> float:
        """Of this beacon's candidate passes, the share that were close (with the prior)."""
        record = self.levels[beacon_id]
        return (record.close_sum + CLOSE_PRIOR_WEIGHT * CLOSE_PRIOR_SHARE) / (record.close_weight + CLOSE_PRIOR_WEIGHT)

    def describe(self, beacon_id: str) -> str:
        """What this beacon has shown, for the hub's closing summary."""
        record = self.levels[beacon_id]
        dx, dy = record.close.offset_m()
        return (f"{record.close_fixes} close-pass fixes, {record.far_fixes} far, {record.stray} stray; close passes "
                f"{self.close_share(beacon_id):.0%} of candidates, at ({dx:+.1f}, {dy:+.1f}) m from the beacon "
                f"+- {math.sqrt(record.close.variance_m2()):.1f} m; level {self.level_dbm(beacon_id):.0f} dBm")

    def fix(self, beacon_id: str, pose_xy: np.ndarray, pose_covariance: np.ndarray,
            close_covariance: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool] | None:
        """(point, covariance, close) of a candidate's fix for a pose at its peak, or None for a stray; the
        beacon learns from it."""
        record, beacon = self.levels[beacon_id], self.beacons[beacon_id]
        at = np.array([beacon.x_m, beacon.y_m])
        from_beacon = pose_xy - at
        far_covariance = np.eye(2) * record.far.variance_m2()
        share = self.close_share(beacon_id)
        near = share * _density(from_beacon - record.close.offset_m(), pose_covariance + close_covariance)
        far = (1.0 - share) * _density(from_beacon - record.far.offset_m(), pose_covariance + far_covariance)
        responsibility = near / (near + far) if near + far > 0.0 else 0.0
        genuine = (1.0 - STRAY_SHARE) * (near + far)
        genuine = genuine / (genuine + self.stray_density)
        fix = None
        if genuine < 0.5:
            record.stray += 1
        elif responsibility >= 0.5:
            fix = at + record.close.offset_m(), close_covariance / (responsibility * genuine), True
            record.close_fixes += 1
        else:
            fix = at + record.far.offset_m(), far_covariance / ((1.0 - responsibility) * genuine), False
            record.far_fixes += 1
        record.close.learn(genuine * responsibility, from_beacon, pose_covariance)
        record.far.learn(genuine * (1.0 - responsibility), from_beacon, pose_covariance)
        forget = 1.0 - 1.0 / FIX_MEMORY
        record.close_sum = forget * record.close_sum + genuine * responsibility
        record.close_weight = forget * record.close_weight + genuine
        return fix


def mahalanobis2(deviation: np.ndarray, covariance: np.ndarray) -> float:
    """The squared Mahalanobis size of `deviation` under `covariance` (what the chi-square gates compare)."""
    return float(deviation @ np.linalg.solve(covariance, deviation))


def _density(deviation: np.ndarray, covariance: np.ndarray) -> float:
    """The 2-D normal density of `deviation` under `covariance`."""
    return math.exp(-0.5 * mahalanobis2(deviation, covariance)) / (
        2.0 * math.pi * math.sqrt(float(np.linalg.det(covariance))))


@dataclass
class ContactDistance:
    """How far apart two chairs' centres are when they touch, learned from the contacts the hub took.

    Chairs differ (sports chairs with bumpers, day chairs, footplates first or wheels first): the
    centres of two touching chairs are 0.6-1.2 m apart. Each taken pair's estimated distance
    updates a running mean and a spread beyond the two poses' own variance, blended with the prior
    CONTACT_DISTANCE_M +- CONTACT_SD_M."""

    sum_m: float = 0.0
    sum_sq_m2: float = 0.0  # squared deviations from the running mean, beyond the poses' variance
    weight: float = 0.0

    def mean_m(self) -> float:
        return (self.sum_m + CONTACT_PRIOR_WEIGHT * CONTACT_DISTANCE_M) / (self.weight + CONTACT_PRIOR_WEIGHT)

    def variance_m2(self) -> float:
        learned = (self.sum_sq_m2 + CONTACT_PRIOR_WEIGHT * CONTACT_SD_M**2) / (self.weight + CONTACT_PRIOR_WEIGHT)
        return max(learned, CONTACT_FLOOR_SD_M**2)

    def taken(self, distance_m: float, pose_variance_m2: float) -> None:
        forget = 1.0 - 1.0 / CONTACT_MEMORY
        deviation = distance_m - self.mean_m()
        self.sum_m = forget * self.sum_m + distance_m
        self.sum_sq_m2 = forget * self.sum_sq_m2 + deviation * deviation - pose_variance_m2
        self.weight = forget * self.weight + 1.0


@dataclass
class ContactTiming:
    """How far apart in venue time a contact's two impacts are, learned from the contacts the hub took
    (the pairs' squared differences, blended with the prior `prior_sd_s` as CONTACT_TIMING_PRIOR_WEIGHT
    contacts). The clocks' alignment (hub/clocks.py: two devices' smallest link latencies differ by a
    few ms) and each seat sampling the pulse (5 ms at 200 Hz) make it milliseconds, so two bumps that
    merely fall in one pairing window (a pile-up of two contacts, a coincidence) are told from one
    contact by their timing."""

    prior_sd_s: float  # the pairing window's worth: as loose as the clocks the venue was set up for
    sum_sq_s2: float = 0.0
    weight: float = 0.0

    def variance_s2(self) -> float:
        prior = CONTACT_TIMING_PRIOR_WEIGHT
        learned = (self.sum_sq_s2 + prior * self.prior_sd_s**2) / (self.weight + prior)
        return max(learned, CONTACT_TIMING_FLOOR_SD_S**2)

    def taken(self, difference_s: float) -> None:
        forget = 1.0 - 1.0 / CONTACT_MEMORY
        self.sum_sq_s2 = forget * self.sum_sq_s2 + difference_s * difference_s
        self.weight = forget * self.weight + 1.0


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
