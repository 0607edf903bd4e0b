"""The swimming paper's per-length method (edge/swim/paper.py), its errata worked by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from edge.swim.paper import G, lateral_profile, paper_length
from protocol.errors import InputError

SECOND = 1_000_000_000


def test_a_length_worked_by_hand():
    # Four samples 1 s apart. Forward acceleration 1, 1, -1, -1 m/s^2: the trapezoid increments
    # are 1, 0, -1 m/s, so the velocity (their cumulative sum, erratum 1) is 0, 1, 1, 0 m/s.
    # Yaw rate 0, 0, 0, 6 deg/s: increments 0, 0, 3 deg, A = 3 deg against A_real = 0, spread
    # evenly over the 3 increments: -1, -1, 2 deg, cumulative heading 0, -1, -2, 0 deg.
    # Lane-parallel distance L = cos 1 + cos 2 (trapezoid), k = 2 m / L (erratum 2), swum = 2 k.
    times = np.arange(4) * SECOND
    accel_g = np.array([1.0, 1.0, -1.0, -1.0]) / G
    yaw_dps = np.array([0.0, 0.0, 0.0, 6.0])
    estimate = paper_length(times, accel_g, yaw_dps, lane_length_m=2.0)
    lane = math.cos(math.radians(1)) + math.cos(math.radians(2))
    assert estimate.heading_error_deg == pytest.approx(3.0)
    assert estimate.scale == pytest.approx(2.0 / lane)
    assert estimate.swum_distance_m == pytest.approx(4.0 / lane)
    assert estimate.lane_distance_m == pytest.approx(2.0)
    # as printed, k = L / L_real: the integral of v (2 m) times lane / 2, shorter than the lane itself
    printed = 2.0 * (lane / 2.0)
    assert printed < 2.0 < estimate.swum_distance_m


def test_the_diagonal_route_is_measured_against_its_own_wall_heading():
    # 1000 Hz, 20 s: a push to 1.25 m/s, then straight; at 10 s a 1 s right turn of 35.75 deg.
    rate = 1000
    times = np.arange(20 * rate + 1) * (SECOND // rate)
    accel_g = np.zeros(len(times))
    accel_g[:500] = 2.5 / G  # 0.5 s at 2.5 m/s^2
    yaw = np.zeros(len(times))
    yaw[10 * rate:11 * rate] = -35.75
    yaw += 0.8  # a gyro bias: spread out by the wall-heading correction
    estimate = paper_length(times, accel_g, yaw, 25.0, end_heading_deg=-35.75)
    assert estimate.heading_error_deg == pytest.approx(0.8 * 20, rel=1e-3)
    # the legs are 12.34 m and 12.5 m of raw distance, the second turned by 35.75 deg (minus the
    # turn itself): lane L = 12.34 + 0.62 + 12.5 cos(35.75) ... scaled to 25 m, about 27.6 m swum
    raw = 1.25 * 0.25 + 1.25 * 19.5
    lane = 1.25 * 0.25 + 1.25 * 9.5 + sum(1.25 * math.cos(math.radians(35.75 * f)) / 1000 for f in np.arange(1000) / 1000) \
        + 1.25 * 9 * math.cos(math.radians(35.75))
    assert estimate.swum_distance_m == pytest.approx(25.0 * raw / lane, rel=2e-3)
    assert estimate.lateral_m.max() > 3.0  # the path bows left of the chord (start-to-end line)


def test_bad_lengths_are_refused_with_the_sample_named():
    with pytest.raises(InputError, match="at least 3 samples"):
        paper_length(np.array([0, 1]), np.zeros(2), np.zeros(2), 25.0)
    with pytest.raises(InputError, match="sample 2 at 1 ns is not after 5 ns"):
        paper_length(np.array([0, 5, 1]), np.zeros(3), np.zeros(3), 25.0)
    with pytest.raises(InputError, match="cannot scale"):
        paper_length(np.arange(5) * SECOND, np.zeros(5), np.zeros(5), 25.0)


def test_lateral_profile_is_the_offset_from_the_chord_every_metre():
    lane = np.linspace(0.0, 10.0, 101)
    cross = 0.5 * np.sin(np.pi * lane / 10.0)
    profile = lateral_profile(lane, cross, 1.0)
    assert len(profile) == 11
    assert profile[5] == pytest.approx(0.5, abs=1e-3)
    assert profile[0] == pytest.approx(0.0) and profile[-1] == pytest.approx(0.0, abs=1e-6)
