"""Pedestrian simulator, preset `floors` (docs/simulator-pedestrian.md): two floors joined by a staircase,
the truth's floor, each floor's plan, the phones' barometers (hypsometric pressure difference between
floors), the BLE beacons on each floor (path loss, floor-slab loss), stands on floor 1, the
--beacons / --barometer options on other presets, parameter validation and determinism.

One module-scoped full `floors` session of two walkers (about 0.5 s) carries most checks; the rest
are short sessions."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import shapely

from hub.pedestrian.walkable import plan_area
from protocol.errors import ConfigError
from protocol.session_log import LogMessages, read_session
from sim_devices.pedestrian import PedestrianParams, params_with_overrides, simulate_pedestrian
from sim_devices.pedestrian.params import check

STAIRWELL = shapely.box(12.6, 1.4, 24.1, 4.05)  # docs / floors.py: x 12.6-24.1 m, y 1.4-4.05 m
HALF_LANDING_X_M = (17.76, 18.96)  # foot 14.4 + flight 3.36, then the 1.2 m landing
OFF_STAIRS_Y_M = 4.5  # the corridor's centre line is y 5.2; the stair run is at y 2.2
PLAN_TOLERANCE_M = 0.3
DEFAULTS = PedestrianParams()
# p = p0 exp(-z / H), H = R_d T / g (dry air), written out here rather than imported
SCALE_HEIGHT_M = 287.05 * (DEFAULTS.barometer.air_temperature_c + 273.15) / 9.80665


def _floor_drop_hpa(height_m: float = DEFAULTS.floors.height_m) -> float:
    return DEFAULTS.barometer.ground_hpa * (1.0 - math.exp(-height_m / SCALE_HEIGHT_M))


def _messages(path: Path, *names: str) -> list[tuple[int, str, object]]:
    return list(LogMessages(path, lambda topic, name: name in names))


def _by_sensor(rows, field: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    grouped: dict[str, list[tuple[int, float]]] = {}
    for _, _, message in rows:
        grouped.setdefault(message.sensor_id, []).append((message.timestamp_ns, getattr(message, field)))
    return {sensor: (np.array([r[0] for r in values], dtype=np.int64), np.array([r[1] for r in values]))
            for sensor, values in grouped.items()}


def _truth_at(truth, stamps_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, floor) of the truth at the given stamps: x, y interpolated, the floor of the nearest pose."""
    x = np.interp(stamps_ns, truth.time_ns, truth.x_m)
    y = np.interp(stamps_ns, truth.time_ns, truth.y_m)
    right = np.clip(np.searchsorted(truth.time_ns, stamps_ns), 1, len(truth.time_ns) - 1)
    nearer = np.where(stamps_ns - truth.time_ns[right - 1] < truth.time_ns[right] - stamps_ns, right - 1, right)
    return x, y, truth.floor[nearer]


@pytest.fixture(scope="module")
def floors_run(tmp_path_factory):
    path = tmp_path_factory.mktemp("floors") / "floors.mcap"
    summary = simulate_pedestrian(path, seed=1, people=2, preset="floors", mount="hand")
    return path, summary


@pytest.fixture(scope="module")
def floors_data(floors_run):
    data = read_session(floors_run[0])
    assert data.problems == []
    return data


# -- floors and plans ------------------------------------------------------------------------------


def test_venue_has_a_plan_per_floor_both_with_the_stairwell(floors_data):
    venue = floors_data.session.venue
    assert venue.name == "pdr-office-2f"
    assert venue.floors == (0, 1)
    assert [number for number, _ in venue.floor_plans] == [0, 1]
    ground, upper = plan_area(venue.plan_of(0)), plan_area(venue.plan_of(1))
    assert not ground.equals(upper)
    for area in (ground, upper):
        assert area.covers(STAIRWELL.buffer(-0.01))
    # the docs' differences: the hall on floor 0 only (a void on floor 1); floor 1's open office has no
    # partitions between the north rooms (x 13.9-14.2 m is a wall on floor 0)
    hall, partition = shapely.Point(41.0, 12.0), shapely.Point(14.05, 14.6)
    assert ground.covers(hall) and not upper.covers(hall)
    assert upper.covers(partition) and not ground.covers(partition)
    assert floors_data.session.source["floor_height_m"] == DEFAULTS.floors.height_m


