"""BLE path: advertisement parsers, the Thingy:52 decoder, and BleSources against a fake radio.

The fakes stand exactly where bleak 3.1 stands (same class signatures, checked against the installed
package below); they record what the code under test does and let a test push notifications,
advertisements and link losses into the BLE loop, waiting until each has been handled. Nothing
sleeps: every wait is a queue or thread join with a timeout.
"""

from __future__ import annotations

import inspect
import itertools
import logging
import queue
import threading
from typing import Any

import bleak
import pytest
from bleak.backends.scanner import AdvertisementData
from bleak.exc import (
    BleakBluetoothNotAvailableError,
    BleakBluetoothNotAvailableReason,
    BleakDeviceNotFoundError,
)

from edge.decoders.ble_adverts import (
    EDDYSTONE_SERVICE_UUID,
    THINGY_RAW_MOTION_UUID,
    ThingyMotionDecoder,
    beacon_identities,
    normalize_identity,
    parse_eddystone_uid,
    parse_ibeacon,
)
from edge.decoders.samples import BatchSettings, ImuBatcher
from edge.decoders.ximu3 import InertialFrame, MagnetometerFrame, Rejected, RejectReason, mag_au_to_gauss
from edge.sources.ble import BleSources, Retry, parse_ble_url
from protocol import messages
from protocol.errors import ConfigError
from support.ble import (BEACON_UUID, INSTANCE, NAMESPACE, WAIT_S, FakeBleakClient, FakeBleakScanner, FakeRadio,
                         eddystone_bytes, ibeacon_bytes, motion_bytes)

THINGY = "F1:22:33:44:55:66"


# -- advertisement parsers ------------------------------------------------------------------------


def test_ibeacon_is_parsed():
    beacon = parse_ibeacon({0x004C: ibeacon_bytes(1, 65535, -61)})
    assert beacon is not None
    assert (beacon.uuid, beacon.major, beacon.minor, beacon.tx_power_dbm) == (BEACON_UUID, 1, 65535, -61)
    assert beacon.identity == f"ibeacon:{BEACON_UUID}:1:65535"


@pytest.mark.parametrize("manufacturer_data", [
    {0x004C: ibeacon_bytes(1, 2)[:-1]},  # truncated
    {0x004C: ibeacon_bytes(1, 2) + b"\x00"},  # too long
    {0x0059: ibeacon_bytes(1, 2)},  # Nordic's company id, not Apple's
    {0x004C: b"\x10\x05" + ibeacon_bytes(1, 2)[2:]},  # Apple "Nearby", same length
    {0x004C: b""},
    {0x004C: "not bytes"},
    {},
])
def test_malformed_ibeacon_is_none(manufacturer_data):
    assert parse_ibeacon(manufacturer_data) is None


def test_eddystone_uid_is_parsed_with_and_without_reserved_bytes():
    for payload in (eddystone_bytes(), eddystone_bytes(reserved=b"")):
        beacon = parse_eddystone_uid({EDDYSTONE_SERVICE_UUID: payload})
        assert beacon is not None
        assert (beacon.namespace, beacon.instance, beacon.tx_power_dbm) == (NAMESPACE, INSTANCE, -18)
        assert beacon.identity == "eddystone:00010203040506070809:a1b2c3d4e5f6"
    assert parse_eddystone_uid({EDDYSTONE_SERVICE_UUID.upper(): eddystone_bytes()}) is not None


@pytest.mark.parametrize("service_data", [
    {EDDYSTONE_SERVICE_UUID: eddystone_bytes(frame=0x10)},  # URL frame
    {EDDYSTONE_SERVICE_UUID: eddystone_bytes(frame=0x20)},  # TLM frame
    {EDDYSTONE_SERVICE_UUID: eddystone_bytes()[:17]},  # truncated
    {EDDYSTONE_SERVICE_UUID: eddystone_bytes() + b"\x00"},  # too long
    {"0000fe9a-0000-1000-8000-00805f9b34fb": eddystone_bytes()},  # another service
    {EDDYSTONE_SERVICE_UUID: None},
    {},
])
def test_malformed_eddystone_is_none(service_data):
    assert parse_eddystone_uid(service_data) is None


def test_identities_of_one_advertisement():
    assert beacon_identities({0x004C: ibeacon_bytes(3, 4)}, {EDDYSTONE_SERVICE_UUID: eddystone_bytes()}) == [
        f"ibeacon:{BEACON_UUID}:3:4", "eddystone:00010203040506070809:a1b2c3d4e5f6"]
    assert beacon_identities({0x0006: b"\x01\x09"}, {}) == []


