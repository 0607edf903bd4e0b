"""Our per-chair dead reckoning: an extended Kalman filter in constant memory.

State: x, y (m, court frame), heading (rad), seat-gyro yaw bias (rad/s), wheel scale (1),
seat-gyro scale error (1), magnetic north in the court frame (rad).
- Distance from the wheels (mean of both axle gyros: camber leak cancels, the paper's eq. 5),
  times a wheel scale; the wheel gyros' own biases are re-learned whenever the chair is still,
  so a still chair does not creep.
- Heading from the seat gyro, never from the wheels alone (a 0.5 % left/right radius mismatch is
  0.34 deg per metre, algorithms.md). Its bias is re-estimated whenever the chair is still (a
  zero-rate update), which the paper's method never does.
- A lost seat packet would lose the turns made meanwhile (pivots run at 300+ deg/s): across a
  gap the heading change comes from the wheels' differential rotation, whose ratio to the seat
  gyro's turn is learned online (camber and track make it chair-specific).
- The seat magnetometer is a gated, self-calibrating aid: the chair's hard iron is a fixed offset
  in the chair frame, found by a running circle fit as the chair turns; once the fit is sound,
  the field's angle around the circle centre is (north - heading), with north a state learned
  from the known start heading. Updates are weak (building disturbance: ~10 deg) and
  chi-square gated, so they bound the slow heading drift (gyro scale, residual bias) without
  importing the disturbance. Tilt comes from gravity measured while still, never while moving
  (a sprint's 2.5 m/s^2 would read as 14 deg of pitch).
- Uncertainty grows with distance and rotation, not time; an impact adds a shove variance.

`step(settings, state, sample) -> state` is pure; `start` makes the first state. dt comes from
the timestamps; a gap (dt > `gap_s`) or a timestamp going backwards sets a flag, never raises.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, replace

import numpy as np

DEG = math.pi / 180.0
X, Y, HEADING, BIAS, SCALE, GYRO_SCALE, NORTH = range(7)
N = 7


class Flag(enum.IntFlag):
    NONE = 0
    STILL = 1  # zero-rate update applied this step
    GAP = 2  # dt exceeded gap_s: the wheels bridged the turn
    BACKWARDS = 4  # timestamp not after the previous one: sample ignored
    IMPACT = 8  # |a| - 1 g rose above impact_g: position variance inflated once per impact
    MAG_USED = 16  # magnetometer update applied
    MAG_REJECTED = 32  # magnetometer disagreed beyond the gate


@dataclass(frozen=True)
class ChairSettings:
    wheel_diameter_m: float = 0.61
    gyro_noise_dps_per_sqrt_hz: float = 0.01  # MPU-9250 rate noise density
    gyro_bias_walk_dps_per_sqrt_s: float = 0.002  # MEMS in-run instability
    initial_gyro_bias_sd_dps: float = 1.0  # prior before the first still period
    gyro_scale_sd: float = 0.02  # prior of the seat gyro's scale error (MPU-9250: +-3 %)
    wheel_scale_sd: float = 0.01  # prior of effective / measured wheel diameter
    wheel_scale_walk_per_sqrt_s: float = 1e-5
    along_track_sd_per_m: float = 0.03  # slip in sprints and braking, 1-3 %
    cross_track_sd_per_m: float = 0.03  # sideways skid in turns
    impact_g: float = 4.0  # a jolt this hard may be a contact that shoves the chair
    impact_shove_sd_m: float = 0.3  # shoves move chairs 0.1-1 m with no wheel rotation (simulator)
    still_wheel_dps: float = 3.0  # both wheels slower than this (bias up to ~1.5 deg/s + noise)
    still_gyro_dps: float = 2.0  # seat yaw rate below this, before bias correction (4 x the bias SD)
    still_accel_g: float = 0.05  # |a| within this of its slow mean
    still_time_s: float = 0.5  # conditions held this long (a pivot reversing slowly passes in less)
    still_rate_sd_dps: float = 0.3  # how still "still" is (fidgeting), per update
    wheel_bias_time_s: float = 2.0  # time constant of the wheel-bias average while still
    accel_mean_time_s: float = 1.0  # time constant of the slow |a| mean
    gap_s: float = 0.1
    track_m: float = 0.82  # wheel contact track, only a prior for the wheel-turn ratio
    camber_deg: float = 17.0  # likewise
    wheel_turn_memory_s: float = 60.0  # forgetting time of the wheel-turn ratio estimate
    wheel_turn_sd: float = 0.1  # heading uncertainty per radian bridged by the wheels (skid)
    wheel_rate_limit_dps: float = 2000.0  # faster "rates" are a wheel catching up after lost packets
    mag_period_s: float = 0.5  # one magnetometer update per this (disturbance is spatially correlated)
    mag_heading_sd_deg: float = 12.0  # building disturbance (docs/simulator.md: ~9 deg RMS) + soft iron
    mag_correlation_s: float = 5.0  # the disturbance changes over metres: samples closer in time repeat it
    mag_gate_chi2: float = 6.63  # 99 % for 1 dof
    mag_fit_memory_s: float = 300.0  # forgetting time of the hard-iron circle fit
    mag_fit_min_spread: float = 0.5  # the fit is trusted once field angles spread this well (0..1)
    mag_fit_min_points: int = 40  # and once it holds this many updates' worth of points (20 s)
    mag_recover_rejections: int = 20  # this many rejections in a row: north is re-learned (as Fusion does)


@dataclass(frozen=True)
class ChairSample:
    """One seat sample and how far each wheel turned since the previous one (device clock).

    Wheel rotation comes as increments of each axle gyro's own integral, so a lost seat packet
    loses no distance: the next increment spans the gap. Vectors are in the chair frame.
    """

    time_ns: int
    yaw_rate_dps: float  # seat gyro about the chair's up axis
    left_rotation_deg: float  # forward-positive, since the previous sample
    right_rotation_deg: float
    accel_g: tuple[float, float, float]
    mag_gauss: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class MagAid:
    """The magnetometer aid's own state: hard-iron fit and bookkeeping (fixed size)."""

    fit: np.ndarray  # (4, 4) running moments [x, y, 1, x^2 + y^2] of the levelled field
    due_s: float  # time until the next update
    ready: bool  # north has been initialised from the fit
    rejections: int  # consecutive gate rejections
    innovation_deg: float  # last residual (diagnostic)


