"""`reckon doctor` against real parts: venue files on disk, x-IMU3 bytes on a real pseudo-terminal,
a real session log, a real TCP port, a real hub (`run_hub`) on loopback. Only the Bluetooth
adapter listing is faked (a folder standing in for /sys/class/bluetooth). Waits are bounded and
end on data or on the hub's ready event, never on a sleep."""

from __future__ import annotations

import json
import os
import socket
import threading
from pathlib import Path

import numpy as np
import pytest

from hub.chair.hub import HubSettings
from protocol import keys, messages
from protocol.session import load_toml
from protocol.session_log import SessionWriter
from reckon.transport.bus import Publisher, open_session, zenoh_config
from reckon.cli import main
from reckon.transport.config import free_endpoint
from reckon.tools.doctor import DoctorSettings, Level, run_doctor
from reckon.processes.hub import run_hub
from sim_devices.devices.ximu3 import SerialDevice

VENUE = """
[venue]
name = "court"

[[venue.beacons]]
id = "goal-a"
x_m = 1.575
y_m = 7.5

[[agents]]
id = "chair1"

[[agents.sensors]]
id = "seat"
mount = "seat"
rate_hz = {rate_hz}

[[agents.sensors]]
id = "left"
mount = "left_wheel"
spin_axis = "+z"

[[agents.sensors]]
id = "right"
mount = "right_wheel"
spin_axis = "-z"
"""


def venue_file(tmp_path: Path, rate_hz: object = 200.0, text: str = VENUE) -> Path:
    path = tmp_path / "venue.toml"
    path.write_text(text.replace("{rate_hz}", str(rate_hz)))
    return path


def checks(report, name_start):
    return [c for c in report.checks if c.name.startswith(name_start)]


def only(report, name_start):
    found = checks(report, name_start)
    assert len(found) == 1, [c.line() for c in report.checks]
    return found[0]


def test_a_good_venue_file_passes(tmp_path):
    report = run_doctor(DoctorSettings(venue=venue_file(tmp_path)))
    venue = only(report, "venue")
    assert venue.level is Level.OK and "1 agents, 3 sensors, 1 beacons" in venue.message
    assert report.ok and not [c for c in report.checks if c.level is Level.FAIL]


def test_the_chair_kernels_are_reported_built_for_this_machine_or_not(tmp_path, monkeypatch):
    from reckon import kernels

    kernels.chair_kernels()  # built, as install.sh and dev.py leave it
    built = only(run_doctor(DoctorSettings(venue=venue_file(tmp_path))), "chair kernels")
    assert built.level is Level.OK and kernels.module_path(kernels.build_key()).name in built.message
    monkeypatch.setattr(kernels, "build_key", lambda: "f" * 16)  # another source or machine: none built for it
    missing = only(run_doctor(DoctorSettings(venue=venue_file(tmp_path))), "chair kernels")
    assert missing.level is Level.WARN and "python -m reckon.kernels" in missing.fix


