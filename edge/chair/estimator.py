"""Our per-chair dead reckoning: an extended Kalman filter in constant memory.

State (edge/chair/state.py): x, y (m, court frame), heading (rad), seat-gyro yaw bias (rad/s), wheel scale (1),
seat-gyro scale error (1), magnetic north in the court frame (rad).
- Distance from the wheels (mean of both axle gyros: camber leak cancels, the paper's eq. 5),
  times a wheel scale; the wheel gyros' own biases are re-learned whenever the chair is still,
  so a still chair does not creep.
- Heading from the seat gyro, never from the wheels alone (a 0.5 % left/right radius mismatch is
  0.34 deg per metre, algorithms.md). Its bias is re-estimated whenever the chair is still (a
  zero-rate update), which the paper's method never does. Its scale is checked once against the
  axle IMUs, two more gyros that see the same yaw x cos camber (`_axle_scale`): a chair spins
  thousands of degrees a game, so 1-2 % of scale is tens of degrees of heading.
- A lost seat packet would lose the turns made meanwhile (pivots run at 300+ deg/s): across a
  gap the heading change comes from the wheels' axle IMUs, which see the chair's yaw in the
  wheel plane (edge/chair/merger.py: untouched by scrub and skid), times a ratio to the seat
  gyro's turn learned online (about 1 / cos camber); without them, from the wheels' differential
  rotation, likewise learned (camber and track make it chair-specific, pivots scrub). The merger
  fills a silent seat with bridge samples (no seat reading), so a gap is followed step by step.
- The seat magnetometer is a self-calibrating aid that learns the hall it is in, and the hub's
  map of it (edge/chair/magnetometer.py: the hard-iron fit, the hall's disturbance and its
  correlation length, the gyro measured by the field's turn, north - heading once per correlation
  length).
- Uncertainty grows with distance and rotation, not time; an impact adds a shove variance in
  proportion to its horizontal share (of the specific force beyond gravity): a bump from below
  (a caster landing, the floor) cannot slide the chair, a contact can.

`step(settings, state, sample) -> state` is pure; `start` makes the first state. dt comes from
the timestamps; a gap (dt > `gap_s`) or a timestamp going backwards sets a flag, never raises.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from edge.chair.magnetometer import magnetometer
from edge.chair.state import (BIAS, DEG, GYRO_SCALE, HEADING, MAG_FIT_SIZE, MAG_STATS, N, SCALE, X, Y, AxleScale,
                              ChairSample, ChairSettings, ChairState, Flag, MagAid)


def wheel_turn_ratio_prior(settings: ChairSettings) -> float:
    """Heading change (rad) per degree of (right - left) wheel rotation, from geometry.

    Forward-positive axle rates differ by yaw_rate * (track / r - 2 sin(camber)): the track
    turns the wheels apart, camber leaks the yaw into each axle with opposite signs.
    """
    radius = 0.5 * settings.wheel_diameter_m
    return (math.pi / 180.0) / (settings.track_m / radius - 2.0 * math.sin(settings.camber_deg * DEG))


def wheel_axis_ratio_prior(settings: ChairSettings) -> float:
    """Heading change (rad) per degree of the axle IMUs' yaw, which reads yaw * cos(camber)."""
    return DEG / math.cos(settings.camber_deg * DEG)


def start(settings: ChairSettings, sample: ChairSample, x_m: float, y_m: float, heading_rad: float,
          position_sd_m: float = 0.1, heading_sd_rad: float = 2 * DEG) -> ChairState:
    cov = np.diag([position_sd_m**2, position_sd_m**2, heading_sd_rad**2, (settings.initial_gyro_bias_sd_dps * DEG) ** 2,
                   settings.wheel_scale_sd**2, settings.gyro_scale_sd**2, math.pi**2])
    prior_weight = 1e4  # deg^2 of wheel difference: about one slow pivot's worth of evidence
    norm = math.sqrt(sum(a * a for a in sample.accel_g)) or 1.0
    return ChairState(sample.time_ns, np.array([x_m, y_m, heading_rad, 0.0, 1.0, 0.0, 0.0]), cov,
                      sample.yaw_rate_dps, 0.0, 0.0, 0.0, norm, tuple(a / norm for a in sample.accel_g), Flag.NONE,
                      False, 0.0, wheel_turn_ratio_prior(settings) * prior_weight, prior_weight,
                      wheel_axis_ratio_prior(settings) * prior_weight, prior_weight,
                      MagAid(np.zeros(MAG_FIT_SIZE), 0.0, False, 0, 0.0, np.zeros(MAG_STATS), 0.0, 0.0, math.nan, 0.0, 0.0,
                             0.0), AxleScale(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, False))


