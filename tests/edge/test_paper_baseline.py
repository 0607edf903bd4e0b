"""The wheelchair paper's formulas against hand-worked cases."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from edge.chair.paper.impacts import detect_impacts, vibration_g
from edge.chair.paper.mag_heading import magnetometer_heading
from edge.mounting import seat_to_chair, signed_axis
from edge.chair.paper.dr import PaperDrState, dead_reckon, step
from edge.chair.paper.wheel import chair_travel_m, travel_from_rotation_m, wheel_rotation_deg
from hub.chair.paper import (centroid_shift, decay_reliability, midpoint_collision, pair_impacts,
                             weighted_collision)


def test_one_wheel_turn_rolls_pi_times_the_diameter():
    # erratum: the paper's eq. 4 would give 0.61 m for a 610 mm wheel; the rim rolls pi * D
    assert travel_from_rotation_m(np.array([360.0]), 0.61)[0] == pytest.approx(math.pi * 0.61)


def test_wheel_rotation_is_the_trapezoid_integral():
    times = np.array([0, 100_000_000, 300_000_000])  # 0, 0.1, 0.3 s (a gap is bridged)
    rates = np.array([100.0, 200.0, 200.0])
    np.testing.assert_allclose(wheel_rotation_deg(times, rates), [0.0, 15.0, 55.0])


def test_chair_travel_is_the_mean_of_both_wheels():
    assert chair_travel_m(np.array([2.0]), np.array([1.0]))[0] == 1.5


def test_dead_reckoning_hand_worked():
    x, y = dead_reckon(PaperDrState(1.0, 2.0, 0.0), np.array([1.0, 2.0, -1.0]), np.array([math.pi / 2, math.pi, 0.0]))
    # 1 m along 0, then 2 m along pi/2, then -1 m along pi
    np.testing.assert_allclose(x, [1.0, 2.0, 2.0, 3.0], atol=1e-12)
    np.testing.assert_allclose(y, [2.0, 2.0, 4.0, 4.0], atol=1e-12)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.floats(-0.05, 0.05), st.floats(-10, 10)), min_size=1, max_size=50))
def test_batch_dead_reckoning_equals_looped_step(steps):
    travel = np.array([s[0] for s in steps])
    heading = np.array([s[1] for s in steps])
    state = PaperDrState(0.5, -0.5, 0.3)
    xs, ys = dead_reckon(state, travel, heading)
    for k in range(len(steps)):
        state = step(state, travel[k], heading[k])
        assert state.x_m == pytest.approx(xs[k + 1], abs=1e-9)
        assert state.y_m == pytest.approx(ys[k + 1], abs=1e-9)


def test_vibration_and_impacts():
    assert vibration_g(np.array([[0.0, 0.0, 9.0]]))[0] == pytest.approx(8.0)
    assert vibration_g(np.array([[0.0, 0.0, 0.0]]))[0] == pytest.approx(1.0)  # free fall
    times = np.arange(200) * 5_000_000
    accel = np.tile([0.0, 0.0, 1.0], (200, 1))
    accel[50] = [0.0, 0.0, 9.0]  # exactly 8 g: not above the threshold
    accel[100] = [6.0, 0.0, 6.0]  # |a| = 8.49 g -> Z = 7.49
    accel[150:152] = [[0.0, 0.0, 10.0], [0.0, 0.0, 12.0]]  # one impact, peak 11 g
    impacts = detect_impacts(times, accel, 8.0)
    assert [(i.time_ns, round(i.peak_g, 6)) for i in impacts] == [(151 * 5_000_000, 11.0)]


def test_pairing_rule():
    s = 1_000_000_000
    assert [(c.agent_a, c.agent_b) for c in pair_impacts([(0, "b"), (int(0.4 * s), "a")])] == [("a", "b")]
    assert pair_impacts([(0, "a"), (int(0.6 * s), "b")]) == []  # too far apart
    assert pair_impacts([(0, "a"), (int(0.1 * s), "b"), (int(0.2 * s), "c")]) == []  # three chairs: skipped
    assert pair_impacts([(0, "a"), (int(0.1 * s), "a")]) == []  # one chair twice is no collision
    pairs = pair_impacts([(0, "a"), (int(0.3 * s), "b"), (10 * s, "c"), (int(10.2 * s), "d")])
    assert [(c.time_ns, c.agent_a, c.agent_b) for c in pairs] == [(0, "a", "b"), (10 * s, "c", "d")]


def test_weighted_collision_eq_8_9_hand_worked():
    point, reliability = weighted_collision(np.array([0.0, 0.0]), np.array([3.0, 0.0]), 1.0, 0.5)
    np.testing.assert_allclose(point, [1.0, 0.0])  # 3 * 0.5 / 1.5
    assert reliability == pytest.approx(1.0 + (0.5 - 1.0) / 3.0)
    np.testing.assert_allclose(midpoint_collision(np.array([0.0, 0.0]), np.array([3.0, 1.0])), [1.5, 0.5])


def test_reliability_reaches_its_floor_after_99_s():
    reliability = 1.0
    for _ in range(989):
        reliability = decay_reliability(reliability)
    assert reliability > 0.01 + 1e-9
    for _ in range(5):
        reliability = decay_reliability(reliability)
    assert reliability == pytest.approx(0.01)


def test_centroid_divides_by_the_number_of_positions():
    # three positions 0..F with F = 2: the centroid divides by 3 (the paper prints F = 2)
    positions = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 3.0]])
    shift = centroid_shift(positions.sum(axis=0), len(positions), np.array([5.0, 5.0]))
    np.testing.assert_allclose(shift, [4.0, 4.0])


def test_mounting_axes():
    values = np.array([[1.0, 2.0, 3.0]])
    assert signed_axis(values, "-y")[0] == -2.0
    # seat mounted upside down and backwards: forward = -x, left = +y, so up = -z
    np.testing.assert_allclose(seat_to_chair(values, "-x", "+y"), [[-1.0, 2.0, -3.0]])


def test_magnetometer_heading_follows_a_turning_chair():
    times = np.arange(400) * 5_000_000
    # still for the first second, then 1.5 turns in the next second
    heading = 0.3 + 3 * math.pi * np.clip(times * 1e-9 - 1.0, 0.0, None)
    north = 1.2  # court angle of magnetic north
    field = np.stack([np.cos(north - heading), np.sin(north - heading), -np.ones(400)], axis=1) * 0.3
    np.testing.assert_allclose(magnetometer_heading(times, field, start_heading_rad=0.3), heading, atol=1e-9)