def test_venue_identity_is_normalised_or_rejected():
    assert normalize_identity(f"iBeacon:{BEACON_UUID.upper()}:007:0") == f"ibeacon:{BEACON_UUID}:7:0"
    assert normalize_identity("EDDYSTONE:00010203040506070809:A1B2C3D4E5F6") == \
        "eddystone:00010203040506070809:a1b2c3d4e5f6"
    for bad in (f"ibeacon:{BEACON_UUID}:1:70000", "ibeacon:1234:1:2", "eddystone:0001:a1b2c3d4e5f6", "goal_a", 3):
        with pytest.raises(ConfigError, match="not ibeacon:<uuid>"):
            normalize_identity(bad, "beacon 'goal_a'")


# -- Thingy:52 raw motion decoder -----------------------------------------------------------------


def test_thingy_values_are_scaled_and_stamped_with_receive_time():
    decoder = ThingyMotionDecoder()
    raw = motion_bytes((1024, -512, 16384), (32, -3200, 0), (640, -16, 1))
    frames = decoder.feed(bytearray(raw), receive_ns=1_234_567_891)
    mag, inertial = frames
    assert isinstance(mag, MagnetometerFrame) and isinstance(inertial, InertialFrame)
    assert inertial.accel_g == (1.0, -0.5, 16.0)  # Q6.10 g
    assert inertial.gyro_dps == (1.0, -100.0, 0.0)  # Q11.5 deg/s
    assert mag_au_to_gauss(mag.mag_au) == pytest.approx((0.40, -0.01, 0.000625))  # Q12.4 uT, / 100
    assert inertial.timestamp_us == mag.timestamp_us == 1_234_567
    assert inertial.raw == raw


def test_thingy_wrong_length_is_rejected_and_counted():
    decoder = ThingyMotionDecoder()
    decoder.feed(motion_bytes((0, 0, 0), (0, 0, 0), (0, 0, 0)), 1_000)
    for data in (b"\x00" * 17, b"\x00" * 20):
        (rejected,) = decoder.feed(data, 2_000)
        assert isinstance(rejected, Rejected) and rejected.reason is RejectReason.BAD_LENGTH
        assert "expected 18" in rejected.detail
    assert decoder.rejected_frames == 2 and decoder.rejected_by_reason == {"bad_length": 2}
    assert decoder.feed(b"", 3_000)[0].offset == 18 + 17 + 20


def test_thingy_times_stay_strictly_increasing():
    decoder = ThingyMotionDecoder()
    zero = motion_bytes((0, 0, 0), (0, 0, 0), (0, 0, 0))
    times = [decoder.feed(zero, ns)[1].timestamp_us for ns in (5_000_000, 5_000_400, 4_999_000, 3_000_000_000, 2_000)]
    assert times == [5_000, 5_001, 5_002, 3_000_000, 2]  # same-us and small back-steps nudged; a big step kept
    assert decoder.nudged == 2


def test_thingy_frames_batch_into_gauss():
    decoder, batcher = ThingyMotionDecoder(), ImuBatcher("chair1", "seat", BatchSettings(samples_per_batch=2))
    out = []
    for i in range(2):
        out += batcher.feed(decoder.feed(motion_bytes((0, 0, 1024), (64, 0, 0), (480, 0, -800)), (i + 1) * 5_000_000))
    (batch,) = out
    assert list(batch.accel_g) == [0.0, 0.0, 1.0] * 2
    assert list(batch.gyro_dps) == [2.0, 0.0, 0.0] * 2
    assert list(batch.mag_gauss) == pytest.approx([0.3, 0.0, -0.5] * 2)  # 30 uT, -50 uT
    assert list(batch.sample_offset_ns) == [0, 5_000_000]


# -- URLs and configuration -----------------------------------------------------------------------


def test_ble_urls():
    assert parse_ble_url("ble://f1:22:33:44:55:aa") == "F1:22:33:44:55:AA"
    assert parse_ble_url("ble://scan") == "scan"
    for bad in ("ble://F1:22:33:44:55", "ble://F1223344556A", "ble://F1:22:33:44:55:GG", "ble://F1:22:33:44:55:66/x",
                "ble://", "serial:///dev/ttyUSB0", "ble://SCAN?x=1"):
        with pytest.raises(ConfigError, match="expected ble://AA:BB:CC:DD:EE:FF") as error:
            parse_ble_url(bad)
        assert repr(bad) in str(error.value)


def test_bad_specs_fail_before_anything_starts():
    radio, stop = FakeRadio(), threading.Event()
    for specs, beacons, message in (
            ([("seat", f"ble://{THINGY}"), ("left", f"ble://{THINGY.lower()}")], {}, "also given for sensor 'seat'"),
            ([("rx", "ble://scan"), ("rx2", "ble://scan")], {}, "also given"),
            ([("rx", "ble://scan")], {"ibeacon:nope": "goal_a"}, "beacon 'goal_a'"),
            ([], {}, "no BLE sources")):
        with pytest.raises(ConfigError, match=message):
            BleSources(specs, "chair1", beacons, stop, client_factory=radio.Client, scanner_factory=radio.Scanner)
    assert radio.made == []