def step(settings: ChairSettings, state: ChairState, sample: ChairSample) -> ChairState:
    dt = (sample.time_ns - state.time_ns) * 1e-9
    if dt <= 0.0:
        return replace(state, flags=Flag.BACKWARDS)
    seat = math.isfinite(sample.yaw_rate_dps)  # a bridge sample has the wheels only
    flags = Flag.GAP if dt > settings.gap_s or not seat or not math.isfinite(state.yaw_rate_dps) else Flag.NONE
    accel_norm = math.sqrt(sum(a * a for a in sample.accel_g)) if seat else state.accel_mean_g
    left_dps, right_dps = sample.left_rotation_deg / dt, sample.right_rotation_deg / dt
    quiet = (abs(left_dps) < settings.still_wheel_dps and abs(right_dps) < settings.still_wheel_dps
             and abs(sample.yaw_rate_dps) < settings.still_gyro_dps)
    # |a| steady against its own mean over this quiet spell, not a slow mean carried over from play:
    # at rest |a| reads its scale and bias (0.97 g, say), in play vibration and pushes lift the mean
    # (1.02 g), so a slow mean let no brief stop count, and an edge that started mid-play went a
    # minute on the bias prior alone (1 deg/s: 30-45 deg of heading)
    alpha = dt / (state.still_s + dt) if quiet else 1.0
    accel_mean = state.accel_mean_g + alpha * (accel_norm - state.accel_mean_g)
    still_now = quiet and abs(accel_norm - accel_mean) < settings.still_accel_g
    still_s = state.still_s + dt if still_now else 0.0
    still = still_s >= settings.still_time_s

    # wheel travel over the step, bias-corrected (the paper's eq. 3-5 with pi); nothing while still
    left = sample.left_rotation_deg - state.left_bias_dps * dt
    right = sample.right_rotation_deg - state.right_bias_dps * dt
    base_travel = 0.0 if still else math.pi * settings.wheel_diameter_m * 0.5 * (left + right) / 360.0
    left_bias, right_bias, gravity = state.left_bias_dps, state.right_bias_dps, state.gravity
    if still:
        beta = min(dt / settings.wheel_bias_time_s, 1.0)
        left_bias += beta * (left_dps - left_bias)
        right_bias += beta * (right_dps - right_bias)
        gravity = _blend_unit(gravity, sample.accel_g, beta)

    mean, cov = state.mean, state.cov
    wheel_difference = right - left
    turn_xy, turn_xy_weight = state.turn_xy, state.turn_xx
    axis_xy, axis_xx = state.axis_xy, state.axis_xx
    wheel_yaw = sample.wheel_yaw_deg
    gyro_rate = 0.5 * (state.yaw_rate_dps + sample.yaw_rate_dps) * DEG - mean[BIAS]
    seat_turn = math.nan  # the seat's turn where the axles' is comparable (no gap, no catch-up)
    if flags & Flag.GAP:  # the seat gyro saw nothing in between: the wheels tell the turn
        if math.isfinite(wheel_yaw):
            turn = axis_xy / axis_xx * wheel_yaw
            turn_var = (settings.wheel_axis_sd * turn) ** 2 + (settings.wheel_axis_bias_dps * DEG * dt) ** 2
        else:
            turn = turn_xy / turn_xy_weight * wheel_difference
            turn_var = (settings.wheel_turn_sd * turn) ** 2
        d_turn_d_bias = d_turn_d_scale = 0.0
    else:
        turn = (1.0 + mean[GYRO_SCALE]) * gyro_rate * dt
        turn_var = (settings.gyro_noise_dps_per_sqrt_hz * DEG) ** 2 * dt
        d_turn_d_bias = -(1.0 + mean[GYRO_SCALE]) * dt
        d_turn_d_scale = gyro_rate * dt
        if max(abs(left_dps), abs(right_dps)) <= settings.wheel_rate_limit_dps:  # not a catch-up after a gap
            seat_turn = gyro_rate * dt
            forget = math.exp(-dt / settings.wheel_turn_memory_s)
            turn_xy = forget * turn_xy + turn * wheel_difference
            turn_xy_weight = forget * turn_xy_weight + wheel_difference * wheel_difference
            if math.isfinite(wheel_yaw):
                axis_xy = forget * axis_xy + turn * wheel_yaw
                axis_xx = forget * axis_xx + wheel_yaw * wheel_yaw

    mid = mean[HEADING] + 0.5 * turn
    travel = mean[SCALE] * base_travel
    c, s = math.cos(mid), math.sin(mid)
    new_mean = mean.copy()
    new_mean[X] += travel * c
    new_mean[Y] += travel * s
    new_mean[HEADING] += turn
    in_impact = accel_norm - 1.0 > settings.impact_g
    shove = in_impact and not state.in_impact  # once per impact, not per sample above the threshold
    shove_var = 0.0
    if shove:
        flags |= Flag.IMPACT
        horizontal = (sample.accel_g[0] - gravity[0]) ** 2 + (sample.accel_g[1] - gravity[1]) ** 2
        vertical = (sample.accel_g[2] - gravity[2]) ** 2
        shove_var = settings.impact_shove_sd_m**2 * (horizontal / (horizontal + vertical))
    new_cov = _propagate_covariance(settings, cov, c, s, travel, base_travel, d_turn_d_bias, d_turn_d_scale,
                                    turn_var, shove_var, dt)

    if still:  # zero-rate update: the seat gyro reads its bias
        flags |= Flag.STILL
        new_mean, new_cov = _scalar_update(new_mean, new_cov, BIAS, 1.0, sample.yaw_rate_dps * DEG - new_mean[BIAS],
                                           (settings.still_rate_sd_dps * DEG) ** 2)

    axle, new_mean, new_cov, axle_flags = _axle_scale(settings, state.axle, seat_turn, wheel_yaw, dt, new_mean, new_cov)
    flags |= axle_flags
    raw_turn = math.nan if flags & Flag.GAP else 0.5 * (state.yaw_rate_dps + sample.yaw_rate_dps) * DEG * dt
    mag, new_mean, new_cov, mag_flags = magnetometer(settings, state.mag, sample, gravity, new_mean, new_cov, dt,
                                                      abs(travel), raw_turn)
    return ChairState(sample.time_ns, new_mean, new_cov, sample.yaw_rate_dps, left_bias, right_bias, still_s,
                      accel_mean, gravity, flags | mag_flags, in_impact, state.travel_m + abs(travel), turn_xy,
                      turn_xy_weight, axis_xy, axis_xx, mag, axle)


