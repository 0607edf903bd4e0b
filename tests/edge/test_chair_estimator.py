"""Our per-chair filter: hand-made motions, still periods, gaps, magnetometer aid, constant memory."""

from __future__ import annotations

import gc
import math
import tracemalloc

import numpy as np
import pytest

from edge.chair.estimator import position_update, start, step, wheel_turn_ratio_prior
from edge.chair.magnetometer import _fit_centre, _level
from edge.chair.state import BIAS, GYRO_SCALE, HEADING, MAG_FIT_SIZE, X, Y, ChairSample, ChairSettings, Flag
from hub.chair.corrections import BEACON_BASE_SD_M, FAR_PRIOR_SD_M, BeaconLevels, ContactDistance, contact_update
from protocol.session import Beacon
from protocol.session_log import read_session
from reckon.evaluation.inputs import build_inputs
from reckon.evaluation.reckon_run import merged_samples
from sim_devices.wheelchair import simulate
from sim_devices.wheelchair.worlds import world_params

COURT_M2 = 28.0 * 15.0  # an IWBF court

SETTINGS = ChairSettings(wheel_diameter_m=0.6)
DT_NS = 5_000_000  # 200 Hz
GRAVITY = (0.0, 0.0, 1.0)


def roll_deg(distance_m: float) -> float:
    return distance_m / (math.pi * SETTINGS.wheel_diameter_m) * 360.0


def sample(i: int, yaw_dps: float = 0.0, left_deg: float = 0.0, right_deg: float = 0.0, accel=GRAVITY, mag=None):
    return ChairSample(i * DT_NS, yaw_dps, left_deg, right_deg, accel, mag)


def run(samples, x=0.0, y=0.0, heading=0.0, **start_options):
    state = start(SETTINGS, samples[0], x, y, heading, **start_options)
    for s in samples[1:]:
        state = step(SETTINGS, state, s)
    return state


def test_straight_roll_moves_pi_d_per_turn():
    per_step = roll_deg(1.0) / 200  # 1 m/s
    state = run([sample(i, left_deg=per_step, right_deg=per_step) for i in range(0, 1001)])
    assert state.mean[X] == pytest.approx(5.0, rel=1e-6)
    assert abs(state.mean[Y]) < 1e-9
    assert state.cov[X, X] > 0.01**2  # uncertainty grew with distance


def test_turning_in_place_then_rolling_goes_the_new_way():
    samples = [sample(i, yaw_dps=90.0) for i in range(0, 201)]  # 90 deg in 1 s
    per_step = roll_deg(1.0) / 200
    samples += [sample(i, left_deg=per_step, right_deg=per_step) for i in range(201, 401)]
    state = run(samples)
    assert state.mean[HEADING] == pytest.approx(math.pi / 2, abs=0.01)
    assert state.mean[X] == pytest.approx(0.0, abs=0.01)
    assert state.mean[Y] == pytest.approx(1.0, abs=0.01)


def test_still_periods_learn_the_gyro_bias_and_stop_wheel_creep():
    bias = 0.4  # deg/s on the seat gyro, 0.6 deg/s on each wheel
    creep = 0.6 / 200
    state = run([sample(i, yaw_dps=bias, left_deg=creep, right_deg=creep) for i in range(0, 2001)])
    assert math.degrees(state.mean[BIAS]) == pytest.approx(bias, abs=0.05)
    assert state.flags & Flag.STILL
    assert abs(state.mean[X]) < 0.01  # the creeping wheels did not move a still chair
    assert state.left_bias_dps == pytest.approx(0.6, abs=0.05)
    assert abs(math.degrees(state.mean[HEADING])) < 1.0  # heading stopped drifting once the bias was known


def stop_after_play(stop_s: float, rest_accel: list[float]):
    """4 s of rolling at 1 m/s with |a| shaken between 0.99 and 1.11 g (mean 1.05), then the wheels and
    the seat quiet for `stop_s` with |a| from `rest_accel` in turn; the seat gyro reads a 0.4 deg/s bias
    throughout, which the filter does not know yet (an edge started mid-play)."""
    per_step = roll_deg(1.0) / 200
    play = [sample(i, yaw_dps=0.4, left_deg=per_step, right_deg=per_step, accel=(0.0, 0.0, 0.99 + 0.12 * (i % 2)))
            for i in range(0, 801)]
    rest = [sample(i, yaw_dps=0.4, accel=(0.0, 0.0, rest_accel[i % len(rest_accel)]))
            for i in range(801, 801 + round(stop_s * 200))]
    state = start(SETTINGS, play[0], 0.0, 0.0, 0.0)
    flags = Flag.NONE
    for s in play[1:] + rest:
        state = step(SETTINGS, state, s)
        flags |= state.flags
    return state, flags