@dataclass(frozen=True)
class ChairState:
    time_ns: int
    mean: np.ndarray  # (7,)
    cov: np.ndarray  # (7, 7)
    yaw_rate_dps: float  # previous sample, for the trapezoid
    left_bias_dps: float
    right_bias_dps: float
    still_s: float
    accel_mean_g: float
    gravity: tuple[float, float, float]  # unit vector, chair frame, measured while still
    flags: Flag
    in_impact: bool  # the last sample was above impact_g (an impact spans several samples)
    travel_m: float  # total distance rolled (diagnostic)
    turn_xy: float  # running sums for the wheel-turn ratio: sum(gyro turn * wheel difference)
    turn_xx: float  # and sum(wheel difference^2), both with forgetting
    mag: MagAid


def wheel_turn_ratio_prior(settings: ChairSettings) -> float:
    """Heading change (rad) per degree of (right - left) wheel rotation, from geometry.

    Forward-positive axle rates differ by yaw_rate * (track / r - 2 sin(camber)): the track
    turns the wheels apart, camber leaks the yaw into each axle with opposite signs.
    """
    radius = 0.5 * settings.wheel_diameter_m
    return (math.pi / 180.0) / (settings.track_m / radius - 2.0 * math.sin(settings.camber_deg * DEG))


def start(settings: ChairSettings, sample: ChairSample, x_m: float, y_m: float, heading_rad: float,
          position_sd_m: float = 0.1, heading_sd_rad: float = 2 * DEG) -> ChairState:
    cov = np.diag([position_sd_m**2, position_sd_m**2, heading_sd_rad**2, (settings.initial_gyro_bias_sd_dps * DEG) ** 2,
                   settings.wheel_scale_sd**2, settings.gyro_scale_sd**2, math.pi**2])
    prior_weight = 1e4  # deg^2 of wheel difference: about one slow pivot's worth of evidence
    norm = math.sqrt(sum(a * a for a in sample.accel_g)) or 1.0
    return ChairState(sample.time_ns, np.array([x_m, y_m, heading_rad, 0.0, 1.0, 0.0, 0.0]), cov,
                      sample.yaw_rate_dps, 0.0, 0.0, 0.0, norm, tuple(a / norm for a in sample.accel_g), Flag.NONE,
                      False, 0.0, wheel_turn_ratio_prior(settings) * prior_weight, prior_weight,
                      MagAid(np.zeros((4, 4)), 0.0, False, 0, 0.0))


