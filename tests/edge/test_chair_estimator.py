"""Our per-chair filter: hand-made motions, still periods, gaps, magnetometer aid, constant memory."""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pytest

from edge.chair.estimator import (BIAS, HEADING, X, Y, ChairSample, ChairSettings, Flag, position_update, start,
                                  step, wheel_turn_ratio_prior)
from hub.chair.corrections import beacon_fix, contact_update
from protocol.session import Beacon

SETTINGS = ChairSettings(wheel_diameter_m=0.6)
DT_NS = 5_000_000  # 200 Hz
GRAVITY = (0.0, 0.0, 1.0)


def roll_deg(distance_m: float) -> float:
    return distance_m / (math.pi * SETTINGS.wheel_diameter_m) * 360.0


def sample(i: int, yaw_dps: float = 0.0, left_deg: float = 0.0, right_deg: float = 0.0, accel=GRAVITY, mag=None):
    return ChairSample(i * DT_NS, yaw_dps, left_deg, right_deg, accel, mag)


def run(samples, x=0.0, y=0.0, heading=0.0):
    state = start(SETTINGS, samples[0], x, y, heading)
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
    assert with_mag < 4.0
    assert with_mag < without / 2


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
    after_10, _ = tracemalloc.get_traced_memory()
    state = advance(state, 1011, 20_000)  # 100 s of data; tracemalloc makes each step ~15x slower
    after_many, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert after_many - after_10 < 4096  # a few bytes of allocator noise, not growth
    assert state.mean.shape == (7,) and state.cov.shape == (7, 7) and state.mag.fit.shape == (4, 4)


def test_position_fix_is_gated():
    state = run([sample(i) for i in range(0, 10)], x=5.0, y=5.0)
    fixed, used = position_update(state, np.array([5.5, 5.0]), np.eye(2) * 0.25)
    assert used and 5.0 < fixed.mean[X] < 5.5
    _, used = position_update(state, np.array([50.0, 5.0]), np.eye(2) * 0.25)
    assert not used


def test_beacon_fix_uncertainty_follows_rssi():
    beacon = Beacon("goal", 1.575, 7.5)
    near, far = beacon_fix(beacon, -60.0), beacon_fix(beacon, -68.0)
    assert near is not None and far is not None and far.covariance[0, 0] > near.covariance[0, 0]
    assert beacon_fix(beacon, -85.0) is None  # tens of metres: no fix


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
