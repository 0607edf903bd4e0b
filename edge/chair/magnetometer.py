"""The seat magnetometer's aid to the chair filter: edge/chair/estimator.py's `step` calls
`magnetometer` with every sample; edge/chair/mag_kernel.py is its compiled mirror.

The seat magnetometer is a self-calibrating aid that learns the hall it is in. The chair's hard
iron is a fixed offset in the chair frame, found as the chair turns by a running least-squares fit
of reading = centre + R(-heading) field, the heading the filter's: around the centre the field's
angle is (north - heading). A circle fit, which needs no heading, reads the hall's changes of the
field's strength from place to place as the circle's shape (in a hall disturbed by 23 deg RMS its
centre put the readings 12-30 deg RMS off the truth where the fit against the heading leaves 8-15,
docs/reckon-estimator.md); a constant error of the heading only turns the fitted field, not the
centre. A building's disturbance is fixed in space, about isotropic, and nobody knows it in advance
(0-25 deg RMS, correlated over 1-10 m):
- its size is learned from the spread of the field's strength around the circle (a disturbance
  that turns the field by a degrees changes its strength by as much), its correlation length
  from how fast successive readings' strengths differ over the travel between them;
- the north - heading readings are checked against the heading where it is known better than
  they claim to be: their squared errors beyond what the heading's own uncertainty explains set
  their variance where that is larger than the spread says (the spread can under-read a
  disturbance smooth over the court: about 8 of 21 deg in one such hall, docs/reckon-estimator.md);
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
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from edge.chair.state import (BIAS, DEG, GYRO_SCALE, HEADING, M_CHECKS, M_DIFF, M_EXCESS, M_LAST, M_RADIAL, M_RADIUS,
                              M_STEP, M_WEIGHT, N, NORTH, X, Y, ChairSample, ChairSettings, Flag, MagAid, wrap)


def magnetometer(settings: ChairSettings, mag: MagAid, sample: ChairSample, gravity: tuple[float, float, float],
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
    forget = math.exp(-settings.mag_period_s / settings.mag_fit_memory_s)
    fit = _fit_add(mag.fit, horizontal, float(mean[HEADING]), forget)
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
                          field_y_m=float(mean[Y]), field_offset_rad=wrap(raw_angle - (mean[NORTH] - mean[HEADING])),
                          field_var_rad2=float(cov[NORTH, NORTH] - 2.0 * cov[NORTH, HEADING] + cov[HEADING, HEADING]))
    variance, correlation_m = mag_disturbance(settings, mag.stats)
    centre_var = _centre_var(fit, variance)  # the strength's spread: untouched by a map of directions
    flags = Flag.NONE
    if not math.isfinite(mag.anchor_angle) or not math.isfinite(turn_gyro):
        mag = replace(mag, anchor_angle=raw_angle, turn_gyro_rad=0.0, turn_s=0.0, turn_m=0.0)
    elif turn_s >= settings.mag_turn_s:
        mean, cov, flags = _turn_update(settings, mag, raw_angle, mean, cov, variance, correlation_m, centre_var)
        mag = replace(mag, anchor_angle=raw_angle, turn_gyro_rad=0.0, turn_s=0.0, turn_m=0.0)
    # north - heading: where the hub's map knows this place better than the hall's own model, its offset out
    # (the turn above is a difference over metres, which a map's errors from cell to cell would only add to)
    angle = raw_angle
    mapped = _trusted(settings, mag.map_var_rad2) if mag.map_var_rad2 > 0.0 else math.inf
    use_map = mapped < variance
    if use_map:
        angle, variance = wrap(raw_angle - mag.map_offset_rad), mapped
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
    innovation = wrap(angle - (mean[NORTH] - mean[HEADING]))
    h = np.zeros(N)
    h[NORTH], h[HEADING] = 1.0, -1.0
    predicted, across = float(h @ cov @ h), centre_var  # the centre's error across the field, as far along any line
    total = predicted + variance + across
    mag = replace(mag, innovation_deg=innovation / DEG, since_update_m=0.0)
    # the hall's own readings checked against a heading known better than they claim to be (an uncertain
    # heading's innovation says little about the reading; the map's readings are the hub's to check)
    if not use_map and predicted < variance:
        mag = replace(mag, stats=_check_disturbance(settings, mag.stats, innovation * innovation - predicted - across))
    if innovation * innovation / total > settings.mag_gate_chi2:
        return replace(mag, rejections=mag.rejections + 1), mean, cov, flags | Flag.MAG_REJECTED
    gain = cov @ h / total
    return replace(mag, rejections=0), mean + gain * innovation, cov - np.outer(gain, h @ cov), flags | Flag.MAG_USED


def _turn_update(settings: ChairSettings, mag: MagAid, angle: float, mean: np.ndarray, cov: np.ndarray,
                 variance: float, correlation_m: float, centre_var: float) -> tuple[np.ndarray, np.ndarray, Flag]:
    """The gyro's bias and scale from the turn the field saw since the anchor reading.

    The disturbance is the hall's, fixed in space: over little travel it hardly changes, so the
    field turns by exactly the chair's turn, however disturbed it is (a pivot measures the gyro's
    scale, a slow stretch its bias). Its change over `turn_m` of travel, 2 var (1 - exp(-d / L)),
    is the measurement's noise."""
    scale, bias = 1.0 + mean[GYRO_SCALE], mean[BIAS]
    predicted = scale * (mag.turn_gyro_rad - bias * mag.turn_s)
    seen = predicted + wrap(-(angle - mag.anchor_angle) - predicted)  # unwrapped near the gyro's turn
    noise = (2.0 * variance * (1.0 - math.exp(-mag.turn_m / correlation_m)) + (settings.mag_turn_sd_deg * DEG) ** 2
             + centre_var * _squared_chord(mag.anchor_angle, angle))
    h_bias, h_scale = -scale * mag.turn_s, mag.turn_gyro_rad - bias * mag.turn_s  # d predicted / d state
    innovation = seen - predicted
    row = h_bias * cov[BIAS] + h_scale * cov[GYRO_SCALE]  # h P
    total = (h_bias * row[BIAS] + h_scale * row[GYRO_SCALE]) + noise
    if innovation * innovation / total > settings.mag_gate_chi2:
        return mean, cov, Flag.MAG_REJECTED
    gain = (h_bias * cov[:, BIAS] + h_scale * cov[:, GYRO_SCALE]) / total  # P h / total
    return mean + gain * innovation, cov - np.outer(gain, row), Flag.MAG_USED


