"""Our per-chair dead reckoning: an extended Kalman filter in constant memory.

State: x, y (m, court frame), heading (rad), seat-gyro yaw bias (rad/s), wheel scale (1),
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
- The seat magnetometer is a self-calibrating aid that learns the hall it is in. The chair's hard
  iron is a fixed offset in the chair frame, found by a running circle fit as the chair turns;
  around its centre the field's angle is (north - heading). A building's disturbance is fixed in
  space, about isotropic, and nobody knows it in advance (0-25 deg RMS, correlated over 1-10 m):
  - its size is learned from the spread of the field's strength around the circle (a disturbance
    that turns the field by a degrees changes its strength by as much), its correlation length
    from how fast successive readings' strengths differ over the travel between them;
  - the turn the field saw over `mag_turn_s` measures the gyro's bias and scale: over little
    travel the disturbance hardly changes, so its change, 2 var (1 - exp(-d / L)), is the
    noise; a pivot in place measures the scale exactly, however disturbed the hall;
  - north - heading is measured once per correlation length of travel, not per second (a parked
    chair repeats one disturbed reading), chi-square gated; north is learned from the known start
    heading and re-learned after `mag_recover_rejections` rejections in a row;
  - a hall more disturbed than `mag_trust_sd_deg` is trusted less than its spread says (chairs
    keep to a few places, so its errors do not average out as independent readings would);
  - every reading's variance includes the fitted centre's own uncertainty;
  - the hub maps the hall from every chair's readings (hub/chair/field_map.py); where its map,
    handed in by the edge as `MagAid.map_offset_rad` / `map_var_rad2`, leaves less than the hall's
    own disturbance, its offset comes out of north - heading (not out of the turn: a difference
    over metres, to which the map's cell-to-cell errors would add); each reading that counts for
    the statistics, north known, is offered to the map (`MagAid.field_*`).
  Tilt comes from gravity measured while still, never while moving (a sprint's 2.5 m/s^2 would
  read as 14 deg of pitch).
- Uncertainty grows with distance and rotation, not time; an impact adds a shove variance in
  proportion to its horizontal share (of the specific force beyond gravity): a bump from below
  (a caster landing, the floor) cannot slide the chair, a contact can.

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
# The magnetometer aid's learned statistics (MagAid.stats), running sums with forgetting: the
# readings' weight; their squared relative strength residuals; successive residuals' squared
# differences and the travel between them; the field strength; and the last residual.
M_WEIGHT, M_RADIAL, M_DIFF, M_STEP, M_RADIUS, M_LAST = range(6)
MAG_STATS = 6


class Flag(enum.IntFlag):
    NONE = 0
    STILL = 1  # zero-rate update applied this step
    GAP = 2  # dt exceeded gap_s: the wheels bridged the turn
    BACKWARDS = 4  # timestamp not after the previous one: sample ignored
    IMPACT = 8  # |a| - 1 g rose above impact_g: position variance inflated once per impact
    MAG_USED = 16  # magnetometer update applied
    MAG_REJECTED = 32  # magnetometer disagreed beyond the gate
    AXLE_SCALE_USED = 64  # the seat gyro's scale measured against the axle IMUs (once per run)
    AXLE_SCALE_REJECTED = 128  # ... and they disagreed beyond the gate (a wrong camber or mounting): not used


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
    impact_shove_sd_m: float = 0.15  # a horizontal impact's shove (worlds 1-10: 0.3 made the filter 3x too doubtful)
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
    wheel_turn_sd: float = 0.1  # heading uncertainty per radian bridged by the wheels' differential (skid)
    wheel_axis_sd: float = 0.02  # ... per radian bridged by the axle IMUs' yaw (ratio learned within ~1 %)
    wheel_axis_bias_dps: float = 1.0  # ... and per second: the in-plane gyro biases (2 axes x 0.5 deg/s), rectified
    wheel_rate_limit_dps: float = 2000.0  # faster "rates" are a wheel catching up after lost packets
    axle_scale_turn_deg: float = 1440.0  # the seat gyro's scale is checked once the axle IMUs saw this much yaw
    axle_scale_window_s: float = 1.0  # the seat's and the axles' turns compared over windows this long
    camber_sd_deg: float = 1.0  # how well the venue file knows the chair's camber (the axles read yaw x cos camber)
    axle_scale_gate_chi2: float = 6.63  # 99 % for 1 dof
    mag_period_s: float = 0.5  # the magnetometer is read this often (fit and disturbance statistics)
    mag_heading_sd_deg: float = 12.0  # prior of the disturbance's heading SD, until the hall's is learned
    mag_floor_sd_deg: float = 2.0  # never trusted closer than this (noise, soft-iron residual)
    mag_level_weight: float = 20.0  # the prior counts as this many readings against the learned statistics
    mag_level_memory: float = 200.0  # readings: forgetting of the learned disturbance statistics
    mag_min_step_m: float = 0.3  # a reading counts for the statistics after this much travel (a still chair repeats one)
    mag_correlation_prior_m: float = 2.0  # prior of the disturbance's correlation length
    mag_correlation_max_m: float = 20.0  # and its bounds
    mag_correlation_min_m: float = 0.5
    mag_turn_s: float = 2.0  # the gyro is measured by the field's turn over this long
    mag_turn_sd_deg: float = 1.5  # noise of a turn the field saw (two readings, the fit's centre error)
    mag_trust_sd_deg: float = 3.0  # beyond this disturbance a reading's variance grows with its square (docs/reckon-estimator.md: worlds 1-10)
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
    wheel_yaw_deg: float = math.nan  # the chair's turn the axle IMUs saw since the previous sample, x cos(camber)


@dataclass(frozen=True)
class MagAid:
    """The magnetometer aid's own state: hard-iron fit, the hall's learned disturbance, bookkeeping (fixed size)."""

    fit: np.ndarray  # (4, 4) running moments [x, y, 1, x^2 + y^2] of the levelled field
    due_s: float  # time until the next reading
    ready: bool  # north has been initialised from the fit
    rejections: int  # consecutive gate rejections
    innovation_deg: float  # last residual (diagnostic)
    stats: np.ndarray  # (MAG_STATS,) the hall's disturbance as learned so far
    since_read_m: float  # travel since the last reading that counted for `stats`
    since_update_m: float  # travel since the last heading correction (or north learned)
    anchor_angle: float  # field angle (north - heading) at the start of the turn being measured; NaN: none
    turn_gyro_rad: float  # raw seat-gyro turn since then (trapezoid, before bias and scale)
    turn_s: float  # and the time
    turn_m: float  # and the travel
    # The hub's map of the hall's field (hub/chair/field_map.py) where the chair is, set by the edge
    # before each batch: the field's direction offset there (rad) and what is left of the
    # disturbance after it (rad^2); 0: no map here. The map is used only where it leaves less than
    # the hall's own learned disturbance (a clean hall's map holds the chairs' heading errors).
    map_offset_rad: float = 0.0
    map_var_rad2: float = 0.0
    # The last reading offered to the map (once per `mag_min_step_m` of travel, north known): its
    # number, time and place, and the field's angle there less the filter's (north - heading),
    # whose variance is `field_var_rad2`. The edge publishes each new one as a FieldReading.
    field_count: int = 0
    field_time_ns: int = 0
    field_x_m: float = 0.0
    field_y_m: float = 0.0
    field_offset_rad: float = 0.0
    field_var_rad2: float = 0.0


@dataclass(frozen=True)
class AxleScale:
    """The seat gyro's turn against the axle IMUs' yaw, for one check of its scale (fixed size).

    Both turns are summed over windows of `axle_scale_window_s` (a wheel clock a few ms off moves
    a window's turn by little, a single step's by much) and the windows regressed through the
    origin, until the axles have seen `axle_scale_turn_deg`."""

    window_seat_rad: float  # the seat gyro's turn in the current window, bias removed, before scale
    window_axle_rad: float  # the axle IMUs' yaw (x cos camber) in it
    window_s: float
    xy: float  # sum over windows of seat x axle turn
    xx: float  # and of axle turn^2
    seen_rad: float  # and of |axle turn|
    done: bool  # the check was made (used or rejected)


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
    axis_xy: float  # likewise for the axle IMUs' yaw: sum(gyro turn * wheel yaw)
    axis_xx: float  # and sum(wheel yaw^2)
    mag: MagAid
    axle: AxleScale


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
                      MagAid(np.zeros((4, 4)), 0.0, False, 0, 0.0, np.zeros(MAG_STATS), 0.0, 0.0, math.nan, 0.0, 0.0,
                             0.0), AxleScale(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, False))


def step(settings: ChairSettings, state: ChairState, sample: ChairSample) -> ChairState:
    dt = (sample.time_ns - state.time_ns) * 1e-9
    if dt <= 0.0:
        return replace(state, flags=Flag.BACKWARDS)
    seat = math.isfinite(sample.yaw_rate_dps)  # a bridge sample has the wheels only
    flags = Flag.GAP if dt > settings.gap_s or not seat or not math.isfinite(state.yaw_rate_dps) else Flag.NONE
    accel_norm = math.sqrt(sum(a * a for a in sample.accel_g)) if seat else state.accel_mean_g
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
    mag, new_mean, new_cov, mag_flags = _magnetometer(settings, state.mag, sample, gravity, new_mean, new_cov, dt,
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


def _magnetometer(settings: ChairSettings, mag: MagAid, sample: ChairSample, gravity: tuple[float, float, float],
                  mean: np.ndarray, cov: np.ndarray, dt: float, travel_m: float, raw_turn_rad: float
                  ) -> tuple[MagAid, np.ndarray, np.ndarray, Flag]:
    """Every `mag_period_s`: extend the hard-iron fit and the hall's statistics; measure the gyro by the
    turn the field saw; learn north, or correct the heading once the chair has moved a correlation
    length since the last correction. `raw_turn_rad` is the seat gyro's raw turn this step (NaN in a gap)."""
    due = mag.due_s - dt
    since_read, since_update = mag.since_read_m + travel_m, mag.since_update_m + travel_m
    turn_gyro, turn_s, turn_m = mag.turn_gyro_rad + raw_turn_rad, mag.turn_s + dt, mag.turn_m + travel_m
    if sample.mag_gauss is None or due > 0.0:
        return replace(mag, due_s=due, since_read_m=since_read, since_update_m=since_update, turn_gyro_rad=turn_gyro,
                       turn_s=turn_s, turn_m=turn_m), mean, cov, Flag.NONE
    horizontal = _level(sample.mag_gauss, gravity)
    fit = _fit_add(mag.fit, horizontal, math.exp(-settings.mag_period_s / settings.mag_fit_memory_s))
    mag = replace(mag, fit=fit, due_s=settings.mag_period_s, since_read_m=since_read, since_update_m=since_update,
                  turn_gyro_rad=turn_gyro, turn_s=turn_s, turn_m=turn_m)
    centre = _fit_centre(fit, settings.mag_fit_min_spread, settings.mag_fit_min_points)
    if centre is None:
        return mag, mean, cov, Flag.NONE
    east, north_part = horizontal[0] - centre[0], horizontal[1] - centre[1]
    raw_angle = math.atan2(north_part, east)  # = north - heading + the hall's disturbance here
    radius = math.sqrt(east * east + north_part * north_part)
    if since_read >= settings.mag_min_step_m:
        mag = replace(mag, stats=_learn_disturbance(settings, mag.stats, radius, since_read), since_read_m=0.0)
        if mag.ready:
            mag = replace(mag, field_count=mag.field_count + 1, field_time_ns=sample.time_ns, field_x_m=float(mean[X]),
                          field_y_m=float(mean[Y]), field_offset_rad=_wrap(raw_angle - (mean[NORTH] - mean[HEADING])),
                          field_var_rad2=float(cov[NORTH, NORTH] - 2.0 * cov[NORTH, HEADING] + cov[HEADING, HEADING]))
    variance, correlation_m = mag_disturbance(settings, mag.stats)
    centre_spread = _centre_spread(fit, radius, variance)  # the strength's spread: untouched by a map of directions
    flags = Flag.NONE
    if not math.isfinite(mag.anchor_angle) or not math.isfinite(turn_gyro):
        mag = replace(mag, anchor_angle=raw_angle, turn_gyro_rad=0.0, turn_s=0.0, turn_m=0.0)
    elif turn_s >= settings.mag_turn_s:
        mean, cov, flags = _turn_update(settings, mag, raw_angle, mean, cov, variance, correlation_m, centre_spread)
        mag = replace(mag, anchor_angle=raw_angle, turn_gyro_rad=0.0, turn_s=0.0, turn_m=0.0)
    # north - heading: where the hub's map knows this place better than the hall's own model, its offset out
    # (the turn above is a difference over metres, which a map's errors from cell to cell would only add to)
    angle = raw_angle
    mapped = _trusted(settings, mag.map_var_rad2) if mag.map_var_rad2 > 0.0 else math.inf
    if mapped < variance:
        angle, variance = _wrap(raw_angle - mag.map_offset_rad), mapped
    if not mag.ready or mag.rejections >= settings.mag_recover_rejections:
        # (re)learn north = angle + heading: it inherits the heading's error and all its correlations
        mean, cov = mean.copy(), cov.copy()
        mean[NORTH] = angle + mean[HEADING]
        cov[NORTH, :] = cov[HEADING, :]
        cov[:, NORTH] = cov[:, HEADING]
        cov[NORTH, NORTH] = cov[HEADING, HEADING] + variance
        return replace(mag, ready=True, rejections=0, since_update_m=0.0), mean, cov, flags
    if since_update < correlation_m:  # the same stretch of disturbed field: nothing new about the heading
        return mag, mean, cov, flags
    innovation = _wrap(angle - (mean[NORTH] - mean[HEADING]))
    h = np.zeros(N)
    h[NORTH], h[HEADING] = 1.0, -1.0
    total = float(h @ cov @ h) + variance + _across(centre_spread, -math.sin(angle), math.cos(angle))
    mag = replace(mag, innovation_deg=innovation / DEG, since_update_m=0.0)
    if innovation * innovation / total > settings.mag_gate_chi2:
        return replace(mag, rejections=mag.rejections + 1), mean, cov, flags | Flag.MAG_REJECTED
    gain = cov @ h / total
    return replace(mag, rejections=0), mean + gain * innovation, cov - np.outer(gain, h @ cov), flags | Flag.MAG_USED


def _turn_update(settings: ChairSettings, mag: MagAid, angle: float, mean: np.ndarray, cov: np.ndarray,
                 variance: float, correlation_m: float, centre_spread: tuple[float, float, float]
                 ) -> tuple[np.ndarray, np.ndarray, Flag]:
    """The gyro's bias and scale from the turn the field saw since the anchor reading.

    The disturbance is the hall's, fixed in space: over little travel it hardly changes, so the
    field turns by exactly the chair's turn, however disturbed it is (a pivot measures the gyro's
    scale, a slow stretch its bias). Its change over `turn_m` of travel, 2 var (1 - exp(-d / L)),
    is the measurement's noise."""
    scale, bias = 1.0 + mean[GYRO_SCALE], mean[BIAS]
    predicted = scale * (mag.turn_gyro_rad - bias * mag.turn_s)
    seen = predicted + _wrap(-(angle - mag.anchor_angle) - predicted)  # unwrapped near the gyro's turn
    noise = (2.0 * variance * (1.0 - math.exp(-mag.turn_m / correlation_m)) + (settings.mag_turn_sd_deg * DEG) ** 2
             + _across(centre_spread, math.sin(mag.anchor_angle) - math.sin(angle),
                       math.cos(angle) - math.cos(mag.anchor_angle)))
    h_bias, h_scale = -scale * mag.turn_s, mag.turn_gyro_rad - bias * mag.turn_s  # d predicted / d state
    innovation = seen - predicted
    row = h_bias * cov[BIAS] + h_scale * cov[GYRO_SCALE]  # h P
    total = (h_bias * row[BIAS] + h_scale * row[GYRO_SCALE]) + noise
    if innovation * innovation / total > settings.mag_gate_chi2:
        return mean, cov, Flag.MAG_REJECTED
    gain = (h_bias * cov[:, BIAS] + h_scale * cov[:, GYRO_SCALE]) / total  # P h / total
    return mean + gain * innovation, cov - np.outer(gain, row), Flag.MAG_USED


