"""x-IMU3 decoder: against the vendor's own parser, the manual's examples, chunking and garbage
properties, bounded buffer, and the ImuBatch grouping."""

from __future__ import annotations

import array
import struct
import threading
import tracemalloc

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from edge.decoders import (
    BatchSettings,
    ImuBatcher,
    InertialFrame,
    MagnetometerFrame,
    RejectReason,
    Rejected,
    Ximu3Decoder,
    mag_au_to_gauss,
)
from protocol.errors import ConfigError
from sim_devices.devices import ximu3_encoder as enc

SAMPLE_PERIOD_US = 5_000  # 200 Hz


def f32(values):
    return tuple(array.array("f", values).tolist())


def ascii_f32(values):
    """What a 4-decimal ASCII message carries, as f32."""
    return f32([float(f"{v:.4f}") for v in values])


def good(frames):
    return [f for f in frames if not isinstance(f, Rejected)]


def random_samples(n, seed, stuffing=True):
    rng = np.random.default_rng(seed)
    base_us = 0xDB0A_0000  # timestamp bytes include 0x0A and 0xDB: exercises byte stuffing
    time_ns = (base_us + SAMPLE_PERIOD_US * np.arange(n)) * 1000
    gyro = rng.uniform(-2000, 2000, (n, 3))
    accel = rng.uniform(-16, 16, (n, 3))
    mag = rng.uniform(-1.2, 1.2, (n, 3))  # gauss
    if stuffing:  # floats whose little-endian bytes hold 0x0A and 0xDB
        gyro[::7, 0] = struct.unpack("<f", b"\x0a\xdb\x0a\x42")[0]
        accel[::5, 2] = struct.unpack("<f", b"\xdb\x0a\xdb\x3f")[0]
    return time_ns, gyro, accel, mag


# -- against the vendor's parser ----------------------------------------------------------------


def vendor_decode(path, expected, timeout_s=10.0):
    """Run ximu3's FileConnection over `path`; wait (bounded) until `expected` I+M messages arrived."""
    ximu3 = pytest.importorskip("ximu3", reason="the vendor parser (pip install ximu3) is a test extra")
    inertial, magnetometer = [], []
    done = threading.Event()

    def on_inertial(m):
        inertial.append((m.timestamp, (m.gyroscope_x, m.gyroscope_y, m.gyroscope_z),
                         (m.accelerometer_x, m.accelerometer_y, m.accelerometer_z)))
        if len(inertial) + len(magnetometer) >= expected:
            done.set()

    def on_magnetometer(m):
        magnetometer.append((m.timestamp, (m.x, m.y, m.z)))
        if len(inertial) + len(magnetometer) >= expected:
            done.set()

    connection = ximu3.Connection(ximu3.FileConnectionConfig(str(path)))
    connection.add_inertial_callback(on_inertial)
    connection.add_magnetometer_callback(on_magnetometer)
    connection.open()
    try:
        assert done.wait(timeout_s), f"vendor parser gave {len(inertial) + len(magnetometer)} of {expected} messages"
    finally:
        connection.close()
    return inertial, magnetometer


@pytest.mark.parametrize("ascii", [False, True], ids=["binary", "ascii"])
def test_decoder_matches_vendor_parser(tmp_path, ascii):
    n = 300
    time_ns, gyro, accel, mag = random_samples(n, seed=7)
    stream = b"".join(message for _, message in enc.encode_samples(time_ns, gyro, accel, mag, ascii=ascii))
    # plus lines both parsers skip: a command response and a quaternion message
    stream = b'{"ping":{"interface":"USB","name":"x-IMU3","sn":"0123"}}\n' + stream + b"Q,1,1.0,0.0,0.0,0.0\r\n"
    if not ascii:
        assert stream.count(b"\xdb\xdc") > 50 and stream.count(b"\xdb\xdd") > 50  # stuffing was exercised
    path = tmp_path / "stream.bin"
    path.write_bytes(stream)

    vendor_inertial, vendor_magnetometer = vendor_decode(path, expected=2 * n)
    decoder = Ximu3Decoder()
    frames = decoder.feed(stream)
    ours_inertial = [(f.timestamp_us, f.gyro_dps, f.accel_g) for f in frames if isinstance(f, InertialFrame)]
    ours_magnetometer = [(f.timestamp_us, f.mag_au) for f in frames if isinstance(f, MagnetometerFrame)]
    assert len(ours_inertial) == len(vendor_inertial) == n
    assert len(ours_magnetometer) == len(vendor_magnetometer) == n
    assert ours_inertial == vendor_inertial  # every timestamp and every f32 value, exactly
    assert ours_magnetometer == vendor_magnetometer
    counters = decoder.counters
    assert counters.rejected_frames == 0 and counters.command_responses == 1 and counters.skipped_by_id == {"Q": 1}


