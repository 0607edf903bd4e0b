"""The chair filter's magnetometer aid, compiled: `magnetometer` is what edge/chair/kernel.py's
step calls, the reference's aid (edge/chair/magnetometer.py: the hard-iron circle fit, north - heading
read once per correlation length, the field's turn measuring gyro bias and scale, the hall's learned
disturbance) in place on the packed state, in the same order of operations.
"""

from __future__ import annotations

import math

from numba import njit

from edge.chair.state import (BIAS, DEG, GYRO_SCALE, HEADING, M_CHECKS, M_DIFF, M_EXCESS, M_LAST, M_RADIAL, M_RADIUS,
                              M_STEP, M_WEIGHT, MAG_STATS, NORTH, N, X, Y)
from edge.chair.kernel_math import pow2, sum3, wrap
from edge.chair.layout import (FIELD_COUNT, FIELD_OFFSET, FIELD_TIME_HIGH, FIELD_TIME_LOW, FIELD_VAR, FIELD_X,
                               FIELD_Y, GRAVITY, MAG_ANCHOR, MAG_DUE, MAG_INNOVATION, MAG_READY,
                               MAG_REJECTED, MAG_REJECTIONS, MAG_SINCE_READ, MAG_SINCE_UPDATE, MAG_STATS_AT,
                               MAG_TURN_GYRO, MAP_OFFSET, MAP_VAR, MAG_TURN_M, MAG_TURN_S, MAG_USED, S_MAG_CORRELATION_MAX, S_MAG_CORRELATION_MIN,
                               S_MAG_CORRELATION_PRIOR, S_MAG_FIT_FORGET, S_MAG_FLOOR_VAR, S_MAG_FORGET,
                               S_MAG_GATE_CHI2, S_MAG_HEADING_VAR, S_MAG_LEVEL_WEIGHT, S_MAG_MIN_POINTS,
                               S_MAG_MIN_SPREAD_SQ, S_MAG_MIN_STEP, S_MAG_PERIOD, S_MAG_RECOVER_REJECTIONS,
                               S_MAG_TRUST_VAR, S_MAG_TURN_S, S_MAG_TURN_VAR, V_MAG, W_GAIN, W_ROW)


@njit(inline='always')
def magnetometer(s, st, mean, cov, fit, work, sample, time_ns):
    """A due reading: extend the hard-iron fit and the hall's statistics, measure the gyro by the
    field's turn, then learn north or correct the heading (the reference's `magnetometer`)."""
    forward, left = _level(sample, st)
    _fit_add(fit, forward, left, mean[HEADING], s[S_MAG_FIT_FORGET])
    st[MAG_DUE] = s[S_MAG_PERIOD]
    found, centre_x, centre_y = _fit_centre(fit, s[S_MAG_MIN_SPREAD_SQ], s[S_MAG_MIN_POINTS])
    if not found:
        return 0
    east, north_part = forward - centre_x, left - centre_y
    raw_angle = math.atan2(north_part, east)  # = north - heading + the hall's disturbance here
    radius = math.sqrt(east * east + north_part * north_part)
    stats = st[MAG_STATS_AT:MAG_STATS_AT + MAG_STATS]
    if st[MAG_SINCE_READ] >= s[S_MAG_MIN_STEP]:
        _learn_disturbance(s, stats, radius, st[MAG_SINCE_READ])
        st[MAG_SINCE_READ] = 0.0
        if st[MAG_READY] != 0.0:  # a reading for the hub's map
            st[FIELD_COUNT] += 1.0
            st[FIELD_TIME_HIGH] = time_ns >> 32
            st[FIELD_TIME_LOW] = time_ns & 0xFFFFFFFF
            st[FIELD_X] = mean[X]
            st[FIELD_Y] = mean[Y]
            st[FIELD_OFFSET] = wrap(raw_angle - (mean[NORTH] - mean[HEADING]))
            st[FIELD_VAR] = cov[NORTH, NORTH] - 2.0 * cov[NORTH, HEADING] + cov[HEADING, HEADING]
    variance, correlation_m = _mag_disturbance(s, stats)
    centre_var = _centre_var(fit, variance)
    flags = 0
    if not math.isfinite(st[MAG_ANCHOR]) or not math.isfinite(st[MAG_TURN_GYRO]):
        _reset_turn(st, raw_angle)
    elif st[MAG_TURN_S] >= s[S_MAG_TURN_S]:
        flags = _turn_update(s, st, mean, cov, work, raw_angle, variance, correlation_m, centre_var)
        _reset_turn(st, raw_angle)
    angle = raw_angle  # north - heading: the hub's map's offset out where it knows this place better
    mapped = _trusted(s, st[MAP_VAR]) if st[MAP_VAR] > 0.0 else math.inf
    use_map = mapped < variance
    if use_map:
        angle = wrap(raw_angle - st[MAP_OFFSET])
        variance = mapped
    if st[MAG_READY] == 0.0 or st[MAG_REJECTIONS] >= s[S_MAG_RECOVER_REJECTIONS]:
        # (re)learn north = angle + heading: it inherits the heading's error and all its correlations
        mean[NORTH] = angle + mean[HEADING]
        for j in range(N):
            cov[NORTH, j] = cov[HEADING, j]
        for i in range(N):
            cov[i, NORTH] = cov[i, HEADING]
        cov[NORTH, NORTH] = cov[HEADING, HEADING] + variance
        st[MAG_READY] = 1.0
        st[MAG_REJECTIONS] = 0.0
        st[MAG_SINCE_UPDATE] = 0.0
        return flags
    if st[MAG_SINCE_UPDATE] < correlation_m:  # the same stretch of disturbed field
        return flags
    innovation = wrap(angle - (mean[NORTH] - mean[HEADING]))
    # h = e_NORTH - e_HEADING: every product with h is one exact subtraction, as in numpy
    gain, row = work[W_GAIN], work[W_ROW]
    for j in range(N):
        row[j] = cov[NORTH, j] - cov[HEADING, j]  # h P
    predicted = row[NORTH] - row[HEADING]
    across = centre_var
    total = predicted + variance + across
    st[MAG_INNOVATION] = innovation / DEG
    st[MAG_SINCE_UPDATE] = 0.0
    if not use_map and predicted < variance:  # the reference's `_check_disturbance`
        forget = s[S_MAG_FORGET]
        stats[M_EXCESS] = forget * stats[M_EXCESS] + (innovation * innovation - predicted - across)
        stats[M_CHECKS] = forget * stats[M_CHECKS] + 1.0
    if innovation * innovation / total > s[S_MAG_GATE_CHI2]:
        st[MAG_REJECTIONS] += 1.0
        return flags | MAG_REJECTED
    for i in range(N):
        gain[i] = (cov[i, NORTH] - cov[i, HEADING]) / total
    for i in range(N):
        mean[i] += gain[i] * innovation
        for j in range(N):
            cov[i, j] -= gain[i] * row[j]
    st[MAG_REJECTIONS] = 0.0
    return flags | MAG_USED