def test_a_bad_venue_file_fails_naming_the_key_and_exits_1(tmp_path, capsys):
    path = venue_file(tmp_path, rate_hz=0)
    report = run_doctor(DoctorSettings(venue=path))
    venue = only(report, "venue")
    assert venue.level is Level.FAIL and not report.ok
    assert f"{path}: agents[0].sensors[0].rate_hz: 0 is outside" in venue.message
    assert main(["-q", "doctor", "--venue", str(path), "--no-bus", "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] is False and any("rate_hz" in c["message"] and c["level"] == "FAIL" for c in out["checks"])


def test_a_chair_without_its_wheels_fails_with_the_reason(tmp_path):
    text = VENUE.split("[[agents.sensors]]\nid = \"left\"")[0]
    report = run_doctor(DoctorSettings(venue=venue_file(tmp_path, text=text)))
    agent = only(report, "agent chair1")
    assert agent.level is Level.FAIL and "left_wheel, right_wheel" in agent.message


def test_a_source_for_an_unknown_sensor_fails(tmp_path):
    report = run_doctor(DoctorSettings(venue=venue_file(tmp_path), sources=("hat=serial:///dev/null",)))
    source = only(report, "source")
    assert source.level is Level.FAIL and "'hat' is not a sensor" in source.message and "seat" in source.message


def inertial_device(seconds=10.0, rate_hz=200):
    n = int(seconds * rate_hz)
    rng = np.random.default_rng(3)
    time_ns = 5_000_000_000 + np.arange(n, dtype=np.int64) * (1_000_000_000 // rate_hz)
    return SerialDevice.from_arrays(time_ns, rng.uniform(-100, 100, (n, 3)), rng.uniform(-2, 2, (n, 3)), speed=1.0)


@pytest.mark.parametrize("venue_rate_hz, level", [(200.0, Level.OK), (100.0, Level.WARN)])
def test_a_serial_device_on_a_real_pty_is_found_and_its_frames_decode(tmp_path, venue_rate_hz, level):
    # Paced at real time and started before the doctor opens the port: the bytes written before
    # (flushed by the open, as on a real port) are lost, the stream after them is read.
    with inertial_device() as device:
        device.play()
        report = run_doctor(DoctorSettings(venue=venue_file(tmp_path, venue_rate_hz),
                                           sources=(f"seat=serial://{device.port}?baud=115200",), listen_s=5.0))
    source = only(report, "source")
    assert source.level is level, source.line()
    frames = int(source.message.split(" inertial frames")[0])
    assert frames >= 100
    measured = float(source.message.split(" Hz by the device clock")[0].rsplit(", ", 1)[1])
    assert measured == pytest.approx(200.0, rel=0.02)  # the device clock's 200 Hz, not the read pace


def test_a_serial_device_that_sends_garbage_fails_and_a_silent_one_warns(tmp_path):
    rng = np.random.default_rng(5)
    garbage = [(i * 1_000_000, bytes(rng.integers(0, 256, 64, dtype=np.uint8).tolist()) + b"\xdb\x00")
               for i in range(5000)]
    with SerialDevice(garbage, speed=1.0) as noisy, SerialDevice([], speed=1.0) as silent:
        noisy.play()
        report = run_doctor(DoctorSettings(sources=(f"seat=serial://{noisy.port}", f"left=serial://{silent.port}"),
                                           listen_s=0.5))
    noisy_check, silent_check = checks(report, "source")
    assert noisy_check.level is Level.FAIL and "no valid frame" in noisy_check.message
    assert "protocol or baud" in noisy_check.fix
    assert silent_check.level is Level.WARN and "sent nothing in 0.5 s" in silent_check.message


def test_a_missing_serial_port_fails_in_plain_words(tmp_path):
    report = run_doctor(DoctorSettings(venue=venue_file(tmp_path), sources=("seat=serial:///dev/ttyNOPE9",)))
    source = only(report, "source")
    assert source.level is Level.FAIL and source.message == "/dev/ttyNOPE9 does not exist"
    assert "plug the device in" in source.fix


def test_a_malformed_url_fails_with_the_parsers_words(tmp_path):
    report = run_doctor(DoctorSettings(venue=venue_file(tmp_path), sources=("seat=serial:///dev/x?bauds=9600",)))
    source = only(report, "source")
    assert source.level is Level.FAIL and "unknown key 'bauds'" in source.message


@pytest.mark.skipif(os.geteuid() == 0, reason="root opens any file: no permission problem to show")
def test_a_port_without_permission_says_dialout(tmp_path):
    port = tmp_path / "ttyFAKE"
    port.write_bytes(b"")
    port.chmod(0)
    report = run_doctor(DoctorSettings(sources=(f"seat=serial://{port}",)))
    assert "dialout" in only(report, "source").fix


def test_ble_needs_an_adapter_and_identities_for_a_scan(tmp_path):
    sysfs = tmp_path / "bluetooth"
    sysfs.mkdir()
    venue = venue_file(tmp_path)
    settings = DoctorSettings(venue=venue, sources=("seat=ble://AA:BB:CC:DD:EE:FF", "rx=ble://scan"),
                              bluetooth_sysfs=sysfs)
    assert [c.level for c in checks(run_doctor(settings), "source")] == [Level.WARN, Level.WARN]
    (sysfs / "hci0").mkdir()
    seat, scan = checks(run_doctor(settings), "source")
    assert seat.level is Level.OK and "hci0" in seat.message
    assert scan.level is Level.FAIL and "identity" in scan.message  # the venue's beacon has none
    bad = run_doctor(DoctorSettings(venue=venue, sources=("seat=ble://nothing",), bluetooth_sysfs=sysfs))
    assert only(bad, "source").level is Level.FAIL and "not a Bluetooth address" in only(bad, "source").message


def test_phone_port_in_use_fails_and_a_certificate_is_found(tmp_path):
    from edge.sources.phone.tls import ensure_certificate

    text = VENUE.replace('mount = "seat"', 'mount = "hand"').split("[[agents.sensors]]\nid = \"left\"")[0]
    venue = venue_file(tmp_path, text=text.replace('id = "chair1"', 'id = "walker"\nkind = "pedestrian"'))
    with socket.create_server(("127.0.0.1", 0)) as busy:
        port = busy.getsockname()[1]
        in_use = run_doctor(DoctorSettings(venue=venue, sources=(f"seat=phone://127.0.0.1:{port}",)))
    assert only(in_use, "source").level is Level.FAIL and f"port {port} is in use" in only(in_use, "source").message
    free = run_doctor(DoctorSettings(venue=venue, sources=(f"seat=phone://127.0.0.1:{port}",)))
    assert only(free, "source").level is Level.WARN and "no certificate yet" in only(free, "source").message
    ensure_certificate(tmp_path / "phone-tls", "127.0.0.1")
    made = run_doctor(DoctorSettings(venue=venue, sources=(f"seat=phone://127.0.0.1:{port}",)))
    assert only(made, "source").level is Level.OK and "valid 39" in only(made, "source").message  # 397 days


def test_mcap_source_reads_the_log_and_names_a_missing_agent(tmp_path):
    session = load_toml(venue_file(tmp_path))
    log = tmp_path / "game.mcap"
    time_ns = np.arange(20, dtype=np.int64) * 5_000_000
    with SessionWriter(log, session) as writer:
        writer.write(keys.imu("court", "chair1", "seat"),
                     messages.imu_batch("chair1", "seat", 0, time_ns, np.zeros((20, 3)), np.zeros((20, 3)), None))
    good = only(run_doctor(DoctorSettings(sources=(f"mcap://{log}",), agent="chair1")), "source")
    assert good.level is Level.OK and "1 messages, 1 agents" in good.message
    other = only(run_doctor(DoctorSettings(sources=(f"mcap://{log}",), agent="chair9")), "source")
    assert other.level is Level.FAIL and "no messages of agent 'chair9'" in other.message
    (tmp_path / "junk.mcap").write_bytes(b"not an mcap file")
    junk = only(run_doctor(DoctorSettings(sources=(f"mcap://{tmp_path / 'junk.mcap'}",))), "source")
    assert junk.level is Level.FAIL and "junk.mcap" in junk.message


def test_clock_sync_is_reported_one_way_or_the_other(tmp_path):
    clock = only(run_doctor(DoctorSettings()), "clock")
    assert clock.level in (Level.OK, Level.WARN) and ("synchronised" in clock.message or "cannot tell" in clock.message)


def feed_poses(endpoint: str, stop: threading.Event) -> None:
    """An edge's pose stream for chair1, 50 Hz, until `stop`."""
    with open_session(zenoh_config(connect=[endpoint])) as bus, Publisher(bus) as publisher:
        count = 0
        while not stop.wait(0.02):
            count += 1
            publisher.publish(keys.pose("court", "chair1", "edge"), messages.new(
                "EstimatedPose", timestamp_ns=count * 20_000_000, agent_id="chair1", x_m=1.0, y_m=7.5,
                method="reckon"))


def test_bus_check_against_a_real_hub_gives_the_clock_offset(tmp_path):
    venue = venue_file(tmp_path)
    endpoint = free_endpoint()
    stop, ready, feeding = threading.Event(), threading.Event(), threading.Event()
    hub = threading.Thread(target=run_hub, args=(zenoh_config(listen=[endpoint]), load_toml(venue), stop,
                                                 HubSettings()), kwargs={"ready": ready})
    hub.start()
    feeder = threading.Thread(target=feed_poses, args=(endpoint, feeding))
    try:
        assert ready.wait(10.0)
        feeder.start()
        report = run_doctor(DoctorSettings(venue=venue, bus=zenoh_config(connect=[endpoint]), bus_timeout_s=5.0,
                                           streams_s=1.0))
    finally:
        feeding.set()
        stop.set()
        feeder.join(10.0)
        hub.join(10.0)
    assert only(report, "bus").level is Level.OK and "answers" in only(report, "bus").message
    offset = only(report, "clock offset hub")
    assert offset.level is Level.OK, offset.line()
    milliseconds = float(offset.message.split("clock is ")[1].split(" ms")[0])
    assert 0.0 <= milliseconds < 50.0  # one machine's clock: only the bus delay
    flowing = only(report, "agent chair1")
    assert flowing.level is Level.OK and "pose/live" in flowing.message


def test_bus_check_with_nothing_listening_fails_within_its_timeout(tmp_path):
    report = run_doctor(DoctorSettings(venue=venue_file(tmp_path), bus=zenoh_config(connect=[free_endpoint()]),
                                       bus_timeout_s=0.5, streams_s=60.0))
    bus = only(report, "bus")
    assert bus.level is Level.FAIL and "no hub of venue 'court' answered within 0.5 s" in bus.message
    assert "connect tcp/" in bus.message and "--connect" in bus.fix  # where it looked, and what to check
    # it gave up at the hub's timeout: the 60 s traffic watch, which needs a hub, never began
    assert not checks(report, "clock offset") and not checks(report, "agent") and not checks(report, "device")
    assert not report.ok
