"""The TSND serial path end to end: TsndDevice (a real pty, commanded) <- SerialSource.from_url
commands it -> pyserial -> TsndDecoder -> ImuBatcher, compared with what the device sent. Every
wait is bounded and waits on data or on the device's signals, never on a sleep."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from edge.decoders import ImuBatcher, InertialFrame, Rejected
from edge.decoders import tsnd
from edge.decoders.tsnd import TsndDecoder, TsndMessage
from edge.sources import SerialSource
from edge.sources.serial import parse_serial_protocol
from protocol.errors import ConfigError, InputError
from protocol.messages import imu_batch
from protocol.session import session_from_dict
from protocol.session_log import SessionWriter
from edge.sources.serial import SerialSources
from sim_devices.devices.pty import Faults
from sim_devices.devices.tsnd import TsndDevice

DEADLINE_S = 10.0  # upper bound of any wait; a passing run takes about a second
SETUP_CODES = [0x15, 0x16, 0x22, 0x25, 0x13]  # stop, acc+gyro period, ranges, start


def samples(seconds=1.0, rate_hz=1000, seed=0, start_ns=45_000_000_000_000):  # 12:30 device time
    rng = np.random.default_rng(seed)
    n = int(seconds * rate_hz)
    time_ns = start_ns + np.arange(n, dtype=np.int64) * (1_000_000_000 // rate_hz)
    return time_ns, rng.uniform(-3, 3, (n, 3)), rng.uniform(-900, 900, (n, 3)), rng.uniform(-0.6, 0.6, (n, 3))


def read_until(source, done, deadline_s=DEADLINE_S):
    """Read frames until `done(frames)` or the deadline."""
    frames = []
    deadline = time.monotonic() + deadline_s
    while time.monotonic() < deadline and not done(frames):
        frames += source.read_frames()
    return frames


def inertial(frames):
    return [f for f in frames if isinstance(f, InertialFrame)]


def stopped(frames):
    return any(isinstance(f, TsndMessage) and f.code == tsnd.STOPPED for f in frames)


@pytest.mark.parametrize("faults", [Faults(), Faults(seed=3, garbage_every=7, drop_every=53, corrupt_every=61)],
                         ids=["clean", "faults"])
def test_source_commands_the_device_and_1000_hz_samples_arrive(faults):
    time_ns, accel, gyro, _ = samples()
    recorded = []
    with TsndDevice(time_ns, accel, gyro, speed=1.0, faults=faults) as device:
        url = f"serial://{device.port}?protocol=tsnd&rate_hz=1000"
        with SerialSource.from_url(url, record_raw=recorded.append) as source:
            frames = read_until(source, stopped)  # the device stops by itself at the end of its samples
            assert device.finished.is_set() and device.error is None
        counters = source.decoder.counters
    assert device.commands[:5] == SETUP_CODES and device.period_ms == 1
    assert counters.messages_by_code == {"0x8F": 4, "0x93": 1, "0x88": 1, "0x89": 1}  # 4 acks, started, stopped
    expected = device.expected_indices()
    assert list(device.streamed) == list(range(len(time_ns)))  # period 1 ms: every sample
    got = inertial(frames)
    assert [f.timestamp_us for f in got] == (time_ns[expected] // 1000).tolist()
    np.testing.assert_allclose([f.accel_g for f in got], accel[expected], atol=0.5e-4 + 1e-12)
    np.testing.assert_allclose([f.gyro_dps for f in got], gyro[expected], atol=0.5e-2 + 1e-9)
    assert b"".join(recorded) == b"".join(f.raw for f in frames)  # nothing the device sent was lost
    if faults.garbage_every:
        assert len(device.damaged) == 34 and len(got) == len(time_ns) - 34
        # every garbage insertion and damaged frame is rejected (a run may hold garbage and the frame after it)
        assert counters.rejected_frames >= len(time_ns) // 7 and counters.rejected_by_reason["bad_checksum"] > 20
        assert counters.rejected_frames == sum(isinstance(f, Rejected) for f in frames)
    else:
        assert counters.rejected_frames == 0


def test_stop_command_stops_the_stream_and_start_resumes_it():
    time_ns, accel, gyro, _ = samples(seconds=60.0)  # a minute in real time: only the commands end it
    with TsndDevice(time_ns, accel, gyro, speed=1.0) as device:
        with SerialSource.from_url(f"serial://{device.port}?protocol=tsnd&rate_hz=500&read_timeout_s=0.02") as source:
            before = read_until(source, lambda frames: len(inertial(frames)) >= 100)
            source.write(tsnd.stop_measurement())
            before += read_until(source, stopped)
            assert stopped(before) and not device.measuring
            after_stop = read_until(source, lambda frames: False, deadline_s=0.3)  # 150 samples' worth of silence
            assert after_stop == []
            last = inertial(before)[-1]
            source.write(tsnd.start_measurement())
            resumed = read_until(source, lambda frames: len(inertial(frames)) >= 10)
        assert device.idle.wait(DEADLINE_S) and device.commands[-1] == 0x15  # the source's teardown stopped it
    timestamps = [f.timestamp_us for f in inertial(before)]
    assert np.all(np.diff(timestamps) == 2000)  # rate_hz=500: every other 1000 Hz sample
    assert inertial(resumed)[0].timestamp_us == last.timestamp_us + 2000  # carries on where it stopped
    assert [f.code for f in resumed if isinstance(f, TsndMessage)][:2] == [0x93, tsnd.STARTED]


def test_session_log_sensor_plays_back_with_magnetometer(tmp_path):
    session = session_from_dict({"venue": {"name": "pool", "court_length_m": 25.0}, "agents": [
        {"id": "swimmer", "kind": "swimmer", "sensors": [{"id": "swimmer-waist", "mount": "waist",
                                                          "rate_hz": 1000.0}]}]})
    time_ns, accel, gyro, mag = samples(seconds=0.5, seed=4)
    path = tmp_path / "swim.mcap"
    with SessionWriter(path, session) as writer:
        for sequence, start in enumerate(range(0, len(time_ns), 20)):
            window = slice(start, start + 20)
            writer.write("reckon/pool/swimmer/imu/swimmer-waist", imu_batch(
                "swimmer", "swimmer-waist", sequence, time_ns[window], accel[window], gyro[window], mag[window]))
    with TsndDevice.from_session(path, "swimmer-waist", speed=0) as device:
        setup = tsnd.acc_gyro_settings(1) + tsnd.magnetometer_settings(10) + tsnd.start_measurement()
        with SerialSource(f"serial://{device.port}", TsndDecoder(), setup=setup, teardown=tsnd.stop_measurement()) as source:
            frames = read_until(source, stopped)
    batcher = ImuBatcher("swimmer", "swimmer-waist")
    batches = batcher.feed(frames) + batcher.flush()
    assert sum(len(b.sample_offset_ns) for b in batches) == len(time_ns) and batcher.samples_without_mag == 0
    got_mag = np.concatenate([np.reshape(b.mag_gauss, (-1, 3)) for b in batches])
    np.testing.assert_allclose(got_mag[::10], mag[::10], atol=0.5e-3)  # 0.1 uT steps; one reading per 10 ms
    with pytest.raises(InputError, match="no IMU 'nobody'"):
        TsndDevice.from_session(path, "nobody")


def test_edge_serial_sources_pick_the_tsnd_decoder_and_stop_the_device_on_close():
    time_ns, accel, gyro, _ = samples(seconds=30.0)
    stop = threading.Event()
    with TsndDevice(time_ns, accel, gyro, speed=1.0) as device:
        sources = SerialSources([("swimmer-waist", f"serial://{device.port}?protocol=tsnd&rate_hz=1000")],
                                "swimmer", stop)
        deadline = threading.Timer(DEADLINE_S, stop.set)  # bounded even if no batch ever came
        deadline.start()
        count = 0
        for batch in sources:  # ends once the reader has seen `stop` (it checks every read_timeout_s)
            assert batch.sensor_id == "swimmer-waist" and batch.received_ns > 0
            count += len(batch.sample_offset_ns)
            if count >= 200:
                stop.set()
        deadline.cancel()
        assert count >= 200 and device.error is None
        assert isinstance(sources.sources[0][1].decoder, TsndDecoder)
        assert device.idle.wait(DEADLINE_S)  # the source's teardown stopped the measurement
        assert device.commands[:5] == SETUP_CODES and device.commands[-1] == 0x15


@pytest.mark.parametrize("url, expected", [
    ("serial:///dev/ttyUSB0", ("ximu3", None)),
    ("serial:///dev/rfcomm0?protocol=tsnd", ("tsnd", 1000.0)),
    ("serial:///dev/rfcomm0?protocol=tsnd&rate_hz=200&baud=921600", ("tsnd", 200.0)),
])
def test_serial_protocol_urls(url, expected):
    assert parse_serial_protocol(url) == expected


@pytest.mark.parametrize("url, message", [
    ("serial:///dev/x?protocol=tsnd&rate_hz=300", r"serial:///dev/x\?protocol=tsnd&rate_hz=300: rate_hz=300: the "
                                                  r"period 1000/300 = 3.333 ms is not a whole number"),
    ("serial:///dev/x?protocol=tsnd&rate_hz=0.5", r"rate_hz=0.5 is outside \[1.0, 1000.0\]"),
    ("serial:///dev/x?protocol=tsnd&rate_hz=2", "the period 500 ms exceeds the 255 ms"),
    ("serial:///dev/x?protocol=tsnd&rate_hz=fast", "rate_hz='fast' is not a number"),
    ("serial:///dev/x?rate_hz=100", "rate_hz is for protocol=tsnd"),
    ("serial:///dev/x?protocol=imu", "protocol='imu' is not one of ximu3, tsnd"),
])
def test_bad_protocol_urls_name_url_value_and_limit(url, message):
    with pytest.raises(ConfigError, match=message):
        SerialSource.from_url(url)