def test_a_brief_stop_in_play_learns_the_gyro_bias():
    """At rest the accelerometer reads its own scale and bias (0.97 g), in play vibration lifts |a|'s
    mean: the stop is judged against |a| over the stop itself, so 0.7 s of it is enough."""
    state, flags = stop_after_play(0.7, [0.97])
    assert flags & Flag.STILL
    assert math.degrees(state.mean[BIAS]) == pytest.approx(0.4, abs=0.1)
    assert math.degrees(math.sqrt(state.cov[BIAS, BIAS])) < 0.1  # the prior was 1 deg/s


def test_a_gyro_warming_up_in_play_stays_inside_the_stated_heading_uncertainty():
    """After power-on a MEMS gyro's bias moves as it warms (0-0.5 deg/s over 100-600 s): here 0.15
    deg/s over a minute of play after a stop that learned it. Its heading error (4.5 deg) must stay
    within two stated SDs: the bias walk covers the warm-up, not only the in-run instability."""
    stop = [sample(i, yaw_dps=0.2) for i in range(0, 401)]
    per_step = roll_deg(1.0) / 200
    play = [sample(i, yaw_dps=0.2 + 0.15 * (i - 401) / 12000, left_deg=per_step, right_deg=per_step)
            for i in range(401, 12401)]
    state = run(stop + play, heading_sd_rad=math.radians(0.1))  # a stand's heading
    error = math.degrees(state.mean[HEADING])  # the chair rolled straight: the true heading stayed 0
    assert error == pytest.approx(0.5 * 0.15 * 60.0, abs=0.5)  # nothing in play tells the drift
    assert abs(error) < 2.0 * math.degrees(math.sqrt(state.cov[HEADING, HEADING]))


def test_a_chair_jostled_with_its_wheels_quiet_is_not_still():
    state, flags = stop_after_play(2.0, [0.9, 1.1])
    assert not flags & Flag.STILL
    assert math.degrees(math.sqrt(state.cov[BIAS, BIAS])) > 0.9


def test_a_gap_in_seat_data_is_bridged_by_the_wheels():
    # the chair pivots at 90 deg/s; the seat misses 0.5 s; the wheels keep counting
    ratio = wheel_turn_ratio_prior(SETTINGS)  # rad per deg of right - left
    wheel_per_step = math.radians(90.0) / 200 / ratio / 2
    samples = [sample(i, yaw_dps=90.0, left_deg=-wheel_per_step, right_deg=wheel_per_step) for i in range(0, 201)]
    gap = ChairSample(300 * DT_NS, 90.0, -wheel_per_step * 100, wheel_per_step * 100, GRAVITY, None)
    state = run(samples)
    state = step(SETTINGS, state, gap)
    assert state.flags & Flag.GAP
    assert math.degrees(state.mean[HEADING]) == pytest.approx(135.0, abs=2.0)


def test_a_silent_seat_is_bridged_by_the_axle_imus_yaw_not_the_scrubbing_wheels():
    # a 300 deg/s pivot whose wheels scrub: they turn 10 % further apart than the chair turns; the axle
    # IMUs see the chair's yaw x cos(camber). 1 s with the seat, 0.5 s of bridge samples, then the seat again.
    cos_camber = math.cos(math.radians(SETTINGS.camber_deg))
    ratio = wheel_turn_ratio_prior(SETTINGS)
    wheel = math.radians(300.0) / 200 / ratio / 2 * 1.1
    def pivot(i, seat=True, every=1):
        return ChairSample(i * DT_NS, 300.0 if seat else math.nan, -wheel * every, wheel * every,
                           GRAVITY if seat else (math.nan,) * 3, None, 300.0 / 200 * cos_camber * every)
    samples = [pivot(i) for i in range(0, 201)] + [pivot(i, seat=False, every=2) for i in range(202, 302, 2)]
    samples += [pivot(302, every=2)] + [pivot(i) for i in range(303, 311)]
    state = start(SETTINGS, samples[0], 0.0, 0.0, 0.0)
    flags = Flag.NONE
    for s in samples[1:]:
        state = step(SETTINGS, state, s)
        flags |= state.flags
    assert flags & Flag.GAP and not state.flags & Flag.GAP  # bridged, then the seat again
    turned = 300.0 * 310 / 200
    assert math.degrees(state.mean[HEADING]) == pytest.approx(turned, abs=1.0)
    assert state.axis_xy / state.axis_xx == pytest.approx(math.radians(1.0) / cos_camber, rel=1e-3)
    assert math.isfinite(state.accel_mean_g) and state.accel_mean_g == pytest.approx(1.0)


