"""The live path's merger of a chair's three IMUs."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from edge.chair.merger import ChairMerger
from protocol.messages import imu_batch
from protocol.session import Agent, Mount, Sensor

AGENT = Agent("chair01", sensors=(Sensor("left", Mount.LEFT_WHEEL, spin_axis="+z"),
                                  Sensor("right", Mount.RIGHT_WHEEL, spin_axis="-y"),
                                  Sensor("seat", Mount.SEAT, forward_axis="-x", left_axis="+y")))
DT = 5_000_000


def streams(n: int = 200):
    """Left wheel 90 deg/s on +z, right 180 deg/s on -y, seat yawing 10 deg/s, mounted backwards."""
    seat = [("seat", i * DT + 1_000_000, (0.0, 0.0, -1.0), (0.0, 0.0, -10.0), (0.2, 0.0, 0.3)) for i in range(n)]
    left = [("left", i * DT, (0.0, 0.0, 0.0), (0.0, 0.0, 90.0), None) for i in range(n + 2)]
    right = [("right", i * DT + 2_000_000, (0.0, 0.0, 0.0), (0.0, -180.0, 0.0), None) for i in range(n + 2)]
    return seat, left, right


def merge(order, max_wait_s=100.0):
    merger = ChairMerger(AGENT, max_wait_s=max_wait_s)
    out = []
    for sensor, t, accel, gyro, mag in order:
        out += merger.push(sensor, t, accel, gyro, mag)
    return out + merger.flush(), merger


def test_axes_and_increments():
    seat, left, right = streams()
    samples, merger = merge(sorted(seat + left + right, key=lambda s: s[1]))
    assert len(samples) == len(seat) and merger.counters.extrapolated == 0
    later = samples[10]
    assert later.yaw_rate_dps == pytest.approx(-10.0 * -1.0)  # up = forward x left = (-x) x (+y) = -z
    assert later.accel_g == pytest.approx((0.0, 0.0, 1.0))
    assert later.mag_gauss == pytest.approx((-0.2, 0.0, -0.3))
    assert later.left_rotation_deg == pytest.approx(90.0 * 0.005)
    assert later.right_rotation_deg == pytest.approx(180.0 * 0.005)
    assert samples[0].left_rotation_deg == 0.0  # the first sample only anchors


@settings(max_examples=40, deadline=None)
@given(st.randoms(use_true_random=False))
def test_any_interleaving_gives_the_same_samples(random):
    seat, left, right = streams(60)
    reference, _ = merge(sorted(seat + left + right, key=lambda s: s[1]))
    queues = [list(seat), list(left), list(right)]
    order = []
    while any(queues):  # each sensor keeps its own order; the sensors interleave at random
        q = random.choice([q for q in queues if q])
        order.append(q.pop(0))
    samples, _ = merge(order)
    assert [s.time_ns for s in samples] == [s.time_ns for s in reference]
    np.testing.assert_allclose([s.left_rotation_deg for s in samples], [s.left_rotation_deg for s in reference], atol=1e-9)
    np.testing.assert_allclose([s.right_rotation_deg for s in samples], [s.right_rotation_deg for s in reference], atol=1e-9)


def test_batches_equal_single_samples():
    seat, left, right = streams(40)
    by_sample, _ = merge(sorted(seat + left + right, key=lambda s: s[1]))
    merger = ChairMerger(AGENT, max_wait_s=100.0)
    out = []
    for stream in (left, right, seat):
        sensor = stream[0][0]
        times = np.array([s[1] for s in stream], dtype=np.int64)
        batch = imu_batch("chair01", sensor, 0, times, np.array([s[2] for s in stream]), np.array([s[3] for s in stream]),
                          None if stream[0][4] is None else np.array([s[4] for s in stream]))
        out += merger.push_batch(batch)
    out += merger.flush()
    assert [s.time_ns for s in out] == [s.time_ns for s in by_sample]
    np.testing.assert_allclose([s.right_rotation_deg for s in out], [s.right_rotation_deg for s in by_sample], rtol=1e-6)


def test_a_silent_wheel_is_extrapolated_after_the_wait_and_memory_stays_bounded():
    seat, left, right = streams(400)
    order = sorted(seat + left[:100] + right, key=lambda s: s[1])  # the left wheel stops after 0.5 s
    merger = ChairMerger(AGENT, max_wait_s=0.2)
    longest = 0
    samples = []
    for sensor, t, accel, gyro, mag in order:
        samples += merger.push(sensor, t, accel, gyro, mag)
        longest = max(longest, len(merger.pending))
    assert merger.counters.extrapolated > 250
    assert longest <= 0.2 / 0.005 + 2  # pending never holds more than the wait
    assert samples[-1].left_rotation_deg == pytest.approx(90.0 * 0.005)  # held at the last rate


def test_out_of_order_samples_are_dropped_and_counted():
    seat, left, right = streams(20)
    order = sorted(seat + left + right, key=lambda s: s[1])
    order.insert(30, seat[2])  # a repeated old seat sample
    samples, merger = merge(order)
    assert merger.counters.seat_out_of_order == 1 and len(samples) == len(seat)


def test_missing_sensor_is_refused():
    with pytest.raises(ValueError, match="needs seat, left_wheel and right_wheel"):
        ChairMerger(Agent("chair02", sensors=(Sensor("seat", Mount.SEAT),)))


def test_a_seat_far_behind_the_wheels_is_counted():
    seat, left, right = streams(1500)
    merger = ChairMerger(AGENT, max_wait_s=100.0)
    for item in left + right:  # the wheels race 7.5 s ahead before the seat says anything
        merger.push(*item)
    for item in seat:
        merger.push(*item)
    merger.flush()
    assert merger.counters.wheel_overrun > 0