def test_each_walker_goes_up_once_and_comes_down_once(floors_run, floors_data):
    _, summary = floors_run
    assert set(floors_data.truth) == {"p01", "p02"}
    for agent_id, truth in floors_data.truth.items():
        floors = truth.floor
        assert floors is not None, f"{agent_id}: TruthPose carries no floor"
        assert set(np.unique(floors).tolist()) == {0, 1}
        changes = np.flatnonzero(np.diff(floors))
        assert len(changes) == 2, f"{agent_id}: {len(changes)} floor changes"
        assert floors[0] == 0 and floors[changes[0] + 1] == 1 and floors[-1] == 0
        # the floor changes on the stair, at the half landing (it counts as the upper floor)
        for row in (*changes, *(changes + 1)):
            assert STAIRWELL.covers(shapely.Point(truth.x_m[row], truth.y_m[row]))
            assert HALF_LANDING_X_M[0] - 0.5 <= truth.x_m[row] <= HALF_LANDING_X_M[1] + 0.5
        # some time on floor 1 well away from the stair
        upper = (floors == 1) & (truth.y_m > OFF_STAIRS_Y_M)
        assert np.count_nonzero(upper) * 0.5 > 30.0
    assert summary.floor_changes == 4


def test_truth_positions_are_walkable_on_their_own_floor(floors_data):
    venue = floors_data.session.venue
    areas = {floor: plan_area(venue.plan_of(floor)) for floor in venue.floors}
    for agent_id, truth in floors_data.truth.items():
        points = shapely.points(truth.x_m, truth.y_m)
        for floor, area in areas.items():
            mine = truth.floor == floor
            off = shapely.distance(area, points[mine])
            worst = float(np.max(off)) if len(off) else 0.0
            assert worst <= PLAN_TOLERANCE_M, f"{agent_id} on floor {floor}: {worst:.2f} m off the plan"
            # the track between consecutive poses on this floor stays on its plan too (2 Hz chords)
            track = _track(truth, floor)
            assert track.length > 50.0
            assert track.difference(area.buffer(0.05)).length < 0.1, (agent_id, floor)
        # floor 1's tour goes through the open office: across floor 0's two partitions (0.3 m each)
        # between the north rooms, which floor 0's plan does not allow
        crossed = _track(truth, 1).difference(areas[0]).length
        assert crossed == pytest.approx(0.6, abs=0.1), agent_id


def _track(truth, floor: int) -> shapely.MultiLineString:
    """The truth's chords between consecutive poses both on `floor`."""
    rows = np.flatnonzero((truth.floor[:-1] == floor) & (truth.floor[1:] == floor))
    return shapely.multilinestrings([[(truth.x_m[i], truth.y_m[i]), (truth.x_m[i + 1], truth.y_m[i + 1])]
                                     for i in rows])


# -- barometer -------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def pressure(floors_run):
    return _by_sensor(_messages(floors_run[0], "Pressure"), "pressure_hpa")


def test_pressure_streams_rate_and_stamps(floors_run, floors_data, pressure):
    path, summary = floors_run
    sensors = {s.id: agent.id for agent in floors_data.session.agents for s in agent.sensors}
    assert set(pressure) == set(sensors) == {"p01-hand", "p02-hand"}
    rate = DEFAULTS.barometer.rate_hz
    for sensor_id, (stamps, values) in pressure.items():
        assert np.all(np.diff(stamps) > 0), sensor_id
        span_s = (stamps[-1] - stamps[0]) * 1e-9
        assert (len(stamps) - 1) / span_s == pytest.approx(rate, rel=0.01)
        assert np.median(np.diff(stamps)) * 1e-9 == pytest.approx(1.0 / rate, rel=0.01)
        imu = floors_data.imu[sensor_id].time_ns  # the barometer runs over the phone's whole recording
        assert abs(stamps[0] - imu[0]) < 0.05e9 and abs(stamps[-1] - imu[-1]) < 1.0 / rate * 1e9
        assert np.all(np.abs(values - DEFAULTS.barometer.ground_hpa) < 5.0)
    assert summary.pressure_samples == sum(len(s) for s, _ in pressure.values())
    for _, topic, message in _messages(path, "Pressure"):
        assert message.agent_id == sensors[message.sensor_id] and topic.endswith(f"/pressure/{message.sensor_id}")