def test_time_going_backwards_is_flagged_not_fatal():
    state = run([sample(i) for i in range(0, 10)])
    again = step(SETTINGS, state, sample(5))
    assert again.flags & Flag.BACKWARDS and again.time_ns == state.time_ns


def test_magnetometer_corrects_a_wrong_gyro_scale():
    """The gyro reads 5 % high; the field (with a hard-iron offset) keeps the heading honest."""
    north, hard_iron = 0.7, np.array([0.08, -0.05])
    samples, truth = [], []
    heading = 0.0
    ratio = wheel_turn_ratio_prior(SETTINGS)
    for i in range(0, 200 * 200):  # 200 s of pivoting back and forth, wheels turning opposite ways
        rate = 60.0 * math.sin(2 * math.pi * i / 200 / 25.0)  # deg/s, +-60
        heading += math.radians(rate) / 200
        truth.append(heading)
        wheel = math.radians(rate) / 200 / ratio / 2
        field = 0.3 * np.array([math.cos(north - heading), math.sin(north - heading)]) + hard_iron
        samples.append(sample(i, yaw_dps=rate * 1.05, left_deg=-wheel, right_deg=wheel, mag=(field[0], field[1], -0.35)))

    def late_rms_deg(with_mag: bool) -> float:
        state = start(SETTINGS, samples[0], 0.0, 0.0, 0.0)
        errors = []
        for i, s in enumerate(samples[1:], start=1):
            s = s if with_mag else ChairSample(s.time_ns, s.yaw_rate_dps, s.left_rotation_deg, s.right_rotation_deg,
                                               s.accel_g, None)
            state = step(SETTINGS, state, s)
            if i > 100 * 200:
                errors.append((state.mean[HEADING] - truth[i] + math.pi) % (2 * math.pi) - math.pi)
        return math.degrees(float(np.sqrt(np.mean(np.square(errors)))))

    with_mag, without = late_rms_deg(True), late_rms_deg(False)
    assert with_mag < 5.0  # 4.2 deg: until the hall is shown clean, a field beyond mag_trust_sd_deg is trusted less
    assert with_mag < without / 2


def spinning(seconds: float, seat_scale: float, axle_sign: float = 1.0):
    """A chair spinning left at 120 deg/s, the seat gyro reading `seat_scale` x the truth, the axle IMUs
    the truth x cos(camber) (x `axle_sign`); no magnetometer, no stop. (samples, true headings)."""
    cos_camber = math.cos(math.radians(SETTINGS.camber_deg))
    wheel = math.radians(120.0) / 200 / wheel_turn_ratio_prior(SETTINGS) / 2
    n = int(seconds * 200)
    samples = [ChairSample(i * DT_NS, 120.0 * seat_scale, -wheel, wheel, GRAVITY, None,
                           axle_sign * 120.0 / 200 * cos_camber) for i in range(n)]
    return samples, [math.radians(120.0) * i / 200 for i in range(n)]


