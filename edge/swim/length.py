"""Our estimate of one length from the 100 Hz rows of edge/swim/bins.py, once its walls are known.

The rows from the push-off (`push`) to the moment the swimmer is still again at the far wall
(`stop`: the next push-off, or rest) carry three constraints the paper's method does not use:
- the horizontal velocity is zero at both ends: the velocity drift (accelerometer bias and any
  gravity left by the attitude) is removed as a straight line in time, in both axes;
- the track's ends are on the two walls: the chord from push-off to touch, across the lane by
  the route's plan (0 straight; the diagonal's 19.8 deg), is the pool length: scale k;
- only the body's track counts: the speed is the velocity along the body's heading, so the
  sensor's sway across it (a lever arm rolling with the body, at the stroke frequency) and the
  attitude's errors across the track do not add distance.
Velocities are earth-frame vectors from the quaternion attitude (gravity removed whatever the
body's roll and pitch), and headings are the quaternion's, not a z gyro's integral.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import butter, find_peaks, sosfiltfilt

from edge.swim.bins import DV_X, DV_Y, GYRO_X, GYRO_Z, HEAD_X, HEAD_Y, RATE, SURGE, T, UP_X, UP_Z
from edge.swim.paper import LengthEstimate, lateral_profile
from protocol.session import Route, route_end_heading_rad

HEADING_CUTOFF_HZ = 0.2  # below breathing (every 2-3 strokes: 0.4-0.8 Hz) and strokes; the diagonal's
# turn (1.5-3 m, about 2 s) and snaking (periods over 10 s) pass
# The diagonal turns at half the length; before 15 % the swimmer is still gliding, rolling from the
# side to prone, which swings a tilted sensor's forward axis.
PRE_TURN_SHARE = (0.15, 0.4)
POST_TURN_SHARE = (0.6, 0.95)
STRAIGHT_SHARE = (0.15, 0.95)
# YawDrift. Prior: the simulator's gyro turn-on offset SD (docs/simulator-swim.md), which the
# attitude filter does not remove about the vertical. Reading SDs, measured on simulated waist
# crawl sets (seeds 1-6, 4 lengths): the lane pair 0.05 deg/s, the within-length 0.3 (taken wider:
# a real swimmer's turn strays from the plan more than the simulator's). Walk: the offset's own
# walk over a length is far below either. Two lane headings pair only across a turn onto the same
# lane (a rest at the wall in between is fine; a swimmer who left the lane is not).
DRIFT_PRIOR_SD_DPS = 0.5
DRIFT_PAIR_SD_DPS = 0.08
DRIFT_WITHIN_SD_DPS = 0.4
DRIFT_WALK_DPS = 0.02
# RestGyro. Floating still at the wall before a set (3-5 s, nearly upright) every gyro axis reads
# its offset; projected on the swimming vertical it is the heading's drift, within 0.1 deg/s of the
# drift learnt over 4 lengths (simulated waist crawl sets, seeds 1, 3, 6: -0.25 / -0.22, 0.65 / 0.55,
# 0.53 / 0.53; the body-frame offsets within 0.2 of the drawn ones, the vertical's component within
# 0.05, waist and head, seeds 1-6). SD taken 0.15: a real swimmer at the wall sways more than the
# simulator's 0.3 deg. Rest: rotation under REST_RATE_DPS (edge/swim_walls.STILL_RATE_DPS: at rest every
# sensor reads at most 2 deg/s, swimming at least 9.5) for REST_MIN_S in a row.
DRIFT_REST_SD_DPS = 0.15
REST_RATE_DPS = 5.0
REST_MIN_S = 1.5
DRIFT_GATE_SD = 3.0
DRIFT_PAIR_MAX_S = 180.0
DRIFT_RESIDUAL_MAX_DEG = 25.0
GLIDE_S = 1.5  # after the push-off, before the first stroke: not counted for the stroke rate
STROKE_BAND_HZ = (0.4, 3.0)


def count_strokes(surge_g: np.ndarray, rate_hz: float) -> int:
    """Stroke surges in the forward specific force: peaks of the band-passed signal at least
    0.6 of the dominant period apart."""
    if len(surge_g) < rate_hz * 2:
        return 0
    low, high = STROKE_BAND_HZ
    sos = butter(2, [low / (rate_hz / 2), high / (rate_hz / 2)], btype="band", output="sos")
    band = sosfiltfilt(sos, surge_g - surge_g.mean())
    spectrum = np.abs(np.fft.rfft(band * np.hanning(len(band))))
    freqs = np.fft.rfftfreq(len(band), 1.0 / rate_hz)
    inside = (freqs >= low) & (freqs <= high)
    if not inside.any() or spectrum[inside].max() <= 0:
        return 0
    period_s = 1.0 / freqs[inside][np.argmax(spectrum[inside])]
    peaks, _ = find_peaks(band, distance=max(1, int(0.6 * period_s * rate_hz)), prominence=0.3 * band.std())
    return len(peaks)


@dataclass(frozen=True)
class LaneReading:
    """A length's headings in the attitude filter's frame, uncorrected: the lane's (rad) and when
    (the middle of the rows it was read from, ns), and the drift rate the length shows by itself
    (deg/s): the heading after the turn against the heading before it and the route's turn."""

    heading_rad: float
    time_ns: int
    drift_dps: float
    rest_dps: float = math.nan  # the drift the rest before the length read (RestGyro), if one came before it