def test_manual_examples_decode():
    """The manual's examples: timestamp 1 s, gyro 0, accel (0, 0, 1) g; magnetometer (1, 0, 0) a.u."""
    binary = bytes.fromhex("C9 40420F0000000000" + "00000000" * 5 + "0000803F 0A")
    ascii = b"I,1000000,0.0000,0.0000,0.0000,0.0000,0.0000,1.0000\n"
    mag_binary = bytes.fromhex("CD 40420F0000000000 0000803F 00000000 00000000 0A")
    for raw in (binary, ascii):
        (frame,) = Ximu3Decoder().feed(raw)
        assert frame == InertialFrame(1_000_000, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), raw)
    (frame,) = Ximu3Decoder().feed(mag_binary)
    assert frame == MagnetometerFrame(1_000_000, (1.0, 0.0, 0.0), mag_binary)
    assert enc.inertial_binary(1_000_000, (0, 0, 0), (0, 0, 1)) == binary
    assert enc.magnetometer_binary(1_000_000, (1, 0, 0)) == mag_binary
    assert mag_au_to_gauss((1.0, -2.0, 0.0)) == (0.5, -1.0, 0.0)  # 1 a.u. ~ 50 uT = 0.5 gauss


# -- failure modes, one fixture each ------------------------------------------------------------

GOOD = enc.inertial_binary(1_000, (1.0, 2.0, 3.0), (0.0, 0.0, 1.0))
GOOD_2 = enc.inertial_binary(6_000, (1.5, 2.5, 3.5), (0.0, 0.0, 1.0))


@pytest.mark.parametrize("line, reason", [
    (GOOD[:-2] + b"\n", RejectReason.BAD_LENGTH),  # one byte lost
    (GOOD[:5] + b"\xdb\x00" + GOOD[5:], RejectReason.BAD_ESCAPE),
    (GOOD[:-1] + b"\xdb\n", RejectReason.BAD_ESCAPE),  # escape at the very end
    (enc.inertial_binary(1, (float("nan"), 0, 0), (0, 0, 1)), RejectReason.NOT_FINITE),
    (b"I,1000,1.0,2.0,3.0,0.0,0.0\r\n", RejectReason.BAD_ASCII),  # five numbers
    (b"I,1000,1.0,2.0,3.0,0.0,0.0,1e99\r\n", RejectReason.NOT_FINITE),  # beyond f32
    (b"M,-5,1.0,2.0,3.0\r\n", RejectReason.BAD_ASCII),
    (b'{"ping":\n', RejectReason.BAD_JSON),
    (b"hello\n", RejectReason.NOT_A_MESSAGE),
])
def test_each_failure_mode_is_rejected_with_its_reason(line, reason):
    decoder = Ximu3Decoder()
    frames = decoder.feed(line + GOOD)
    assert [type(f) for f in frames] == [Rejected, InertialFrame]
    assert frames[0].reason is reason and frames[0].raw == line and frames[0].offset == 0
    assert "at byte 0" in frames[0].detail
    assert decoder.counters.rejected_by_reason == {reason.value: 1}


def test_other_messages_and_command_responses_are_skipped_and_counted():
    stream = (b'{"serial_number":"0123ABCD"}\n' + b"Q,1000,1.0000,0.0000,0.0000,0.0000\r\n"
              + enc.stuff(struct.pack("<BQ4f", ord("Q") + 0x80, 1000, 1, 0, 0, 0)) + b"\n"
              + b"B,1000,85.0000,4.1000,1.0000\r\n" + GOOD)
    decoder = Ximu3Decoder()
    frames = decoder.feed(stream)
    assert [type(f) for f in frames] == [InertialFrame]
    counters = decoder.counters
    assert counters.command_responses == 1
    assert counters.skipped_by_id == {"Q": 1, "0xD1": 1, "B": 1}
    assert counters.skipped_bytes + len(GOOD) == len(stream) and counters.rejected_frames == 0