def test_the_axle_imus_check_the_seat_gyros_scale_once():
    """3 % high: once the axles saw four turns, the scale moves by what two independent gyros and the
    camber's uncertainty allow (prior 2 %, their error 2 % / sqrt 2 and tan c x 1 deg: 64 % of the way)."""
    samples, truth = spinning(40.0, 1.03)
    state, flags = start(SETTINGS, samples[0], 0.0, 0.0, 0.0), []
    for s in samples[1:]:
        state = step(SETTINGS, state, s)
        flags.append(state.flags)
    used = [i for i, f in enumerate(flags) if f & Flag.AXLE_SCALE_USED]
    assert len(used) == 1 and not any(f & Flag.AXLE_SCALE_REJECTED for f in flags)
    assert 1440.0 <= 120.0 * used[0] / 200 * math.cos(math.radians(SETTINGS.camber_deg)) < 1440.0 + 120.0
    prior = SETTINGS.gyro_scale_sd**2
    axles = prior / 2 + (math.tan(math.radians(SETTINGS.camber_deg)) * math.radians(SETTINGS.camber_sd_deg)) ** 2
    assert state.mean[GYRO_SCALE] == pytest.approx(prior / (prior + axles) * (1 / 1.03 - 1), rel=1e-3)
    # after the check the heading drifts at the rest of the error (~1.1 %), without it at all 3 %
    without = run([ChairSample(s.time_ns, s.yaw_rate_dps, s.left_rotation_deg, s.right_rotation_deg, s.accel_g)
                   for s in samples])
    drift_without = math.degrees(without.mean[HEADING] - truth[-1])
    assert drift_without == pytest.approx(0.03 * 120.0 * 40, rel=0.02)
    saved = drift_without - math.degrees(state.mean[HEADING] - truth[-1])
    assert saved > 0.5 * 0.03 * 120.0 * (40 - used[0] / 200)


def test_axles_that_turn_against_the_seat_are_refused():
    """A venue file with an axle IMU's spin axis the wrong way: the check is refused, the scale untouched."""
    samples, _ = spinning(20.0, 1.03, axle_sign=-1.0)
    state, flags = start(SETTINGS, samples[0], 0.0, 0.0, 0.0), Flag.NONE
    for s in samples[1:]:
        state = step(SETTINGS, state, s)
        flags |= state.flags
    assert flags & Flag.AXLE_SCALE_REJECTED and not flags & Flag.AXLE_SCALE_USED
    assert state.mean[GYRO_SCALE] == 0.0


def pivots_then(rest, north=0.7, hard_iron=(0.08, -0.05), bias_dps=0.0, seconds=60, pivot_roll_deg=0.0):
    """`seconds` of pivoting back and forth (+-60 deg/s, rolling `pivot_roll_deg` per sample) in an
    undisturbed field, then `rest`: (samples, true headings).

    `rest(i, heading)` gives (yaw rate deg/s, wheel roll deg per sample, field turn rad) per later sample."""
    samples, truth, heading = [], [], 0.0
    ratio = wheel_turn_ratio_prior(SETTINGS)
    for i in range(seconds * 200 + len(rest)):
        if i < seconds * 200:
            rate, roll, disturbance = 60.0 * math.sin(2 * math.pi * i / 200 / 25.0), pivot_roll_deg, 0.0
        else:
            rate, roll, disturbance = rest[i - seconds * 200]
        heading += math.radians(rate) / 200
        truth.append(heading)
        wheel = math.radians(rate) / 200 / ratio / 2
        angle = north - heading + disturbance
        field = 0.3 * np.array([math.cos(angle), math.sin(angle)]) + np.array(hard_iron)
        samples.append(sample(i, yaw_dps=rate + bias_dps, left_deg=roll - wheel, right_deg=roll + wheel,
                              mag=(field[0], field[1], -0.35)))
    return samples, truth


def test_a_parked_chair_in_a_disturbed_spot_keeps_its_heading():
    """It rolls 1 m into a spot where the field is turned 20 deg and stays there two minutes: one
    disturbed place, read again and again, is one reading, not hundreds."""
    roll = roll_deg(1.0) / 200  # 1 m/s for a second, then parked
    rest = [(0.0, roll, math.radians(20.0))] * 200 + [(0.0, 0.0, math.radians(20.0))] * (120 * 200)
    samples, truth = pivots_then(rest)
    state = start(SETTINGS, samples[0], 0.0, 0.0, 0.0)
    heading_readings = 0
    for i, s in enumerate(samples[1:], start=1):
        before = state.mag.innovation_deg
        state = step(SETTINGS, state, s)
        heading_readings += i > 61 * 200 and state.mag.innovation_deg != before
    error = math.degrees((state.mean[HEADING] - truth[-1] + math.pi) % (2 * math.pi) - math.pi)
    assert state.mag.ready and heading_readings == 0  # parked: no reading of north - heading at all
    assert abs(error) < 1.5


