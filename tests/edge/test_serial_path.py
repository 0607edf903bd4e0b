"""The serial device path end to end: SerialDevice (a real pty) -> pyserial -> SerialSource ->
Ximu3Decoder -> ImuBatcher, compared sample by sample with what was sent. Every wait is bounded
and waits on data or on the device's done signal, never on a sleep."""

from __future__ import annotations

import logging
import time

import numpy as np
import pytest

from edge.decoders import ImuBatcher, InertialFrame, Ximu3Decoder
from edge.sources import DeviceDisconnected, DeviceUnavailable, SerialSource, parse_serial_url
from protocol.errors import ConfigError, ReckonError
from protocol.session import session_from_dict
from protocol.messages import imu_batch
from protocol.session_log import SessionWriter, read_session
from sim_devices.devices.pty import Faults
from sim_devices.devices.ximu3 import SerialDevice

RATE_HZ = 200
DEADLINE_S = 10.0  # upper bound of any wait; a passing run takes a fraction of a second


def samples(seconds=2.0, seed=0, start_ns=7_000_000_123):
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE_HZ)
    time_ns = start_ns + np.arange(n, dtype=np.int64) * (1_000_000_000 // RATE_HZ)
    gyro = rng.uniform(-800, 800, (n, 3))
    accel = rng.uniform(-8, 8, (n, 3))
    mag = rng.uniform(-0.6, 0.6, (n, 3))  # gauss
    return time_ns, gyro, accel, mag


def receive(device, source, expected_inertial):
    """Play `device` into `source`; read until `expected_inertial` inertial frames have come and
    every byte the device wrote was read, or the deadline passes."""
    frames = []
    deadline = time.monotonic() + DEADLINE_S
    device.play()
    while time.monotonic() < deadline:
        frames += source.read_frames()
        inertial = sum(isinstance(f, InertialFrame) for f in frames)
        if inertial >= expected_inertial and device.wait_done(0) and source.bytes_read >= device.bytes_total:
            break
    assert device.wait_done(timeout_s=1.0)
    return frames


def expected_samples(device, ascii, max_mag_age_ns=500_000_000):
    """What should arrive: every undamaged inertial message, paired with the latest undamaged
    magnetometer message (the device sends M before the I of the same sample)."""
    rows, mag = [], None
    for index, (stamp, message) in enumerate(device.messages):
        if index in device.damaged:
            continue
        frame = Ximu3Decoder().feed(message)[0]
        if isinstance(frame, InertialFrame):
            paired = mag if mag is not None and abs(mag[0] - frame.timestamp_us) * 1000 <= max_mag_age_ns else None
            rows.append((stamp, frame.gyro_dps, frame.accel_g, None if paired is None else paired[1]))
        else:
            mag = (frame.timestamp_us, frame.mag_au)
    return rows


def flatten(batches):
    times, gyro, accel, mag = [], [], [], []
    for batch in batches:
        times += [batch.timestamp_ns + offset for offset in batch.sample_offset_ns]
        gyro += np.reshape(batch.gyro_dps, (-1, 3)).tolist()
        accel += np.reshape(batch.accel_g, (-1, 3)).tolist()
        count = len(batch.sample_offset_ns)
        mag += np.reshape(batch.mag_gauss, (-1, 3)).tolist() if len(batch.mag_gauss) else [None] * count
    return np.array(times), np.array(gyro), np.array(accel), mag


@pytest.mark.parametrize("ascii, faults", [
    (False, Faults(seed=1, garbage_every=7, drop_every=53, corrupt_every=61)),
    (True, Faults(seed=2, garbage_every=5, corrupt_every=41)),  # ASCII: a dropped digit still parses
], ids=["binary", "ascii"])
def test_samples_arrive_through_a_real_pty_as_sent(ascii, faults):
    time_ns, gyro, accel, mag = samples()
    recorded = []
    with SerialDevice.from_arrays(time_ns, gyro, accel, mag, ascii=ascii, speed=20.0, faults=faults) as device:
        assert device.port.startswith("/dev/")
        expected = expected_samples(device, ascii)
        assert len(device.damaged) > 5 and len(expected) < len(time_ns)  # the faults did damage messages
        with SerialSource(f"serial://{device.port}?baud=115200", Ximu3Decoder(), record_raw=recorded.append) as source:
            frames = receive(device, source, len(expected))
    batcher = ImuBatcher("chair01", "chair01-seat")
    batches = batcher.feed(frames) + batcher.flush()
    assert all(len(b.sample_offset_ns) == 20 for b in batches[:-1])
    got_times, got_gyro, got_accel, got_mag = flatten(batches)

    want_times = np.array([row[0] for row in expected])
    assert len(got_times) == len(want_times)
    assert np.all(np.abs(got_times - want_times) <= 500)  # whole microseconds on the wire
    assert np.array_equal(got_gyro, np.array([row[1] for row in expected]))  # f32 on the wire and in ImuBatch
    assert np.array_equal(got_accel, np.array([row[2] for row in expected]))
    want_mag = [None if row[3] is None else np.array(row[3]) * 0.5 for row in expected]  # a.u. -> gauss
    for got_row, want_row in zip(got_mag, want_mag):
        assert (got_row is None) == (want_row is None)
        if want_row is not None:
            np.testing.assert_allclose(got_row, want_row, rtol=1e-6)
    # and against the original float64 samples, within f32 (binary) or four decimals (ASCII)
    kept = np.searchsorted(time_ns, want_times)
    tolerance = dict(atol=5.1e-5) if ascii else dict(rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(got_gyro, gyro[kept], **tolerance)
    np.testing.assert_allclose(got_accel, accel[kept], **tolerance)
    # nothing the device wrote was lost before decoding, garbage included
    assert b"".join(recorded) == device.stream_bytes()
    counters = source.decoder.counters
    assert counters.rejected_frames > 0 and counters.pending_bytes == 0


def test_session_log_sensor_plays_back(tmp_path):
    session = session_from_dict({"venue": {"name": "court"}, "agents": [{"id": "chair01", "sensors": [
        {"id": "chair01-seat", "mount": "seat"}]}]})
    time_ns, gyro, accel, mag = samples(seconds=1.0, seed=4)
    path = tmp_path / "session.mcap"
    with SessionWriter(path, session) as writer:
        for sequence, start in enumerate(range(0, len(time_ns), 20)):
            window = slice(start, start + 20)
            writer.write("reckon/court/chair01/imu/chair01-seat",
                         imu_batch("chair01", "chair01-seat", sequence, time_ns[window], accel[window], gyro[window],
                                   mag[window]))
    series = read_session(path).imu["chair01-seat"]
    with SerialDevice.from_session(path, "chair01-seat", speed=0) as device:  # as fast as the reader takes it
        with SerialSource(f"serial://{device.port}", Ximu3Decoder()) as source:
            frames = receive(device, source, len(time_ns))
    batcher = ImuBatcher("chair01", "chair01-seat")
    got_times, got_gyro, got_accel, got_mag = flatten(batcher.feed(frames) + batcher.flush())
    assert np.all(np.abs(got_times - series.time_ns) <= 500)
    np.testing.assert_allclose(got_gyro, series.gyro_dps, rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(got_accel, series.accel_g, rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(np.array(got_mag), series.mag_gauss, rtol=1e-6, atol=1e-7)
    with pytest.raises(ReckonError, match="no IMU 'chair09-seat'"):
        SerialDevice.from_session(path, "chair09-seat")


def test_device_that_disappears_raises_device_disconnected():
    time_ns, gyro, accel, mag = samples(seconds=60.0)
    with SerialDevice.from_arrays(time_ns, gyro, accel, mag, speed=1.0) as device:  # a minute, real time
        with SerialSource(f"serial://{device.port}?read_timeout_s=0.02", Ximu3Decoder()) as source:
            device.play()
            deadline = time.monotonic() + DEADLINE_S
            while not source.frames_read and time.monotonic() < deadline:
                source.read_frames()
            assert source.frames_read
            device.close()  # unplugged
            with pytest.raises(DeviceDisconnected, match=r"device disconnected after \d+ bytes") as lost:
                while time.monotonic() < deadline:
                    source.read_frames()
            assert isinstance(lost.value, ReckonError) and isinstance(lost.value.frames, list)


def test_port_that_cannot_be_opened_raises_device_unavailable():
    with pytest.raises(DeviceUnavailable, match="/dev/no-such-tty"):
        SerialSource("serial:///dev/no-such-tty?baud=9600", Ximu3Decoder()).open()


def test_rejected_frames_are_summarised_at_a_limited_rate(caplog):
    time_ns, gyro, accel, mag = samples(seconds=1.0)
    now = [0.0]
    with SerialDevice.from_arrays(time_ns, gyro, accel, mag, speed=0, faults=Faults(garbage_every=1)) as device:
        source = SerialSource(f"serial://{device.port}", Ximu3Decoder(), warn_every_s=5.0, clock=lambda: now[0])
        with caplog.at_level(logging.WARNING, logger="edge.sources.serial"):
            with source:
                receive(device, source, len(time_ns))
                counters = source.decoder.counters
                assert counters.rejected_frames > 200 and counters.inertial_frames == len(time_ns)
                assert caplog.records == []  # hundreds rejected, but the clock has not moved on
                now[0] = 6.0
                source.read_frames()  # the first read after the period logs one summary
                assert len(caplog.records) == 1
            assert len(caplog.records) == 1  # close() had nothing new to report
    message = caplog.records[0].getMessage()
    assert f"serial://{device.port}: " in message and "rejected frames in the last 6.0 s" in message


@pytest.mark.parametrize("url, expected", [
    ("serial:///dev/ttyUSB0", ("/dev/ttyUSB0", 115_200, 0.05)),
    ("serial:///dev/ttyACM1?baud=921600", ("/dev/ttyACM1", 921_600, 0.05)),
    ("serial://COM3?baud=9600&read_timeout_s=0.2", ("COM3", 9_600, 0.2)),
])
def test_serial_urls_parse(url, expected):
    assert parse_serial_url(url) == expected


@pytest.mark.parametrize("url, message", [
    ("ble://AA:BB", "expected a serial:// URL"),
    ("serial://", "no port"),
    ("serial:///dev/ttyUSB0?bauds=9600", "unknown key 'bauds'"),
    ("serial:///dev/ttyUSB0?baud=fast", "baud='fast' is not a number"),
    ("serial:///dev/ttyUSB0?baud=0", r"baud=0 is outside \[50, 20000000\]"),
])
def test_bad_serial_urls_name_the_problem(url, message):
    with pytest.raises(ConfigError, match=message):
        parse_serial_url(url)