@dataclass(frozen=True)
class YawDrift:
    """The heading's drift rate about the vertical (deg/s), a Kalman estimate updated every length.

    Without a magnetometer nothing observes the gyro offset about the vertical, and what the
    attitude filter leaves of it (-0.7 to +0.6 deg/s in the simulator's sets, constant over a set)
    turns a diagonal's second half by 1.5-6.5 deg at the wall. The pool observes it twice:
    consecutive lengths swim the same lane in opposite directions, so their lane headings differ by
    exactly 180 deg (what is left over, over the time between the readings, is the drift: a precise
    reading), and within a length the heading after the turn should differ from the one before by
    the route's turn (a noisy one: snaking, and a swimmer's turn is not exactly the plan's; it is
    what the first length has). Fixed-size state.
    """

    rate_dps: float = 0.0
    variance: float = DRIFT_PRIOR_SD_DPS ** 2
    last: LaneReading | None = None

    def learn(self, lane: LaneReading) -> "YawDrift":
        """The state after the next length's reading (its predecessor's is `last`)."""
        rate, variance = self.rate_dps, self.variance + DRIFT_WALK_DPS ** 2
        readings = [(lane.rest_dps, DRIFT_REST_SD_DPS), (lane.drift_dps, DRIFT_WITHIN_SD_DPS)]
        if self.last is not None:
            gap_s = (lane.time_ns - self.last.time_ns) * 1e-9
            residual = math.degrees(math.remainder(lane.heading_rad - self.last.heading_rad - math.pi, 2 * math.pi))
            if 0.0 < gap_s <= DRIFT_PAIR_MAX_S and abs(residual) <= DRIFT_RESIDUAL_MAX_DEG:
                readings.append((residual / gap_s, DRIFT_PAIR_SD_DPS))  # else not a turn onto the same lane
        for value, sd in readings:
            spread = variance + sd ** 2
            # A reading far outside what the estimate and its own noise allow is not a drift: a
            # kickboard's turn is not the body's, a swimmer who stopped mid-length.
            if math.isfinite(value) and (value - rate) ** 2 <= DRIFT_GATE_SD ** 2 * spread:
                gain = variance / spread
                rate, variance = rate + gain * (value - rate), (1.0 - gain) * variance
        return YawDrift(rate, variance, lane)


