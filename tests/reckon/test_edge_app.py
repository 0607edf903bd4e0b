"""`reckon edge` end to end: a session's chair through the live path over real Zenoh into a recorder."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from protocol.session_log import read_session
from reckon.transport.bus import zenoh_config
from reckon.processes.edge import mcap_source, open_sources, run_edge
from reckon.evaluation.inputs import build_inputs
from reckon.evaluation.reckon_run import merged_samples
from reckon.transport.record import record
from edge.chair.estimator import start, step
from edge.chair.state import ChairSettings
from protocol.errors import ConfigError
from support.ble import BEACON_UUID, FakeBleakClient, FakeRadio, ibeacon_bytes, motion_bytes
from support.games import Game
from support.venue import agent_table, sensor_table, write_venue
from support.waits import wait_until

GAME = Game(players=2, duration_s=20.0, seed=4)
WAIT_S = 60.0


def edge_into_recorder(game, agent_id: str, output, endpoint: str):
    """Run `run_edge` on one agent of `game` into a recorder on `endpoint` (a fresh loopback one)."""
    stop, ready = threading.Event(), threading.Event()
    session = read_session(game).session
    recorder = threading.Thread(target=record, args=(zenoh_config(listen=[endpoint]), "court", output, stop, ready),
                                kwargs={"description": session}, daemon=True)
    recorder.start()
    assert ready.wait(WAIT_S)
    source = mcap_source(game, agent_id, speed=0.0, stop=threading.Event())
    summary = run_edge(zenoh_config(connect=[endpoint]), session, agent_id, source, threading.Event(), wait_for=1)
    stop.set()
    recorder.join(WAIT_S)
    assert not recorder.is_alive()
    return summary


def offline_run(game, agent_id: str):
    """(sample count, final state) of the offline path (`reckon eval`) on the same log."""
    agent = next(a for a in build_inputs(read_session(game)).agents if a.agent.id == agent_id)
    samples = merged_samples(agent)
    settings = ChairSettings(wheel_diameter_m=agent.agent.wheel_diameter_m, camber_deg=agent.agent.camber_deg)
    state = start(settings, samples[0], agent.agent.start_x_m, agent.agent.start_y_m, agent.agent.start_heading_rad)
    for sample in samples[1:]:
        state = step(settings, state, sample)
    return len(samples), state


def test_edge_publishes_the_same_poses_as_the_offline_path(game, free_endpoint, tmp_path):
    output = tmp_path / "edge.mcap"
    summary = edge_into_recorder(game, "chair01", output, free_endpoint())
    count, state = offline_run(game, "chair01")
    assert summary.samples == count
    np.testing.assert_allclose(summary.final_pose, state.mean[:3], atol=1e-6)

    data, recorded = read_session(game), read_session(output)
    assert set(recorded.imu) == {s.id for s in data.session.agent("chair01").sensors}  # raw data passed on
    truth = data.truth["chair01"]
    assert np.hypot(summary.final_pose[0] - truth.x_m[-1], summary.final_pose[1] - truth.y_m[-1]) < 3.0
    assert summary.poses >= 20 * 50 * 0.9  # 50 Hz


def test_poses_on_the_bus(game, free_endpoint, tmp_path):
    """The recorder sees EstimatedPose messages on pose/edge at about 50 Hz, covariance attached."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    output = tmp_path / "poses.mcap"
    edge_into_recorder(game, "chair02", output, free_endpoint())
    with open(output, "rb") as f:
        poses = [m for _, c, _, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()
                 if c.topic == "reckon/court/chair02/pose/edge"]
    assert len(poses) >= 900
    assert len(poses[-1].covariance) == 9 and poses[-1].method == "reckon"


def test_unknown_agent_and_scheme_are_config_errors(game):
    with pytest.raises(ConfigError, match="not in"):
        open_sources([f"mcap://{game}"], "chair99", 0.0, threading.Event())
    with pytest.raises(ConfigError, match="'ble://AA:BB': no sensor id in front; expected mcap://FILE"):
        open_sources(["ble://AA:BB"], "chair01", 0.0, threading.Event())
    with pytest.raises(ConfigError, match="'chair01-seat=ble://AA:BB': .*'AA:BB' is not a Bluetooth address"):
        open_sources(["chair01-seat=ble://AA:BB"], "chair01", 0.0, threading.Event())
    with pytest.raises(ConfigError, match="'chair01-seat=tcp://x': unknown scheme 'tcp' "
                                          r"\(known: mcap, serial, ble, phone\); expected mcap://FILE"):
        open_sources(["chair01-seat=tcp://x"], "chair01", 0.0, threading.Event())
    with pytest.raises(ConfigError, match="--venue VENUE.toml is needed"):
        open_sources(["chair01-seat=serial:///dev/null"], "chair01", 0.0, threading.Event())


