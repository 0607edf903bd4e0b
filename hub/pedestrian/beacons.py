"""BLE beacons as proximity fixes for people with phones: the moment of closest approach.

A phone hears a venue beacon from tens of metres (down to -100 dBm), so a sighting is not a zone
as under a goal, and RSSI is a poor range: the path-loss exponent is 1.8-4.3 within one building,
shadowing 4-8 dB, the walker's body 3-5 dB, and beacons and phones differ by several dB each
(algorithms.md, BLE proximity). What RSSI does tell is *when* the phone passed closest: its
level, smoothed over `smoothing_s`, peaks then. How close, only this beacon's own close passes
can say. So, per beacon:

- a pass: the smoothed level's peak, ended once the level has fallen `drop_db` below it or nothing
  was heard for `pass_end_s`; the peak's time is taken `smoothing_s` earlier (the smoothing's lag);
- the beacon's level: the second strongest of its last LEVEL_PASSES pass peaks (learned: the tx
  power, the hall's path loss and the phone's offset are all in it; most passes of a beacon are
  not close ones, so a median would learn what far looks like, and the strongest alone would
  follow one lucky fade); until MIN_PASSES peaks, the level a beacon at its stated tx power gives
  at `close_m` in free space;
- a close pass: a peak within `accept_db` of the level, and never weaker than `floor_db` under
  that free-space figure (a beacon only ever passed far must not teach that far is close). It
  gives a fix at the beacon's place, sd `fix_sd_m`, at the peak's time.

The fix is then gated by the caller against its own track (`gate`): one outside the 99 % ellipse
is refused and counted; a beacon refused more often than taken (at least `distrust_after` times)
is distrusted from then on (moved, or its place wrong in the venue file). Beacons on another
floor than the walker's are not used. State: a fixed record per venue beacon; memory is constant.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from protocol.session import Beacon

LEVEL_PASSES = 8
MIN_PASSES = 3
GATE_CHI2_2DOF = 9.21  # 99 %
PHONE_HEIGHT_M = 1.1  # held in front at about elbow height (0.62 x 1.7 m); in a pocket 0.9


@dataclass(frozen=True)
class BeaconSettings:
    # a phone reports a beacon 1-5 times a second, each +-3 dB of fading (2 s chosen on simulated
    # seeds 2-4 from 1, 2, 3 s: docs/pdr-estimator.md)
    smoothing_s: float = 2.0
    drop_db: float = 5.0  # the level has fallen this far below its peak: walking away
    rise_db: float = 3.0  # a peak rose this far from the pass's start (a tail walking away is no pass)
    pass_end_s: float = 3.0  # ... or nothing heard for this long
    accept_db: float = 3.0  # a peak this close to the beacon's learned level is a close pass
    close_m: float = 2.0  # horizontal distance of a close pass, for the free-space level
    floor_db: float = 8.0  # a close pass is never weaker than the free-space level minus this
    fix_sd_m: float = 2.0  # a close pass is within 1-3 m of the beacon (shadowing moves the peak)
    distrust_after: int = 3  # refusals before a beacon refused more often than taken is ignored

    def __post_init__(self) -> None:
        for name in ("smoothing_s", "drop_db", "rise_db", "pass_end_s", "accept_db", "close_m", "floor_db", "fix_sd_m"):
            value = getattr(self, name)
            if not (0.0 < value < math.inf):
                raise ValueError(f"BeaconSettings.{name} {value!r} must be finite and > 0")


@dataclass(frozen=True)
class ProximityFix:
    beacon_id: str
    time_ns: int  # the moment of closest approach
    x_m: float
    y_m: float
    sd_m: float
    peak_dbm: float
    level_dbm: float  # the level it was judged against


@dataclass
class BeaconRecord:
    """One beacon as one phone hears it."""

    smoothed_dbm: float = math.nan
    last_ns: int = 0
    peak_dbm: float = -math.inf
    peak_ns: int = 0
    start_dbm: float = math.nan  # the pass's lowest level before its peak: a peak must rise from it
    peaks: deque = field(default_factory=lambda: deque(maxlen=LEVEL_PASSES))
    taken: int = 0
    refused: int = 0

    def distrusted(self, settings: BeaconSettings) -> bool:
        return self.refused >= settings.distrust_after and self.refused > self.taken


def free_space_level_dbm(beacon: Beacon, horizontal_m: float) -> float:
    """RSSI at `horizontal_m` from under the beacon with the path-loss exponent 2 of free space."""
    slant_m = math.hypot(horizontal_m, max(beacon.height_m - PHONE_HEIGHT_M, 0.0))
    return beacon.tx_power_dbm - 20.0 * math.log10(max(slant_m, 0.1))


class BeaconPasses:
    """One phone's passes of the venue's beacons: `sight(...)` and `tick(...)` return the close passes."""

    def __init__(self, beacons: tuple[Beacon, ...], settings: BeaconSettings = BeaconSettings()) -> None:
        self.settings = settings
        self.beacons = {beacon.id: beacon for beacon in beacons}
        self.records = {beacon.id: BeaconRecord() for beacon in beacons}
        self.unknown = 0  # sightings of a beacon the venue does not list
        self.passes = 0  # peaks seen
        self.far = 0  # ... not close enough for a fix

    def sight(self, time_ns: int, beacon_id: str, rssi_dbm: float) -> list[ProximityFix]:
        """One sighting; the close passes it ended (a sighting after a silence ends the pass before it)."""
        record = self.records.get(beacon_id)
        if record is None or not math.isfinite(rssi_dbm):
            self.unknown += 1
            return []
        if time_ns <= record.last_ns and not math.isnan(record.smoothed_dbm):
            return []  # older than what was taken: out of order
        out = []
        if not math.isnan(record.smoothed_dbm) and (time_ns - record.last_ns) * 1e-9 > self.settings.pass_end_s:
            out += self._end(beacon_id, record)
        if math.isnan(record.smoothed_dbm):
            record.smoothed_dbm = record.start_dbm = rssi_dbm
        else:
            follow = 1.0 - math.exp(-(time_ns - record.last_ns) * 1e-9 / self.settings.smoothing_s)
            record.smoothed_dbm += (rssi_dbm - record.smoothed_dbm) * follow
        record.last_ns = time_ns
        if record.smoothed_dbm > record.peak_dbm:
            record.peak_dbm, record.peak_ns = record.smoothed_dbm, time_ns
        if record.peak_dbm - record.start_dbm < self.settings.rise_db:
            if record.smoothed_dbm < record.start_dbm:  # still falling: the pass starts from the new low
                record.start_dbm = record.peak_dbm = record.smoothed_dbm
                record.peak_ns = time_ns
        elif record.smoothed_dbm < record.peak_dbm - self.settings.drop_db:
            out += self._end(beacon_id, record, keep_level=True)
        return out

    def tick(self, time_ns: int) -> list[ProximityFix]:
        """Time has passed (a pose): the passes of beacons silent for `pass_end_s` end."""
        out = []
        for beacon_id, record in self.records.items():
            if not math.isnan(record.smoothed_dbm) and (time_ns - record.last_ns) * 1e-9 > self.settings.pass_end_s:
                out += self._end(beacon_id, record)
        return out

    def judged(self, fix: ProximityFix, taken: bool) -> None:
        """The caller's gate took or refused this fix."""
        record = self.records[fix.beacon_id]
        if taken:
            record.taken += 1
        else:
            record.refused += 1

    def level_dbm(self, beacon_id: str) -> tuple[float, bool]:
        """(the level of a close pass of this beacon, learned?)."""
        record, beacon = self.records[beacon_id], self.beacons[beacon_id]
        if len(record.peaks) >= MIN_PASSES:
            return float(sorted(record.peaks)[-2]), True
        return free_space_level_dbm(beacon, self.settings.close_m), False

    def _end(self, beacon_id: str, record: BeaconRecord, keep_level: bool = False) -> list[ProximityFix]:
        """The pass is over: its peak, a fix when close. `keep_level`: the walker is still in range
        (the level fell), so the next pass starts from the present level, not afresh."""
        peak_dbm, peak_ns, rise_db = record.peak_dbm, record.peak_ns, record.peak_dbm - record.start_dbm
        if keep_level:
            record.peak_dbm, record.peak_ns = record.smoothed_dbm, record.last_ns
            record.start_dbm = record.smoothed_dbm
        else:
            record.smoothed_dbm, record.peak_dbm, record.start_dbm = math.nan, -math.inf, math.nan
        if not math.isfinite(peak_dbm) or not rise_db >= self.settings.rise_db:
            return []
        self.passes += 1
        settings, beacon = self.settings, self.beacons[beacon_id]
        level, _ = self.level_dbm(beacon_id)
        record.peaks.append(peak_dbm)
        floor = free_space_level_dbm(beacon, settings.close_m) - settings.floor_db
        if peak_dbm < level - settings.accept_db or peak_dbm < floor or record.distrusted(settings):
            self.far += 1
            return []
        return [ProximityFix(beacon_id, peak_ns - int(settings.smoothing_s * 1e9), beacon.x_m, beacon.y_m,
                             settings.fix_sd_m, peak_dbm, level)]


def gate(fix: ProximityFix, x_m: float, y_m: float, covariance_xy: np.ndarray, floor_sd_m: float = 1.0) -> bool:
    """Is the fix consistent with the track's position (x, y) at its time (99 % ellipse)? The
    track's covariance is floored at `floor_sd_m` (a collapsed particle cloud is not that sure)."""
    innovation = np.array([fix.x_m - x_m, fix.y_m - y_m])
    spread = np.asarray(covariance_xy, dtype=float) + np.eye(2) * (floor_sd_m ** 2 + fix.sd_m ** 2)
    return float(innovation @ np.linalg.solve(spread, innovation)) <= GATE_CHI2_2DOF
