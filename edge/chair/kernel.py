"""The per-chair filter compiled for throughput: `step` of edge/chair/estimator.py over a whole batch at once.

Why: one Python `step` costs ~17 us (~60k samples/s), and the edge estimator's target in replay
is >= 1 M samples/s per core. `run_batch` is a numba loop over flat arrays (edge/chair/layout.py),
with no allocation per sample, that does what calling `step` once per sample does: the same math in
the same order (zero-rate update, gap bridging by the wheels, impact shove, BACKWARDS samples, the
magnetometer aid). edge/chair/estimator.py's `step` stays the readable reference: change the filter
there first, then here; tests/edge/test_chair_kernel.py holds the kernel to it.

Same operations in the same order round the same, so the two agree bit for bit (measured on
x86-64, Python 3.11, numpy 2.4 with its bundled OpenBLAS 0.3.31), and elsewhere in the last bits:
- Python's `x ** 2` is libm's pow(x, 2.0), which differs from x * x in the last bit for ~0.1 %
  of values: the kernel calls pow too (`pow2`), never letting LLVM turn it into x * x.
- numpy hands the 7x7 products to OpenBLAS, whose small-matrix kernels sum each dot product in
  index order with fused multiply-adds: the kernel does the same (`fma`), skipping only the
  Jacobian's structural zeros, which add nothing there either. Another BLAS build or CPU may sum
  in another order: ~1e-14 apart after a game (the tests allow 1e-9).
- Python 3.12's sum() of floats is compensated; the kernel sums plainly, as 3.11 does.

How it runs: the edge, `reckon eval` and the bench load it ahead-of-time compiled (numba.pycc, built
once per source and machine by reckon/kernels.py), so their processes never import numba (some
150 MiB and seconds of start-up). Importing this module compiles just in time instead (the tests,
and a machine without a C compiler); no on-disk cache, since numba's would key on this file alone
and miss a change to the layout's or the estimator's constants frozen into the machine code.

The magnetometer aid's part of the step is edge/chair/mag_kernel.py; the arithmetic both round as
the reference does (fma, pow2, sum3, wrap) is edge/chair/kernel_math.py.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from edge.chair.state import BIAS, DEG, GYRO_SCALE, HEADING, SCALE, N, X, Y, ChairSample, ChairSettings, ChairState
from edge.chair.kernel_math import fma, pow2, sum3
# The loop reads the layout's hundred indices as globals (numba freezes them as constants): all of them.
from edge.chair.layout import *  # noqa: F403
from edge.chair.mag_kernel import magnetometer
from edge.chair.merge_kernel import merge_batch


def just_in_time() -> ChairKernels:
    """This module's kernels, compiled in this process: what the tests use, and the fallback where
    the ahead-of-time module cannot be built (reckon/kernels.py)."""
    return ChairKernels(merge_batch, run_batch, run_poses, merge_and_run)


def step_batch(settings: ChairSettings, state: ChairState, samples: list[ChairSample]) -> tuple[ChairState, np.ndarray]:
    """`step` over `samples` in turn: (final state, each sample's flags as int64)."""
    times, values = pack_samples(samples)
    vector, flags = run_batch(pack_settings(settings), pack_state(state), times, values)
    return unpack_state(vector), flags


# --- compiled part -------------------------------------------------------------------------

# Helpers run in the per-sample path are inlined (numba IR): a call passing numba arrays costs
# more than the arithmetic of the small ones, ~40 % of the loop's time in all.

@njit
def run_batch(settings: np.ndarray, state: np.ndarray, times: np.ndarray,
              values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Step a packed state through every sample: (new packed state, each sample's flags).

    `state` is not written to; batches may be split anywhere (feed each result to the next).
    """
    if (settings.shape[0] != SETTINGS_SIZE or state.shape[0] != STATE_SIZE or values.shape[0] != times.shape[0]
            or values.shape[1] != SAMPLE_WIDTH):
        raise ValueError("run_batch: arrays not as pack_settings, pack_state and pack_samples make them")
    out = state.copy()
    flags = np.zeros(times.shape[0], dtype=np.int64)
    mean = out[MEAN:MEAN + N]  # views: the loop updates `out` in place
    cov = out[COV:COV + N * N].reshape((N, N))
    fit = out[MAG_FIT:MAG_FIT + MAG_FIT_SIZE]
    work = np.empty((W_ROWS, N))
    time_ns = (np.int64(out[TIME_HIGH]) << 32) + np.int64(out[TIME_LOW])
    for i in range(times.shape[0]):
        elapsed_ns = times[i] - time_ns
        if elapsed_ns <= 0:  # the sample is ignored, only the flag changes
            flags[i] = BACKWARDS
            out[FLAGS] = BACKWARDS
            continue
        flags[i] = _step(settings, out, mean, cov, fit, work, elapsed_ns * 1e-9, values[i], times[i])
        time_ns = times[i]
    out[TIME_HIGH] = time_ns >> 32
    out[TIME_LOW] = time_ns & 0xFFFFFFFF
    return out, flags


@njit
def run_poses(settings: np.ndarray, state: np.ndarray, times: np.ndarray, values: np.ndarray, next_pose_ns: int,
              period_ns: int) -> tuple[int, int, int, np.ndarray, np.ndarray]:
    """`run_batch` up to each pose time of a fixed schedule and to the last sample, as ChairEdge
    publishes them, `state` advanced in place: (the flags of every sample OR-ed, the next pose time,
    the number of poses, times: the poses', then the impacts'; rows: the poses' (x, y, heading,
    their 3 x 3 covariance row-major: POSE_WIDTH), then the impacts' (accel, then gravity at the end
    of their run: IMPACT_WIDTH, in the first columns)). Two arrays and the state in place, because
    each array handed back costs the ahead-of-time compiled call ~0.7 us (an edge's whole push path
    is ~18 us a batch: docs/benchmarks.md). A pose
    is due at a sample at or after `next_pose_ns`; the next then at +period, or half a period before
    the sample that came late (a fixed schedule: timestamp jitter costs no pose). One call per batch
    instead of one per pose; the runs are the same, so the same bits (run_batch splits anywhere)."""
    n = times.shape[0]
    out_times = np.empty(2 * n, dtype=np.int64)  # poses from the front, impacts from n, then moved up
    rows = np.zeros((2 * n, POSE_WIDTH))
    vector = state
    flags_seen = 0
    begin = posed = hit = 0
    for i in range(n):
        time_ns = times[i]
        if time_ns < next_pose_ns and i < n - 1:
            continue
        vector, flags = run_batch(settings, vector, times[begin:i + 1], values[begin:i + 1])
        for j in range(flags.shape[0]):
            flags_seen |= flags[j]
            if flags[j] & IMPACT:
                out_times[n + hit] = times[begin + j]
                for k in range(3):
                    rows[n + hit, k] = values[begin + j, V_ACCEL + k]
                    rows[n + hit, 3 + k] = vector[GRAVITY + k]
                hit += 1
        begin = i + 1
        if time_ns >= next_pose_ns:
            next_pose_ns = max(next_pose_ns + period_ns, time_ns - period_ns // 2)
            out_times[posed] = time_ns
            for k in range(3):
                rows[posed, k] = vector[MEAN + k]
                for m in range(3):
                    rows[posed, 3 + 3 * k + m] = vector[COV + N * k + m]
            posed += 1
    state[:] = vector
    out_times[posed:posed + hit] = out_times[n:n + hit]
    rows[posed:posed + hit] = rows[n:n + hit]
    return flags_seen, next_pose_ns, posed, out_times[:posed + hit], rows[:posed + hit]


@njit
def merge_and_run(config: np.ndarray, ints: np.ndarray, floats: np.ndarray, role: int, time_ns: int,
                  offsets: np.ndarray, accel: np.ndarray, gyro: np.ndarray, mag: np.ndarray, flush: int,
                  settings: np.ndarray, state: np.ndarray, next_pose_ns: int,
                  period_ns: int) -> tuple[int, int, int, int, np.ndarray, np.ndarray]:
    """A chair edge's step per batch once its filter has started: edge/chair/merge_kernel.py's
    `merge_batch`, then `run_poses` over what it released, in one call (each call from Python
    costs microseconds): (samples merged, then run_poses' results)."""
    times, values = merge_batch(config, ints, floats, role, time_ns, offsets, accel, gyro, mag, flush)
    flags, next_pose_ns, posed, out_times, rows = run_poses(settings, state, times, values, next_pose_ns, period_ns)
    return times.shape[0], flags, next_pose_ns, posed, out_times, rows


@njit(inline='always')
def _step(s, st, mean, cov, fit, work, dt, sample, time_ns):
    """edge/chair/estimator.py's `step` for dt > 0, in place on the packed state; returns the flags."""
    yaw_rate = sample[V_YAW_RATE]
    seat = math.isfinite(yaw_rate)  # a bridge sample has the wheels only
    flags = GAP if dt > s[S_GAP] or not seat or not math.isfinite(st[YAW_RATE]) else 0
    if seat:
        accel_norm = math.sqrt(sum3(sample[V_ACCEL] * sample[V_ACCEL], sample[V_ACCEL + 1] * sample[V_ACCEL + 1],
                                     sample[V_ACCEL + 2] * sample[V_ACCEL + 2]))
    else:
        accel_norm = st[ACCEL_MEAN]
    left_dps, right_dps = sample[V_LEFT] / dt, sample[V_RIGHT] / dt
    quiet = (abs(left_dps) < s[S_STILL_WHEEL] and abs(right_dps) < s[S_STILL_WHEEL]
             and abs(yaw_rate) < s[S_STILL_GYRO])
    alpha = dt / (st[STILL_S] + dt) if quiet else 1.0  # |a|'s mean over this quiet spell (the reference says why)
    accel_mean = st[ACCEL_MEAN] + alpha * (accel_norm - st[ACCEL_MEAN])
    still_now = quiet and abs(accel_norm - accel_mean) < s[S_STILL_ACCEL]
    still_s = st[STILL_S] + dt if still_now else 0.0
    still = still_s >= s[S_STILL_TIME]

    left = sample[V_LEFT] - st[LEFT_BIAS] * dt
    right = sample[V_RIGHT] - st[RIGHT_BIAS] * dt
    base_travel = 0.0 if still else s[S_HALF_CIRCUMFERENCE] * (left + right) / 360.0
    if still:
        beta = min(dt / s[S_WHEEL_BIAS_TIME], 1.0)
        st[LEFT_BIAS] += beta * (left_dps - st[LEFT_BIAS])
        st[RIGHT_BIAS] += beta * (right_dps - st[RIGHT_BIAS])
        _blend_gravity(st, sample, beta)

    wheel_difference = right - left
    wheel_yaw = sample[V_WHEEL_YAW]
    gyro_rate = 0.5 * (st[YAW_RATE] + yaw_rate) * DEG - mean[BIAS]
    seat_turn = math.nan  # the seat's turn where the axles' is comparable (no gap, no catch-up)
    if flags & GAP:  # the seat gyro saw nothing in between: the wheels tell the turn
        if math.isfinite(wheel_yaw):
            turn = st[AXIS_XY] / st[AXIS_XX] * wheel_yaw
            turn_var = pow2(s[S_WHEEL_AXIS_SD] * turn) + pow2(s[S_WHEEL_AXIS_BIAS] * dt)
        else:
            turn = st[TURN_XY] / st[TURN_XX] * wheel_difference
            turn_var = pow2(s[S_WHEEL_TURN_SD] * turn)
        d_turn_d_bias = d_turn_d_scale = 0.0
    else:
        turn = (1.0 + mean[GYRO_SCALE]) * gyro_rate * dt
        turn_var = s[S_GYRO_NOISE_VAR] * dt
        d_turn_d_bias = -(1.0 + mean[GYRO_SCALE]) * dt
        d_turn_d_scale = gyro_rate * dt
        if max(abs(left_dps), abs(right_dps)) <= s[S_WHEEL_RATE_LIMIT]:  # not a catch-up after a gap
            seat_turn = gyro_rate * dt
            forget = math.exp(-dt / s[S_WHEEL_TURN_MEMORY])
            st[TURN_XY] = forget * st[TURN_XY] + turn * wheel_difference
            st[TURN_XX] = forget * st[TURN_XX] + wheel_difference * wheel_difference
            if math.isfinite(wheel_yaw):
                st[AXIS_XY] = forget * st[AXIS_XY] + turn * wheel_yaw
                st[AXIS_XX] = forget * st[AXIS_XX] + wheel_yaw * wheel_yaw

    mid = mean[HEADING] + 0.5 * turn
    travel = mean[SCALE] * base_travel
    c, sn = math.cos(mid), math.sin(mid)
    mean[X] += travel * c
    mean[Y] += travel * sn
    mean[HEADING] += turn
    in_impact = accel_norm - 1.0 > s[S_IMPACT_G]
    shove = in_impact and st[IN_IMPACT] == 0.0  # once per impact, not per sample above the threshold
    shove_var = 0.0
    if shove:
        flags |= IMPACT
        horizontal = (pow2(sample[V_ACCEL] - st[GRAVITY])
                      + pow2(sample[V_ACCEL + 1] - st[GRAVITY + 1]))
        vertical = pow2(sample[V_ACCEL + 2] - st[GRAVITY + 2])
        shove_var = s[S_SHOVE_VAR] * (horizontal / (horizontal + vertical))
    _propagate_covariance(s, cov, work, c, sn, travel, base_travel, d_turn_d_bias, d_turn_d_scale, turn_var,
                          shove_var, dt)

    if still:  # zero-rate update: the seat gyro reads its bias
        flags |= STILL
        _scalar_update(mean, cov, work, BIAS, yaw_rate * DEG - mean[BIAS], s[S_STILL_RATE_VAR])
    if st[AXLE_DONE] == 0.0:
        flags |= _axle_scale(s, st, mean, cov, work, seat_turn, wheel_yaw, dt)

    # the magnetometer aid reads once every mag period; travel and the gyro's turn add up meanwhile
    st[MAG_SINCE_READ] += abs(travel)
    st[MAG_SINCE_UPDATE] += abs(travel)
    st[MAG_TURN_GYRO] += math.nan if flags & GAP else 0.5 * (st[YAW_RATE] + yaw_rate) * DEG * dt
    st[MAG_TURN_S] += dt
    st[MAG_TURN_M] += abs(travel)
    due = st[MAG_DUE] - dt
    if sample[V_HAS_MAG] == 0.0 or due > 0.0:
        st[MAG_DUE] = due
    else:
        flags |= magnetometer(s, st, mean, cov, fit, work, sample, time_ns)
    st[YAW_RATE] = yaw_rate
    st[STILL_S] = still_s
    st[ACCEL_MEAN] = accel_mean
    st[FLAGS] = flags
    st[IN_IMPACT] = 1.0 if in_impact else 0.0
    st[TRAVEL] += abs(travel)
    return flags


@njit(inline='always')
def _propagate_covariance(s, cov, work, c, sn, travel, base_travel, d_turn_d_bias, d_turn_d_scale, turn_var,
                          shove_var, dt):
    """P <- F P F^T + Q in place, touching only what F's sparsity changes.

    F is the identity except in rows X, Y and HEADING, so F P differs from P only in those rows
    and (F P) F^T from F P only in those columns: 140 multiply-adds instead of 2 x 343. Each
    sum runs over F's non-zeros in index order with fused multiply-adds, as numpy's BLAS call
    in the reference does (zero terms add nothing there either).
    """
    # F's non-identity entries, as `_propagate_covariance` in the reference builds the Jacobian
    x_heading, y_heading = -travel * sn, travel * c
    x_scale, y_scale = base_travel * c, base_travel * sn
    x_bias, y_bias = -travel * sn * 0.5 * d_turn_d_bias, travel * c * 0.5 * d_turn_d_bias
    x_gyro, y_gyro = -travel * sn * 0.5 * d_turn_d_scale, travel * c * 0.5 * d_turn_d_scale

    # A = F P: its rows X, Y, HEADING into work, the other rows are P's own
    for j in range(N):
        work[W_FP, j] = fma(x_gyro, cov[GYRO_SCALE, j], fma(x_scale, cov[SCALE, j], fma(
            x_bias, cov[BIAS, j], fma(x_heading, cov[HEADING, j], cov[X, j]))))
        work[W_FP + 1, j] = fma(y_gyro, cov[GYRO_SCALE, j], fma(y_scale, cov[SCALE, j], fma(
            y_bias, cov[BIAS, j], fma(y_heading, cov[HEADING, j], cov[Y, j]))))
        work[W_FP + 2, j] = fma(d_turn_d_scale, cov[GYRO_SCALE, j], fma(d_turn_d_bias, cov[BIAS, j], cov[HEADING, j]))
    for j in range(N):
        cov[X, j], cov[Y, j], cov[HEADING, j] = work[W_FP, j], work[W_FP + 1, j], work[W_FP + 2, j]

    # A F^T: columns X, Y, HEADING of every row
    for i in range(N):
        a_x, a_y, a_heading = cov[i, X], cov[i, Y], cov[i, HEADING]
        a_bias, a_scale, a_gyro = cov[i, BIAS], cov[i, SCALE], cov[i, GYRO_SCALE]
        cov[i, X] = fma(a_gyro, x_gyro, fma(a_scale, x_scale, fma(a_bias, x_bias, fma(a_heading, x_heading, a_x))))
        cov[i, Y] = fma(a_gyro, y_gyro, fma(a_scale, y_scale, fma(a_bias, y_bias, fma(a_heading, y_heading, a_y))))
        cov[i, HEADING] = fma(a_gyro, d_turn_d_scale, fma(a_bias, d_turn_d_bias, a_heading))

    # + Q: slip along and across the mid-step heading, the gyro's noise, the random walks
    along = pow2(s[S_ALONG_SD] * travel)
    across = pow2(s[S_ACROSS_SD] * travel)
    along += shove_var
    across += shove_var
    cov[X, X] += along * c * c + across * sn * sn
    cov[Y, Y] += along * sn * sn + across * c * c
    cov[X, Y] += (along - across) * c * sn
    cov[Y, X] += (along - across) * c * sn
    cov[HEADING, HEADING] += turn_var
    cov[BIAS, BIAS] += s[S_BIAS_WALK_VAR] * dt
    cov[SCALE, SCALE] += s[S_SCALE_WALK_VAR] * dt


@njit(inline='always')
def _scalar_update(mean, cov, work, index, innovation, noise_var):
    """The reference's `_scalar_update` for h = e_index: P's column is the gain, its row h P."""
    variance = cov[index, index] + noise_var
    gain, row = work[W_GAIN], work[W_ROW]
    for i in range(N):
        gain[i] = cov[i, index] / variance
        row[i] = cov[index, i]
    for i in range(N):
        mean[i] += gain[i] * innovation
        for j in range(N):
            cov[i, j] -= gain[i] * row[j]


@njit(inline='always')
def _axle_scale(s, st, mean, cov, work, seat_turn, axle_turn_deg, dt):
    """The reference's `_axle_scale` (not yet done): the seat gyro's scale, once, against the axle IMUs."""
    if not (math.isfinite(seat_turn) and math.isfinite(axle_turn_deg)):
        st[AXLE_WINDOW_SEAT] = 0.0
        st[AXLE_WINDOW_AXLE] = 0.0
        st[AXLE_WINDOW_S] = 0.0
        return 0
    seat_rad, axle_rad = st[AXLE_WINDOW_SEAT] + seat_turn, st[AXLE_WINDOW_AXLE] + axle_turn_deg * DEG
    window_s = st[AXLE_WINDOW_S] + dt
    if window_s < s[S_AXLE_WINDOW]:
        st[AXLE_WINDOW_SEAT], st[AXLE_WINDOW_AXLE], st[AXLE_WINDOW_S] = seat_rad, axle_rad, window_s
        return 0
    st[AXLE_WINDOW_SEAT] = 0.0
    st[AXLE_WINDOW_AXLE] = 0.0
    st[AXLE_WINDOW_S] = 0.0
    st[AXLE_XY] += seat_rad * axle_rad
    st[AXLE_XX] += axle_rad * axle_rad
    st[AXLE_SEEN] += abs(axle_rad)
    if st[AXLE_SEEN] < s[S_AXLE_TURN]:
        return 0
    st[AXLE_DONE] = 1.0
    if st[AXLE_XY] <= 0.0:
        return AXLE_SCALE_REJECTED
    measured = st[AXLE_XX] / (st[AXLE_XY] * s[S_AXLE_COS]) - 1.0
    innovation = measured - mean[GYRO_SCALE]
    if innovation * innovation / (cov[GYRO_SCALE, GYRO_SCALE] + s[S_AXLE_NOISE]) > s[S_AXLE_GATE]:
        return AXLE_SCALE_REJECTED
    _scalar_update(mean, cov, work, GYRO_SCALE, innovation, s[S_AXLE_NOISE])
    return AXLE_SCALE_USED


@njit(inline='always')
def _blend_gravity(st, sample, weight):
    """The reference's `_blend_unit` of the stored gravity towards this sample's accel, in place."""
    b0 = st[GRAVITY] + weight * (sample[V_ACCEL] - st[GRAVITY])
    b1 = st[GRAVITY + 1] + weight * (sample[V_ACCEL + 1] - st[GRAVITY + 1])
    b2 = st[GRAVITY + 2] + weight * (sample[V_ACCEL + 2] - st[GRAVITY + 2])
    norm = math.sqrt(sum3(b0 * b0, b1 * b1, b2 * b2))
    if norm == 0.0:
        norm = 1.0
    st[GRAVITY], st[GRAVITY + 1], st[GRAVITY + 2] = b0 / norm, b1 / norm, b2 / norm


