"""Our estimate of one length from the 100 Hz rows of edge/swim_bins.py, once its walls are known.

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

import numpy as np
from scipy.signal import butter, find_peaks, sosfiltfilt

from edge.swim_bins import DV_X, DV_Y, HEAD_X, HEAD_Y, SURGE, T
from edge.swim_paper import LengthEstimate, lateral_profile
from protocol.session import Route, route_end_heading_rad

HEADING_CUTOFF_HZ = 0.2  # below breathing (every 2-3 strokes: 0.4-0.8 Hz) and strokes; the diagonal's
# turn (1.5-3 m, about 2 s) and snaking (periods over 10 s) pass
# The diagonal turns at half the length; before 15 % the swimmer is still gliding, rolling from the
# side to prone, which swings a tilted sensor's forward axis.
PRE_TURN_SHARE = (0.15, 0.4)
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


def reckon_length(rows: np.ndarray, push: int, touch: int, stop: int, pool_length_m: float, route: Route,
                  rate_hz: float = 100.0) -> LengthEstimate:
    """Our estimate of rows[push..touch], with zero velocity at push and stop."""
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
    track = np.vstack([np.zeros(2), np.cumsum(step[:, None] * (head[1:] + head[:-1]) * 0.5, axis=0)])
    lane_dir = _lane_direction(track, head, step, route)
    lane_left = np.array([-lane_dir[1], lane_dir[0]])
    lane_raw = float(track[-1] @ lane_dir)
    scale = pool_length_m / lane_raw if lane_raw > 1e-6 else math.nan
    swum = scale * float(step.sum())
    lane_m, cross_m = scale * (track @ lane_dir), scale * (track @ lane_left)
    start_heading = _heading(rows, push, push + int(GLIDE_S * rate_hz))
    end_heading = _heading(rows, max(push, touch - int(1.0 * rate_hz)), touch)
    turned = math.degrees(math.remainder(end_heading - start_heading, 2 * math.pi))
    expected = math.degrees(route_end_heading_rad(route))
    strokes = count_strokes(rows[push + int(GLIDE_S * rate_hz):touch + 1, SURGE], rate_hz)
    estimate = LengthEstimate(int(rows[push, T]), int(rows[touch, T]), swum, float(lane_m[-1]), scale,
                              turned - expected, lateral_profile(lane_m, cross_m), stroke_count=strokes)
    return estimate


def _lane_direction(track: np.ndarray, head: np.ndarray, step: np.ndarray, route: Route) -> np.ndarray:
    """The lane's direction in the earth frame. Straight: the chord from push-off to touch (both
    ends on the walls). Diagonal: the heading before the route's turn (PRE_TURN_SHARE of the
    distance), which, unlike the chord, does not depend on where the swimmer turned."""
    chord = track[-1]
    if route is Route.DIAGONAL:
        travelled = np.concatenate(([0.0], np.cumsum(step)))
        share = travelled / travelled[-1]
        chord = head[(share >= PRE_TURN_SHARE[0]) & (share <= PRE_TURN_SHARE[1])].sum(axis=0)
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
