"""A chair filter's flat layouts: the packed state, settings and sample rows that edge/chair/kernel.py's
compiled loop reads, and the packing to and from edge/chair/state.py's readable types.

Kept apart from the compiled loop so that what runs it (ChairEdge, the bench) needs numpy alone: the
loop itself is loaded ahead-of-time compiled (reckon/kernels.py), and numba stays out of the edge
process. All float64: a state vector (`pack_state`, `STATE_SIZE` long, whatever the number of steps),
a settings vector (`pack_settings`: what `step` reads, with its constant sub-expressions evaluated
once in Python exactly as `step` writes them), and per sample one int64 time plus a row of
`SAMPLE_WIDTH` values (`pack_samples`).
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

import numpy as np

from edge.chair.estimator import axle_scale_noise
from edge.chair.state import DEG, MAG_FIT_SIZE, MAG_STATS, N, AxleScale, ChairSample, ChairSettings, ChairState, Flag, MagAid

# --- state vector --------------------------------------------------------------------------
TIME_HIGH = 0  # time_ns >> 32 and time_ns & 0xFFFFFFFF: each exact in a float64, the whole is not
TIME_LOW = 1
MEAN = 2  # N values
COV = MEAN + N  # N * N values, row-major
YAW_RATE = COV + N * N
LEFT_BIAS = YAW_RATE + 1
RIGHT_BIAS = LEFT_BIAS + 1
STILL_S = RIGHT_BIAS + 1
ACCEL_MEAN = STILL_S + 1
GRAVITY = ACCEL_MEAN + 1  # 3 values
FLAGS = GRAVITY + 3
IN_IMPACT = FLAGS + 1  # 0 or 1
TRAVEL = IN_IMPACT + 1
TURN_XY = TRAVEL + 1
TURN_XX = TURN_XY + 1
AXIS_XY = TURN_XX + 1
AXIS_XX = AXIS_XY + 1
MAG_FIT = AXIS_XX + 1  # the hard-iron fit's 7 running sums
MAG_DUE = MAG_FIT + MAG_FIT_SIZE
MAG_READY = MAG_DUE + 1  # 0 or 1
MAG_REJECTIONS = MAG_READY + 1
MAG_INNOVATION = MAG_REJECTIONS + 1
MAG_STATS_AT = MAG_INNOVATION + 1  # MAG_STATS values, MagAid.stats
MAG_SINCE_READ = MAG_STATS_AT + MAG_STATS
MAG_SINCE_UPDATE = MAG_SINCE_READ + 1
MAG_ANCHOR = MAG_SINCE_UPDATE + 1
MAG_TURN_GYRO = MAG_ANCHOR + 1
MAG_TURN_S = MAG_TURN_GYRO + 1
MAG_TURN_M = MAG_TURN_S + 1
MAP_OFFSET = MAG_TURN_M + 1  # the hub's field map where the chair is (set before each batch)
MAP_VAR = MAP_OFFSET + 1
FIELD_COUNT = MAP_VAR + 1  # the last reading offered to the map
FIELD_TIME_HIGH = FIELD_COUNT + 1  # as TIME_HIGH / TIME_LOW
FIELD_TIME_LOW = FIELD_TIME_HIGH + 1
FIELD_X = FIELD_TIME_LOW + 1
FIELD_Y = FIELD_X + 1
FIELD_OFFSET = FIELD_Y + 1
FIELD_VAR = FIELD_OFFSET + 1
AXLE_WINDOW_SEAT = FIELD_VAR + 1  # AxleScale's fields, in order
AXLE_WINDOW_AXLE = AXLE_WINDOW_SEAT + 1
AXLE_WINDOW_S = AXLE_WINDOW_AXLE + 1
AXLE_XY = AXLE_WINDOW_S + 1
AXLE_XX = AXLE_XY + 1
AXLE_SEEN = AXLE_XX + 1
AXLE_DONE = AXLE_SEEN + 1  # 0 or 1
STATE_SIZE = AXLE_DONE + 1

# --- settings vector -----------------------------------------------------------------------
(S_GAP, S_STILL_WHEEL, S_STILL_GYRO, S_STILL_ACCEL, S_STILL_TIME, S_HALF_CIRCUMFERENCE,
 S_WHEEL_BIAS_TIME, S_WHEEL_TURN_SD, S_GYRO_NOISE_VAR, S_WHEEL_RATE_LIMIT, S_WHEEL_TURN_MEMORY, S_IMPACT_G,
 S_ALONG_SD, S_ACROSS_SD, S_SHOVE_VAR, S_BIAS_WALK_VAR, S_SCALE_WALK_VAR, S_STILL_RATE_VAR, S_MAG_PERIOD,
 S_MAG_FIT_FORGET, S_MAG_MIN_SPREAD_SQ, S_MAG_MIN_POINTS, S_MAG_HEADING_VAR, S_MAG_GATE_CHI2,
 S_MAG_RECOVER_REJECTIONS, S_MAG_FLOOR_VAR, S_MAG_LEVEL_WEIGHT, S_MAG_FORGET, S_MAG_MIN_STEP, S_MAG_CORRELATION_PRIOR,
 S_MAG_CORRELATION_MAX, S_MAG_CORRELATION_MIN, S_MAG_TRUST_VAR, S_MAG_TURN_S, S_MAG_TURN_VAR, S_WHEEL_AXIS_SD,
 S_WHEEL_AXIS_BIAS, S_AXLE_TURN, S_AXLE_WINDOW, S_AXLE_COS, S_AXLE_NOISE, S_AXLE_GATE) = range(42)
SETTINGS_SIZE = S_AXLE_GATE + 1

# --- sample rows ---------------------------------------------------------------------------
V_YAW_RATE, V_LEFT, V_RIGHT, V_ACCEL, V_MAG, V_HAS_MAG, V_WHEEL_YAW = 0, 1, 2, 3, 6, 9, 10  # accel, mag: 3 each
SAMPLE_WIDTH = 11

STILL, GAP, BACKWARDS, IMPACT = int(Flag.STILL), int(Flag.GAP), int(Flag.BACKWARDS), int(Flag.IMPACT)
MAG_USED, MAG_REJECTED = int(Flag.MAG_USED), int(Flag.MAG_REJECTED)
AXLE_SCALE_USED, AXLE_SCALE_REJECTED = int(Flag.AXLE_SCALE_USED), int(Flag.AXLE_SCALE_REJECTED)
# rows `run_poses` returns: a pose's x, y, heading and their 3 x 3 covariance (row-major); an
# impact's accel (g, chair frame) and the gravity the filter had learned by the end of its run
POSE_WIDTH, IMPACT_WIDTH = 12, 6
# rows of the scratch array `run_batch` allocates once: F P's rows X, Y, HEADING; a Kalman gain;
# h P
W_FP, W_GAIN, W_ROW, W_ROWS = 0, 3, 4, 5


def pack_settings(settings: ChairSettings) -> np.ndarray:
    """What `step` reads of the settings; each constant expression written exactly as in `step`."""
    s = settings
    vector = np.zeros(SETTINGS_SIZE)
    vector[S_GAP] = s.gap_s
    vector[S_STILL_WHEEL] = s.still_wheel_dps
    vector[S_STILL_GYRO] = s.still_gyro_dps
    vector[S_STILL_ACCEL] = s.still_accel_g
    vector[S_STILL_TIME] = s.still_time_s
    vector[S_HALF_CIRCUMFERENCE] = math.pi * s.wheel_diameter_m * 0.5
    vector[S_WHEEL_BIAS_TIME] = s.wheel_bias_time_s
    vector[S_WHEEL_TURN_SD] = s.wheel_turn_sd
    vector[S_GYRO_NOISE_VAR] = (s.gyro_noise_dps_per_sqrt_hz * DEG) ** 2
    vector[S_WHEEL_RATE_LIMIT] = s.wheel_rate_limit_dps
    vector[S_WHEEL_TURN_MEMORY] = s.wheel_turn_memory_s
    vector[S_IMPACT_G] = s.impact_g
    vector[S_ALONG_SD] = s.along_track_sd_per_m
    vector[S_ACROSS_SD] = s.cross_track_sd_per_m
    vector[S_SHOVE_VAR] = s.impact_shove_sd_m**2
    vector[S_BIAS_WALK_VAR] = (s.gyro_bias_walk_dps_per_sqrt_s * DEG) ** 2
    vector[S_SCALE_WALK_VAR] = s.wheel_scale_walk_per_sqrt_s**2
    vector[S_STILL_RATE_VAR] = (s.still_rate_sd_dps * DEG) ** 2
    vector[S_MAG_PERIOD] = s.mag_period_s
    vector[S_MAG_FIT_FORGET] = math.exp(-s.mag_period_s / s.mag_fit_memory_s)
    vector[S_MAG_MIN_SPREAD_SQ] = s.mag_fit_min_spread**2
    vector[S_MAG_MIN_POINTS] = s.mag_fit_min_points
    vector[S_MAG_HEADING_VAR] = (s.mag_heading_sd_deg * DEG) ** 2
    vector[S_MAG_GATE_CHI2] = s.mag_gate_chi2
    vector[S_MAG_RECOVER_REJECTIONS] = s.mag_recover_rejections
    vector[S_MAG_FLOOR_VAR] = (s.mag_floor_sd_deg * DEG) ** 2
    vector[S_MAG_LEVEL_WEIGHT] = s.mag_level_weight
    vector[S_MAG_FORGET] = 1.0 - 1.0 / s.mag_level_memory
    vector[S_MAG_MIN_STEP] = s.mag_min_step_m
    vector[S_MAG_CORRELATION_PRIOR] = s.mag_correlation_prior_m
    vector[S_MAG_CORRELATION_MAX] = s.mag_correlation_max_m
    vector[S_MAG_CORRELATION_MIN] = s.mag_correlation_min_m
    vector[S_MAG_TRUST_VAR] = (s.mag_trust_sd_deg * DEG) ** 2
    vector[S_MAG_TURN_S] = s.mag_turn_s
    vector[S_MAG_TURN_VAR] = (s.mag_turn_sd_deg * DEG) ** 2
    vector[S_WHEEL_AXIS_SD] = s.wheel_axis_sd
    vector[S_WHEEL_AXIS_BIAS] = s.wheel_axis_bias_dps * DEG
    vector[S_AXLE_TURN] = s.axle_scale_turn_deg * DEG
    vector[S_AXLE_WINDOW] = s.axle_scale_window_s
    vector[S_AXLE_COS] = math.cos(s.camber_deg * DEG)
    vector[S_AXLE_NOISE] = axle_scale_noise(s)
    vector[S_AXLE_GATE] = s.axle_scale_gate_chi2
    return vector


def pack_state(state: ChairState) -> np.ndarray:
    """Everything in a ChairState as `STATE_SIZE` float64s (`unpack_state` is the inverse)."""
    vector = np.zeros(STATE_SIZE)
    vector[TIME_HIGH], vector[TIME_LOW] = state.time_ns >> 32, state.time_ns & 0xFFFFFFFF
    vector[MEAN:MEAN + N] = state.mean
    vector[COV:COV + N * N] = np.asarray(state.cov, dtype=float).ravel()
    vector[YAW_RATE] = state.yaw_rate_dps
    vector[LEFT_BIAS], vector[RIGHT_BIAS] = state.left_bias_dps, state.right_bias_dps
    vector[STILL_S] = state.still_s
    vector[ACCEL_MEAN] = state.accel_mean_g
    vector[GRAVITY:GRAVITY + 3] = state.gravity
    vector[FLAGS] = int(state.flags)
    vector[IN_IMPACT] = state.in_impact
    vector[TRAVEL] = state.travel_m
    vector[TURN_XY], vector[TURN_XX] = state.turn_xy, state.turn_xx
    vector[AXIS_XY], vector[AXIS_XX] = state.axis_xy, state.axis_xx
    vector[MAG_FIT:MAG_FIT + MAG_FIT_SIZE] = np.asarray(state.mag.fit, dtype=float)
    vector[MAG_DUE] = state.mag.due_s
    vector[MAG_READY] = state.mag.ready
    vector[MAG_REJECTIONS] = state.mag.rejections
    vector[MAG_INNOVATION] = state.mag.innovation_deg
    vector[MAG_STATS_AT:MAG_STATS_AT + MAG_STATS] = state.mag.stats
    vector[MAG_SINCE_READ], vector[MAG_SINCE_UPDATE] = state.mag.since_read_m, state.mag.since_update_m
    vector[MAG_ANCHOR], vector[MAG_TURN_GYRO] = state.mag.anchor_angle, state.mag.turn_gyro_rad
    vector[MAG_TURN_S], vector[MAG_TURN_M] = state.mag.turn_s, state.mag.turn_m
    m = state.mag
    vector[MAP_OFFSET], vector[MAP_VAR], vector[FIELD_COUNT] = m.map_offset_rad, m.map_var_rad2, m.field_count
    vector[FIELD_TIME_HIGH], vector[FIELD_TIME_LOW] = m.field_time_ns >> 32, m.field_time_ns & 0xFFFFFFFF
    vector[FIELD_X], vector[FIELD_Y] = m.field_x_m, m.field_y_m
    vector[FIELD_OFFSET], vector[FIELD_VAR] = m.field_offset_rad, m.field_var_rad2
    a = state.axle
    vector[AXLE_WINDOW_SEAT:AXLE_DONE + 1] = (a.window_seat_rad, a.window_axle_rad, a.window_s, a.xy, a.xx, a.seen_rad,
                                              a.done)
    return vector


def unpack_state(vector: np.ndarray) -> ChairState:
    if vector.shape != (STATE_SIZE,):
        raise ValueError(f"a packed chair state has {STATE_SIZE} values, not shape {vector.shape}")
    v = vector
    mag = MagAid(v[MAG_FIT:MAG_FIT + MAG_FIT_SIZE].copy(), float(v[MAG_DUE]), bool(v[MAG_READY]),
                 int(v[MAG_REJECTIONS]), float(v[MAG_INNOVATION]), v[MAG_STATS_AT:MAG_STATS_AT + MAG_STATS].copy(),
                 float(v[MAG_SINCE_READ]), float(v[MAG_SINCE_UPDATE]), float(v[MAG_ANCHOR]), float(v[MAG_TURN_GYRO]),
                 float(v[MAG_TURN_S]), float(v[MAG_TURN_M]), float(v[MAP_OFFSET]), float(v[MAP_VAR]),
                 int(v[FIELD_COUNT]), (int(v[FIELD_TIME_HIGH]) << 32) + int(v[FIELD_TIME_LOW]), float(v[FIELD_X]),
                 float(v[FIELD_Y]), float(v[FIELD_OFFSET]), float(v[FIELD_VAR]))
    return ChairState(_time_ns(v), v[MEAN:MEAN + N].copy(), v[COV:COV + N * N].reshape(N, N).copy(),
                      float(v[YAW_RATE]), float(v[LEFT_BIAS]), float(v[RIGHT_BIAS]), float(v[STILL_S]),
                      float(v[ACCEL_MEAN]), tuple(float(g) for g in v[GRAVITY:GRAVITY + 3]), Flag(int(v[FLAGS])),
                      bool(v[IN_IMPACT]), float(v[TRAVEL]), float(v[TURN_XY]), float(v[TURN_XX]), float(v[AXIS_XY]),
                      float(v[AXIS_XX]), mag,
                      AxleScale(*(float(x) for x in v[AXLE_WINDOW_SEAT:AXLE_DONE]), bool(v[AXLE_DONE])))


def pack_samples(samples: list[ChairSample]) -> tuple[np.ndarray, np.ndarray]:
    """(times int64 (n,), values float64 (n, SAMPLE_WIDTH)); a missing magnetometer is NaN, has_mag 0."""
    times = np.fromiter((s.time_ns for s in samples), dtype=np.int64, count=len(samples))
    nan3 = (math.nan, math.nan, math.nan)
    values = np.array([(s.yaw_rate_dps, s.left_rotation_deg, s.right_rotation_deg, *s.accel_g,
                        *(nan3 if s.mag_gauss is None else s.mag_gauss), 0.0 if s.mag_gauss is None else 1.0,
                        s.wheel_yaw_deg)
                       for s in samples], dtype=float).reshape(len(samples), SAMPLE_WIDTH)
    return times, values


def state_time_ns(vector: np.ndarray) -> int:
    """The time of a packed state."""
    return _time_ns(vector)


def _time_ns(vector: np.ndarray) -> int:
    return (int(vector[TIME_HIGH]) << 32) + int(vector[TIME_LOW])


def unpack_sample(time_ns: int, row: np.ndarray) -> ChairSample:
    """The ChairSample of one packed row (`pack_samples`' inverse)."""
    mag = None if row[V_HAS_MAG] == 0.0 else (float(row[V_MAG]), float(row[V_MAG + 1]), float(row[V_MAG + 2]))
    return ChairSample(int(time_ns), float(row[V_YAW_RATE]), float(row[V_LEFT]), float(row[V_RIGHT]),
                       (float(row[V_ACCEL]), float(row[V_ACCEL + 1]), float(row[V_ACCEL + 2])), mag,
                       float(row[V_WHEEL_YAW]))


class ChairKernels(NamedTuple):
    """A chair's compiled steps (edge/chair/merge_kernel.py's `merge_batch`, edge/chair/kernel.py's
    `run_batch`, `run_poses` and `merge_and_run`), however they were compiled: ahead of time
    (reckon/kernels.py) or just in time."""

    merge_batch: Callable[..., tuple[np.ndarray, np.ndarray]]
    run_batch: Callable[..., tuple[np.ndarray, np.ndarray]]
    run_poses: Callable[..., tuple]
    merge_and_run: Callable[..., tuple]