def _centre_spread(fit: np.ndarray, radius: float, variance: float) -> tuple[float, float, float]:
    """(xx, xy, yy) covariance of the fitted circle's centre over its radius squared (rad^2).

    The algebraic residual of a reading a relative distance e off the circle is 2 r^2 e, so the
    least-squares centre has covariance r^2 var(e) S^-1 / w, S the readings' scatter and w their
    weight: 2 var(e) / w on a full circle, more on a short arc."""
    w = fit[2, 2]
    mean_x, mean_y = fit[0, 2] / w, fit[1, 2] / w
    sxx, sxy, syy = fit[0, 0] / w - mean_x * mean_x, fit[1, 0] / w - mean_y * mean_x, fit[1, 1] / w - mean_y * mean_y
    scale = radius * radius * variance / (w * (sxx * syy - sxy * sxy))
    return scale * syy, -scale * sxy, scale * sxx


def _across(spread: tuple[float, float, float], nx: float, ny: float) -> float:
    """The variance (rad^2) a centre of covariance `spread` adds to a field angle along (nx, ny)."""
    return spread[0] * nx * nx + 2.0 * spread[1] * nx * ny + spread[2] * ny * ny


def _learn_disturbance(settings: ChairSettings, stats: np.ndarray, radius: float, step_m: float) -> np.ndarray:
    """The statistics after one more reading `step_m` from the last: a field of radius `radius` around the fit's centre.

    A disturbance of the same size along and across the field (a building's is about isotropic)
    changes the field's strength by as much, relative to it, as it turns it: the spread of the
    strength measures the heading disturbance without knowing the heading. How fast successive
    readings' strengths differ over the travel between them gives its correlation length."""
    out = stats.copy()
    forget = 1.0 - 1.0 / settings.mag_level_memory
    radius_mean = out[M_RADIUS] / out[M_WEIGHT] if out[M_WEIGHT] > 0.0 else radius
    residual = (radius - radius_mean) / radius_mean
    if out[M_WEIGHT] > 0.0:
        out[M_DIFF] = forget * out[M_DIFF] + (residual - out[M_LAST]) ** 2
        out[M_STEP] = forget * out[M_STEP] + step_m
    out[M_RADIAL] = forget * out[M_RADIAL] + residual * residual
    out[M_RADIUS] = forget * out[M_RADIUS] + radius
    out[M_WEIGHT] = forget * out[M_WEIGHT] + 1.0
    out[M_LAST] = residual
    return out