def step(settings: ChairSettings, state: ChairState, sample: ChairSample) -> ChairState:
    dt = (sample.time_ns - state.time_ns) * 1e-9
    if dt <= 0.0:
        return replace(state, flags=Flag.BACKWARDS)
    flags = Flag.GAP if dt > settings.gap_s else Flag.NONE
    accel_norm = math.sqrt(sum(a * a for a in sample.accel_g))
    alpha = min(dt / settings.accel_mean_time_s, 1.0)
    accel_mean = state.accel_mean_g + alpha * (accel_norm - state.accel_mean_g)
    left_dps, right_dps = sample.left_rotation_deg / dt, sample.right_rotation_deg / dt
    still_now = (abs(left_dps) < settings.still_wheel_dps and abs(right_dps) < settings.still_wheel_dps
                 and abs(sample.yaw_rate_dps) < settings.still_gyro_dps
                 and abs(accel_norm - accel_mean) < settings.still_accel_g)
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
    gyro_rate = 0.5 * (state.yaw_rate_dps + sample.yaw_rate_dps) * DEG - mean[BIAS]
    if flags & Flag.GAP:  # the seat gyro saw nothing in between: the wheels tell the turn
        turn = turn_xy / turn_xy_weight * wheel_difference
        turn_var = (settings.wheel_turn_sd * turn) ** 2
        d_turn_d_bias = d_turn_d_scale = 0.0
    else:
        turn = (1.0 + mean[GYRO_SCALE]) * gyro_rate * dt
        turn_var = (settings.gyro_noise_dps_per_sqrt_hz * DEG) ** 2 * dt
        d_turn_d_bias = -(1.0 + mean[GYRO_SCALE]) * dt
        d_turn_d_scale = gyro_rate * dt
        if max(abs(left_dps), abs(right_dps)) <= settings.wheel_rate_limit_dps:  # not a catch-up after a gap
            forget = math.exp(-dt / settings.wheel_turn_memory_s)
            turn_xy = forget * turn_xy + turn * wheel_difference
            turn_xy_weight = forget * turn_xy_weight + wheel_difference * wheel_difference

    mid = mean[HEADING] + 0.5 * turn
    travel = mean[SCALE] * base_travel
    c, s = math.cos(mid), math.sin(mid)
    new_mean = mean.copy()
    new_mean[X] += travel * c
    new_mean[Y] += travel * s
    new_mean[HEADING] += turn
    in_impact = accel_norm - 1.0 > settings.impact_g
    shove = in_impact and not state.in_impact  # once per impact, not per sample above the threshold
    if shove:
        flags |= Flag.IMPACT
    new_cov = _propagate_covariance(settings, cov, c, s, travel, base_travel, d_turn_d_bias, d_turn_d_scale,
                                    turn_var, shove, dt)

    if still:  # zero-rate update: the seat gyro reads its bias
        flags |= Flag.STILL
        new_mean, new_cov = _scalar_update(new_mean, new_cov, BIAS, 1.0, sample.yaw_rate_dps * DEG - new_mean[BIAS],
                                           (settings.still_rate_sd_dps * DEG) ** 2)

    mag, new_mean, new_cov, mag_flags = _magnetometer(settings, state.mag, sample, gravity, new_mean, new_cov, dt)
    return ChairState(sample.time_ns, new_mean, new_cov, sample.yaw_rate_dps, left_bias, right_bias, still_s,
                      accel_mean, gravity, flags | mag_flags, in_impact, state.travel_m + abs(travel), turn_xy,
                      turn_xy_weight, mag)


