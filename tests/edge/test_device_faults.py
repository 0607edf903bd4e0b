"""Device faults (edge/health.py): each one injected into a simulated chair's real stream
(its ImuBatch sequence, or x-IMU3 bytes through real pseudo-terminals) -> handled, counted, flagged
in DeviceStatus, and the chair estimator's poses not corrupted."""

from __future__ import annotations

import os
import threading
import time

import numpy as np
import pytest

from edge.chair.edge import ChairEdge
from edge.decoders import ximu3
from edge.health import DeviceHealth, HealthSettings
from protocol import messages
from protocol.errors import ConfigError
from protocol.session_log import LogMessages, read_session
from reckon.transport.bus import zenoh_config
from edge.sources.mcap import mcap_source
from edge.sources.serial import SerialSources
from reckon.processes.edge import run_edge
from reckon.transport.record import record
from sim_devices.devices.ximu3 import SerialDevice
from support.games import Game
from support.waits import wait_until

GAME = Game(players=1, duration_s=12.0, seed=4)
WAIT_S = 30.0
RANGES = (16.0, 1500.0)  # the simulated sensor's full scales (sim_devices/wheelchair/params.py)


@pytest.fixture(scope="module")
def batches(game):
    return [m for m in mcap_source(game, "chair01", 0.0, threading.Event()) if messages.type_name(m) == "ImuBatch"]


def copy(batch, **changes):
    out = messages.ImuBatch()
    out.CopyFrom(batch)
    for name, value in changes.items():
        setattr(out, name, value)
    return out


def run(game, stream, settings=None):
    """(poses as (t, x, y, heading) rows, the health monitor) of chair01 over `stream`."""
    agent = read_session(game).session.agent("chair01")
    edge, health = ChairEdge(agent), DeviceHealth("chair01", settings, ranges=RANGES)
    out = []
    for batch in stream:
        for ready in health.push(batch, batch.received_ns):
            out += edge.push(ready)
    for ready in health.flush():
        out += edge.push(ready)
    out += edge.flush()
    poses = np.array([(p.timestamp_ns, p.x_m, p.y_m, p.heading_rad) for p in out
                      if messages.type_name(p) == "EstimatedPose"])
    return poses, health


@pytest.fixture(scope="module")
def clean(game, batches):
    return run(game, batches)


def test_clean_stream_passes_untouched_and_unflagged(clean, batches):
    poses, health = clean
    assert len(poses) > 400
    for sensor_id, state in health.sensors.items():
        assert (state.duplicates, state.out_of_order, state.clock_jumps, state.saturated) == (0, 0, 0, 0), sensor_id
        assert health.flags(sensor_id, state.last_arrival_ns) in ([], ["gap"])  # the simulator loses packets
    assert sum(s.samples for s in health.sensors.values()) == sum(len(b.sample_offset_ns) for b in batches)


def test_duplicate_batches_are_dropped_and_do_not_change_the_pose(game, batches, clean):
    stream = []
    for index, batch in enumerate(batches):
        stream.append(batch)
        if index % 7 == 3:
            stream.append(copy(batch))  # resent at once
        if index % 11 == 5 and index >= 4:
            stream.append(copy(batches[index - 4]))  # resent later (still among the last 64)
    poses, health = run(game, stream)
    np.testing.assert_array_equal(poses, clean[0])
    injected = len(stream) - len(batches)
    assert sum(s.duplicates for s in health.sensors.values()) == injected
    sensor = batches[3].sensor_id
    status = health.status(sensor, batches[3].received_ns)
    assert status.duplicates >= 1 and "duplicate" in status.flags


