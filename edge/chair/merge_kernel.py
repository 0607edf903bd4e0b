"""The chair merger compiled: edge/chair/merger.py's `ChairMerger` over a whole batch of one sensor at once.

`merge_batch` does, per sample, what `ChairMerger.push` does (a wheel's sample integrated, a seat
sample queued, then every seat sample that is ready sent out with the wheels' increments, bridges
over a silent seat, the wheel clocks learning their offsets), on the packed state of
edge/chair/merge_layout.py, in place. Same operations in the same order, so the same bits: Python's
int / int of two times is float / float here (both exact below 2^53), `int()` truncates as
Python's does, sums start from 0.0 as Python's `sum` does from 0. The merger.py docstring says
what the merger does and why; this file only mirrors it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from edge.chair.layout import SAMPLE_WIDTH, V_ACCEL, V_HAS_MAG, V_LEFT, V_MAG, V_RIGHT, V_WHEEL_YAW, V_YAW_RATE
from edge.chair.merge_layout import (C_PLANE_A, C_PLANE_B, C_SEAT, C_SPIN_INDEX, C_SPIN_SIGN, F_LAST_YAW,
                                     F_PEND_ACCEL, F_PEND_HAS_MAG, F_PEND_MAG, F_PEND_YAW, F_W_LAST_ROTATION,
                                     F_W_LAST_YAW, F_W_PREVIOUS, F_W_RATE, F_W_ROTATIONS, F_W_SPAN, F_W_SUMS,
                                     F_W_YAW_RATE, F_W_YAWS, I_BRIDGED, I_EXTRAPOLATED, I_HAS_LAST_SEAT, I_LAST_SEAT,
                                     I_MAX_WAIT, I_PEND_COUNT, I_PEND_HEAD, I_PEND_TIMES, I_SAMPLES,
                                     I_SEAT_OUT_OF_ORDER, I_W_CLOCK_COUNT, I_W_CLOCK_UPDATES, I_W_COUNT, I_W_HEAD,
                                     I_W_LAST_OFFSET, I_W_OFFSET, I_W_OUT_OF_ORDER, I_W_OVERRUN, I_W_TIMES,
                                     I_WHEEL_OVERRUN, PENDING, SEAT, WHEEL_FLOATS, WHEEL_INTS)
from edge.chair.merger import BRIDGE_AFTER_NS, BRIDGE_STEP_NS, HISTORY, SEAT_STEP_MAX_NS, WHEEL_SILENT_NS
from edge.chair.wheel_clock import GAIN, MAX_OFFSET_NS, MAX_STEP_NS, MAX_WINDOW_S, SETTLED_SE_NS, UPDATE_S


@njit
def merge_batch(config: np.ndarray, ints: np.ndarray, floats: np.ndarray, role: int, time_ns: int,
                offsets: np.ndarray, accel: np.ndarray, gyro: np.ndarray, mag: np.ndarray,
                flush: int) -> tuple[np.ndarray, np.ndarray]:
    """Push one sensor's samples (`role`: SEAT, LEFT or RIGHT; sample i at `time_ns` + `offsets[i]`,
    as an ImuBatch has them; `mag` (0, 3) when it has none), then, if `flush`, release everything:
    the ready chair samples as (times, rows of SAMPLE_WIDTH)."""
    out_times = np.empty(max(8, 2 * offsets.shape[0]), dtype=np.int64)
    out_rows = np.empty((out_times.shape[0], SAMPLE_WIDTH))
    count = 0
    has_mag = mag.shape[0] == offsets.shape[0]
    for i in range(offsets.shape[0]):
        if role == SEAT:
            _push_seat(config, ints, floats, time_ns + offsets[i], accel[i], gyro[i], mag, i if has_mag else -1)
        else:
            _push_wheel(config, ints, floats, role - 1, time_ns + offsets[i], accel[i], gyro[i])
        out_times, out_rows, count = _ready(ints, floats, False, out_times, out_rows, count)
    if flush:
        out_times, out_rows, count = _ready(ints, floats, True, out_times, out_rows, count)
    return out_times[:count].copy(), out_rows[:count].copy()


@njit
def _push_wheel(config, ints, floats, w, time_ns, accel, gyro):
    """WheelIntegrator.push of wheel w, with its spin and the yaw its axle IMU sees (plane_yaw_dps)."""
    spin = config[C_SPIN_SIGN + w] * gyro[int(config[C_SPIN_INDEX + w])]
    a, b = int(config[C_PLANE_A + w]), int(config[C_PLANE_B + w])
    size = math.sqrt(gyro[a] * gyro[a] + gyro[b] * gyro[b])
    yaw_dps = size if gyro[a] * accel[a] + gyro[b] * accel[b] >= 0.0 else -size
    wi, wf = w * WHEEL_INTS, w * WHEEL_FLOATS
    n = ints[wi + I_W_COUNT]
    rotation = yaw = 0.0
    if n > 0:
        newest = (ints[wi + I_W_HEAD] + n - 1) % HISTORY
        if time_ns <= ints[wi + I_W_TIMES + newest]:
            ints[wi + I_W_OUT_OF_ORDER] += 1
            return
        dt = (time_ns - ints[wi + I_W_TIMES + newest]) * 1e-9
        rotation = floats[wf + F_W_ROTATIONS + newest] + 0.5 * (floats[wf + F_W_RATE] + spin) * dt
        yaw = floats[wf + F_W_YAWS + newest] + 0.5 * (floats[wf + F_W_YAW_RATE] + yaw_dps) * dt
    if n == HISTORY:  # the ring is full: the oldest goes
        slot = ints[wi + I_W_HEAD]
        ints[wi + I_W_HEAD] = (slot + 1) % HISTORY
    else:
        slot = (ints[wi + I_W_HEAD] + n) % HISTORY
        ints[wi + I_W_COUNT] = n + 1
    ints[wi + I_W_TIMES + slot] = time_ns
    floats[wf + F_W_ROTATIONS + slot] = rotation
    floats[wf + F_W_YAWS + slot] = yaw
    floats[wf + F_W_RATE] = spin
    floats[wf + F_W_YAW_RATE] = yaw_dps


@njit
def _push_seat(config, ints, floats, time_ns, accel, gyro, mag, mag_row):
    """A seat sample in the chair frame, queued unless it is not after the newest seen; its
    magnetometer is `mag[mag_row]` (-1: none). `_ready` runs after every push and keeps the ring
    from filling (a full one releases its oldest), so there is always a free slot here."""
    n = ints[I_PEND_COUNT]
    if n > 0:
        newest, known = ints[I_PEND_TIMES + ((ints[I_PEND_HEAD] + n - 1) % PENDING)], True
    else:
        newest, known = ints[I_LAST_SEAT], ints[I_HAS_LAST_SEAT] != 0
    if known and time_ns <= newest:
        ints[I_SEAT_OUT_OF_ORDER] += 1
        return
    slot = (ints[I_PEND_HEAD] + n) % PENDING
    ints[I_PEND_COUNT] = n + 1
    ints[I_PEND_TIMES + slot] = time_ns
    floats[F_PEND_YAW + slot] = _chair(config, gyro, 2)
    for k in range(3):
        floats[F_PEND_ACCEL + 3 * slot + k] = _chair(config, accel, k)
        floats[F_PEND_MAG + 3 * slot + k] = _chair(config, mag[mag_row], k) if mag_row >= 0 else math.nan
    floats[F_PEND_HAS_MAG + slot] = 1.0 if mag_row >= 0 else 0.0


@njit
def _chair(config, vector, k):
    """Component k (forward, left, up) of a seat vector in the chair frame."""
    return config[C_SEAT + 2 * k + 1] * vector[int(config[C_SEAT + 2 * k])]


@njit
def _ready(ints, floats, flush, out_times, out_rows, count):
    """ChairMerger._ready: every pending seat sample whose wheels have reported past it (or overdue)."""
    while ints[I_PEND_COUNT] > 0:
        head, n = ints[I_PEND_HEAD], ints[I_PEND_COUNT]
        time_ns = ints[I_PEND_TIMES + head]
        covered = True
        for w in range(2):
            wi = w * WHEEL_INTS
            m = ints[wi + I_W_COUNT]
            newest_ns = ints[wi + I_W_TIMES + ((ints[wi + I_W_HEAD] + m - 1) % HISTORY)]
            if m == 0 or newest_ns < time_ns + ints[wi + I_W_OFFSET]:
                covered = False
        newest = ints[I_PEND_TIMES + ((head + n - 1) % PENDING)]
        overdue = newest - time_ns > ints[I_MAX_WAIT] or n == PENDING  # a full ring: merge_layout.py
        if not (covered or overdue or flush):
            break
        ints[I_PEND_HEAD] = (head + 1) % PENDING
        ints[I_PEND_COUNT] = n - 1
        if not covered:
            ints[I_EXTRAPOLATED] += 1
        if ints[I_HAS_LAST_SEAT] and time_ns - ints[I_LAST_SEAT] > BRIDGE_AFTER_NS:
            for bridge_ns in range(ints[I_LAST_SEAT] + BRIDGE_STEP_NS, time_ns - BRIDGE_STEP_NS // 2, BRIDGE_STEP_NS):
                now = _wheels_at(ints, floats, bridge_ns)
                if now[2] or now[5]:  # where a wheel was heard
                    if count == out_times.shape[0]:
                        out_times, out_rows = _grown(out_times, out_rows)
                    _sample(ints, floats, bridge_ns, math.nan, -1, now, out_times, out_rows, count)
                    count += 1
                    ints[I_BRIDGED] += 1
        if count == out_times.shape[0]:
            out_times, out_rows = _grown(out_times, out_rows)
        _sample(ints, floats, time_ns, floats[F_PEND_YAW + head], head, _wheels_at(ints, floats, time_ns),
                out_times, out_rows, count)
        count += 1
    return out_times, out_rows, count


@njit
def _grown(out_times, out_rows):
    times = np.empty(2 * out_times.shape[0], dtype=np.int64)
    rows = np.empty((times.shape[0], SAMPLE_WIDTH))
    times[:out_times.shape[0]] = out_times
    rows[:out_rows.shape[0]] = out_rows
    return times, rows


@njit
def _wheels_at(ints, floats, time_ns):
    """(left rotation, yaw, seen, right rotation, yaw, seen), each wheel read on its own clock."""
    lr, ly, ls = _wheel_at(ints, floats, 0, time_ns + ints[I_W_OFFSET])
    rr, ry, rs = _wheel_at(ints, floats, 1, time_ns + ints[WHEEL_INTS + I_W_OFFSET])
    ints[I_WHEEL_OVERRUN] = ints[I_W_OVERRUN] + ints[WHEEL_INTS + I_W_OVERRUN]
    return lr, ly, ls, rr, ry, rs


@njit
def _wheel_at(ints, floats, w, time_ns):
    """WheelIntegrator.at: (rotation, yaw, seen) at `time_ns`."""
    wi, wf = w * WHEEL_INTS, w * WHEEL_FLOATS
    n, head = ints[wi + I_W_COUNT], ints[wi + I_W_HEAD]
    if n == 0:
        return 0.0, 0.0, False
    newest = (head + n - 1) % HISTORY
    last_ns = ints[wi + I_W_TIMES + newest]
    if time_ns >= last_ns:
        ahead = time_ns - last_ns
        return (floats[wf + F_W_ROTATIONS + newest] + floats[wf + F_W_RATE] * ahead * 1e-9,
                floats[wf + F_W_YAWS + newest] + floats[wf + F_W_YAW_RATE] * ahead * 1e-9, ahead <= WHEEL_SILENT_NS)
    low, high = 0, n  # bisect_right over the ring in time order
    while low < high:
        middle = (low + high) // 2
        if time_ns < ints[wi + I_W_TIMES + ((head + middle) % HISTORY)]:
            high = middle
        else:
            low = middle + 1
    if low == 0:  # before the wheel's first sample, or (history full) before what is kept
        if n == HISTORY:
            ints[wi + I_W_OVERRUN] += 1
        return floats[wf + F_W_ROTATIONS + head], floats[wf + F_W_YAWS + head], False
    k0, k1 = (head + low - 1) % HISTORY, (head + low) % HISTORY
    t0, t1 = ints[wi + I_W_TIMES + k0], ints[wi + I_W_TIMES + k1]
    weight = (time_ns - t0) / (t1 - t0)
    r0, y0 = floats[wf + F_W_ROTATIONS + k0], floats[wf + F_W_YAWS + k0]
    return (r0 + (floats[wf + F_W_ROTATIONS + k1] - r0) * weight, y0 + (floats[wf + F_W_YAWS + k1] - y0) * weight,
            t1 - t0 <= WHEEL_SILENT_NS)


@njit
def _sample(ints, floats, time_ns, yaw, slot, now, out_times, out_rows, row):
    """ChairMerger._sample into out row `row`: the wheels' increments since the previous sample;
    `slot` is the pending seat sample's (accel, mag), -1 for a bridge."""
    left_turn = left_yaw = right_turn = right_yaw = 0.0
    if ints[I_HAS_LAST_SEAT]:
        left_turn = now[0] - floats[F_W_LAST_ROTATION]
        left_yaw = now[1] - floats[F_W_LAST_YAW]
        right_turn = now[3] - floats[WHEEL_FLOATS + F_W_LAST_ROTATION]
        right_yaw = now[4] - floats[WHEEL_FLOATS + F_W_LAST_YAW]
        _align(ints, floats, time_ns - ints[I_LAST_SEAT], yaw, now[2], left_yaw, now[5], right_yaw)
    floats[F_W_LAST_ROTATION], floats[F_W_LAST_YAW] = now[0], now[1]
    floats[WHEEL_FLOATS + F_W_LAST_ROTATION], floats[WHEEL_FLOATS + F_W_LAST_YAW] = now[3], now[4]
    ints[I_LAST_SEAT], ints[I_HAS_LAST_SEAT] = time_ns, 1
    floats[F_LAST_YAW] = yaw
    ints[I_SAMPLES] += 1
    # a wheel that was silent here knows nothing of the turn: the other one tells it alone
    if now[2] and now[5] or not (now[2] or now[5]):
        wheel_yaw = (0.0 + left_yaw + right_yaw) / 2
    elif now[2]:
        wheel_yaw = (0.0 + left_yaw) / 1
    else:
        wheel_yaw = (0.0 + right_yaw) / 1
    out_times[row] = time_ns
    r = out_rows[row]
    r[V_YAW_RATE], r[V_LEFT], r[V_RIGHT], r[V_WHEEL_YAW] = yaw, left_turn, right_turn, wheel_yaw
    for k in range(3):
        r[V_ACCEL + k] = floats[F_PEND_ACCEL + 3 * slot + k] if slot >= 0 else math.nan
        r[V_MAG + k] = floats[F_PEND_MAG + 3 * slot + k] if slot >= 0 else math.nan
    r[V_HAS_MAG] = floats[F_PEND_HAS_MAG + slot] if slot >= 0 else 0.0