def _magnetometer(settings: ChairSettings, mag: MagAid, sample: ChairSample, gravity: tuple[float, float, float],
                  mean: np.ndarray, cov: np.ndarray, dt: float) -> tuple[MagAid, np.ndarray, np.ndarray, Flag]:
    """Every `mag_period_s`: extend the hard-iron fit, then learn north or correct the heading."""
    due = mag.due_s - dt
    if sample.mag_gauss is None or due > 0.0:
        return replace(mag, due_s=due), mean, cov, Flag.NONE
    horizontal = _level(sample.mag_gauss, gravity)
    fit = _fit_add(mag.fit, horizontal, math.exp(-settings.mag_period_s / settings.mag_fit_memory_s))
    mag = replace(mag, fit=fit, due_s=settings.mag_period_s)
    centre = _fit_centre(fit, settings.mag_fit_min_spread, settings.mag_fit_min_points)
    if centre is None:
        return mag, mean, cov, Flag.NONE
    angle = math.atan2(horizontal[1] - centre[1], horizontal[0] - centre[0])  # = north - heading
    if not mag.ready or mag.rejections >= settings.mag_recover_rejections:
        # (re)learn north = angle + heading: it inherits the heading's error and all its correlations
        mean, cov = mean.copy(), cov.copy()
        mean[NORTH] = angle + mean[HEADING]
        cov[NORTH, :] = cov[HEADING, :]
        cov[:, NORTH] = cov[:, HEADING]
        cov[NORTH, NORTH] = cov[HEADING, HEADING] + (settings.mag_heading_sd_deg * DEG) ** 2
        return replace(mag, ready=True, rejections=0), mean, cov, Flag.NONE
    innovation = _wrap(angle - (mean[NORTH] - mean[HEADING]))
    h = np.zeros(N)
    h[NORTH], h[HEADING] = 1.0, -1.0
    # updates every mag_period_s share one disturbance for ~mag_correlation_s: de-weight them
    repeat = max(settings.mag_correlation_s / settings.mag_period_s, 1.0)
    variance = float(h @ cov @ h) + repeat * (settings.mag_heading_sd_deg * DEG) ** 2
    mag = replace(mag, innovation_deg=innovation / DEG)
    if innovation * innovation / variance > settings.mag_gate_chi2:
        return replace(mag, rejections=mag.rejections + 1), mean, cov, Flag.MAG_REJECTED
    gain = cov @ h / variance
    return replace(mag, rejections=0), mean + gain * innovation, cov - np.outer(gain, h @ cov), Flag.MAG_USED


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
                          shove: bool, dt: float) -> np.ndarray:
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
    if shove:
        along += settings.impact_shove_sd_m**2
        across += settings.impact_shove_sd_m**2
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


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def _blend_unit(old: tuple[float, float, float], new: tuple[float, float, float], weight: float) -> tuple[float, float, float]:
    blended = [o + weight * (n - o) for o, n in zip(old, new)]
    norm = math.sqrt(sum(b * b for b in blended)) or 1.0
    return (blended[0] / norm, blended[1] / norm, blended[2] / norm)


def _level(field: tuple[float, float, float], gravity: tuple[float, float, float]) -> tuple[float, float]:
    """The field's horizontal part in chair forward/left axes, using the still-measured gravity."""
    up = gravity
    along_up = sum(f * u for f, u in zip(field, up))
    horizontal = [f - along_up * u for f, u in zip(field, up)]
    # forward axis levelled: chair x with its vertical part removed
    forward = [1.0 - up[0] * up[0], -up[0] * up[1], -up[0] * up[2]]
    norm = math.sqrt(sum(f * f for f in forward)) or 1.0
    forward = [f / norm for f in forward]
    left = [up[1] * forward[2] - up[2] * forward[1], up[2] * forward[0] - up[0] * forward[2],
            up[0] * forward[1] - up[1] * forward[0]]
    return (sum(h * f for h, f in zip(horizontal, forward)), sum(h * lv for h, lv in zip(horizontal, left)))


def _fit_add(moments: np.ndarray, point: tuple[float, float], forget: float) -> np.ndarray:
    vector = np.array([point[0], point[1], 1.0, point[0] ** 2 + point[1] ** 2])
    return forget * moments + np.outer(vector, vector)


def _fit_centre(moments: np.ndarray, min_spread: float, min_points: float) -> tuple[float, float] | None:
    """Centre of the circle x^2 + y^2 = a x + b y + c fitted to the running moments.

    None until the points spread around the circle: the smaller principal spread of the
    points must reach `min_spread` of the radius (a full circle gives 1/sqrt(2) = 0.71).
    """
    weight = moments[2, 2]
    if weight < min_points:
        return None
    mean = moments[:2, 2] / weight
    scatter = moments[:2, :2] / weight - np.outer(mean, mean)
    try:
        a, b, c = np.linalg.solve(moments[:3, :3], moments[:3, 3])
    except np.linalg.LinAlgError:
        return None
    centre = (float(a) / 2.0, float(b) / 2.0)
    radius_sq = c + centre[0] ** 2 + centre[1] ** 2
    smallest = float(np.linalg.eigvalsh(scatter)[0])
    if radius_sq <= 0.0 or 2.0 * smallest < min_spread**2 * radius_sq:
        return None
    return centre