def _transits(truth):
    """(time of the floor change, floor left, floor reached) of each stair transit."""
    return [(int(truth.time_ns[row]), int(truth.floor[row]), int(truth.floor[row + 1]))
            for row in np.flatnonzero(np.diff(truth.floor))]


def test_pressure_drops_by_the_hypsometric_figure_upstairs(floors_data, pressure):
    """Each stair transit: the median pressure over the last (up to) 20 s off the stairs on the floor left
    minus that over the first 20 s off the stairs on the floor reached is +0.47 hPa going up (4 m at ~0.117 hPa/m), -0.47 coming down;
    the same phone, so its offset cancels; the noise (0.015 hPa a sample) averages out and the
    weather trend (SD 0.2 hPa/h) and building jumps (SD 0.05 hPa, 0.5/min) stay within 0.15 hPa."""
    drop = _floor_drop_hpa()
    assert drop == pytest.approx(0.467, abs=0.005)
    assert drop / DEFAULTS.floors.height_m == pytest.approx(0.117, abs=0.002)
    for agent_id, truth in floors_data.truth.items():
        stamps, values = pressure[f"{agent_id}-hand"]
        _, y, floor = _truth_at(truth, stamps)
        off = y > OFF_STAIRS_Y_M
        window = int(20.0 * DEFAULTS.barometer.rate_hz)
        for change_ns, left, reached in _transits(truth):
            before = np.flatnonzero(off & (floor == left) & (stamps < change_ns))[-window:]
            after = np.flatnonzero(off & (floor == reached) & (stamps > change_ns))[:window]
            assert len(before) >= window // 4 and len(after) >= window // 4  # at least 5 s each side
            assert stamps[after[-1]] - stamps[before[0]] < 90e9  # both sides near the transit
            step = float(np.median(values[before]) - np.median(values[after]))
            assert step == pytest.approx(drop * (reached - left), abs=0.15), (agent_id, left, reached, step)


def test_pressure_step_exact_once_the_recorded_weather_is_removed(floors_data, pressure):
    """`source.barometer` holds the session's draws (trend, building jumps): with that common part
    taken off (each jump as a step halfway through its rise, the rise itself left out), the floor
    step of every transit (a minute either side) and over the whole walk is the hypsometric figure
    to 0.02 hPa (about 0.17 m)."""
    drop = _floor_drop_hpa()
    source = floors_data.session.source
    record = source["barometer"]
    assert record["ground_hpa"] == DEFAULTS.barometer.ground_hpa
    assert record["scale_height_m"] == pytest.approx(SCALE_HEIGHT_M, rel=1e-6)
    epoch_ns = source["params"]["clock"]["start_unix_s"] * 1_000_000_000
    rise_s = DEFAULTS.barometer.hvac_rise_s
    for agent_id, truth in floors_data.truth.items():
        stamps, values = pressure[f"{agent_id}-hand"]
        _, y, floor = _truth_at(truth, stamps)
        session_s = (stamps - epoch_ns) * 1e-9
        world = record["trend_hpa_per_h"] / 3600.0 * session_s
        usable = y > OFF_STAIRS_Y_M
        for jump in record["jumps"]:
            world = world + jump["hpa"] * (session_s >= jump["time_s"] + rise_s / 2)
            usable &= ~((session_s > jump["time_s"]) & (session_s < jump["time_s"] + rise_s))
        calm = values - world
        for change_ns, left, reached in _transits(truth):
            before = usable & (floor == left) & (stamps < change_ns) & (stamps > change_ns - 60e9)
            after = usable & (floor == reached) & (stamps > change_ns) & (stamps < change_ns + 60e9)
            assert before.sum() > 50 and after.sum() > 50
            step = float(np.median(calm[before]) - np.median(calm[after]))
            assert step == pytest.approx(drop * (reached - left), abs=0.02), (agent_id, left, reached, step)
        whole = float(np.median(calm[usable & (floor == 0)]) - np.median(calm[usable & (floor == 1)]))
        assert whole == pytest.approx(drop, abs=0.02), agent_id