def test_batches_swapped_within_the_window_are_put_back_in_order(game, batches, clean):
    stream = list(batches)
    swapped = 0
    for index in range(10, len(stream) - 3, 25):  # a batch overtaken by the next two of its sensor
        sensor = stream[index].sensor_id
        later = [j for j in range(index + 1, len(stream)) if stream[j].sensor_id == sensor][:2]
        if len(later) == 2 and stream[later[0]].sequence == stream[index].sequence + 1:
            moved = stream.pop(index)
            stream.insert(later[1], moved)
            swapped += 1
    assert swapped > 10
    poses, health = run(game, stream)
    np.testing.assert_array_equal(poses, clean[0])
    assert sum(s.out_of_order for s in health.sensors.values()) == swapped


def test_a_batch_later_than_the_window_is_dropped_and_counted(game, batches, clean):
    stream = list(batches)
    seat = [i for i, b in enumerate(stream) if b.sensor_id == "chair01-seat"]
    late = stream.pop(seat[30])
    stream.insert(seat[40], late)  # ten of its sensor's batches later: past the 4-batch hold
    poses, health = run(game, stream)
    seat_health = health.sensors["chair01-seat"]
    assert seat_health.out_of_order == 1 and seat_health.gaps == 1
    assert seat_health.samples == clean[1].sensors["chair01-seat"].samples - len(late.sample_offset_ns)
    # one 0.1 s seat batch missing: the wheels bridge it, the path stays within a few cm
    np.testing.assert_allclose(poses[-1, 1:3], clean[0][-1, 1:3], atol=0.05)


def test_malformed_batches_are_dropped_counted_and_flagged_and_the_stream_goes_on(game, batches, clean):
    stream = list(batches)
    seat = [i for i, b in enumerate(stream) if b.sensor_id == "chair01-seat"]
    left = [i for i, b in enumerate(stream) if b.sensor_id == "chair01-left"]
    short_accel = copy(stream[seat[30]])
    del short_accel.accel_g[-1]  # one value short: no longer 3 per sample
    stray_mag = copy(stream[left[30]])
    stray_mag.mag_gauss[:] = [0.1, 0.2]  # magnetometer values neither none nor 3 per sample
    stream[seat[30]], stream[left[30]] = short_accel, stray_mag
    poses, health = run(game, stream)
    for sensor_id, index in (("chair01-seat", seat[30]), ("chair01-left", left[30])):
        state = health.sensors[sensor_id]
        assert state.malformed == 1 and state.gaps == clean[1].sensors[sensor_id].gaps  # not also a gap
        assert state.samples == clean[1].sensors[sensor_id].samples - len(batches[index].sample_offset_ns)
        status = health.status(sensor_id, batches[index].received_ns)
        assert status.malformed == 1 and "malformed" in status.flags
    assert len(poses) == len(clean[0])  # the lost 0.1 s is bridged; every pose still comes
    np.testing.assert_allclose(poses[-1, 1:3], clean[0][-1, 1:3], atol=0.1)


@pytest.mark.parametrize("jump_s", [120.0, -3600.0], ids=["forward", "back"])
@pytest.mark.parametrize("sensor", ["chair01-seat", "chair01-left"])
def test_a_clock_jump_is_re_anchored(game, batches, clean, jump_s, sensor):
    stream, seen = [], 0
    for batch in batches:
        if batch.sensor_id == sensor:
            seen += 1
            if seen > 50:  # from 5 s on, the device clock reads jump_s off
                batch = copy(batch, timestamp_ns=batch.timestamp_ns + int(jump_s * 1e9))
        stream.append(batch)
    poses, health = run(game, stream)
    state = health.sensors[sensor]
    assert state.clock_jumps == 1 and abs(state.shift_ns + jump_s * 1e9) < 0.05e9
    jumped_at = [b for b in stream if b.sensor_id == sensor][50].received_ns
    assert state.seen_at["clock_jump"] == jumped_at
    assert "clock_jump" not in health.flags(sensor, stream[-1].received_ns)  # 2 s later: cleared
    assert state.samples == clean[1].sensors[sensor].samples  # nothing dropped
    dt_s = np.diff(poses[:, 0]) * 1e-9
    assert dt_s.min() > 0 and dt_s.max() < 0.1  # continuous time for the estimator
    np.testing.assert_allclose(poses[-1, 1:3], clean[0][-1, 1:3], atol=0.05)