def test_truncated_message_waits_then_completes():
    decoder = Ximu3Decoder()
    assert decoder.feed(GOOD + GOOD_2[:10]) == [Ximu3Decoder().feed(GOOD)[0]]
    assert decoder.counters.pending_bytes == 10 and decoder.counters.rejected_frames == 0
    (frame,) = decoder.feed(GOOD_2[10:])
    assert frame.timestamp_us == 6_000 and frame.raw == GOOD_2
    # at end of stream, reset() hands the partial message back as TRUNCATED
    decoder.feed(GOOD[:7])
    (dropped,) = decoder.reset()
    assert dropped.reason is RejectReason.TRUNCATED and dropped.raw == GOOD[:7]
    assert decoder.counters.pending_bytes == 0


def test_overlong_line_is_dropped_with_reason_and_decoding_resumes():
    decoder = Ximu3Decoder(max_message_bytes=256)
    flood = bytes(range(0x20, 0x7F)) * 10  # 950 bytes, no LF
    frames = decoder.feed(GOOD + flood + GOOD_2 + GOOD)
    assert [type(f) for f in frames] == [InertialFrame, Rejected, Rejected, Rejected, Rejected, InertialFrame,
                                         InertialFrame]
    rejected = [f for f in frames if isinstance(f, Rejected)]
    assert {f.reason for f in rejected} == {RejectReason.OVERLONG}
    assert b"".join(f.raw for f in rejected) == flood  # every dropped byte kept, none of GOOD_2's
    assert all(len(f.raw) <= 256 for f in rejected)
    assert "no LF within 256 bytes at byte 34" in rejected[0].detail
    assert [f.timestamp_us for f in good(frames)] == [1_000, 6_000, 1_000]
    assert decoder.counters.pending_bytes == 0


def test_settings_are_checked():
    with pytest.raises(ConfigError, match="max_message_bytes: 10 is outside"):
        Ximu3Decoder(max_message_bytes=10)
    with pytest.raises(ConfigError, match="samples_per_batch: 0"):
        BatchSettings(samples_per_batch=0)


# -- properties ---------------------------------------------------------------------------------

gyro_values = st.tuples(*[st.floats(-2000, 2000, width=32)] * 3)
accel_values = st.tuples(*[st.floats(-24, 24, width=32)] * 3)
mag_values = st.tuples(*[st.floats(-4, 4, width=32)] * 3)


@st.composite
def message_streams(draw, min_messages=1, max_messages=30):
    """Encoded I/M messages (binary and ASCII) with 200 Hz timestamps, as a list of bytes."""
    count = draw(st.integers(min_messages, max_messages))
    start_us = draw(st.integers(0, 2**48))
    out = []
    for i in range(count):
        stamp = start_us + SAMPLE_PERIOD_US * i
        ascii = draw(st.booleans())
        if draw(st.booleans()):
            encode = enc.inertial_ascii if ascii else enc.inertial_binary
            out.append(encode(stamp, draw(gyro_values), draw(accel_values)))
        else:
            encode = enc.magnetometer_ascii if ascii else enc.magnetometer_binary
            out.append(encode(stamp, draw(mag_values)))
    return out


other_lines = st.sampled_from([
    b'{"ping":null}\n', b"Q,5,1.0000,0.0000,0.0000,0.0000\r\n", b"\n", b"\xdb\xdb\n", b"junk\r\n",
    b"I,12,oops\r\n", b"x" * 700,  # longer than the 256-byte limit used below: an overlong line
])


def chunked(data, cuts):
    points = sorted({0, len(data), *[c % (len(data) + 1) for c in cuts]})
    return [data[a:b] for a, b in zip(points, points[1:])]


@settings(max_examples=150, deadline=None)
@given(messages=message_streams(), extras=st.lists(st.tuples(st.integers(0, 30), other_lines), max_size=6),
       cuts=st.lists(st.integers(0, 10_000), max_size=40))
