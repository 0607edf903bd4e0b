"""The swimming paper's method (methods.md section 2), per length, with its errata fixed.

One length is the samples from the push-off to the wall touch, wall times given (the paper
cut its lengths by hand; it has no wall detection). Sensor frame: x the direction of travel,
z up; the paper integrates the raw x acceleration (gravity included) and the raw z gyro.

    alpha_i = (w_i + w_i+1) / 2 * dt_i                   heading increments (eq. 1)
    A_err = sum(alpha) - A_real                           heading error at the wall (eq. 2-3)
    alpha'_i = alpha_i - A_err / n                        spread evenly (eq. 4; see below)
    theta_i = sum_{j<i} alpha'_j                          the heading used below is cumulative
    v_i = sum trapezoid(a)                                velocity from rest (eq. 5; ERRATUM 1)
    L = integral v cos(theta)                             lane-parallel distance (eq. 6-8)
    k = L_real / L,  D = integral k v                     scaled swum distance (eq. 9-12; ERRATUM 2)

ERRATUM 1: eq. 5 as printed gives each v(i) as a per-sample increment; velocity is their
cumulative sum. ERRATUM 2: eq. 9 writes k = L / L_real, which scales the wrong way; k = L_real / L
makes the lane-parallel distance the pool length. Eq. 4 divides by N - 1 for samples 0..N, which
leaves A_err / (N - 1) uncorrected; we divide by the n = N increments so the heading at the wall
is exactly A_real (a 1/N difference, 5e-5 for a 20 s length at 1000 Hz).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from protocol.errors import InputError

G = 9.80665  # m/s^2 per g
PROFILE_STEP_M = 1.0


@dataclass(frozen=True)
class LengthEstimate:
    """One length as a method sees it. lateral_m[i]: the track's offset to the left of the line
    between the length's ends at i * profile_step_m along the lane."""

    start_ns: int
    end_ns: int
    swum_distance_m: float
    lane_distance_m: float
    scale: float
    heading_error_deg: float
    lateral_m: np.ndarray
    profile_step_m: float = PROFILE_STEP_M
    stroke_count: int = 0
    # Share of the travel along the heading that went backwards (ours; 0 for the paper's). A swimmer
    # does not swim backwards: much of it means the velocity's drift was taken out wrongly.
    backward_share: float = 0.0

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) * 1e-9


def _trapezoid_steps(values: np.ndarray, dt: np.ndarray) -> np.ndarray:
    return (values[:-1] + values[1:]) * 0.5 * dt


def _cumulative(steps: np.ndarray) -> np.ndarray:
    return np.concatenate(([0.0], np.cumsum(steps)))


def lateral_profile(lane_m: np.ndarray, cross_m: np.ndarray, step_m: float = PROFILE_STEP_M) -> np.ndarray:
    """Offset to the left of the chord between the track's ends, every `step_m` of lane distance.

    `lane_m`, `cross_m`: the track in the length's frame (along the start heading, and to its left).
    """
    if len(lane_m) < 2 or not (np.all(np.isfinite(lane_m)) and np.all(np.isfinite(cross_m))):
        return np.zeros(0)
    chord = np.array([lane_m[-1] - lane_m[0], cross_m[-1] - cross_m[0]])
    norm = float(np.hypot(*chord))
    if norm < 1e-9:
        return np.zeros(0)
    along = ((lane_m - lane_m[0]) * chord[0] + (cross_m - cross_m[0]) * chord[1]) / norm
    left = (-(lane_m - lane_m[0]) * chord[1] + (cross_m - cross_m[0]) * chord[0]) / norm
    order = np.maximum.accumulate(along)  # a monotone abscissa for the interpolation
    points = np.arange(0.0, max(order[-1], 0.0) + 1e-9, step_m)
    return np.interp(points, order, left)


def paper_length(time_ns: np.ndarray, forward_accel_g: np.ndarray, yaw_rate_dps: np.ndarray,
                 lane_length_m: float, end_heading_deg: float = 0.0) -> LengthEstimate:
    """The paper's estimate for one length: samples from the push-off to the wall touch.

    `forward_accel_g`: the sensor's x axis (g), `yaw_rate_dps`: its z gyro (deg/s), both raw.
    `end_heading_deg`: the route's heading at the wall relative to the start (the paper's A_real:
    0 straight, -35.75 on its diagonal).
    """
    t_ns = np.asarray(time_ns, dtype=np.int64)
    if len(t_ns) < 3:
        raise InputError(f"a length needs at least 3 samples, got {len(t_ns)}")
    dt = np.diff(t_ns) * 1e-9
    if np.any(dt <= 0):
        at = int(np.argmax(dt <= 0))
        raise InputError(f"sample times must increase: sample {at + 1} at {int(t_ns[at + 1])} ns is not after "
                         f"{int(t_ns[at])} ns")
    alpha = _trapezoid_steps(np.asarray(yaw_rate_dps, dtype=float), dt)
    heading_error = float(alpha.sum()) - end_heading_deg
    theta = np.radians(_cumulative(alpha - heading_error / len(alpha)))
    velocity = _cumulative(_trapezoid_steps(np.asarray(forward_accel_g, dtype=float) * G, dt))
    lane_raw = float(_trapezoid_steps(velocity * np.cos(theta), dt).sum())
    if not math.isfinite(lane_raw) or abs(lane_raw) < 1e-9:
        raise InputError(f"the integrated lane-parallel distance is {lane_raw} m: cannot scale it to "
                         f"{lane_length_m} m")
    scale = lane_length_m / lane_raw
    speed = scale * velocity
    swum = float(_trapezoid_steps(speed, dt).sum())
    lane = _cumulative(_trapezoid_steps(speed * np.cos(theta), dt))
    cross = _cumulative(_trapezoid_steps(speed * np.sin(theta), dt))
    return LengthEstimate(int(t_ns[0]), int(t_ns[-1]), swum, float(lane[-1]), scale, heading_error,
                          lateral_profile(lane, cross))
