"""Protocol: message round-trips, keys, strict session descriptions, MCAP session logs."""

from __future__ import annotations

import copy
import json
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol import keys, messages
from protocol.errors import ConfigError, InputError
from protocol.session import load_toml, session_from_dict, to_dict
from protocol.messages import imu_batch
from protocol.session_log import SessionWriter, read_session
from support.venue import agent_table, sensor_table, write_venue

SESSION = {
    "venue": {"name": "court", "beacons": [{"id": "goal-a", "x_m": 1.575, "y_m": 7.5}]},
    "agents": [{"id": "chair01", "wheel_diameter_m": 0.67, "sensors": [
        {"id": "chair01-left", "mount": "left_wheel", "spin_axis": "+z"},
        {"id": "chair01-right", "mount": "right_wheel", "spin_axis": "-z"},
        {"id": "chair01-seat", "mount": "seat"}]}],
}


def test_every_message_round_trips_with_schema_version():
    samples = {
        "ImuBatch": dict(timestamp_ns=1, agent_id="a", sensor_id="s", sequence=3, sample_offset_ns=[0, 5],
                         accel_g=[0.0] * 6, gyro_dps=[1.5] * 6),
        "BeaconSighting": dict(timestamp_ns=2, agent_id="a", sensor_id="s", beacon_id="b", rssi_dbm=-71.5),
        "TruthPose": dict(timestamp_ns=3, agent_id="a", x_m=1.25, y_m=-2.5, heading_rad=0.5),
        "EstimatedPose": dict(timestamp_ns=4, agent_id="a", x_m=1.0, y_m=2.0, covariance=[0.1] * 9,
                              method="paper", track=messages.Track.LIVE),
        "PoseBatch": dict(timestamp_ns=4, poses=[messages.new("EstimatedPose", timestamp_ns=3, agent_id=agent,
                                                              x_m=1.0, track=messages.Track.LIVE) for agent in "ab"]),
        "ImpactEvent": dict(timestamp_ns=5, agent_id="a", sensor_id="s", peak_g=9.5),
        "Correction": dict(timestamp_ns=6, agent_id="a", kind=messages.CorrectionKind.COLLISION, dx_m=0.5,
                           other_agent_id="b"),
        "TruthContact": dict(timestamp_ns=7, agent_id="a", other_agent_id="b", kind=messages.ContactKind.LATERAL,
                             closing_speed_mps=1.5),
        "Pressure": dict(timestamp_ns=15, agent_id="walker", sensor_id="phone", pressure_hpa=1013.2456),
        "FieldReading": dict(timestamp_ns=16, agent_id="a", x_m=3.0, y_m=4.5, offset_rad=-0.07, variance_rad2=0.002),
        "FieldMap": dict(timestamp_ns=17, agent_id="a", origin_x_m=-2.0, origin_y_m=-2.0, cell_m=2.0, columns=2,
                         rows=1, offset_rad=[0.05, -0.1], variance_rad2=[0.003, 0.0]),
        "PositionFix": dict(timestamp_ns=8, agent_id="a", kind=messages.CorrectionKind.MANUAL, x_m=1.0, y_m=2.0,
                            covariance=[0.25, 0.0, 0.0, 0.25], source_id="operator"),
        "SwimLength": dict(timestamp_ns=9, agent_id="a", sensor_id="s", method="reckon", index=2, start_ns=1,
                           swum_distance_m=25.2, lane_distance_m=25.0, duration_s=20.5, stroke_count=18,
                           stroke_rate_per_min=52.0, scale=0.98, heading_error_deg=-1.5,
                           lateral_deviation_m=[0.0, 0.1, -0.05], profile_step_m=1.0, walls_detected=True),
        "TruthLength": dict(timestamp_ns=10, agent_id="a", index=2, start_ns=1, swum_distance_m=25.1,
                            lane_distance_m=25.0, stroke_count=18, stroke="crawl", route="diagonal"),
        "CameraFrame": dict(timestamp_ns=11, camera_id="cam1", frame=4, track_id=[3, 7], x_m=[1.5, 2.0],
                            y_m=[0.5, 4.0], height_m=[1.7, 1.6], position_sd_m=0.05),
        "TruthTrackLabel": dict(timestamp_ns=11, camera_id="cam1", frame=4, track_id=[3, 7],
                                person_id=["p1", "p2+extra1"]),
        "TrackIdentity": dict(timestamp_ns=12, agent_id="p1", camera_id="cam1", track_id=3, method="reckon",
                              score=2.5),
        "StandScan": dict(timestamp_ns=13, agent_id="walker1", sensor_id="phone", stand_id="lobby", x_m=3.3,
                          y_m=33.55, floor=1, heading_rad=-1.57, tilt_rad=0.0, payload="RK1|...", accepted=False,
                          reason="integrity code does not match"),
        "ClockSample": dict(timestamp_ns=15, agent_id="a", sensor_id="s", received_ns=1_700_000_000_000_000_000),
        "DeviceStatus": dict(timestamp_ns=14, agent_id="a", sensor_id="s", connected=True, battery_pct=-1.0,
                             last_sample_age_s=0.02, samples=2000, gaps=1, duplicates=2, out_of_order=0,
                             clock_jumps=1, saturated=3, reconnects=1, spooled=0, flags=["saturated"]),
    }
    assert set(samples) == set(messages.TABLES)
    for name, fields in samples.items():
        message = messages.new(name, **fields)
        decoded = messages.CLASSES[name].FromString(message.SerializeToString())
        assert decoded == message
        assert decoded.schema_version == messages.SCHEMA_VERSION