@njit(inline='always')
def _reset_turn(st, angle):
    st[MAG_ANCHOR] = angle
    st[MAG_TURN_GYRO] = 0.0
    st[MAG_TURN_S] = 0.0
    st[MAG_TURN_M] = 0.0


@njit
def _turn_update(s, st, mean, cov, work, angle, variance, correlation_m, centre_var):
    """The reference's `_turn_update`: the gyro's bias and scale from the field's turn since the anchor."""
    anchor, turn_gyro, turn_s = st[MAG_ANCHOR], st[MAG_TURN_GYRO], st[MAG_TURN_S]
    scale, bias = 1.0 + mean[GYRO_SCALE], mean[BIAS]
    predicted = scale * (turn_gyro - bias * turn_s)
    seen = predicted + wrap(-(angle - anchor) - predicted)
    noise = (2.0 * variance * (1.0 - math.exp(-st[MAG_TURN_M] / correlation_m)) + s[S_MAG_TURN_VAR]
             + centre_var * _squared_chord(anchor, angle))
    h_bias, h_scale = -scale * turn_s, turn_gyro - bias * turn_s
    innovation = seen - predicted
    gain, row = work[W_GAIN], work[W_ROW]
    for j in range(N):
        row[j] = h_bias * cov[BIAS, j] + h_scale * cov[GYRO_SCALE, j]
    total = (h_bias * row[BIAS] + h_scale * row[GYRO_SCALE]) + noise
    if innovation * innovation / total > s[S_MAG_GATE_CHI2]:
        return MAG_REJECTED
    for i in range(N):
        gain[i] = (h_bias * cov[i, BIAS] + h_scale * cov[i, GYRO_SCALE]) / total
    for i in range(N):
        mean[i] += gain[i] * innovation
        for j in range(N):
            cov[i, j] -= gain[i] * row[j]
    return MAG_USED


@njit
def _centre_var(fit, variance):
    """The reference's `_centre_var`."""
    w = fit[0]
    mean_cos, mean_sin = fit[1] / w, fit[2] / w
    return variance / (w * (1.0 - mean_cos * mean_cos - mean_sin * mean_sin))


@njit(inline='always')
def _squared_chord(a, b):
    """The reference's `_squared_chord`."""
    along, across = math.sin(a) - math.sin(b), math.cos(b) - math.cos(a)
    return along * along + across * across