def test_repeated_samples_inside_batches_are_dropped(game, batches, clean):
    """A device that resends its last frames: the next batch starts with samples already passed."""
    stream = []
    for index, batch in enumerate(batches):
        if index % 9 == 4 and index > 10:
            previous = next(b for b in reversed(stream) if b.sensor_id == batch.sensor_id)
            # the previous batch's last two samples come again in front of this one
            offsets = [previous.timestamp_ns + o - (previous.timestamp_ns + previous.sample_offset_ns[-2])
                       for o in previous.sample_offset_ns[-2:]]
            start = previous.timestamp_ns + previous.sample_offset_ns[-2]
            batch = copy(batch, timestamp_ns=start)
            del batch.sample_offset_ns[:]
            batch.sample_offset_ns.extend(offsets + [batches[index].timestamp_ns - start + o
                                                     for o in batches[index].sample_offset_ns])
            for name in ("accel_g", "gyro_dps"):
                values = list(getattr(previous, name)[-6:]) + list(getattr(batches[index], name))
                field = getattr(batch, name)
                del field[:]
                field.extend(values)
            del batch.mag_gauss[:]
            if len(previous.mag_gauss) and len(batches[index].mag_gauss):
                batch.mag_gauss.extend(list(previous.mag_gauss[-6:]) + list(batches[index].mag_gauss))
        stream.append(batch)
    poses, health = run(game, stream)
    np.testing.assert_array_equal(poses, clean[0])
    total = sum(s.duplicates + s.out_of_order for s in health.sensors.values())
    assert total == 2 * sum(1 for i in range(len(batches)) if i % 9 == 4 and i > 10)


def test_stuck_and_saturated_samples_are_flagged_and_counted(game, batches):
    stream, seen = [], {"chair01-right": 0, "chair01-seat": 0}
    for batch in batches:
        count = seen[batch.sensor_id] = seen.get(batch.sensor_id, 0) + 1
        if batch.sensor_id == "chair01-right" and 20 <= count < 30:  # 10 batches = 200 samples of a frozen gyro
            batch = copy(batch)
            del batch.gyro_dps[:]
            batch.gyro_dps.extend([0.5, -1.25, 80.0] * len(batch.sample_offset_ns))
        if batch.sensor_id == "chair01-seat" and count == 40:
            batch = copy(batch)
            batch.accel_g[0:6] = [16.0, 0.1, 1.0, -16.0, 0.1, 1.0]  # two samples clipped at +-16 g
        stream.append(batch)
    health = DeviceHealth("chair01", ranges=RANGES)
    stuck_at = None
    for batch in stream:
        health.push(batch, batch.received_ns)
        if stuck_at is None and "stuck" in health.flags("chair01-right", batch.received_ns):
            stuck_at = health.sensors["chair01-right"].samples
    right = health.sensors["chair01-right"]
    assert stuck_at is not None and 19 * 20 + 100 <= stuck_at <= 19 * 20 + 120  # after 100 samples in a row
    assert right.stuck_samples_seen == 200 - 100 + 1
    assert "stuck" not in health.flags("chair01-right", stream[-1].received_ns)  # moving again
    seat = health.status("chair01-seat", stream[-1].received_ns)
    assert seat.saturated == 2
    assert health.sensors["chair01-right"].saturated == 0