@njit
def _align(ints, floats, dt_ns, yaw, left_seen, left_yaw, right_seen, right_yaw):
    """ChairMerger._align: each wheel clock learns from the seat's yaw and its own, consecutive samples only."""
    last_yaw = floats[F_LAST_YAW]
    consecutive = math.isfinite(yaw) and math.isfinite(last_yaw) and dt_ns <= SEAT_STEP_MAX_NS
    for w in range(2):
        wi, wf = w * WHEEL_INTS, w * WHEEL_FLOATS
        seen, turned = (left_seen, left_yaw) if w == 0 else (right_seen, right_yaw)
        if not consecutive or not seen or ints[wi + I_W_OFFSET] != ints[wi + I_W_LAST_OFFSET]:
            for k in range(3):  # WheelClock.restart
                floats[wf + F_W_PREVIOUS + k] = math.nan
        else:
            dt = dt_ns * 1e-9
            _clock_add(ints, floats, w, 0.5 * (last_yaw + yaw), turned / dt, dt)
        ints[wi + I_W_LAST_OFFSET] = ints[wi + I_W_OFFSET]


@njit
def _clock_add(ints, floats, w, seat_dps, wheel_dps, dt):
    """WheelClock.add of wheel w."""
    wi, wf = w * WHEEL_INTS, w * WHEEL_FLOATS
    p = wf + F_W_PREVIOUS
    w2, w1, g1 = floats[p], floats[p + 1], floats[p + 2]
    floats[p], floats[p + 1], floats[p + 2] = w1, wheel_dps, seat_dps
    if not math.isfinite(w2):
        return
    derivative = (wheel_dps - w2) / (2.0 * dt)
    s = wf + F_W_SUMS
    floats[s] += w1 * w1
    floats[s + 1] += w1 * derivative
    floats[s + 2] += derivative * derivative
    floats[s + 3] += g1 * w1
    floats[s + 4] += g1 * derivative
    floats[s + 5] += g1 * g1
    ints[wi + I_W_CLOCK_COUNT] += 1
    floats[wf + F_W_SPAN] += dt
    if floats[wf + F_W_SPAN] >= UPDATE_S:
        _clock_move(ints, floats, w)