def test_keys_are_built_and_parsed_in_one_place():
    key = keys.imu("court", "chair01", "chair01-left")
    assert key == "reckon/court/chair01/imu/chair01-left"
    assert keys.parse(key) == ("court", "chair01", "imu", "chair01-left")
    assert keys.all_agents("court", "imu/*") == "reckon/court/*/imu/*"
    with pytest.raises(ValueError, match="not under"):
        keys.parse("other/court")
    with pytest.raises(ConfigError, match="chair/1"):
        keys.check_id("chair/1", "agents[0].id")


def test_session_description_round_trips():
    session = session_from_dict(SESSION)
    assert session_from_dict(to_dict(session)) == session
    assert session.agent("chair01").wheel_diameter_m == 0.67
    assert session.agent("chair01").sensors[2].forward_axis == "+x"  # seat default: aligned with the chair


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d["agents"][0].update(wheel_size=1), r"agents\[0\]\.wheel_size: unknown key"),
    (lambda d: d["agents"][0]["sensors"][0].update(mount="wheel"), r"sensors\[0\]\.mount: 'wheel' is not one of"),
    (lambda d: d["agents"][0]["sensors"][1].update(mount="left_wheel"), "two sensors at mount 'left_wheel'"),
    (lambda d: d["agents"][0]["sensors"][1].update(id="chair01-left"), "duplicate sensor id 'chair01-left'"),
    (lambda d: d["agents"][0].update(wheel_diameter_m=6.1), r"wheel_diameter_m: 6.1 is outside \[0.2, 1.0\]"),
    (lambda d: d["agents"][0]["sensors"][0].pop("spin_axis"), "needs spin_axis"),
    (lambda d: d["venue"]["beacons"][0].pop("x_m"), "missing key 'x_m'"),
    (lambda d: d.update(agent=[]), "unknown key 'agent'"),
    (lambda d: d["agents"][0].update(id="hub"), r"agents\[0\]\.id: 'hub' is reserved for the hub's keys"),
    (lambda d: d["agents"][0].update(id="camera"), r"agents\[0\]\.id: 'camera' is reserved for the camera's keys"),
])
def test_session_description_errors_name_the_key(mutate, message):
    import copy

    data = copy.deepcopy(SESSION)
    mutate(data)
    with pytest.raises(ConfigError, match=message):
        session_from_dict(data)