def test_a_gyro_clipped_at_full_scale_is_saturated_not_stuck():
    health = DeviceHealth("a", ranges=ximu3.DEVICE.full_scale)
    batch = messages.imu_batch("a", "s", 0, np.arange(200, dtype=np.int64) * 5_000_000,
                               np.tile([0.01, 0.02, 1.0], (200, 1)) + np.random.default_rng(1).normal(0, 1e-3, (200, 3)),
                               np.tile([2000.0, 0.0, 0.0], (200, 1)) + [0, 0.1, 0.1] * np.random.default_rng(2).normal(
                                   0, 1, (200, 3)), None)
    health.push(batch, 1)
    assert health.sensors["s"].saturated == 200
    assert health.flags("s", 1) == ["saturated"]


def test_stale_and_disconnected_flags():
    health = DeviceHealth("a", HealthSettings(stale_s=2.0))
    health.expect("s", 0)
    assert health.flags("s", int(1.9e9)) == []
    assert health.flags("s", int(2.1e9)) == ["stale"]
    status = health.status("s", int(2.1e9), connected=False, reconnects=3)
    assert list(status.flags) == ["disconnected", "stale"] and status.reconnects == 3
    assert status.last_sample_age_s == -1.0  # nothing arrived yet
    health.push(messages.imu_batch("a", "s", 0, np.array([5], dtype=np.int64), np.zeros((1, 3)), np.zeros((1, 3)),
                                   None), int(3e9))
    assert health.status("s", int(3.5e9)).last_sample_age_s == pytest.approx(0.5)


def test_memory_is_bounded_whatever_the_sequences(batches):
    """Random duplicates, reorderings, restarts: the held batches and every counter stay bounded."""
    rng = np.random.default_rng(3)
    health = DeviceHealth("chair01", HealthSettings(reorder_batches=4))
    seat = [b for b in batches if b.sensor_id == "chair01-seat"]
    for step in range(3000):
        batch = copy(seat[step % len(seat)], sequence=int(rng.integers(0, 200)) if rng.random() < 0.3 else step)
        health.push(batch, step)
        state = health.sensors["chair01-seat"]
        assert len(state.held) <= 4 and len(state.seen_at) <= 8 and state.seen_mask < 1 << 64


def test_settings_out_of_range_name_the_key():
    with pytest.raises(ConfigError, match="reorder_batches: 100 is outside"):
        HealthSettings(reorder_batches=100)


# -- real pseudo-terminals ------------------------------------------------------------------------