def _centre_var(fit: np.ndarray, variance: float) -> float:
    """Variance (rad^2) of the fitted centre, along any line, over the field's strength squared.

    A disturbance turning the field by var rad^2 moves each reading by as much along and across:
    r^2 var per axis. The least-squares centre of w readings whose headings' mean resultant length
    is R then has r^2 var / (w (1 - R^2)) per axis: var / w after a full turn, more on a short arc."""
    w = fit[0]
    mean_cos, mean_sin = fit[1] / w, fit[2] / w
    return variance / (w * (1.0 - mean_cos * mean_cos - mean_sin * mean_sin))


def _squared_chord(a: float, b: float) -> float:
    """|u(a) - u(b)|^2 of the unit vectors at angles a and b: how far a centre error turns one reading against another."""
    along, across = math.sin(a) - math.sin(b), math.cos(b) - math.cos(a)
    return along * along + across * across


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


def _check_disturbance(settings: ChairSettings, stats: np.ndarray, excess: float) -> np.ndarray:
    """The statistics after one more north - heading reading whose squared innovation is `excess`
    beyond what the filter's heading and the fit's centre explain: what the reading's own error
    was, whatever the strength's spread said (`mag_disturbance` takes the larger)."""
    out = stats.copy()
    forget = 1.0 - 1.0 / settings.mag_level_memory
    out[M_EXCESS] = forget * out[M_EXCESS] + excess
    out[M_CHECKS] = forget * out[M_CHECKS] + 1.0
    return out


def _trusted(settings: ChairSettings, variance: float) -> float:
    """A disturbance's variance as the aid uses it: floored, and beyond `mag_trust_sd_deg` grown with
    its square (chairs keep to a few places, so its errors do not average out as independent
    readings would)."""
    variance = max(variance, (settings.mag_floor_sd_deg * DEG) ** 2)
    return variance * max(1.0, variance / (settings.mag_trust_sd_deg * DEG) ** 2)


def mag_disturbance(settings: ChairSettings, stats: np.ndarray) -> tuple[float, float]:
    """(heading variance rad^2, correlation length m) of the hall's field: learned, blended with the priors.

    The strength's spread reads a disturbance without knowing the heading, but can under-read one
    smooth over the court: the readings' own errors against the heading, once there are some, set
    the variance where they are larger."""
    prior_weight, weight = settings.mag_level_weight, stats[M_WEIGHT]
    prior_var = (settings.mag_heading_sd_deg * DEG) ** 2
    variance = (stats[M_RADIAL] + prior_weight * prior_var) / (weight + prior_weight)
    if stats[M_CHECKS] > 0.0:
        variance = max(variance, (stats[M_EXCESS] + prior_weight * variance) / (stats[M_CHECKS] + prior_weight))
    variance = _trusted(settings, variance)
    correlation = settings.mag_correlation_prior_m
    if weight > 1.0 and stats[M_RADIAL] > 0.0:
        ratio = 0.5 * (stats[M_DIFF] / stats[M_RADIAL])  # 1 - exp(-step / L), exponential correlation
        step = stats[M_STEP] / weight
        learned = settings.mag_correlation_max_m if ratio <= 0.0 else (
            settings.mag_correlation_min_m if ratio >= 1.0 else -step / math.log(1.0 - ratio))
        learned = min(max(learned, settings.mag_correlation_min_m), settings.mag_correlation_max_m)
        correlation = (weight * learned + prior_weight * correlation) / (weight + prior_weight)
    return variance, correlation


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


def _fit_add(sums: np.ndarray, point: tuple[float, float], heading: float, forget: float) -> np.ndarray:
    """The fit's running sums after one more reading `point` (forward, left) taken at `heading`:
    [weight, cos, sin, forward, left, cos forward - sin left, sin forward + cos left]."""
    c, s = math.cos(heading), math.sin(heading)
    x, y = point
    return forget * sums + np.array([1.0, c, s, x, y, c * x - s * y, s * x + c * y])


def _fit_centre(sums: np.ndarray, min_spread: float, min_points: float) -> tuple[float, float] | None:
    """The centre of reading = centre + R(-heading) field, least squares over the running sums.

    The normal equations' field part eliminated, each axis of the centre is one division by
    1 - R^2, R the mean resultant length of the headings seen. None until they spread: 1 - R^2
    must reach `min_spread` squared (a full turn gives 1, half a turn 0.59).
    """
    weight = sums[0]
    if weight < min_points:
        return None
    c, s = sums[1] / weight, sums[2] / weight
    spread = 1.0 - c * c - s * s
    if spread < min_spread**2:
        return None
    x, y, p, q = sums[3] / weight, sums[4] / weight, sums[5] / weight, sums[6] / weight
    return (x - c * p - s * q) / spread, (y + s * p - c * q) / spread