def test_fakes_match_bleak():
    """The fakes must take what bleak 3.1 takes, so the code cannot call bleak in a way only a fake accepts."""
    client_methods = ("__init__", "connect", "start_notify", "disconnect")
    for fake, real, names in ((FakeBleakClient, bleak.BleakClient, client_methods),
                              (FakeBleakScanner, bleak.BleakScanner, ("__init__", "start", "stop"))):
        for name in names:
            fake_params = inspect.signature(getattr(fake, name)).parameters
            real_params = inspect.signature(getattr(real, name)).parameters
            shape = [(p.name, p.kind) for p in fake_params.values()]
            assert shape == [(p.name, p.kind) for p in real_params.values()], name
            assert inspect.iscoroutinefunction(getattr(fake, name)) == inspect.iscoroutinefunction(getattr(real, name))
    assert {"rssi", "manufacturer_data", "service_data"} <= set(AdvertisementData._fields)


def open_sources(radio: FakeRadio, specs: list[tuple[str, str]], stop: threading.Event, **kwargs: Any) -> BleSources:
    clock = itertools.count(1_000_000_000, 5_000_000)  # 200 Hz worth of host time per call
    kwargs.setdefault("batch_settings", BatchSettings(samples_per_batch=3))
    return BleSources(specs, "chair1", {f"ibeacon:{BEACON_UUID.upper()}:1:2": "goal_a",
                                        "eddystone:00010203040506070809:a1b2c3d4e5f6": "goal_b"}, stop,
                      client_factory=radio.Client, scanner_factory=radio.Scanner, clock_ns=lambda: next(clock),
                      retry=Retry(0.0, 0.0), **kwargs)


def finish(sources: BleSources, stop: threading.Event) -> list[Any]:
    stop.set()
    out = list(sources)
    assert sources.join(WAIT_S)
    return out


def samples(batches: list[Any]) -> list[tuple[float, ...]]:
    """(gyro x, accel z) of every sample, in order."""
    return [(b.gyro_dps[3 * i], b.accel_g[3 * i + 2]) for b in batches for i in range(len(b.sample_offset_ns))]


# -- BleSources -----------------------------------------------------------------------------------


def test_known_beacons_become_sightings_unknown_are_ignored():
    radio, stop = FakeRadio(), threading.Event()
    sources = open_sources(radio, [("rx", "ble://scan")], stop)
    scanner = radio.next_ready()
    scanner.advertise("C0:00:00:00:00:01", -70, manufacturer_data={0x004C: ibeacon_bytes(1, 2)})
    scanner.advertise("C0:00:00:00:00:02", -60, manufacturer_data={0x004C: ibeacon_bytes(1, 3)})  # unknown minor
    scanner.advertise("C0:00:00:00:00:03", -50, manufacturer_data={0x0006: b"\x01\x09\x20"})  # not a beacon
    scanner.advertise("C0:00:00:00:00:04", -81, service_data={EDDYSTONE_SERVICE_UUID: eddystone_bytes()})
    out = finish(sources, stop)
    assert [messages.type_name(m) for m in out] == ["BeaconSighting"] * 2
    assert [(m.agent_id, m.sensor_id, m.beacon_id, m.rssi_dbm) for m in out] == [
        ("chair1", "rx", "goal_a", -70.0), ("chair1", "rx", "goal_b", -81.0)]
    assert out[0].timestamp_ns == 1_000_000_000 and out[1].timestamp_ns == 1_015_000_000  # host clock per advert
    assert scanner.stop_calls == 1 and not scanner.scanning
    assert (sources.stats["rx"].messages, sources.stats["rx"].ignored_adverts) == (2, 2)


def test_notifications_become_imu_batches():
    radio, stop = FakeRadio(), threading.Event()
    sources = open_sources(radio, [("seat", f"ble://{THINGY.lower()}")], stop)
    client = radio.next_ready()
    assert client.address == THINGY and client.notify_callbacks.keys() == {THINGY_RAW_MOTION_UUID}
    for i in range(4):
        client.notify(motion_bytes((0, 0, 1024 + i), (32 * i, 0, 0), (160, 0, 0)))
    out = finish(sources, stop)
    assert [messages.type_name(m) for m in out] == ["ImuBatch"] * 2  # 3 samples, then 1 flushed at stop
    assert [(b.agent_id, b.sensor_id, b.sequence) for b in out] == [("chair1", "seat", 0), ("chair1", "seat", 1)]
    assert samples(out) == [(float(i), (1024 + i) / 1024) for i in range(4)]
    assert out[0].timestamp_ns == 1_000_000_000 and list(out[0].sample_offset_ns) == [0, 5_000_000, 10_000_000]
    assert list(out[0].mag_gauss) == pytest.approx([0.1, 0.0, 0.0] * 3)
    assert client.disconnect_calls == 1 and not client.connected  # hung up at stop