def test_serial_device_unplugged_and_replugged_elsewhere_is_reopened(tmp_path):
    """The port is a by-id style symlink; the device goes away, comes back on another pty whose
    clock restarted (power cycle): the source reopens it, nothing received is lost, the clock
    jump is re-anchored, and DeviceStatus counts the reconnect."""
    rate = 200
    n = 400
    rng = np.random.default_rng(5)
    time_ns = 50_000_000_000 + np.arange(n, dtype=np.int64) * (10**9 // rate)
    gyro, accel = rng.normal(0, 5, (n, 3)), rng.normal(0, 0.1, (n, 3)) + [0, 0, 1]
    link = tmp_path / "usb-x-io_x-IMU3-if00"
    first = SerialDevice.from_arrays(time_ns[:200], gyro[:200], accel[:200], speed=0).open()
    # the second half after the power cycle: its clock starts again near zero
    second = SerialDevice.from_arrays(time_ns[200:] - time_ns[200] + 1_000_000, gyro[200:], accel[200:], speed=0)
    os.symlink(first.port, link)
    stop = threading.Event()
    sources = SerialSources([("seat", f"serial://{link}")], "chair01", stop, reconnect_s=WAIT_S)
    health = DeviceHealth("chair01", ranges=sources.device_ranges["seat"])
    received = []

    def take(samples):
        for batch in iterator:
            received.extend(health.push(batch, batch.received_ns))
            if sum(len(b.sample_offset_ns) for b in received) >= samples:
                return

    try:
        first.play()
        iterator = iter(sources)
        take(200)  # every byte of the first device read before it goes (a pty drops what is left)
        first.close()  # unplugged: the reader sees EIO
        wait_until(lambda: not sources.link("seat")[0], WAIT_S, "the source to see the unplugged device go")
        assert "disconnected" in health.status("seat", time.time_ns(), connected=False).flags
        second.open()
        os.replace(_symlink(tmp_path, second.port), link)  # re-pointed, as udev does
        wait_until(lambda: sources.link("seat")[0], WAIT_S, "the source to reopen the device at its new pty")
        second.play()
        take(n)
        connected, reconnects, battery = sources.link("seat")
    finally:
        stop.set()
        first.close()
        second.close()
    assert (connected, reconnects, battery) == (True, 1, -1.0)
    state = health.sensors["seat"]
    assert state.clock_jumps == 1 and state.samples == n
    times = np.concatenate([b.timestamp_ns + np.array(b.sample_offset_ns, dtype=np.int64) for b in received])
    assert np.all(np.diff(times) > 0)  # one continuous clock for the estimator
    got = np.concatenate([np.reshape(b.gyro_dps, (-1, 3)) for b in received])
    np.testing.assert_allclose(got, gyro, atol=1e-3)  # every sample, in order, float32 as sent
    status = health.status("seat", time.time_ns(), connected=connected, reconnects=reconnects)
    assert status.reconnects == 1 and status.clock_jumps == 1 and status.samples == n


def _symlink(folder, target):
    path = folder / "new-link"
    os.symlink(target, path)
    return path


# -- the edge process: DeviceStatus on the bus ------------------------------------------------------


def test_edge_publishes_device_status_with_the_faults_counted(game, batches, free_endpoint, tmp_path, caplog):
    stream = []
    for index, batch in enumerate(batches):
        stream.append(batch)
        if index % 10 == 0:
            stream.append(copy(batch))
    endpoint, output = free_endpoint(), tmp_path / "edge.mcap"
    stop, ready = threading.Event(), threading.Event()
    session = read_session(game).session
    recorder = threading.Thread(target=record, args=(zenoh_config(listen=[endpoint]), "court", output, stop, ready),
                                kwargs={"description": session}, daemon=True)
    recorder.start()
    assert ready.wait(WAIT_S)
    summary = run_edge(zenoh_config(connect=[endpoint]), session, "chair01", iter(stream), threading.Event(),
                       wait_for=1)
    stop.set()
    recorder.join(WAIT_S)
    assert not recorder.is_alive()
    statuses, imu = {}, 0
    for _, _, message in LogMessages(output, lambda topic, name: name in ("DeviceStatus", "ImuBatch")):
        if messages.type_name(message) == "DeviceStatus":
            statuses.setdefault(message.sensor_id, []).append(message)
        else:
            imu += 1
    assert set(statuses) == {"chair01-left", "chair01-right", "chair01-seat"}
    injected = {}
    for index, batch in enumerate(batches):
        if index % 10 == 0:
            injected[batch.sensor_id] = injected.get(batch.sensor_id, 0) + 1
    for sensor_id, sent in statuses.items():
        assert sent[-1].duplicates == injected.get(sensor_id, 0)
        assert sent[-1].samples == sum(len(b.sample_offset_ns) for b in batches if b.sensor_id == sensor_id)
        assert sent[-1].connected and sent[-1].battery_pct == -1.0 and sent[-1].spooled == 0
    # a flag change goes out at once: the first duplicate of each sensor raised "duplicate"
    assert any("duplicate" in s.flags for s in statuses["chair01-seat"])
    assert imu == len(batches)  # duplicates never reach the bus or the estimator
    # dozens of faults, one warning per sensor (rate-limited to one per 10 s), naming the counts
    warnings = [r.getMessage() for r in caplog.records if r.name == "reckon.processes.edge" and "so far" in r.getMessage()]
    assert len(warnings) <= 3 and len({w.split(":")[0] for w in warnings}) == len(warnings)
    assert any(w.startswith("chair01-seat: duplicate (so far: 0 gaps, 1 duplicates") for w in warnings)
    assert summary.poses > 400