def test_same_frames_however_the_stream_is_chunked(messages, extras, cuts):
    for position, line in sorted(extras, key=lambda e: e[0], reverse=True):
        messages.insert(min(position, len(messages)), line)
    stream = b"".join(messages)
    whole = Ximu3Decoder(max_message_bytes=256)
    expected = whole.feed(stream)
    pieces = Ximu3Decoder(max_message_bytes=256)
    got = [frame for chunk in chunked(stream, cuts) for frame in pieces.feed(chunk)]
    assert got == expected
    assert pieces.counters == whole.counters
    # every byte is accounted for exactly once
    counters = pieces.counters
    assert sum(len(f.raw) for f in got) + counters.skipped_bytes + counters.pending_bytes == len(stream)


# Garbage cannot contain a message start (I, M, 0xC9, 0xCD) here: bytes that form a well-formed
# message are a message to any decoder. test_full_range_garbage below uses every byte value.
garbage_bytes = st.binary(min_size=1, max_size=40).map(
    lambda b: b.translate(bytes.maketrans(b"IM\xc9\xcd", b"\x0a\xdb\x00\xff")))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(messages=message_streams(min_messages=2), garbage=st.dictionaries(st.integers(1, 29), garbage_bytes,
                                                                           min_size=1, max_size=8),
       cuts=st.lists(st.integers(0, 10_000), max_size=20))
def test_garbage_between_messages_is_skipped_and_every_message_still_decodes(messages, garbage, cuts):
    clean = good(Ximu3Decoder().feed(b"".join(messages)))
    assert len(clean) == len(messages)
    parts, garbage_total = [], 0
    for index, message in enumerate(messages):
        if index in garbage:  # before message `index`, never before the first (see the decoder doc)
            parts.append(garbage[index])
            garbage_total += len(garbage[index])
        parts.append(message)
    decoder = Ximu3Decoder()
    frames = [f for chunk in chunked(b"".join(parts), cuts) for f in decoder.feed(chunk)]
    assert good(frames) == clean
    counters = decoder.counters
    assert counters.rejected_bytes + counters.skipped_bytes + counters.pending_bytes == garbage_total
    assert all(f.reason in (RejectReason.GARBAGE, RejectReason.NOT_A_MESSAGE, RejectReason.BAD_ESCAPE,
                            RejectReason.BAD_JSON) for f in frames if isinstance(f, Rejected))


def test_full_range_garbage_including_message_ids():
    rng = np.random.default_rng(11)
    time_ns, gyro, accel, mag = random_samples(600, seed=3)
    messages = [m for _, m in enc.encode_samples(time_ns, gyro, accel, mag, ascii=False)]
    later_ns = time_ns + 600 * SAMPLE_PERIOD_US * 1000  # continues the clock: salvage checks time
    messages += [m for _, m in enc.encode_samples(later_ns, gyro, accel, mag, ascii=True)]
    parts, garbage_total = [], 0
    for index, message in enumerate(messages):
        if index and index % 3 == 0:
            garbage = rng.integers(0, 256, int(rng.integers(1, 48)), dtype=np.uint8).tobytes()
            parts.append(garbage)
            garbage_total += len(garbage)
        parts.append(message)
    decoder = Ximu3Decoder()
    frames = decoder.feed(b"".join(parts))
    assert good(frames) == good(Ximu3Decoder().feed(b"".join(messages)))
    assert decoder.counters.rejected_bytes + decoder.counters.skipped_bytes == garbage_total
    assert decoder.counters.rejected_by_reason.get("garbage", 0) > 100


def test_garbage_before_every_message_from_the_start_costs_only_the_first():
    time_ns, gyro, accel, mag = random_samples(50, seed=9)
    messages = [m for _, m in enc.encode_samples(time_ns, gyro, accel, mag)]
    garbage = b"\x01\x02\xdb"  # no LF: every message shares its line with garbage
    decoder = Ximu3Decoder()
    frames = decoder.feed(b"".join(garbage + m for m in messages))
    assert good(frames) == good(Ximu3Decoder().feed(b"".join(messages[1:])))
    assert frames[0] == Rejected(garbage + messages[0], RejectReason.NOT_A_MESSAGE, 0, frames[0].detail)