def test_the_fields_turn_teaches_the_gyro_bias_without_a_stop():
    """Pivoting in place without ever stopping, the gyro reads 0.6 deg/s high: the turns the field saw
    teach the bias (no still period ever does)."""
    rest = [(60.0 * math.sin(2 * math.pi * i / 200 / 7.0), 0.0, 0.0) for i in range(60 * 200)]
    samples, truth = pivots_then(rest, bias_dps=0.6)
    state = start(SETTINGS, samples[0], 0.0, 0.0, 0.0)
    for s in samples[1:]:
        state = step(SETTINGS, state, s)
        assert not state.flags & Flag.STILL
    assert math.degrees(state.mean[BIAS]) == pytest.approx(0.6, abs=0.1)


def test_memory_does_not_grow_with_steps():
    per_step = roll_deg(2.0) / 200
    state = start(SETTINGS, sample(0), 0.0, 0.0, 0.0)

    def advance(state, first, count):
        for i in range(first, first + count):
            state = step(SETTINGS, state, sample(i, yaw_dps=10.0 * math.sin(i / 300), left_deg=per_step,
                                                 right_deg=per_step, mag=(0.2, 0.1, -0.3)))
        return state

    state = advance(state, 1, 1000)
    tracemalloc.start()
    state = advance(state, 1001, 10)
    gc.collect()  # what a full collection frees (cyclic garbage, free lists) is not the filter's state
    after_10, _ = tracemalloc.get_traced_memory()
    state = advance(state, 1011, 20_000)  # 100 s of data; tracemalloc makes each step ~15x slower
    gc.collect()
    after_many, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert after_many - after_10 < 4096  # a few bytes of allocator noise, not growth
    assert state.mean.shape == (7,) and state.cov.shape == (7, 7) and state.mag.fit.shape == (MAG_FIT_SIZE,)


def test_position_fix_is_gated():
    state = run([sample(i) for i in range(0, 10)], x=5.0, y=5.0)
    fixed, used = position_update(state, np.array([5.5, 5.0]), np.eye(2) * 0.25)
    assert used and 5.0 < fixed.mean[X] < 5.5
    _, used = position_update(state, np.array([50.0, 5.0]), np.eye(2) * 0.25)
    assert not used


def test_beacon_fixes_follow_the_venue_file_and_what_the_beacon_has_shown():
    beacon = Beacon("goal", 1.575, 7.5, tx_power_dbm=-59.0, height_m=2.9)
    levels = BeaconLevels((beacon,), COURT_M2)
    stated = -59.0 - 20 * math.log10(math.hypot(1.0, 2.4))  # the file's level: 1 m from under it, free space
    assert levels.level_dbm("goal") == pytest.approx(stated) and levels.pass_floor_dbm("goal") == pytest.approx(stated - 12)
    near, far = levels.close("goal", -60.0), levels.close("goal", -68.0)
    assert near is not None and far is not None and far[0, 0] > near[0, 0] >= BEACON_BASE_SD_M**2  # sigma >= 3 m
    assert levels.close("goal", -85.0) is None  # tens of metres by the venue file, and far below the level
    assert levels.level_dbm("goal") == -68.0 and levels.pass_floor_dbm("goal") == -80.0  # learned from 3 peaks
    # a hall quieter than its file: this beacon's passes peak near -80 dBm; its own close ones count
    quiet = BeaconLevels((beacon,), COURT_M2)
    for peak in (-80.0, -92.0, -79.0, -90.0):
        quiet.close("goal", peak)
    assert quiet.level_dbm("goal") == -80.0 and quiet.pass_floor_dbm("goal") == -92.0
    assert quiet.close("goal", -81.0) is not None and quiet.close("goal", -88.0) is None