def _axle_scale(settings: ChairSettings, axle: AxleScale, seat_turn: float, axle_turn_deg: float, dt: float,
                mean: np.ndarray, cov: np.ndarray) -> tuple[AxleScale, np.ndarray, np.ndarray, Flag]:
    """The seat gyro's scale, once, from the turn two independent gyros saw: the axle IMUs.

    A chair spins thousands of degrees a game, one way more than the other, so a scale error of
    1-2 % is tens of degrees of heading, and in a disturbed hall the field's turn pins it only
    over minutes. The axle IMUs read the same yaw x cos camber with their own scale errors, as
    large as the seat's but independent: the seat's turn over theirs measures the seat's scale
    to the mean of their errors (gyro_scale_sd / sqrt 2) and the camber's (tan c x camber_sd).
    Their errors are the same every window, so the measurement counts once, not per window.
    `seat_turn` is NaN where the two are not comparable (a gap, a wheel catching up): the
    window there is dropped."""
    if axle.done:
        return axle, mean, cov, Flag.NONE
    if not (math.isfinite(seat_turn) and math.isfinite(axle_turn_deg)):
        return replace(axle, window_seat_rad=0.0, window_axle_rad=0.0, window_s=0.0), mean, cov, Flag.NONE
    seat_rad, axle_rad = axle.window_seat_rad + seat_turn, axle.window_axle_rad + axle_turn_deg * DEG
    window_s = axle.window_s + dt
    if window_s < settings.axle_scale_window_s:
        return replace(axle, window_seat_rad=seat_rad, window_axle_rad=axle_rad, window_s=window_s), mean, cov, Flag.NONE
    xy, xx, seen = axle.xy + seat_rad * axle_rad, axle.xx + axle_rad * axle_rad, axle.seen_rad + abs(axle_rad)
    if seen < settings.axle_scale_turn_deg * DEG:
        return AxleScale(0.0, 0.0, 0.0, xy, xx, seen, False), mean, cov, Flag.NONE
    done = AxleScale(0.0, 0.0, 0.0, xy, xx, seen, True)
    if xy <= 0.0:  # the axles turn against the seat: a mounting the venue file has wrong
        return done, mean, cov, Flag.AXLE_SCALE_REJECTED
    noise = axle_scale_noise(settings)
    innovation = axle_scale_measured(settings, done) - mean[GYRO_SCALE]
    if innovation * innovation / (cov[GYRO_SCALE, GYRO_SCALE] + noise) > settings.axle_scale_gate_chi2:
        return done, mean, cov, Flag.AXLE_SCALE_REJECTED
    mean, cov = _scalar_update(mean, cov, GYRO_SCALE, 1.0, innovation, noise)
    return done, mean, cov, Flag.AXLE_SCALE_USED