def test_decoder_and_batcher_memory_is_constant():
    time_ns, gyro, accel, mag = random_samples(2_000, seed=5, stuffing=False)
    block = b"".join(m for _, m in enc.encode_samples(time_ns, gyro, accel, mag)) + b"\x00garbage\xdb\n"
    decoder, batcher = Ximu3Decoder(), ImuBatcher("chair01", "chair01-seat")

    def run(repeats):
        for _ in range(repeats):
            for start in range(0, len(block), 997):
                batcher.feed(decoder.feed(block[start:start + 997]))

    tracemalloc.start()
    try:
        run(1)
        after_few = tracemalloc.get_traced_memory()[0]
        run(8)  # 32,000 more frames
        after_many = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    assert after_many - after_few < 16_384
    assert batcher.samples == 9 * 2_000


# -- ImuBatch grouping --------------------------------------------------------------------------


def inertial(stamp_us, value=1.0):
    return InertialFrame(stamp_us, (value, 2.0, 3.0), (0.0, 0.0, 1.0), b"")


def magnetometer(stamp_us, value=1.0):
    return MagnetometerFrame(stamp_us, (value, 0.0, -1.0), b"")


def test_batches_have_fixed_size_device_clock_times_and_latest_magnetometer():
    batcher = ImuBatcher("chair01", "chair01-seat")
    frames = []
    for i in range(45):
        if i % 10 == 0:  # the x-IMU3's magnetometer is slower than its inertial rate
            frames.append(magnetometer(1_000 + SAMPLE_PERIOD_US * i, value=float(i)))
        frames.append(inertial(1_000 + SAMPLE_PERIOD_US * i, value=float(i)))
    frames.append(Rejected(b"x\n", RejectReason.NOT_A_MESSAGE, 0, ""))  # ignored here
    batches = batcher.feed(frames)
    assert len(batches) == 2 and [len(b.sample_offset_ns) for b in batches] == [20, 20]
    first = batches[0]
    assert (first.agent_id, first.sensor_id, first.sequence, first.timestamp_ns) == ("chair01", "chair01-seat", 0,
                                                                                       1_000_000)
    assert list(first.sample_offset_ns) == [SAMPLE_PERIOD_US * 1000 * i for i in range(20)]
    assert list(first.gyro_dps[0::3]) == [float(i) for i in range(20)]
    assert list(first.mag_gauss[0::3]) == [0.5 * (i // 10 * 10) for i in range(20)]  # a.u. -> gauss, held
    (rest,) = batcher.flush()
    assert len(rest.sample_offset_ns) == 5 and rest.sequence == 2 and batcher.flush() == []


def test_batch_without_magnetometer_for_every_sample_has_none():
    batcher = ImuBatcher("a", "s", BatchSettings(samples_per_batch=4, max_mag_age_us=20_000))
    frames = [inertial(0), magnetometer(1), inertial(5_000), inertial(10_000), inertial(15_000),  # first lacks one
              inertial(20_000), inertial(25_000), inertial(30_000), inertial(35_000)]  # reading goes stale
    first, second = batcher.feed(frames)
    assert list(first.mag_gauss) == [] and list(second.mag_gauss) == []
    assert batcher.samples_without_mag == 1 + 3


def test_clock_jump_closes_the_batch_early():
    batcher = ImuBatcher("a", "s", BatchSettings(samples_per_batch=4))
    batches = batcher.feed([inertial(10_000), inertial(15_000), inertial(3_000), inertial(8_000),
                            inertial(8_000 + 5_000_000)])  # then a gap longer than a uint32 offset
    batches += batcher.flush()
    assert [b.timestamp_ns for b in batches] == [10_000_000, 3_000_000, 5_008_000_000]
    assert [len(b.sample_offset_ns) for b in batches] == [2, 2, 1]
    assert batcher.clock_jumps == 1


def test_decoder_core_imports_no_io_library():
    import subprocess
    import sys

    code = ("import sys, edge.decoders; "
            "print(sorted({'serial', 'mcap', 'zenoh', 'bleak', 'asyncio', 'socket'} & set(sys.modules)))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert result.stdout.strip() == "[]"