def test_link_loss_is_retried_and_nothing_received_is_lost(caplog):
    radio, stop = FakeRadio(), threading.Event()
    sources = open_sources(radio, [("seat", f"ble://{THINGY}")], stop)
    first = radio.next_ready()
    for i in range(4):
        first.notify(motion_bytes((0, 0, 1024), (32 * i, 0, 0), (0, 0, 0)))
    radio.connect_errors.append(BleakDeviceNotFoundError(THINGY))  # the first retry finds nothing
    with caplog.at_level(logging.WARNING):
        first.drop_link()
        second = radio.next_ready()
    assert second is not first
    for i in range(4, 6):
        second.notify(motion_bytes((0, 0, 1024), (32 * i, 0, 0), (0, 0, 0)))
    out = finish(sources, stop)
    assert [len(b.sample_offset_ns) for b in out] == [3, 1, 2]  # the partial batch went out at the loss
    assert [b.sequence for b in out] == [0, 1, 2]
    assert [gyro for gyro, _ in samples(out)] == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
    stats = sources.stats["seat"]
    assert (stats.connects, stats.reconnects, stats.link_losses, stats.failed_attempts) == (2, 1, 1, 1)
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 2 and all(THINGY in w for w in warnings)
    assert "link lost" in warnings[0] and "BleakDeviceNotFoundError" in warnings[1]
    assert first.disconnect_calls == 0 and second.disconnect_calls == 1


def test_stop_ends_iteration_of_a_live_source():
    radio, stop = FakeRadio(), threading.Event()
    sources = open_sources(radio, [("seat", f"ble://{THINGY}"), ("rx", "ble://scan")], stop)
    ready = {type(radio.next_ready()).__name__, type(radio.next_ready()).__name__}
    assert ready == {"Client", "Scanner"}
    received: queue.Queue[Any] = queue.Queue()
    consumer = threading.Thread(target=lambda: [received.put(m) for m in sources], daemon=True)
    consumer.start()
    radio.made[0].notify(motion_bytes((0, 0, 1024), (0, 0, 0), (0, 0, 0)))
    stop.set()
    consumer.join(WAIT_S)
    assert not consumer.is_alive() and sources.join(WAIT_S)
    assert received.qsize() == 1  # the one sample, flushed at stop


def test_a_full_queue_blocks_instead_of_dropping():
    radio, stop = FakeRadio(), threading.Event()
    sources = open_sources(radio, [("seat", f"ble://{THINGY}")], stop, queue_size=1,
                           batch_settings=BatchSettings(samples_per_batch=1))
    client = radio.next_ready()
    received: list[Any] = []
    consumer = threading.Thread(target=lambda: received.extend(sources), daemon=True)
    consumer.start()
    for i in range(50):
        client.notify(motion_bytes((0, 0, 0), (i, 0, 0), (0, 0, 0)))
    stop.set()
    consumer.join(WAIT_S)
    assert [b.gyro_dps[0] * 32 for b in received] == list(range(50))
    assert sources.dropped_at_shutdown == 0


def test_no_bluetooth_at_start_is_raised_in_the_consumer():
    radio, stop = FakeRadio(), threading.Event()
    off = BleakBluetoothNotAvailableError("adapter is off", BleakBluetoothNotAvailableReason.POWERED_OFF)
    radio.start_errors.append(off)
    sources = open_sources(radio, [("rx", "ble://scan")], stop)
    with pytest.raises(BleakBluetoothNotAvailableError, match="adapter is off"):
        list(sources)
    assert sources.join(WAIT_S)


def test_an_error_in_a_callback_is_raised_in_the_consumer_after_the_data():
    radio, stop = FakeRadio(), threading.Event()
    calls = itertools.count()

    def clock() -> int:
        if next(calls) == 1:
            raise RuntimeError("clock broke")
        return 1_000_000_000

    sources = BleSources([("seat", f"ble://{THINGY}")], "chair1", {}, stop, client_factory=radio.Client,
                         scanner_factory=radio.Scanner, clock_ns=clock, retry=Retry(0.0, 0.0))
    client = radio.next_ready()
    client.notify(motion_bytes((0, 0, 0), (0, 0, 0), (0, 0, 0)))
    client.notify(motion_bytes((0, 0, 0), (0, 0, 0), (0, 0, 0)))
    stream = iter(sources)
    assert len(next(stream).sample_offset_ns) == 1  # flushed before the error
    with pytest.raises(RuntimeError, match="clock broke"):
        next(stream)
    assert sources.join(WAIT_S) and client.disconnect_calls == 1