def test_a_beacon_learns_where_its_close_passes_are_and_how_many_are_far():
    """Chairs that peak 2.5 m in front of the goal (+x), within 0.8 m, and candidates of which 40 % are far
    passes 6-16 m out: the close kind's offset and share are learned, a far candidate is sent as a far fix."""
    beacon = Beacon("goal", 1.575, 7.5, tx_power_dbm=-59.0, height_m=2.9)
    levels = BeaconLevels((beacon,), COURT_M2)
    rng = np.random.default_rng(7)
    pose_cov, stated = np.eye(2) * 0.1, np.eye(2) * 4.0
    kinds = []
    for _ in range(300):
        if rng.random() < 0.6:
            from_beacon = np.array([2.5, 0.0]) + rng.normal(0.0, 0.8, 2)
        else:
            from_beacon = np.array([rng.uniform(6.0, 16.0), rng.uniform(-7.0, 7.0)])
        pose = np.array([beacon.x_m, beacon.y_m]) + from_beacon + rng.normal(0.0, math.sqrt(0.1), 2)
        fix = levels.fix("goal", pose, pose_cov, stated)
        kinds.append(None if fix is None else fix[2])
    record = levels.levels["goal"]
    assert record.close.offset_m() == pytest.approx([2.5, 0.0], abs=0.4)  # in front of the goal, not under it
    assert 0.45 < levels.close_share("goal") < 0.75
    assert record.close_fixes + record.far_fixes + record.stray == 300
    assert record.stray < 20  # only the far box's corners, 16 m out, look like strays
    assert 0.45 < np.mean([kind for kind in kinds if kind is not None]) < 0.75
    line = levels.describe("goal")
    assert line.startswith(f"{record.close_fixes} close-pass fixes, {record.far_fixes} far, {record.stray} stray")
    assert "(+2." in line
    near_point, near_cov, close = levels.fix("goal", np.array([beacon.x_m + 2.6, beacon.y_m]), pose_cov, stated)
    assert close and np.hypot(*(near_point - [beacon.x_m + 2.5, beacon.y_m])) < 0.4
    assert near_cov[0, 0] == pytest.approx(4.0, rel=0.2)  # the venue file's sigma: the learned spread is below it
    far_point, far_cov, close = levels.fix("goal", np.array([beacon.x_m + 14.0, beacon.y_m + 5.0]), pose_cov, stated)
    assert not close and far_point[0] > beacon.x_m + 6.0 and far_cov[0, 0] > 9.0  # metres, not a spot
    # poses that state far more variance than their innovations show: spreads stay positive, fixes finite
    for _ in range(200):
        levels.fix("goal", np.array([beacon.x_m + 2.5, beacon.y_m]), np.eye(2) * 50.0, stated)
    assert record.close.variance_m2() > 0.0 and record.far.variance_m2() > 0.0
    for out_m in (2.5, 12.0):  # 12 m: where neither kind has been any more, a stray (None)
        fix = levels.fix("goal", np.array([beacon.x_m + out_m, beacon.y_m]), np.eye(2) * 0.1, stated)
        assert (fix is None) == (out_m == 12.0)
        assert fix is None or (np.all(np.isfinite(fix[0])) and np.all(np.linalg.eigvalsh(fix[1]) > 0.0))


def test_a_candidate_whose_pose_puts_it_across_the_court_is_no_fix():
    """A chair parked 20 m from the goal, its pose good to half a metre, hears the beacon peak (the strongest
    of many fades): neither a close nor a far pass, so no fix at all; one 8 m out whose pose states metres
    still gets a far fix, weaker by the chance that it was a stray."""
    beacon = Beacon("goal", 1.575, 7.5, tx_power_dbm=-59.0, height_m=2.9)
    levels = BeaconLevels((beacon,), COURT_M2)
    at, stated = np.array([beacon.x_m, beacon.y_m]), np.eye(2) * 9.0
    assert levels.fix("goal", at + [20.0, 0.0], np.eye(2) * 0.25, stated) is None
    assert levels.levels["goal"].stray == 1 and levels.levels["goal"].far_fixes == 0
    point, covariance, close = levels.fix("goal", at + [8.0, 0.0], np.eye(2) * 4.0, stated)
    assert not close and np.hypot(*(point - at)) < 3.0
    assert covariance[0, 0] > FAR_PRIOR_SD_M**2  # the far kind's 5 m, and more: it may have been a stray
    # a stray teaches neither kind: the far kind's place is where genuine far passes were
    for _ in range(50):
        assert levels.fix("goal", at + [24.0, 5.0], np.eye(2) * 0.25, stated) is None
    assert np.hypot(*levels.levels["goal"].far.offset_m()) < 4.0
    with pytest.raises(ValueError, match="court area 0"):
        BeaconLevels((beacon,), 0.0)


