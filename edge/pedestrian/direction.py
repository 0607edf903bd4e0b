"""The walking direction from the phone's own acceleration, however the phone sits (a pocket, a
swinging hand): a pure estimator, `step(settings, state, time_ns, accel_earth_ms2) -> state`.

Input: the linear acceleration in the AHRS earth frame (x, y horizontal, z up; gravity removed),
m/s^2. Output (`heading_rad`): the walking direction's heading in that same frame, so a stand's
heading offset applies to it as to a phone axis. The moments can be kept in a horizontal frame
that turns with a phone axis (`reference_heading_rad`); then `offset_rad` is the walking direction
relative to that axis, constant while the phone sits still in its pocket, through every turn.

1. Axis. While walking, the horizontal acceleration swings mostly fore-aft: the body brakes and
   speeds up within each step, a thigh swings forward and back. Its principal axis (the major
   eigenvector of the running 2x2 covariance, forgotten over `axis_time_constant_s`, about two
   steps) is the walking line (Kunze et al. 2009, ISWC, "Which way am I facing"; Deng et al. 2015,
   Sensors 15:21518, PCA for a phone in the pocket).
2. Sign (the 180 deg ambiguity). The centre of mass vaults over the stance leg like an inverted
   pendulum: kinetic and potential energy swap out of phase (Cavagna, Heglund & Taylor 1977,
   Am J Physiol 233:R243), so the body is slowest at its highest and speeds up while it falls:
   d(v_f^2 / 2)/dt ~ -g v_z, i.e. the forward acceleration a_f opposes the vertical velocity v_z
   within every step. The score is the running correlation E[-a_f v_z] / rms(v_z) of the
   acceleration along the axis (the same stance-phase relation uDirect reads at one instant per
   step: Hoseinitabatabaei et al. 2011, PerCom; this needs no peak timing). With a_v = cos(wt)
   and -a_f = cos(wt - delta) (delta = 90 deg: the pure pendulum; less when the braking comes
   with the heel-strike peak), the score is ~ sin(delta): right for any delta in (0, 180) deg.
   E[-a_f a_v] (the heel-strike collision, Donelan, Kram & Kuo 2002, J Exp Biol 205:3717) is
   left out on purpose: a phone on a swinging segment (the front of a thigh, a hand) rises as it
   swings forward, in phase, which would dominate that term, but is in quadrature with v_z.
   The score is the projection on the current axis, forgotten over `sign_time_constant_s` (several
   strides: the sign only changes when the phone is re-seated, not when the walker turns).
The swing of a thigh or an arm is at stride frequency (half the step frequency), so over a stride
it adds to the axis but hardly to the sign score, which lives at step frequency.

State: a fixed set of floats (running means, moments, one leaky integrator, the continuous axis
and the score); dt comes from the timestamps; a gap over `gap_s` restarts the integrator and is
counted; a timestamp that does not advance is ignored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace


@dataclass(frozen=True)
class DirectionSettings:
    # About two steps (one stride at 0.8-1 Hz): the thigh or arm swing averages out, turns lag by about this.
    axis_time_constant_s: float = 1.2
    # Several strides: the sign evidence of a few steps, kept through turns (it is relative to the axis).
    sign_time_constant_s: float = 4.0
    # Removed running mean: an AHRS tilt error leaks gravity as a slowly varying horizontal bias.
    mean_time_constant_s: float = 2.0
    # Leaky integration of a_v into v_z: at 1.8 Hz steps, a 1 s leak shifts v_z's phase by 5 deg only.
    velocity_leak_s: float = 1.0
    # Below this RMS horizontal acceleration there is no walking to read (walking: 0.5-3 m/s^2).
    min_horizontal_rms_ms2: float = 0.15
    gap_s: float = 0.25


@dataclass(frozen=True)
class DirectionState:
    time_ns: int = -1
    mean_x_ms2: float = 0.0
    mean_y_ms2: float = 0.0
    mean_z_ms2: float = 0.0
    vertical_velocity_ms: float = 0.0
    moment_xx_m2s4: float = 0.0  # running covariance of the horizontal acceleration
    moment_xy_m2s4: float = 0.0
    moment_yy_m2s4: float = 0.0
    vertical_power_m2s4: float = 0.0  # running mean of a_v^2 and v_z^2 (the score's normalisers)
    velocity_power_m2s2: float = 0.0
    axis_x: float = 0.0  # principal axis, kept continuous (never flipped by the eigen solver); 0, 0: none yet
    axis_y: float = 0.0
    sign_score_ms2: float = 0.0  # > 0: +axis is forward
    reference_heading_rad: float = 0.0  # the last sample's reference frame heading
    gaps: int = 0


def step(settings: DirectionSettings, state: DirectionState, time_ns: int,
         accel_earth_ms2: tuple[float, float, float], reference_heading_rad: float = 0.0) -> DirectionState:
    """One sample of linear acceleration in the AHRS earth frame (m/s^2, z up, gravity removed).
    `reference_heading_rad`: the heading of the horizontal frame the moments are kept in; 0: the
    earth frame itself; the heading of a phone axis: a frame that turns with the phone, so the
    gyro carries turns and the moments see only how the phone sits (see `heading_rad`)."""
    east, north, z = accel_earth_ms2
    cos_r, sin_r = math.cos(reference_heading_rad), math.sin(reference_heading_rad)
    x, y = cos_r * east + sin_r * north, -sin_r * east + cos_r * north
    if state.time_ns < 0:
        return replace(state, time_ns=time_ns, mean_x_ms2=x, mean_y_ms2=y, mean_z_ms2=z,
                       reference_heading_rad=reference_heading_rad)
    if time_ns <= state.time_ns:
        return state
    dt_s = (time_ns - state.time_ns) * 1e-9
    velocity, gaps = state.vertical_velocity_ms, state.gaps
    if dt_s > settings.gap_s:
        velocity, gaps, dt_s = 0.0, gaps + 1, settings.gap_s  # no integral across a gap
    mean_weight = 1.0 - math.exp(-dt_s / settings.mean_time_constant_s)
    mean_x = state.mean_x_ms2 + mean_weight * (x - state.mean_x_ms2)
    mean_y = state.mean_y_ms2 + mean_weight * (y - state.mean_y_ms2)
    mean_z = state.mean_z_ms2 + mean_weight * (z - state.mean_z_ms2)
    hx, hy, vertical = x - mean_x, y - mean_y, z - mean_z
    velocity = velocity * math.exp(-dt_s / settings.velocity_leak_s) + vertical * dt_s
    axis_weight = 1.0 - math.exp(-dt_s / settings.axis_time_constant_s)
    xx = state.moment_xx_m2s4 + axis_weight * (hx * hx - state.moment_xx_m2s4)
    xy = state.moment_xy_m2s4 + axis_weight * (hx * hy - state.moment_xy_m2s4)
    yy = state.moment_yy_m2s4 + axis_weight * (hy * hy - state.moment_yy_m2s4)
    vertical_power = state.vertical_power_m2s4 + axis_weight * (vertical * vertical - state.vertical_power_m2s4)
    velocity_power = state.velocity_power_m2s2 + axis_weight * (velocity * velocity - state.velocity_power_m2s2)
    angle = 0.5 * math.atan2(2.0 * xy, xx - yy)  # major eigenvector of [[xx, xy], [xy, yy]]
    axis_x, axis_y = math.cos(angle), math.sin(angle)
    if axis_x * state.axis_x + axis_y * state.axis_y < 0.0:  # keep it continuous: the score is relative to it
        axis_x, axis_y = -axis_x, -axis_y
    score = state.sign_score_ms2
    along = hx * axis_x + hy * axis_y
    feature = velocity / math.sqrt(velocity_power) if velocity_power > 1e-12 else 0.0
    sign_weight = 1.0 - math.exp(-dt_s / settings.sign_time_constant_s)
    score += sign_weight * (-along * feature - score)
    return DirectionState(time_ns, mean_x, mean_y, mean_z, velocity, xx, xy, yy, vertical_power, velocity_power,
                          axis_x, axis_y, score, reference_heading_rad, gaps)


def heading_rad(settings: DirectionSettings, state: DirectionState) -> float | None:
    """The walking direction's heading in the AHRS earth frame (counter-clockwise about up), or
    None while there is no walking to read (too little horizontal acceleration, or no sign yet)."""
    offset = offset_rad(settings, state)
    return None if offset is None else math.atan2(math.sin(state.reference_heading_rad + offset),
                                                  math.cos(state.reference_heading_rad + offset))


def offset_rad(settings: DirectionSettings, state: DirectionState) -> float | None:
    """The walking direction relative to the reference frame's heading (radians, in (-pi, pi]), or None."""
    if state.moment_xx_m2s4 + state.moment_yy_m2s4 < settings.min_horizontal_rms_ms2 ** 2:
        return None
    if state.sign_score_ms2 == 0.0:
        return None
    sign = 1.0 if state.sign_score_ms2 > 0.0 else -1.0
    return math.atan2(sign * state.axis_y, sign * state.axis_x)


def elongation(state: DirectionState) -> float:
    """(lambda1 - lambda2) / (lambda1 + lambda2) of the horizontal covariance, in [0, 1]: 0 when the
    horizontal acceleration has no preferred line (standing, circling), 1 along a single line."""
    trace = state.moment_xx_m2s4 + state.moment_yy_m2s4
    if trace <= 0.0:
        return 0.0
    spread = math.hypot(state.moment_xx_m2s4 - state.moment_yy_m2s4, 2.0 * state.moment_xy_m2s4)
    return spread / trace