def test_three_serial_devices_on_ptys_through_the_edge(game, free_endpoint):
    """x-IMU3 bytes on three real pseudo-terminals -> pyserial -> decoder -> merger -> filter."""
    from sim_devices.devices.ximu3 import SerialDevice

    agent = read_session(game).session.agent("chair01")
    # paced (20 x real time) like real devices sharing one clock; unpaced, each pty would race ahead
    devices = [SerialDevice.from_session(game, sensor.id, speed=20.0).open() for sensor in agent.sensors]
    stop = threading.Event()
    try:
        urls = [f"{sensor.id}=serial://{device.port}?baud=115200" for sensor, device in zip(agent.sensors, devices)]
        # reconnect_s=0: a device that goes away ends its stream at once
        session, source = open_sources(urls, "chair01", 0.0, stop, venue_toml=game, reconnect_s=0.0)
        result = {}
        edge = threading.Thread(target=lambda: result.update(summary=run_edge(
            zenoh_config(listen=[free_endpoint()]), session, "chair01", source, stop)), daemon=True)
        edge.start()
        for device in devices:
            device.play()
        for device in devices:
            assert device.wait_done(WAIT_S)
        # unplug only once every byte has been read: bytes still in a pty when it closes are lost,
        # as they would be on a real cable (an edge that ended early is caught by the assert below)
        readers = [reader for _, reader, _ in source.sources]
        wait_until(lambda: all(r.bytes_read >= d.bytes_total for r, d in zip(readers, devices)) or not edge.is_alive(),
                   WAIT_S, "the edge's serial readers to read every byte the three ptys wrote")
        assert [r.bytes_read for r in readers] == [d.bytes_total for d in devices]
    finally:
        for device in devices:
            device.close()  # the readers see the devices go away and end their streams
    edge.join(WAIT_S)
    assert not edge.is_alive()
    summary = result["summary"]

    count, state = offline_run(game, "chair01")
    assert summary.samples == count  # every sample crossed the serial path
    assert summary.wheel_overrun == 0
    # x-IMU3 carries microseconds and float32: the same path to within millimetres
    np.testing.assert_allclose(summary.final_pose[:2], state.mean[:2], atol=0.05)


# -- BLE sources through open_sources (the fake radio of support/ble.py) ----------------------------

THINGY_LEFT, THINGY_SEAT = "F1:22:33:44:55:01", "F1:22:33:44:55:03"


def ble_venue(tmp_path, identity: str | None = None):
    """A one-chair venue TOML with two beacons, the first with `identity` (if given)."""
    goal_a = {"id": "goal-a", "x_m": 1.575, "y_m": 7.5} | ({"identity": identity} if identity else {})
    chair = agent_table("chair01", sensors=[sensor_table("chair01-left", "left_wheel", spin_axis="+z"),
                                            sensor_table("chair01-right", "right_wheel", spin_axis="-z"),
                                            sensor_table("chair01-seat", "seat")])
    return write_venue(tmp_path / "venue.toml", "court", agents=[chair],
                       beacons=[goal_a, {"id": "goal-b", "x_m": 26.425, "y_m": 7.5}])


def test_ble_scan_and_thingy_through_open_sources(tmp_path):
    from protocol import messages

    radio, stop = FakeRadio(), threading.Event()
    venue = ble_venue(tmp_path, identity=f"ibeacon:{BEACON_UUID.upper()}:1:2")
    session, source = open_sources([f"chair01-seat=ble://{THINGY_SEAT.lower()}", "rx=ble://scan"], "chair01", 0.0,
                                   stop, venue_toml=venue,
                                   ble_factories={"client_factory": radio.Client, "scanner_factory": radio.Scanner})
    assert session.venue.beacons[0].identity == f"ibeacon:{BEACON_UUID}:1:2"
    ready = [radio.next_ready(), radio.next_ready()]
    client = next(r for r in ready if isinstance(r, FakeBleakClient))
    scanner = next(r for r in ready if r is not client)
    assert client.address == THINGY_SEAT
    scanner.advertise("C0:00:00:00:00:01", -64, manufacturer_data={0x004C: ibeacon_bytes(1, 2)})
    scanner.advertise("C0:00:00:00:00:02", -60, manufacturer_data={0x004C: ibeacon_bytes(1, 3)})  # not the venue's
    client.notify(motion_bytes((0, 0, 1024), (32, 0, 0), (0, 0, 0)))
    stop.set()
    out = list(source)
    assert source.join(WAIT_S)
    sightings = [m for m in out if messages.type_name(m) == "BeaconSighting"]
    assert [(m.agent_id, m.sensor_id, m.beacon_id, m.rssi_dbm) for m in sightings] == [
        ("chair01", "rx", "goal-a", -64.0)]
    batches = [m for m in out if messages.type_name(m) == "ImuBatch"]
    assert [(b.agent_id, b.sensor_id, len(b.sample_offset_ns)) for b in batches] == [("chair01", "chair01-seat", 1)]