def test_pressure_in_calm_air_gives_floor_and_phone_height(tmp_path):
    """No weather trend, no building jumps, no noise: the floor-to-floor difference is the hypsometric
    figure to 0.01 hPa, and ground pressure + the recorded offset - the median on floor 0 is the
    hand phone's height above the floor (hand_height_ratio x stature) to 0.1 m."""
    path = tmp_path / "calm.mcap"
    params = params_with_overrides({"barometer.weather_trend_hpa_per_h": "0", "barometer.hvac_jump_hpa": "0",
                                    "barometer.noise_hpa": "0"})
    simulate_pedestrian(path, seed=3, people=1, preset="floors", mount="hand", duration_s=90.0, params=params)
    data = read_session(path)
    truth, agent = data.truth["p01"], data.session.agents[0]
    stamps, values = _by_sensor(_messages(path, "Pressure"), "pressure_hpa")["p01-hand"]
    _, y, floor = _truth_at(truth, stamps)
    off = y > OFF_STAIRS_Y_M
    assert np.count_nonzero(off & (floor == 1)) > 100
    ground, upper = float(np.median(values[off & (floor == 0)])), float(np.median(values[off & (floor == 1)]))
    assert ground - upper == pytest.approx(_floor_drop_hpa(), abs=0.01)
    offset = data.session.source["barometer"]["offset_hpa"]["p01-hand"]
    phone_m = -SCALE_HEIGHT_M * math.log((ground - offset) / DEFAULTS.barometer.ground_hpa)
    assert phone_m == pytest.approx(DEFAULTS.people.hand_height_ratio * agent.height_m, abs=0.1)


# -- BLE beacons -----------------------------------------------------------------------------------


def test_beacons_six_per_floor_in_the_venue(floors_run, floors_data):
    beacons = floors_data.session.venue.beacons
    assert len(beacons) == 12 == floors_run[1].beacons
    assert len({b.id for b in beacons}) == 12
    for floor in (0, 1):
        mine = [b for b in beacons if b.floor == floor]
        assert len(mine) == 6, floor
    areas = {floor: plan_area(floors_data.session.venue.plan_of(floor)) for floor in (0, 1)}
    for beacon in beacons:
        assert beacon.floor in (0, 1)
        assert beacon.height_m == DEFAULTS.ble.height_m and beacon.tx_power_dbm == -59.0
        assert areas[beacon.floor].covers(shapely.Point(beacon.x_m, beacon.y_m)), beacon.id
    assert set(floors_data.session.source["ble"]["tx_power_dbm"]) == {b.id for b in beacons}


def test_sightings_name_venue_beacons_with_whole_rssi(floors_run, floors_data):
    path, summary = floors_run
    ids = {b.id for b in floors_data.session.venue.beacons}
    rows = _messages(path, "BeaconSighting")
    assert len(rows) == summary.beacon_sightings > 0
    sensors = {s.id: agent.id for agent in floors_data.session.agents for s in agent.sensors}
    sensitivity = DEFAULTS.ble.sensitivity_dbm
    for _, topic, message in rows:
        assert message.beacon_id in ids
        assert message.rssi_dbm == round(message.rssi_dbm) and sensitivity <= message.rssi_dbm <= 0.0
        assert message.agent_id == sensors[message.sensor_id] and topic.endswith(f"/beacon/{message.sensor_id}")
    assert {m.beacon_id for _, _, m in rows} == ids  # every beacon is heard by someone
    for sensor_id, (stamps, _) in _by_sensor(rows, "rssi_dbm").items():
        assert np.all(np.diff(stamps) >= 0), sensor_id