def test_toml_errors_name_the_file(tmp_path):
    path = write_venue(tmp_path / "venue.toml", "court", colour="red")
    with pytest.raises(ConfigError, match=r"venue.toml: venue.colour: unknown key"):
        load_toml(path)
    path.write_text("[venue\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_toml(path)


def _write_log(path, batches=30):
    session = session_from_dict(SESSION)
    rng = np.random.default_rng(0)
    written = []
    with SessionWriter(path, session) as writer:
        for b in range(batches):
            times = 10**12 + (np.arange(20) + 20 * b) * 5_000_000
            accel, gyro = rng.normal(size=(20, 3)), rng.normal(size=(20, 3))
            mag = rng.normal(size=(20, 3))
            writer.write(keys.imu("court", "chair01", "chair01-seat"),
                         imu_batch("chair01", "chair01-seat", b, times, accel, gyro, mag))
            written.append((times, accel, gyro, mag))
        writer.write(keys.truth("court", "chair01"),
                     messages.new("TruthPose", timestamp_ns=10**12, agent_id="chair01", x_m=3.0, y_m=4.0))
    return session, written


def test_session_log_round_trip(tmp_path):
    session, written = _write_log(tmp_path / "s.mcap")
    data = read_session(tmp_path / "s.mcap")
    assert data.session == session
    series = data.imu["chair01-seat"]
    assert np.array_equal(series.time_ns, np.concatenate([w[0] for w in written]))
    # float32 on the wire
    np.testing.assert_allclose(series.gyro_dps, np.concatenate([w[2] for w in written]), rtol=1e-6, atol=1e-6)
    assert series.mag_gauss is not None and series.lost_batches == 0
    assert data.truth["chair01"].x_m[0] == 3.0
    assert data.problems == []


def test_truncated_log_keeps_what_came_before(tmp_path):
    _write_log(tmp_path / "s.mcap", batches=3000)  # several MCAP chunks
    raw = (tmp_path / "s.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(raw[: int(len(raw) * 0.7)])
    data = read_session(tmp_path / "cut.mcap")
    assert "truncated" in data.problems[0]
    kept = len(data.imu["chair01-seat"].time_ns)
    assert 0 < kept < 3000 * 20


def test_not_a_session_is_a_clear_error(tmp_path):
    (tmp_path / "x.mcap").write_bytes(b"not an mcap at all")
    with pytest.raises(InputError, match="not a reckon session"):
        read_session(tmp_path / "x.mcap")
    with pytest.raises(InputError, match="no such file"):
        read_session(tmp_path / "missing.mcap")


@settings(max_examples=30, deadline=None)
@given(st.lists(st.integers(min_value=0, max_value=4_000_000_000), min_size=1, max_size=40))
def test_imu_batch_times_survive_the_offset_encoding(offsets):
    times = 5 * 10**17 + np.array(sorted(offsets), dtype=np.int64)
    message = imu_batch("a", "s", 0, times, np.zeros((len(times), 3)), np.zeros((len(times), 3)), None)
    decoded = messages.ImuBatch.FromString(message.SerializeToString())
    assert np.array_equal(decoded.timestamp_ns + np.array(decoded.sample_offset_ns, dtype=np.int64), times)


def test_log_is_self_describing_for_generic_protobuf_readers(tmp_path):
    """Foxglove and `mcap cat` decode from the schema record alone: so must a generic reader."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    _write_log(tmp_path / "s.mcap", batches=2)
    with open(tmp_path / "s.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        decoded = [(schema.name, schema.encoding, channel.message_encoding, message)
                   for schema, channel, _, message in reader.iter_decoded_messages()]
    assert {d[0] for d in decoded} == {"reckon.v1.ImuBatch", "reckon.v1.TruthPose"}
    assert all(d[1] == "protobuf" and d[2] == "protobuf" for d in decoded)
    first = decoded[0][3]
    assert type(first) is not messages.ImuBatch  # built from the file's descriptors, not ours
    assert first.sensor_id == "chair01-seat" and len(first.accel_g) == 60


# -- beacon identities (the key `ble://scan` matches advertisements by) ---------------------------

IDENTITY_UUID = "e2c56db5-dffb-48d2-b060-d0f5a71096e0"


def test_beacon_identity_round_trips_through_toml_and_json(tmp_path):
    import json

    from protocol.session import to_json

    path = write_venue(tmp_path / "venue.toml", "court", beacons=[
        {"id": "goal-a", "x_m": 1.575, "y_m": 7.5, "identity": f"iBeacon:{IDENTITY_UUID.upper()}:0001:02"},
        {"id": "goal-b", "x_m": 26.425, "y_m": 7.5, "identity": "EDDYSTONE:00010203040506070809:A1B2C3D4E5F6"},
        {"id": "goal-c", "x_m": 14.0, "y_m": 7.5}],
        agents=[agent_table("chair01", sensors=[sensor_table("chair01-seat", "seat")])])
    session = load_toml(path)
    assert [b.identity for b in session.venue.beacons] == [
        f"ibeacon:{IDENTITY_UUID}:1:2", "eddystone:00010203040506070809:a1b2c3d4e5f6", None]
    data = to_dict(session)
    assert [b.get("identity") for b in data["venue"]["beacons"]] == [
        f"ibeacon:{IDENTITY_UUID}:1:2", "eddystone:00010203040506070809:a1b2c3d4e5f6", None]
    assert "identity" not in data["venue"]["beacons"][2]  # absent, not null: older logs stay byte-identical
    assert session_from_dict(to_dict(session)) == session
    assert session_from_dict(json.loads(to_json(session))) == session


def test_a_session_without_identities_serialises_as_before():
    data = to_dict(session_from_dict(SESSION))
    assert data["venue"]["beacons"] == [{"id": "goal-a", "x_m": 1.575, "y_m": 7.5, "radius_m": 1.0,
                                         "tx_power_dbm": -59.0, "height_m": 2.9}]


@pytest.mark.parametrize("identity", [
    f"ibeacon:{IDENTITY_UUID}:1:70000", "ibeacon:1234:1:2", "eddystone:0001:a1b2c3d4e5f6", "goal_a", 3, ""])
def test_bad_beacon_identity_names_the_key(identity):
    import copy

    data = copy.deepcopy(SESSION)
    data["venue"]["beacons"][0]["identity"] = identity
    with pytest.raises(ConfigError, match=r"venue\.beacons\[0\]\.identity: .* is not ibeacon:<uuid>"):
        session_from_dict(data)


def test_two_beacons_with_one_identity_are_refused():
    import copy

    data = copy.deepcopy(SESSION)
    data["venue"]["beacons"] = [{"id": "goal-a", "x_m": 1.5, "y_m": 7.5, "identity": f"ibeacon:{IDENTITY_UUID}:1:2"},
                                {"id": "goal-b", "x_m": 26.5, "y_m": 7.5, "identity": f"ibeacon:{IDENTITY_UUID}:01:2"}]
    with pytest.raises(ConfigError, match=f"duplicate beacon identity 'ibeacon:{IDENTITY_UUID}:1:2'"):
        session_from_dict(data)


@pytest.mark.parametrize("text", [
    f"ibeacon:{IDENTITY_UUID}:0:65535", f" IBEACON:{IDENTITY_UUID.upper()}:00007:0 ",
    f"ibeacon:{IDENTITY_UUID}:1:65536",
    "eddystone:00010203040506070809:a1b2c3d4e5f6", "eddystone:00010203040506070809:a1b2c3d4e5f", "ibeacon:x:1:2",
    "Eddystone:AAAAAAAAAAAAAAAAAAAA:BBBBBBBBBBBB", 7, None])
def test_identity_rule_is_the_edge_decoders_rule(text):
    """protocol keeps its own copy of the rule (it imports nothing from edge): the two must agree."""
    from edge.decoders.ble_adverts import normalize_identity
    from protocol.session import beacon_identity

    results = []
    for rule in (beacon_identity, normalize_identity):
        try:
            results.append(rule(text, "where"))
        except ConfigError as error:
            results.append(str(error))
    assert results[0] == results[1]


PEDESTRIAN_VENUE = {
    "venue": {"name": "hall", "stands": [{"id": "entrance", "x_m": 3.3, "y_m": 33.55, "heading_deg": -90.0}],
              "map_points": [{"id": "A", "x_m": 0.0, "y_m": 0.0, "directions_deg": [0, 90]},
                             {"id": "B", "x_m": 3.3, "y_m": 0.0, "directions_deg": [0, 180, 90]}],
              "floor_plan": [[[[0, -1], [5, -1], [5, 1], [0, 1]]]]},
    "agents": [{"id": "walker1", "kind": "pedestrian", "height_m": 1.74,
                "sensors": [{"id": "walker1-phone", "mount": "hand", "rate_hz": 50, "forward_axis": "+y",
                             "left_axis": "-x"}]}],
}


def test_pedestrian_venue_round_trips_through_json_and_a_geojson_file(tmp_path):
    session = session_from_dict(PEDESTRIAN_VENUE)
    assert session_from_dict(to_dict(session)) == session
    assert session.venue.stands[0].heading_deg == -90.0 and session.agents[0].height_m == 1.74
    plan = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": [[[0, -1], [5, -1], [5, 1], [0, 1]]]}}]}
    (tmp_path / "plan.geojson").write_text(json.dumps(plan))
    write_venue(tmp_path / "venue.toml", "hall", floor_plan="plan.geojson", agents=[agent_table("walker1", "pedestrian")])
    assert load_toml(tmp_path / "venue.toml").venue.floor_plan == session.venue.floor_plan
    # A chair venue's description is unchanged by the pedestrian fields (older logs stay identical).
    assert "stands" not in to_dict(session_from_dict(SESSION))["venue"]
    assert "height_m" not in to_dict(session_from_dict(SESSION))["agents"][0]


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d["venue"]["stands"][0].update(heading_deg=400), "venue.stands[0].heading_deg: 400 is outside"),
    (lambda d: d["venue"]["map_points"][0].update(directions_deg=[]), "venue.map_points[0].directions_deg: expected"),
    (lambda d: d["venue"]["map_points"][1].update(directions_deg=[0, "north"]),
     "venue.map_points[1].directions_deg[1]: 'north' is not a finite number"),
    (lambda d: d["venue"].update(floor_plan=[[[[0, 0], [1, 0]]]]), "venue.floor_plan[0][0]: a ring needs at least 3"),
    (lambda d: d["venue"].update(floor_plan="missing.geojson"), "venue.floor_plan: cannot read missing.geojson"),
    (lambda d: d["venue"]["stands"].append({"id": "entrance", "x_m": 0, "y_m": 0}), "duplicate stand id 'entrance'"),
    (lambda d: d["agents"][0].update(height_m=3.1), "agents[0].height_m: 3.1 is outside [0.5, 2.5]"),
])
def test_pedestrian_venue_errors_name_the_key(mutate, message):
    data = copy.deepcopy(PEDESTRIAN_VENUE)
    mutate(data)
    with pytest.raises(ConfigError, match=re.escape(message)):
        session_from_dict(data)