@dataclass
class RestGyro:
    """The mean body-frame rate of the last rest (rows whose rotation stays under REST_RATE_DPS for
    REST_MIN_S or more), fed row by row; `take()` hands it to the length that follows, once.
    Fixed-size: a sum, a count and the last rest's mean."""

    total: np.ndarray = field(default_factory=lambda: np.zeros(3))
    count: int = 0
    offset_dps: np.ndarray | None = None

    def add(self, rows: np.ndarray, rate_hz: float = 100.0) -> None:
        for row in rows:
            if row[RATE] < REST_RATE_DPS:
                self.total += row[GYRO_X:GYRO_Z + 1]
                self.count += 1
                continue
            if self.count >= REST_MIN_S * rate_hz:
                self.offset_dps = self.total / self.count
            self.total[:] = 0.0
            self.count = 0

    def take(self) -> np.ndarray | None:
        offset, self.offset_dps = self.offset_dps, None
        return offset


def lane_reading(rows: np.ndarray, push: int, touch: int, stop: int, route: Route,
                 rate_hz: float = 100.0, rest_offset_dps: np.ndarray | None = None) -> LaneReading:
    """The headings of rows[push..touch] that YawDrift learns from (and the rest's gyro offset before
    them, projected on the length's mean vertical)."""
    t_s, head, _, step = _body_track(rows, push, touch, stop, rate_hz)
    window = _lane_window(step, route)
    lane = head[window].sum(axis=0)
    middle = float(t_s[window].mean()) if window.any() else 0.0
    share = _share(step)
    before, after = ((share >= first) & (share <= last) for first, last in (PRE_TURN_SHARE, POST_TURN_SHARE))
    drift = math.nan
    if before.any() and after.any():
        turned = math.remainder(_angle(head[after]) - _angle(head[before]) - route_end_heading_rad(route), 2 * math.pi)
        drift = math.degrees(turned) / float(t_s[after].mean() - t_s[before].mean())
    rest = math.nan
    if rest_offset_dps is not None and window.any():
        up = rows[push:touch + 1][window, UP_X:UP_Z + 1].mean(axis=0)
        rest = float(rest_offset_dps @ up)
    return LaneReading(math.atan2(lane[1], lane[0]), int(rows[push, T] + middle * 1e9), drift, rest)


def reckon_length(rows: np.ndarray, push: int, touch: int, stop: int, pool_length_m: float, route: Route,
                  rate_hz: float = 100.0, drift_dps: float = 0.0) -> LengthEstimate:
    """Our estimate of rows[push..touch], with zero velocity at push and stop, the heading's drift
    (`drift_dps`, YawDrift) taken out."""
    t_s, head, speed, step = _body_track(rows, push, touch, stop, rate_hz)
    if drift_dps:
        # The speed stays: the velocity and the heading are both in the drifting frame.
        window = _lane_window(step, route)
        angle = np.radians(drift_dps) * (t_s - (t_s[window].mean() if window.any() else 0.0))
        c, s = np.cos(angle), np.sin(angle)
        head = np.column_stack([c * head[:, 0] + s * head[:, 1], -s * head[:, 0] + c * head[:, 1]])
    n = len(t_s)
    track = np.vstack([np.zeros(2), np.cumsum(step[:, None] * (head[1:] + head[:-1]) * 0.5, axis=0)])
    lane_dir = _lane_direction(track, head, step, route)
    lane_left = np.array([-lane_dir[1], lane_dir[0]])
    lane_raw = float(track[-1] @ lane_dir)
    scale = pool_length_m / lane_raw if lane_raw > 1e-6 else math.nan
    swum = scale * float(step.sum())
    lane_m, cross_m = scale * (track @ lane_dir), scale * (track @ lane_left)
    start_heading = _heading(rows, push, push + int(GLIDE_S * rate_hz))
    end_heading = _heading(rows, max(push, touch - int(1.0 * rate_hz)), touch)
    turned = math.degrees(math.remainder(end_heading - start_heading, 2 * math.pi)) - drift_dps * t_s[-1]
    expected = math.degrees(route_end_heading_rad(route))
    strokes = count_strokes(rows[push + int(GLIDE_S * rate_hz):push + n, SURGE], rate_hz)
    backward = float(-step[step < 0].sum() / max(float(np.abs(step).sum()), 1e-9))
    return LengthEstimate(int(rows[push, T]), int(rows[touch, T]), swum, float(lane_m[-1]), scale,
                          turned - expected, lateral_profile(lane_m, cross_m), stroke_count=strokes,
                          backward_share=backward)