def test_ble_source_configuration_errors(tmp_path):
    import re

    radio, stop = FakeRadio(), threading.Event()
    factories = {"client_factory": radio.Client, "scanner_factory": radio.Scanner}
    venue = ble_venue(tmp_path)
    for urls, message in (
            (["rx=ble://scan"], rf"'rx=ble://scan': no beacon in {re.escape(str(venue))} has an identity .*"
                                r"identity = .*\[\[venue.beacons\]\]"),
            ([f"chair01-seat=ble://{THINGY_SEAT}", "chair01-left=serial:///dev/null"],
             "ble and serial sources cannot be mixed on one edge: .*device's clock.*host's"),
            (["rx=ble://scan", "chair01-left=serial:///dev/null"], "ble and serial sources cannot be mixed"),
            ([f"chair01-seat=ble://{THINGY_SEAT}", f"chair01-seat=ble://{THINGY_LEFT}"],
             "'chair01-seat' is given twice"),
            ([f"chair09-seat=ble://{THINGY_SEAT}"], "chair01 has no sensor 'chair09-seat'"),
            (["rx/1=ble://scan"], "'rx/1=ble://scan': the receiver id"),
            ([f"chair01-seat=ble://{THINGY_SEAT}", "rx=ble://scan", "rx2=ble://scan"],
             "'rx2=ble://scan': one ble://scan per edge")):
        with pytest.raises(ConfigError, match=message):
            open_sources(urls, "chair01", 0.0, stop, venue_toml=venue, ble_factories=factories)
    with pytest.raises(ConfigError, match="--venue VENUE.toml is needed with BLE sources"):
        open_sources([f"chair01-seat=ble://{THINGY_SEAT}"], "chair01", 0.0, stop, ble_factories=factories)
    assert radio.made == []  # nothing was started


def test_a_phone_edge_forwards_its_barometer_and_names_floors(free_endpoint, tmp_path):
    """A walker of the two-floor simulated building through `reckon edge`: the Pressure readings go on
    to the bus as they came, and the edge's poses name floor 1 after the stairs."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    from sim_devices.pedestrian import simulate_pedestrian

    walk = tmp_path / "floors.mcap"
    simulate_pedestrian(walk, seed=1, people=1, preset="floors", mount="hand", duration_s=60.0)
    output = tmp_path / "edge.mcap"
    stop, ready = threading.Event(), threading.Event()
    session = read_session(walk).session
    endpoint = free_endpoint()
    recorder = threading.Thread(target=record, args=(zenoh_config(listen=[endpoint]), session.venue.name, output,
                                                     stop, ready), kwargs={"description": session}, daemon=True)
    recorder.start()
    assert ready.wait(WAIT_S)
    source = mcap_source(walk, "p01", speed=0.0, stop=threading.Event())
    run_edge(zenoh_config(connect=[endpoint]), session, "p01", source, threading.Event(), wait_for=1)
    stop.set()
    recorder.join(WAIT_S)
    with open(walk, "rb") as f:
        sent = [m.pressure_hpa for _, c, _, m in make_reader(f, decoder_factories=[DecoderFactory()])
                .iter_decoded_messages() if "/pressure/" in c.topic]
    with open(output, "rb") as f:
        seen = [(c.topic, m) for _, c, _, m in make_reader(f, decoder_factories=[DecoderFactory()])
                .iter_decoded_messages()]
    pressures = [m.pressure_hpa for topic, m in seen if topic == "reckon/pdr-office-2f/p01/pressure/p01-hand"]
    assert len(sent) > 500 and pressures == sent
    floors = [m.floor for topic, m in seen if topic == "reckon/pdr-office-2f/p01/pose/edge"]
    assert floors[0] == 0 and floors[-1] == 1 and sorted(floors) == floors  # one change, up
