"""The chair filter's settings, samples and state, and the names of the state's entries: shared by
the reference filter (edge/chair/estimator.py), its magnetometer aid (edge/chair/magnetometer.py),
their compiled mirrors (edge/chair/kernel.py, mag_kernel.py) and the packed layout (layout.py)."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

DEG = math.pi / 180.0
X, Y, HEADING, BIAS, SCALE, GYRO_SCALE, NORTH = range(7)
N = 7
# The magnetometer aid's learned statistics (MagAid.stats), running sums with forgetting: the
# readings' weight; their squared relative strength residuals; successive residuals' squared
# differences and the travel between them; the field strength; the last residual; and the north - heading
# readings' squared innovations beyond what the filter's heading explains, and their weight.
M_WEIGHT, M_RADIAL, M_DIFF, M_STEP, M_RADIUS, M_LAST, M_EXCESS, M_CHECKS = range(8)
MAG_STATS = 8
MAG_FIT_SIZE = 7  # MagAid.fit: the hard-iron fit's running sums


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
    # the bias's random walk: MEMS in-run instability (0.0005-0.005) and, larger, the warm-up after power-on
    # (0-0.5 deg/s over 100-600 s, docs/simulator.md): b sqrt(T) / tau over the 30-60 s between stops, 0.005-0.02
    gyro_bias_walk_dps_per_sqrt_s: float = 0.01
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
    still_accel_g: float = 0.05  # |a| within this of its mean over the quiet spell so far
    still_time_s: float = 0.3  # conditions held this long (worlds 1-10 + 31-50: 0.3 s against 0.5; a pivot reversing passes in ms)
    still_rate_sd_dps: float = 0.3  # how still "still" is (fidgeting), per update
    wheel_bias_time_s: float = 2.0  # time constant of the wheel-bias average while still
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
    mag_fit_memory_s: float = 300.0  # forgetting time of the hard-iron fit
    mag_fit_min_spread: float = 0.5  # the fit is trusted once headings spread this well: sqrt(1 - R^2), 0..1
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

    fit: np.ndarray  # (7,) running sums of the hard-iron fit (magnetometer.py's `_fit_add`)
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
    accel_mean_g: float  # |a|'s mean over the current quiet spell (the last |a| outside one)
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


def wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi
