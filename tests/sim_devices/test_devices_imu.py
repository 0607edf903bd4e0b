"""The shared IMU error model, digitiser and device clock (sim_devices/devices/imu.py, clock.py)."""

from __future__ import annotations

import numpy as np

from sim_devices.devices.clock import DeviceClock, jittered_stamps_ns
from sim_devices.devices.imu import Imu, Triad, TriadErrors, adc_step, digitise, sense

QUIET = Triad(scale_error_sd=0.0, bias_sd=0.0, noise_sd=0.0, full_scale=16.0, step=adc_step(16.0, 16))


def test_digitise_clips_at_the_range_and_rounds_to_the_step_then_the_unit():
    step = 16.0 / 2 ** 15
    values = np.array([[0.3 * step, 0.7 * step, -20.0], [3.0 * step + 0.49 * step, 17.0, 1.2345678]])
    out = digitise(values, QUIET)
    assert out.tolist() == [[0.0, step, -16.0], [3.0 * step, 16.0, round(1.2345678 / step) * step]]
    in_units = digitise(values, Triad(0.0, 0.0, 0.0, 16.0, step, unit=1e-4))
    assert np.allclose(in_units, np.round(out / 1e-4) * 1e-4, rtol=0, atol=1e-12)


def test_an_error_free_triad_reports_the_signal_turned_by_the_mounting():
    rng = np.random.default_rng(1)
    signal = rng.normal(0.0, 1.0, (50, 3))
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 deg about z
    errors = TriadErrors.draw(QUIET, rng)
    assert errors.response.tolist() == [1.0, 1.0, 1.0] and errors.bias.tolist() == [0.0, 0.0, 0.0]
    assert np.array_equal(sense(signal, QUIET, errors, rng, turn), signal @ turn.T)


def test_cross_axis_gives_a_sensitivity_matrix_and_the_walk_is_drawn_before_the_noise():
    triad = Triad(0.01, 0.0, 0.0, 16.0, 1e-6, walk_sd=0.1, cross_axis_sd=0.01)
    rng = np.random.default_rng(2)
    errors = TriadErrors.draw(triad, rng)
    assert errors.response.shape == (3, 3) and np.all(np.abs(np.diag(errors.response) - 1.0) < 0.05)
    drift = sense(np.zeros((1000, 3)), triad, errors, rng)
    replay = np.random.default_rng(2)
    TriadErrors.draw(triad, replay)  # the same draws again: cross-axis terms, scales, bias
    assert np.array_equal(drift, np.cumsum(replay.normal(0.0, 0.1, (1000, 3)), axis=0))


def test_triads_draw_and_sense_in_the_order_given():
    """The same triads listed in another order give other draws: the order is part of a venue's streams."""
    noisy = Triad(0.01, 0.1, 0.5, 16.0, 1e-6)
    signals = {"a": np.zeros((20, 3)), "b": np.zeros((20, 3))}
    first = Imu.draw({"a": noisy, "b": noisy}, np.random.default_rng(3))
    second = Imu.draw({"b": noisy, "a": noisy}, np.random.default_rng(3))
    assert np.array_equal(first.errors["a"].bias, second.errors["b"].bias)
    one = first.measure(signals, np.random.default_rng(4))
    other = second.measure(signals, np.random.default_rng(4))
    assert np.array_equal(one["a"] - first.errors["a"].bias, other["b"] - second.errors["b"].bias)


def test_device_clock_offset_drift_and_jitter_keep_samples_in_order():
    rng = np.random.default_rng(5)
    clock = DeviceClock.draw(rng, start_unix_s=1_704_067_200, offset_ms=10.0, drift_ppm=20.0, jitter_ms=2.0)
    true_s = np.arange(0, 100.0, 0.005)  # 200 Hz: jitter 2 ms would swap samples without the clip
    stamps = clock.stamp_ns(true_s, rng, period_s=0.005)
    assert np.all(np.diff(stamps) > 0)
    plain = clock.stamp_ns(true_s)
    assert np.max(np.abs(stamps - plain)) <= 0.45 * 0.005 * 1e9 + 1
    expected = clock.epoch_ns + np.round(((1.0 + clock.drift) * true_s + clock.offset_s) * 1e9).astype(np.int64)
    assert np.array_equal(plain, expected)
    assert np.array_equal(DeviceClock(clock.epoch_ns).stamp_ns(true_s),
                          clock.epoch_ns + np.round(true_s * 1e9).astype(np.int64))  # an ideal clock: true time


def test_jittered_stamps_are_strictly_increasing():
    true_ns = np.arange(0, 1_000_000_000, 20_000_000, dtype=np.int64)  # 50 Hz
    stamps = jittered_stamps_ns(true_ns, 15.0, np.random.default_rng(6))  # jitter near the period: ties
    assert np.all(np.diff(stamps) >= 1) and stamps.dtype == np.int64
