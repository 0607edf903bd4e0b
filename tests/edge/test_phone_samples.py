"""The phone's pure core (edge/decoders/phone/parse.py, phone_samples.py, phone_rotation.py): parsing, unit checks, alignment, batching,
and every kind of bad input counted without losing what came before."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from edge.decoders.phone.parse import PhoneInputError, parse_browser, parse_sensor_logger
from edge.decoders.phone.rotation import RotationUnitCheck, _orientation_quaternion
from edge.decoders.phone.samples import STANDARD_GRAVITY_MS2, Aligner, Counters, MotionBatcher, PhoneSettings

T0_NS = 1_764_000_000_000_000_000  # an epoch time in 2025
STEP_NS = 10_000_000  # 100 Hz


def sample(i: int, accel=(0.1, 0.2, 9.7), gyro=(1.0, 2.0, 3.0), mag=None):
    return (T0_NS + i * STEP_NS, accel, gyro, mag)


def drain(batcher: MotionBatcher, samples) -> tuple[list, list[str]]:
    batches, problems = batcher.feed(samples)
    more, more_problems = batcher.flush()
    return batches + more, problems + more_problems


def values(batches, field: str) -> np.ndarray:
    return np.concatenate([np.reshape(getattr(b, field), (-1, 3)) for b in batches])


def times(batches) -> list[int]:
    return [b.timestamp_ns + offset for b in batches for offset in b.sample_offset_ns]


def test_browser_motion_maps_w3c_rotation_to_phone_axes():
    text = json.dumps({"type": "motion", "samples": [[1764000000000.25, 0.5, -0.5, 9.8, 30.0, 10.0, 20.0, 10]]})
    kind, rows = parse_browser(text)
    assert kind == "motion"
    assert rows == [(1764000000000250000, (0.5, -0.5, 9.8), (10.0, 20.0, 30.0), None)]  # x=beta, y=gamma, z=alpha


def test_batches_are_in_g_deg_s_gauss_with_sequences_and_offsets():
    batcher = MotionBatcher("walker", "phone", PhoneSettings(samples_per_batch=10))
    batches, problems = drain(batcher, [sample(i, mag=(20.0, -5.0, 40.0)) for i in range(25)])
    assert problems == []
    assert [b.sequence for b in batches] == [0, 1, 2]
    assert times(batches) == [T0_NS + i * STEP_NS for i in range(25)]
    np.testing.assert_allclose(values(batches, "accel_g")[0], np.array([0.1, 0.2, 9.7]) / STANDARD_GRAVITY_MS2, rtol=1e-6)
    np.testing.assert_allclose(values(batches, "gyro_dps")[0], [1.0, 2.0, 3.0])
    np.testing.assert_allclose(values(batches, "mag_gauss")[0], [0.2, -0.05, 0.4], rtol=1e-6)
    assert batches[0].agent_id == "walker" and batches[0].sensor_id == "phone"
    assert batcher.counters.samples_out == 25 and batcher.counters.batches == 3


def test_nan_backwards_and_gap_are_counted_and_the_rest_kept():
    samples = [sample(i) for i in range(30)]
    samples[3] = sample(3, accel=(math.nan, 0.0, 9.8))
    samples[7] = sample(2)  # repeats an earlier time: the clock went back
    samples[20:] = [(t + 2_000_000_000, a, g, m) for t, a, g, m in samples[20:]]  # a 2 s pause
    batcher = MotionBatcher("walker", "phone")
    batches, problems = drain(batcher, samples)
    counters = batcher.counters
    assert (counters.non_finite, counters.backwards, counters.gaps) == (1, 1, 1)
    assert counters.samples_out == 28 and len(times(batches)) == 28
    assert times(batches) == sorted(times(batches))
    assert any("gap of 2010 ms" in p for p in problems)
    assert any("NaN" in p for p in problems) and any("not after the previous one" in p for p in problems)
    # the gap closes the batch: no batch spans it
    assert all(b.sample_offset_ns[-1] < 250_000_000 for b in batches)


def test_acceleration_in_g_is_converted_with_a_problem_said_once():
    batcher = MotionBatcher("walker", "phone")
    batches, problems = drain(batcher, [sample(i, accel=(0.0, 0.0, 1.0)) for i in range(60)])
    assert batcher.counters.converted_g == 60
    assert len([p for p in problems if "looks like g" in p]) == 1
    np.testing.assert_allclose(values(batches, "accel_g")[:, 2], 1.0, rtol=1e-6)


def test_acceleration_without_gravity_is_refused_then_taken_when_it_recovers():
    batcher = MotionBatcher("walker", "phone", PhoneSettings(unit_window=10))
    linear = [sample(i, accel=(0.01, 0.02, 0.03)) for i in range(10)]
    good = [sample(i) for i in range(10, 30)]
    batches, problems = drain(batcher, linear + good)
    assert batcher.counters.refused_units == 10
    assert any("neither gravity in m/s^2" in p for p in problems)
    assert times(batches) == [T0_NS + i * STEP_NS for i in range(10, 30)]


@pytest.mark.parametrize("text, reason", [
    ("not json", "not JSON"),
    ("[1, 2]", "expected a JSON object"),
    ('{"type": "motion", "samples": 5}', "must be a list of samples"),
    ('{"type": "motion", "samples": [[1, 2, 3]]}', "sample 0 must be a list of 8 values"),
    ('{"type": "scan", "t": 5, "text": ""}', "1-1000 characters"),
    ('{"type": "dance"}', "unknown message type 'dance'"),
])
def test_bad_browser_messages_are_refused_with_a_reason(text, reason):
    with pytest.raises(PhoneInputError, match=reason):
        parse_browser(text)


def test_null_values_become_non_finite_samples():
    _, rows = parse_browser(json.dumps({"type": "motion", "samples": [[1.0, None, 0, 9.8, 0, 0, 0, 10]]}))
    batcher = MotionBatcher("walker", "phone")
    assert drain(batcher, rows)[0] == [] and batcher.counters.non_finite == 1


def logger_push(accel, gyro, mag=(), other=0) -> str:
    payload = [{"name": "accelerometer", "time": t, "values": dict(zip("xyz", v))} for t, v in accel]
    payload += [{"name": "gyroscope", "time": t, "values": dict(zip("xyz", v))} for t, v in gyro]
    payload += [{"name": "magnetometer", "time": t, "values": dict(zip("xyz", v))} for t, v in mag]
    payload += [{"name": "battery", "time": 0, "values": {"batteryLevel": 0.5}}] * other
    return json.dumps({"messageId": 1, "sessionId": "s", "deviceId": "d", "payload": payload})


def test_sensor_logger_streams_are_aligned_across_pushes():
    counters = Counters()
    aligner = Aligner(PhoneSettings(), counters)
    accel = [(T0_NS + i * STEP_NS, (0.0, 0.0, 9.81)) for i in range(40)]
    gyro = [(T0_NS + i * STEP_NS + 5_000_000, (0.0, 0.0, 0.1 * i)) for i in range(-1, 40)]  # rad/s, halfway between
    mag = [(T0_NS + i * 50_000_000, (30.0, 0.0, -20.0)) for i in range(8)]
    problems: list[str] = []
    first, ignored = parse_sensor_logger(logger_push(accel[:20], gyro[:20], mag[:4], other=3))
    second, _ = parse_sensor_logger(logger_push(accel[20:], gyro[20:], mag[4:]))
    assert ignored == 3
    samples = aligner.feed(first, problems) + aligner.feed(second, problems)
    assert problems == [] and counters.without_gyro == 0
    assert [s[0] for s in samples] == [t for t, _ in accel]
    # halfway between gyro readings 0.1*(i-1) and 0.1*i rad/s -> 0.1*(i-0.5) rad/s, in deg/s
    np.testing.assert_allclose([s[2][2] for s in samples], [math.degrees(0.1 * (i - 0.5)) for i in range(40)])
    assert all(s[3] == (30.0, 0.0, -20.0) for s in samples)
    # an accelerometer reading after the last gyroscope reading waits for the next push
    later, _ = parse_sensor_logger(logger_push([(T0_NS + 40 * STEP_NS, (0.0, 0.0, 9.81))], []))
    assert aligner.feed(later, problems) == [] and len(aligner.pending) == 1


def test_sensor_logger_prefers_total_acceleration_and_refuses_bad_bodies():
    body = json.dumps({"payload": [{"name": "accelerometer", "time": 1, "values": {"x": 0, "y": 0, "z": 0}},
                                   {"name": "totalacceleration", "time": 1, "values": {"x": 0, "y": 0, "z": 9.8}}]})
    streams, ignored = parse_sensor_logger(body)
    assert streams["accel"] == [(1, (0.0, 0.0, 9.8))] and ignored == 1
    for bad, reason in (("{}", "payload"), ('{"payload": [{"name": "gyroscope"}]}', "needs \"time\""),
                        ("\x00", "not JSON")):
        with pytest.raises(PhoneInputError, match=reason):
            parse_sensor_logger(bad)


def test_accelerometer_without_gyroscope_is_bounded_and_counted():
    counters = Counters()
    aligner = Aligner(PhoneSettings(max_pending=50), counters)
    problems: list[str] = []
    streams, _ = parse_sensor_logger(logger_push([(T0_NS + i, (0.0, 0.0, 9.8)) for i in range(80)], []))
    assert aligner.feed(streams, problems) == []
    assert counters.without_gyro == 30 and len(aligner.pending) == 50
    assert "turn the gyroscope on" in problems[-1]


def test_memory_stays_bounded():
    batcher = MotionBatcher("walker", "phone")
    for block in range(200):
        batcher.feed([sample(block * 100 + i) for i in range(100)])
        assert len(batcher._batch) < batcher.settings.samples_per_batch
        assert len(batcher._window) < batcher.settings.unit_window
    assert batcher.counters.samples_out + len(batcher._batch) + len(batcher._window) == 20_000


def turning(rate_dps: float, seconds: float, reported_scale: float):
    """A phone turning about its z axis at `rate_dps`: orientation rows (as the page sends them) and
    motion samples whose rotation rate is reported as rate_dps * reported_scale."""
    count = int(seconds * 100)
    rows = [[T0_NS / 1e6 + i * 10.0, (rate_dps * i * 0.01) % 360.0, 10.0, 5.0, 0] for i in range(count)]
    samples = [sample(i, gyro=(0.0, 0.0, rate_dps * reported_scale)) for i in range(count)]
    return rows, samples


@pytest.mark.parametrize("reported_scale, expected", [(1.0, 1.0), (math.radians(1.0), math.degrees(1.0))])
def test_rotation_rate_in_rad_s_is_told_from_orientation(reported_scale, expected):
    check = RotationUnitCheck()
    rows, samples = turning(90.0, 3.0, reported_scale)
    problems: list[str] = []
    check.motion(samples)
    check.orientation(rows, problems)
    assert check.decided and check.scale == pytest.approx(expected)
    assert (problems != []) == (expected != 1.0)
    if problems:
        assert "looks like rad/s" in problems[0]


def test_orientation_quaternion_turns_by_the_angle_between():
    q1, q2 = _orientation_quaternion(10.0, 20.0, 30.0), _orientation_quaternion(10.0, 20.0, 31.0)
    assert math.degrees(2 * math.acos(min(1.0, abs(sum(a * b for a, b in zip(q1, q2)))))) == pytest.approx(1.0, abs=1e-6)
    assert sum(v * v for v in q1) == pytest.approx(1.0)


def test_the_core_imports_no_io():
    import subprocess
    import sys

    code = "import json, sys, edge.decoders.phone.samples, edge.decoders.phone.rotation; print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))"
    loaded = set(json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                           check=True).stdout))
    assert not loaded & {"aiohttp", "asyncio", "socket", "ssl", "zenoh"}, sorted(loaded)