def test_the_contact_distance_is_learned_from_the_contacts_taken():
    contact = ContactDistance()
    assert contact.mean_m() == pytest.approx(0.9) and contact.variance_m2() == pytest.approx(0.09)
    rng = np.random.default_rng(4)
    for distance in rng.normal(0.65, 0.05, 200):  # small chairs touching at 0.65 m, poses 0.1 m^2 between them
        contact.taken(distance + rng.normal(0.0, math.sqrt(0.1)), 0.1)
    assert contact.mean_m() == pytest.approx(0.65, abs=0.1)
    assert contact.variance_m2() < 0.05  # the poses' own variance is not counted as the contact's


def test_contact_pulls_two_chairs_to_a_chair_width():
    a = start(SETTINGS, sample(0), 0.0, 0.0, 0.0, position_sd_m=0.5)
    b = start(SETTINGS, sample(0), 2.0, 0.0, 0.0, position_sd_m=0.5)
    a2, b2, used = contact_update(a, b)
    assert used
    separation = b2.mean[X] - a2.mean[X]
    assert 0.9 < separation < 2.0  # pulled towards 0.9 m, weighted by both covariances
    assert a2.mean[X] > 0.0 and b2.mean[X] < 2.0


def test_a_wheel_catching_up_after_lost_packets_does_not_teach_the_turn_ratio():
    state = run([sample(i) for i in range(0, 10)])
    ratio = state.turn_xy / state.turn_xx
    catch_up = sample(10, yaw_dps=0.0, left_deg=-250.0, right_deg=250.0)  # 100,000 deg/s: not a real rate
    after = step(SETTINGS, state, catch_up)
    assert after.turn_xy / after.turn_xx == pytest.approx(ratio)


@pytest.mark.parametrize("jolt, share", [((7.0, 0.0, 1.0), 1.0), ((0.0, 0.0, 8.0), 0.0), ((3.0, 4.0, 6.0), 0.5)],
                         ids=["horizontal", "from-below", "half"])
def test_an_impact_may_shove_the_chair_in_proportion_to_its_horizontal_share(jolt, share):
    parked = [sample(i) for i in range(0, 200)]
    before = run(parked)
    after = step(SETTINGS, before, sample(200, accel=jolt))
    assert after.flags & Flag.IMPACT
    added = after.cov[X, X] - before.cov[X, X]
    assert added == pytest.approx(SETTINGS.impact_shove_sd_m**2 * share, abs=1e-9)


def test_the_hard_iron_fit_holds_in_a_disturbed_hall(tmp_path):
    """Tune world 74's hall (23 deg RMS, correlated over 7 m), two chairs for two minutes: the field's
    angle around the fitted hard-iron centre against north - the true heading. A circle fit, which
    takes the hall's changes of strength for the circle's shape, erred 17 deg RMS for both chairs;
    the fit against the filter's heading about 7-9 deg."""
    path = tmp_path / "world74.mcap"
    simulate(2, 120.0, 1, path, world_params(74), world=74)
    inputs = build_inputs(read_session(path))
    for agent in inputs.agents:
        samples = merged_samples(agent)
        chair = ChairSettings(wheel_diameter_m=agent.agent.wheel_diameter_m, camber_deg=agent.agent.camber_deg)
        state = start(chair, samples[0], *agent.start_pose())
        angles = []  # the levelled field's angle around the fit's centre, plus the true heading: north and its error
        for s in samples[1:]:
            due = state.mag.due_s
            state = step(chair, state, s)
            centre = _fit_centre(state.mag.fit, chair.mag_fit_min_spread, chair.mag_fit_min_points)
            if s.mag_gauss is not None and state.mag.due_s > due and centre is not None:
                forward, left = _level(s.mag_gauss, state.gravity)
                heading = np.interp(s.time_ns, inputs.grid_ns, agent.truth_heading_rad)
                angles.append(math.atan2(left - centre[1], forward - centre[0]) + heading)
        north = math.atan2(np.mean(np.sin(angles)), np.mean(np.cos(angles)))
        errors = np.angle(np.exp(1j * (np.array(angles) - north)))
        assert len(angles) > 150  # ready within 45 s (two readings a second)
        assert math.degrees(math.sqrt(np.mean(errors**2))) < 12.0