def test_sightings_stronger_near_the_beacon_on_its_floor(floors_data):
    """Off the stairs (there the phone's storey is between the two): the median RSSI within 3 m
    (horizontally) of a beacon on the walker's floor beats that > 15 m away on that floor by at least
    10 dB (path loss); and at the same 3-D distance (2.5-5 m: the beacon a floor up or down, or on the
    walker's floor) a beacon on the other floor is heard at least 6 dB weaker (the slab's
    `ble.floor_loss_db`, 20 dB, less what the sensitivity cut hides)."""
    beacons = {b.id: b for b in floors_data.session.venue.beacons}
    height, ble = DEFAULTS.floors.height_m, DEFAULTS.ble
    for agent in floors_data.session.agents:
        truth, seen = floors_data.truth[agent.id], floors_data.sightings[agent.id]
        x, y, floor = _truth_at(truth, seen.time_ns)
        bx = np.array([beacons[i].x_m for i in seen.beacon_id])
        by = np.array([beacons[i].y_m for i in seen.beacon_id])
        bfloor = np.array([beacons[i].floor for i in seen.beacon_id])
        across = np.hypot(x - bx, y - by)
        phone_z = floor * height + DEFAULTS.people.hand_height_ratio * agent.height_m
        distance = np.hypot(across, bfloor * height + ble.height_m - phone_z)
        off, same = y > OFF_STAIRS_Y_M, bfloor == floor
        band = (distance > 2.5) & (distance < 5.0)
        groups = {"near": off & same & (across < 3.0), "far": off & same & (across > 15.0),
                  "band, same floor": off & same & band, "band, other floor": off & ~same & band}
        medians = {}
        for name, chosen in groups.items():
            assert np.count_nonzero(chosen) >= 5, (agent.id, name)
            medians[name] = float(np.median(seen.rssi_dbm[chosen]))
        assert medians["near"] >= medians["far"] + 10.0, (agent.id, medians)
        assert medians["band, same floor"] >= medians["band, other floor"] + 6.0, (agent.id, medians)


# -- stands ----------------------------------------------------------------------------------------


def test_stand_scans_carry_the_stands_floor(floors_data):
    stands = {s.id: s for s in floors_data.session.venue.stands}
    assert {"stand-s1", "stand-hall", "stand-f1"} <= set(stands)
    assert stands["stand-f1"].floor == 1 and stands["stand-s1"].floor == 0 and stands["stand-hall"].floor == 0
    upstairs = 0
    for agent_id, scans in floors_data.scans.items():
        truth = floors_data.truth[agent_id]
        assert scans and scans[0].stand_id == "stand-s1"
        stamps = np.array([scan.timestamp_ns for scan in scans], dtype=np.int64)
        x, y, floor = _truth_at(truth, stamps)
        for scan, tx, ty, tfloor in zip(scans, x, y, floor):
            stand = stands[scan.stand_id]
            assert scan.accepted and scan.floor == stand.floor
            assert (scan.x_m, scan.y_m) == pytest.approx((stand.x_m, stand.y_m), abs=1e-6)
            assert tfloor == stand.floor, (agent_id, scan.stand_id)
            assert math.hypot(tx - stand.x_m, ty - stand.y_m) < 1.0, (agent_id, scan.stand_id)
            upstairs += scan.stand_id == "stand-f1"
    assert upstairs >= 1  # tour 0 passes stand-f1 heading west on floor 1


# -- options ---------------------------------------------------------------------------------------


def test_floorplan_has_no_barometer_nor_beacons_by_default(tmp_path):
    path = tmp_path / "plain.mcap"
    summary = simulate_pedestrian(path, seed=1, people=1, preset="floorplan", mount="hand", duration_s=20.0)
    assert _messages(path, "Pressure", "BeaconSighting") == []
    assert (summary.pressure_samples, summary.beacons, summary.beacon_sightings, summary.floor_changes) == (0, 0, 0, 0)
    data = read_session(path)
    assert data.session.venue.beacons == () and data.session.venue.floor_plans == ()
    assert data.truth["p01"].floor is None  # all floor 0
    assert not {"barometer", "ble"} & set(data.session.source)