def _trusted(settings: ChairSettings, variance: float) -> float:
    """A disturbance's variance as the aid uses it: floored, and beyond `mag_trust_sd_deg` grown with
    its square (chairs keep to a few places, so its errors do not average out as independent
    readings would)."""
    variance = max(variance, (settings.mag_floor_sd_deg * DEG) ** 2)
    return variance * max(1.0, variance / (settings.mag_trust_sd_deg * DEG) ** 2)


def mag_disturbance(settings: ChairSettings, stats: np.ndarray) -> tuple[float, float]:
    """(heading variance rad^2, correlation length m) of the hall's field: learned, blended with the priors."""
    prior_weight, weight = settings.mag_level_weight, stats[M_WEIGHT]
    prior_var = (settings.mag_heading_sd_deg * DEG) ** 2
    variance = _trusted(settings, (stats[M_RADIAL] + prior_weight * prior_var) / (weight + prior_weight))
    correlation = settings.mag_correlation_prior_m
    if weight > 1.0 and stats[M_RADIAL] > 0.0:
        ratio = 0.5 * (stats[M_DIFF] / stats[M_RADIAL])  # 1 - exp(-step / L), exponential correlation
        step = stats[M_STEP] / weight
        learned = settings.mag_correlation_max_m if ratio <= 0.0 else (
            settings.mag_correlation_min_m if ratio >= 1.0 else -step / math.log(1.0 - ratio))
        learned = min(max(learned, settings.mag_correlation_min_m), settings.mag_correlation_max_m)
        correlation = (weight * learned + prior_weight * correlation) / (weight + prior_weight)
    return variance, correlation


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