@njit
def _clock_move(ints, floats, w):
    """WheelClock._move of wheel w."""
    wi, wf = w * WHEEL_INTS, w * WHEEL_FLOATS
    s = wf + F_W_SUMS
    ww, wd, dd, gw, gd, gg = floats[s], floats[s + 1], floats[s + 2], floats[s + 3], floats[s + 4], floats[s + 5]
    det = ww * dd - wd * wd
    done = floats[wf + F_W_SPAN] >= MAX_WINDOW_S
    if det > 0.0 and ww > 0.0:
        a = (gw * dd - gd * wd) / det
        b = (gd * ww - gw * wd) / det
        residual = max(gg - a * gw - b * gd, 0.0)
        b_var = residual / max(ints[wi + I_W_CLOCK_COUNT] - 2, 1) * ww / det
        if a > 0.0 and math.sqrt(b_var) / a * 1e9 < SETTLED_SE_NS:
            move = GAIN * b / a * 1e9  # clipped before int(): a float beyond int64 has no int here
            step = MAX_STEP_NS if move >= MAX_STEP_NS else -MAX_STEP_NS if move <= -MAX_STEP_NS else int(move)
            ints[wi + I_W_OFFSET] = max(-MAX_OFFSET_NS, min(MAX_OFFSET_NS, ints[wi + I_W_OFFSET] + step))
            ints[wi + I_W_CLOCK_UPDATES] += 1
            done = True
    if done:
        for k in range(6):
            floats[s + k] = 0.0
        ints[wi + I_W_CLOCK_COUNT] = 0
        floats[wf + F_W_SPAN] = 0.0
