"""The live path's merger of a chair's three IMUs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from edge.chair.merger import ChairMerger
from protocol.messages import imu_batch
from protocol.session import Agent, Mount, Sensor
from support.chair_streams import AGENT, DT, pivoting, shifted, streams, yawing_streams


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


@pytest.mark.parametrize("yaw_dps", [300.0, -120.0])
def test_each_axle_imu_reads_the_chairs_yaw_times_cos_camber_with_its_sign(yaw_dps):
    seat, left, right = yawing_streams(100, yaw_dps)
    samples, _ = merge(sorted(seat + left + right, key=lambda s: s[1]))
    expected = yaw_dps * math.cos(math.radians(17.0)) * 0.005
    # (the first increment after the anchor starts before the right wheel's first sample)
    np.testing.assert_allclose([s.wheel_yaw_deg for s in samples[2:]], expected, rtol=1e-6)
    assert samples[50].yaw_rate_dps == pytest.approx(yaw_dps)  # the same sense as the seat's yaw


def test_a_silent_seat_is_bridged_by_wheel_samples_and_nothing_is_lost():
    seat, left, right = yawing_streams(200, 300.0)
    del seat[60:120]  # 0.3 s of seat packets lost
    samples, merger = merge(sorted(seat + left + right, key=lambda s: s[1]))
    bridges = [s for s in samples if math.isnan(s.yaw_rate_dps)]
    assert merger.counters.bridged == len(bridges) == 29  # every 10 ms across the 0.305 s silence
    assert all(math.isnan(s.accel_g[0]) and s.mag_gauss is None for s in bridges)
    steps = np.diff([s.time_ns for s in samples])
    assert steps.max() <= 15_000_000 and steps.min() > 0
    spanned = (samples[-1].time_ns - samples[1].time_ns) * 1e-9  # from where both wheels have reported
    assert sum(s.wheel_yaw_deg for s in samples[2:]) == pytest.approx(300.0 * math.cos(math.radians(17.0)) * spanned)
    assert sum(s.left_rotation_deg for s in samples[2:]) == pytest.approx(
        (200.0 + 300.0 * math.sin(math.radians(17.0))) * spanned)


def test_a_wheel_silent_inside_a_bridge_leaves_the_turn_to_the_other():
    # the chair stops turning for 0.2 s, just while the seat and the left wheel are both silent: the left
    # wheel's integral would draw a straight 300 deg/s line across its silence
    seat, left, right = yawing_streams(200, lambda i: 0.0 if 70 <= i < 110 else 300.0)
    del seat[60:120]
    del left[70:110]
    samples, _ = merge(sorted(seat + left + right, key=lambda s: s[1]))
    inside = [s for s in samples if 72 * DT <= s.time_ns <= 108 * DT]
    assert len(inside) >= 6 and all(math.isnan(s.yaw_rate_dps) for s in inside)
    assert all(abs(s.wheel_yaw_deg) < 1e-9 for s in inside)


def test_a_device_silent_altogether_gets_no_bridge_samples():
    seat, left, right = yawing_streams(200, 300.0)
    del seat[60:120], left[60:120], right[60:120]  # all three sensors silent for 0.3 s
    samples, merger = merge(sorted(seat + left + right, key=lambda s: s[1]))
    assert merger.counters.bridged == 0 and not any(math.isnan(s.yaw_rate_dps) for s in samples)
    assert max(np.diff([s.time_ns for s in samples])) > 0.29e9  # one step across the silence


@pytest.mark.parametrize("left_ns, right_ns", [(80_000_000, -40_000_000), (-120_000_000, 0)])
def test_each_wheel_clock_is_aligned_to_the_seat_by_the_yaw_both_see(left_ns, right_ns):
    seat, left, right = yawing_streams(8000, pivoting)  # 40 s
    # the helper stamps the same instant 1 ms later on the seat and 2 ms later on the right wheel
    left, right = shifted(left, left_ns), shifted(right, right_ns)
    samples, merger = merge(sorted(seat + left + right, key=lambda s: s[1]), max_wait_s=2.0)
    assert merger.clocks["left"].offset_ns == pytest.approx(left_ns - 1_000_000, abs=500_000)
    assert merger.clocks["right"].offset_ns == pytest.approx(right_ns + 1_000_000, abs=500_000)
    # aligned, each axle yaw step matches the seat's turn over the same instants
    late = samples[-2000:-10]
    seat_turn = np.array([0.5 * (a.yaw_rate_dps + b.yaw_rate_dps) * 0.005 for a, b in zip(late, late[1:])])
    wheel_turn = np.array([b.wheel_yaw_deg for b in late[1:]]) / math.cos(math.radians(17.0))
    assert np.abs(wheel_turn - seat_turn).max() < 0.01  # deg per 5 ms step (not aligned: 0.16)


def test_a_chair_that_never_turns_leaves_the_wheel_clocks_alone():
    seat, left, right = yawing_streams(4000, 0.0)
    samples, merger = merge(sorted(seat + shifted(left, 50_000_000) + right, key=lambda s: s[1]), max_wait_s=2.0)
    assert merger.clocks["left"].offset_ns == 0 and merger.clocks["left"].updates == 0
    assert len(samples) == 4000