def _body_track(rows: np.ndarray, push: int, touch: int, stop: int,
                rate_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Push-off to touch: times (s from the push-off), the body's low-passed heading (unit
    vectors), the speed along it and the distance steps between rows."""
    if not push < touch <= stop < len(rows):
        raise ValueError(f"rows push {push} < touch {touch} <= stop {stop} < {len(rows)} do not hold")
    span = rows[push:stop + 1]
    t_s = (span[:, T] - span[0, T]) * 1e-9
    velocity = np.cumsum(span[:, [DV_X, DV_Y]], axis=0)
    velocity -= velocity[0]
    drift = velocity[-1] / t_s[-1] if t_s[-1] > 0 else np.zeros(2)
    velocity -= np.outer(t_s, drift)
    n = touch - push + 1
    velocity, t_s = velocity[:n], t_s[:n]
    # The track's direction: the body's heading without its stroke and breathing oscillations
    # (the head turns to breathe; hips and shoulders sway): a zero-phase low-pass.
    head = np.column_stack([_lowpass(span[:n, HEAD_X], HEADING_CUTOFF_HZ, rate_hz),
                            _lowpass(span[:n, HEAD_Y], HEADING_CUTOFF_HZ, rate_hz)])
    head = head / np.maximum(np.hypot(head[:, 0], head[:, 1]), 1e-9)[:, None]
    # Speed along the heading; the velocity across it is the sensor's sway, not the track.
    speed = np.einsum("ij,ij->i", velocity, head)
    dt = np.diff(t_s)
    step = (speed[1:] + speed[:-1]) * 0.5 * dt
    if step.sum() < 0:  # the forward axis points backwards (a sensor mounted reversed, a body pitched past
        head, speed, step = -head, -speed, -step  # the vertical): the travel fixes the heading's sign
    return t_s, head, speed, step


def _share(step: np.ndarray) -> np.ndarray:
    """Each row's share of the length's distance."""
    travelled = np.concatenate(([0.0], np.cumsum(step)))
    return travelled / travelled[-1] if travelled[-1] > 0 else travelled


def _lane_window(step: np.ndarray, route: Route) -> np.ndarray:
    """Rows (of the heading) where the body swims along the lane: from the end of the glide to the
    touch on a straight length, before the turn on a diagonal (PRE_TURN_SHARE of the distance)."""
    share = _share(step)
    first, last = PRE_TURN_SHARE if route is Route.DIAGONAL else STRAIGHT_SHARE
    return (share >= first) & (share <= last)


def _angle(head: np.ndarray) -> float:
    """Direction of the sum of unit heading vectors (rad)."""
    total = head.sum(axis=0)
    return math.atan2(float(total[1]), float(total[0]))


def _lane_direction(track: np.ndarray, head: np.ndarray, step: np.ndarray, route: Route) -> np.ndarray:
    """The lane's direction in the earth frame. Straight: the chord from push-off to touch (both
    ends on the walls). Diagonal: the heading before the route's turn (PRE_TURN_SHARE of the
    distance), which, unlike the chord, does not depend on where the swimmer turned."""
    chord = track[-1]
    if route is Route.DIAGONAL:
        chord = head[_lane_window(step, route)].sum(axis=0)
    norm = float(np.hypot(*chord))
    return chord / norm if norm > 0 else np.array([1.0, 0.0])


def _lowpass(values: np.ndarray, cutoff_hz: float, rate_hz: float) -> np.ndarray:
    if len(values) < 50:
        return values
    sos = butter(2, cutoff_hz / (rate_hz / 2.0), output="sos")
    return sosfiltfilt(sos, values, padlen=min(len(values) - 1, int(rate_hz / cutoff_hz)))


def _heading(rows: np.ndarray, first: int, last: int) -> float:
    """Circular mean heading of the body's forward axis over rows[first..last] (rad)."""
    part = rows[first:last + 1]
    return math.atan2(float(part[:, HEAD_Y].sum()), float(part[:, HEAD_X].sum()))