@njit
def _learn_disturbance(s, stats, radius, step_m):
    """The reference's `_learn_disturbance`, in place."""
    forget = s[S_MAG_FORGET]
    radius_mean = stats[M_RADIUS] / stats[M_WEIGHT] if stats[M_WEIGHT] > 0.0 else radius
    residual = (radius - radius_mean) / radius_mean
    if stats[M_WEIGHT] > 0.0:
        stats[M_DIFF] = forget * stats[M_DIFF] + pow2(residual - stats[M_LAST])
        stats[M_STEP] = forget * stats[M_STEP] + step_m
    stats[M_RADIAL] = forget * stats[M_RADIAL] + residual * residual
    stats[M_RADIUS] = forget * stats[M_RADIUS] + radius
    stats[M_WEIGHT] = forget * stats[M_WEIGHT] + 1.0
    stats[M_LAST] = residual


@njit(inline='always')
def _trusted(s, variance):
    """The reference's `_trusted`: floored, and grown with its square beyond the trusted size."""
    variance = max(variance, s[S_MAG_FLOOR_VAR])
    return variance * max(1.0, variance / s[S_MAG_TRUST_VAR])


@njit
def _mag_disturbance(s, stats):
    """The reference's `mag_disturbance`: (heading variance, correlation length)."""
    prior_weight, weight = s[S_MAG_LEVEL_WEIGHT], stats[M_WEIGHT]
    variance = (stats[M_RADIAL] + prior_weight * s[S_MAG_HEADING_VAR]) / (weight + prior_weight)
    if stats[M_CHECKS] > 0.0:
        variance = max(variance, (stats[M_EXCESS] + prior_weight * variance) / (stats[M_CHECKS] + prior_weight))
    variance = _trusted(s, variance)
    correlation = s[S_MAG_CORRELATION_PRIOR]
    if weight > 1.0 and stats[M_RADIAL] > 0.0:
        ratio = 0.5 * (stats[M_DIFF] / stats[M_RADIAL])
        step = stats[M_STEP] / weight
        if ratio <= 0.0:
            learned = s[S_MAG_CORRELATION_MAX]
        elif ratio >= 1.0:
            learned = s[S_MAG_CORRELATION_MIN]
        else:
            learned = -step / math.log(1.0 - ratio)
        learned = min(max(learned, s[S_MAG_CORRELATION_MIN]), s[S_MAG_CORRELATION_MAX])
        correlation = (weight * learned + prior_weight * correlation) / (weight + prior_weight)
    return variance, correlation


@njit
def _level(sample, st):
    """The field's horizontal part in chair (forward, left) axes, using the still-measured gravity."""
    f0, f1, f2 = sample[V_MAG], sample[V_MAG + 1], sample[V_MAG + 2]
    u0, u1, u2 = st[GRAVITY], st[GRAVITY + 1], st[GRAVITY + 2]
    along_up = sum3(f0 * u0, f1 * u1, f2 * u2)
    h0, h1, h2 = f0 - along_up * u0, f1 - along_up * u1, f2 - along_up * u2
    # forward axis levelled: chair x with its vertical part removed
    w0, w1, w2 = 1.0 - u0 * u0, -u0 * u1, -u0 * u2
    norm = math.sqrt(sum3(w0 * w0, w1 * w1, w2 * w2))
    if norm == 0.0:
        norm = 1.0
    w0, w1, w2 = w0 / norm, w1 / norm, w2 / norm
    l0, l1, l2 = u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0
    return sum3(h0 * w0, h1 * w1, h2 * w2), sum3(h0 * l0, h1 * l1, h2 * l2)


@njit
def _fit_add(fit, x, y, heading, forget):
    """The reference's `_fit_add`, in place."""
    c, s = math.cos(heading), math.sin(heading)
    fit[0] = forget * fit[0] + 1.0
    fit[1] = forget * fit[1] + c
    fit[2] = forget * fit[2] + s
    fit[3] = forget * fit[3] + x
    fit[4] = forget * fit[4] + y
    fit[5] = forget * fit[5] + (c * x - s * y)
    fit[6] = forget * fit[6] + (s * x + c * y)


@njit
def _fit_centre(fit, min_spread_sq, min_points):
    """(found, centre x, centre y): the reference's `_fit_centre`."""
    weight = fit[0]
    if weight < min_points:
        return False, 0.0, 0.0
    c, s = fit[1] / weight, fit[2] / weight
    spread = 1.0 - c * c - s * s
    if spread < min_spread_sq:
        return False, 0.0, 0.0
    x, y, p, q = fit[3] / weight, fit[4] / weight, fit[5] / weight, fit[6] / weight
    return True, (x - c * p - s * q) / spread, (y + s * p - c * q) / spread