def test_floorplan_with_barometer_and_four_beacons(tmp_path):
    path = tmp_path / "extras.mcap"
    summary = simulate_pedestrian(path, seed=1, people=1, preset="floorplan", mount="hand", duration_s=20.0,
                                  barometer=True, beacons=4)
    rows = _messages(path, "Pressure", "BeaconSighting")
    names = [message.DESCRIPTOR.name for _, _, message in rows]
    assert names.count("Pressure") == summary.pressure_samples > 0.9 * 20 * DEFAULTS.barometer.rate_hz
    assert names.count("BeaconSighting") == summary.beacon_sightings > 0
    beacons = read_session(path).session.venue.beacons
    assert len(beacons) == 4 and {b.floor for b in beacons} == {0}
    assert {m.beacon_id for _, _, m in rows if m.DESCRIPTOR.name == "BeaconSighting"} <= {b.id for b in beacons}
    values = np.array([m.pressure_hpa for _, _, m in rows if m.DESCRIPTOR.name == "Pressure"])
    assert np.ptp(values) < 0.3  # one floor: noise, a jump or two, no 0.47 hPa steps


@pytest.mark.parametrize("beacons", [-1, 9, True, 2.0])
def test_bad_beacon_count_is_a_config_error(tmp_path, beacons):
    with pytest.raises(ConfigError, match="beacons"):
        simulate_pedestrian(tmp_path / "bad.mcap", seed=1, people=1, preset="floors", duration_s=5.0,
                            beacons=beacons)


@pytest.mark.parametrize("overrides, key", [
    ({"barometer.rate_hz": "500"}, "barometer.rate_hz"),
    ({"barometer.rate_hz": "40", "sensors.rate_hz": "20"}, "barometer.rate_hz"),
    ({"ble.path_loss_exponent_min": "5", "ble.path_loss_exponent_max": "2"}, "ble.path_loss_exponent_min"),
    ({"floors.height_m": "1"}, "floors.height_m"),
    ({"ble.sensitivity_dbm": "-20"}, "ble.sensitivity_dbm"),
    ({"barometer.noise_hpa": "lots"}, "barometer.noise_hpa"),
])
def test_bad_floor_barometer_ble_values_name_the_key(overrides, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        params_with_overrides(overrides)


def test_check_rejects_a_barometer_faster_than_the_imu():
    params = PedestrianParams()
    fast = dataclasses.replace(params, barometer=dataclasses.replace(params.barometer, rate_hz=40.0),
                               sensors=dataclasses.replace(params.sensors, rate_hz=20.0))
    with pytest.raises(ConfigError, match=r"barometer\.rate_hz"):
        check(fast)
    check(params)  # the defaults pass
    with pytest.raises(ConfigError, match=r"barometer\.rate_hz"):
        simulate_pedestrian(Path("/nonexistent/never.mcap"), preset="floors", people=1, duration_s=5.0,
                            params=fast)


# -- determinism -----------------------------------------------------------------------------------


def _all_messages(path: Path) -> list[tuple[int, str, bytes]]:
    return [(log_time, topic, message.SerializeToString()) for log_time, topic, message in LogMessages(path)]


def test_same_seed_same_log(floors_run, tmp_path):
    path, _ = floors_run
    again = tmp_path / "again.mcap"
    simulate_pedestrian(again, seed=1, people=2, preset="floors", mount="hand")
    first, second = _all_messages(path), _all_messages(again)
    assert len(first) == len(second) > 0
    assert first == second
    assert read_session(path).session.source == read_session(again).session.source
    other = tmp_path / "other.mcap"
    simulate_pedestrian(other, seed=2, people=1, preset="floors", mount="hand", duration_s=30.0)
    pressures = [m.pressure_hpa for _, _, m in _messages(other, "Pressure")]
    assert pressures != [m.pressure_hpa for _, _, m in _messages(path, "Pressure")][:len(pressures)]