def axle_scale_measured(settings: ChairSettings, axle: AxleScale) -> float:
    """The seat gyro's scale correction the axles' windows say (true turn / seat turn - 1), to their errors."""
    return axle.xx / (axle.xy * math.cos(settings.camber_deg * DEG)) - 1.0


def axle_scale_noise(settings: ChairSettings) -> float:
    """That measurement's variance: the two axle gyros' mean scale error and the camber's uncertainty."""
    return settings.gyro_scale_sd**2 / 2.0 + (math.tan(settings.camber_deg * DEG) * settings.camber_sd_deg * DEG) ** 2


def position_update(state: ChairState, measured_xy: np.ndarray, covariance: np.ndarray,
                    gate_chi2: float = 13.8) -> tuple[ChairState, bool]:
    """Absolute position measurement (a beacon, a video or manual fix), chi-square gated (2 dof)."""
    h = np.zeros((2, N))
    h[0, X] = h[1, Y] = 1.0
    innovation = measured_xy - state.mean[:2]
    s_matrix = state.cov[:2, :2] + covariance
    distance = float(innovation @ np.linalg.solve(s_matrix, innovation))
    if distance > gate_chi2:
        return state, False
    gain = state.cov @ h.T @ np.linalg.inv(s_matrix)
    mean = state.mean + gain @ innovation
    cov = (np.eye(N) - gain @ h) @ state.cov
    return replace(state, mean=mean, cov=0.5 * (cov + cov.T)), True


def _propagate_covariance(settings: ChairSettings, cov: np.ndarray, c: float, s: float, travel: float,
                          base_travel: float, d_turn_d_bias: float, d_turn_d_scale: float, turn_var: float,
                          shove_var: float, dt: float) -> np.ndarray:
    """P <- F P F^T + Q for one step; (c, s) = cos/sin of the mid-step heading."""
    jacobian = np.eye(N)
    jacobian[X, HEADING] = -travel * s
    jacobian[Y, HEADING] = travel * c
    jacobian[X, SCALE] = base_travel * c
    jacobian[Y, SCALE] = base_travel * s
    for column, d_turn in ((BIAS, d_turn_d_bias), (GYRO_SCALE, d_turn_d_scale)):
        jacobian[HEADING, column] = d_turn
        jacobian[X, column] = -travel * s * 0.5 * d_turn
        jacobian[Y, column] = travel * c * 0.5 * d_turn
    along = (settings.along_track_sd_per_m * travel) ** 2
    across = (settings.cross_track_sd_per_m * travel) ** 2
    along += shove_var
    across += shove_var
    noise = np.zeros((N, N))
    noise[X, X] = along * c * c + across * s * s
    noise[Y, Y] = along * s * s + across * c * c
    noise[X, Y] = noise[Y, X] = (along - across) * c * s
    noise[HEADING, HEADING] = turn_var
    noise[BIAS, BIAS] = (settings.gyro_bias_walk_dps_per_sqrt_s * DEG) ** 2 * dt
    noise[SCALE, SCALE] = settings.wheel_scale_walk_per_sqrt_s**2 * dt
    return jacobian @ cov @ jacobian.T + noise


def _scalar_update(mean: np.ndarray, cov: np.ndarray, index: int, h: float, innovation: float,
                   noise_var: float) -> tuple[np.ndarray, np.ndarray]:
    variance = h * h * cov[index, index] + noise_var
    gain = cov[:, index] * h / variance
    return mean + gain * innovation, cov - np.outer(gain, h * cov[index, :])


def _blend_unit(old: tuple[float, float, float], new: tuple[float, float, float], weight: float) -> tuple[float, float, float]:
    blended = [o + weight * (n - o) for o, n in zip(old, new)]
    norm = math.sqrt(sum(b * b for b in blended)) or 1.0
    return (blended[0] / norm, blended[1] / norm, blended[2] / norm)
