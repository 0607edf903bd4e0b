"""Wheelchair-basketball simulator: determinism, log contents, physics, sensor conventions, overrides."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from edge.mounting import signed_axis
from edge.chair.paper.wheel import chair_travel_m, travel_from_rotation_m, wheel_rotation_deg
from protocol.errors import ConfigError
from protocol.session import Mount
from protocol.session_log import SessionData, read_session
from sim_devices.wheelchair import SimParams, describe, error_free, params_with_overrides, simulate
from sim_devices.wheelchair.kinematics import STANDARD_GRAVITY, ChairBuild, wheel_imu
from sim_devices.wheelchair.motion import Motion, simulate_motion
from support.games import Game

DOCS = Path(__file__).resolve().parents[2] / "docs" / "simulator.md"
PLAYERS, DURATION_S = 4, 30.0
GAME = Game(PLAYERS, DURATION_S, seed=11)  # a short game with every default error on
# every sensor, wheel, radio and clock error off; three times the blocks, so 30 s has many contacts
IDEAL = Game(PLAYERS, DURATION_S, seed=12, overrides=(("game.block_rate_per_min", "6"),), error_free=True)


@pytest.fixture(scope="module")
def default_game(game, games) -> tuple[SessionData, object]:
    """GAME read back, and what the simulator said about it."""
    return read_session(game), games.summary(GAME)


@pytest.fixture(scope="module")
def ideal(games) -> tuple[SessionData, object]:
    """IDEAL read back, and what the simulator said about it."""
    return read_session(games.path(IDEAL)), games.summary(IDEAL)


def _records(path: Path) -> list[tuple[str, int, bytes]]:
    with open(path, "rb") as stream:
        return [(channel.topic, message.log_time, message.data)
                for _, channel, message in make_reader(stream).iter_messages(log_time_order=False)]


def _z(accel_g: np.ndarray) -> np.ndarray:
    return np.abs(np.linalg.norm(accel_g, axis=1) - 1.0)


# -- determinism and log contents ---------------------------------------------------------------


def test_same_seed_gives_identical_messages_and_another_seed_differs(tmp_path: Path):
    runs = {name: tmp_path / f"{name}.mcap" for name in ("a", "b", "c")}
    for name, seed in (("a", 3), ("b", 3), ("c", 4)):
        simulate(2, 10.0, seed, runs[name])
    first, again, other = (_records(path) for path in runs.values())
    assert len(first) > 1000
    assert first == again
    assert first != other


def test_log_reads_back_with_every_sensor_beacon_and_truth(default_game):
    data, summary = default_game
    assert data.problems == []
    venue = data.session.venue
    assert (venue.name, venue.court_length_m, venue.court_width_m) == ("court", 28.0, 15.0)
    assert sorted((b.x_m, b.y_m, b.radius_m, b.height_m, b.tx_power_dbm) for b in venue.beacons) == [
        (1.575, 7.5, 1.0, 2.9, -59.0), (26.425, 7.5, 1.0, 2.9, -59.0)]
    assert [a.id for a in data.session.agents] == ["chair01", "chair02", "chair03", "chair04"]
    for agent in data.session.agents:
        left, right, seat = (agent.sensor(m) for m in (Mount.LEFT_WHEEL, Mount.RIGHT_WHEEL, Mount.SEAT))
        assert (left.id, left.spin_axis, right.id, right.spin_axis) == (
            f"{agent.id}-left", "+z", f"{agent.id}-right", "-z")
        assert (seat.id, seat.forward_axis, seat.left_axis) == (f"{agent.id}-seat", "+x", "+y")
        assert data.imu[left.id].mag_gauss is None and data.imu[right.id].mag_gauss is None
        assert data.imu[seat.id].mag_gauss.shape == data.imu[seat.id].accel_g.shape
        for sensor in (left, right, seat):
            series = data.imu[sensor.id]
            expected = DURATION_S * 200 - 20 * series.lost_batches
            assert len(series.time_ns) >= expected - 20 * 3  # lost batches at the very end show no gap
        truth = data.truth[agent.id]
        assert len(truth.time_ns) == DURATION_S * 50
        assert set(data.sightings[agent.id].beacon_id) == {"goal-a", "goal-b"}
        assert agent.wheel_diameter_m in (0.61, 0.67)
        assert 15.0 <= agent.camber_deg <= 20.0
    source = data.session.source
    assert (source["seed"], source["players"], source["duration_s"]) == (11, PLAYERS, DURATION_S)
    assert source["params"] == dataclasses.asdict(SimParams())
    assert len(data.contacts) == summary.contacts > 0
    assert all(c.agent_id < c.other_agent_id for c in data.contacts)


def test_summary_counts_match_the_log(tmp_path: Path):
    path = tmp_path / "lossy.mcap"
    summary = simulate(2, 20.0, 5, path, params_with_overrides({"radio.batch_loss_rate": "0.2"}))
    data = read_session(path)
    written = sum(len(series.time_ns) for series in data.imu.values())
    assert written == summary.imu_samples_written < summary.imu_samples
    assert 0 < sum(series.lost_batches for series in data.imu.values()) <= summary.lost_batches
    assert sum(len(s.time_ns) for s in data.sightings.values()) == summary.sightings
    assert summary.truth_poses == sum(len(t.time_ns) for t in data.truth.values())


# -- physics --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def motion() -> Motion:
    return simulate_motion(6, 60.0, SimParams(), np.random.default_rng(21))


def test_speeds_yaw_rates_and_positions_stay_physical(motion: Motion, default_game):
    params = SimParams()
    assert np.abs(motion.speed_mps).max() <= 4.6
    assert motion.speed_mps.max() > 3.0  # they do sprint
    assert motion.speed_mps.min() < -0.3  # and push backward
    assert np.degrees(np.abs(motion.yaw_roll_rps)).max() <= params.chair.yaw_rate_max_dps + 1e-9
    assert np.degrees(np.abs(motion.yaw_roll_rps)).max() > 200.0  # pivots
    for truth in default_game[0].truth.values():
        assert -1.0 <= truth.x_m.min() and truth.x_m.max() <= 29.0
        assert -1.0 <= truth.y_m.min() and truth.y_m.max() <= 16.0


def test_readings_respect_the_sensor_ranges(default_game, tmp_path: Path):
    for series in default_game[0].imu.values():
        assert np.abs(series.gyro_dps).max() <= 1500.0
        assert np.abs(series.accel_g).max() <= 16.0
    path = tmp_path / "narrow.mcap"
    simulate(2, 15.0, 2, path, params_with_overrides({"sensors.gyro_range_dps": "300"}))
    wheel = read_session(path).imu["chair01-left"]
    assert np.abs(wheel.gyro_dps).max() == pytest.approx(300.0)  # clipped at the range, not beyond


def test_seat_reads_one_g_when_the_chair_is_still(default_game):
    data = default_game[0]
    still_samples = 0
    for agent in data.session.agents:
        truth = data.truth[agent.id]
        moving = np.hypot(np.diff(truth.x_m), np.diff(truth.y_m)) + np.abs(np.diff(truth.heading_rad)) > 0
        still = ~np.convolve(np.concatenate([moving, [True]]), np.ones(25), mode="same").astype(bool)
        seat = data.imu[agent.sensor(Mount.SEAT).id]
        at = np.clip(np.searchsorted(truth.time_ns, seat.time_ns), 0, len(still) - 1)
        magnitude = np.linalg.norm(seat.accel_g[still[at]], axis=1)
        still_samples += len(magnitude)
        if len(magnitude):
            assert abs(np.median(magnitude) - 1.0) < 0.1  # biases (20 mg SD) and scale errors (1 % SD)
            assert np.percentile(np.abs(magnitude - 1.0), 99) < 0.2
    assert still_samples > 200 * 5  # the game starts from rest, and dead balls stop everyone


def test_wheel_travel_matches_the_true_path_without_errors(ideal):
    data = ideal[0]
    for agent in data.session.agents:
        truth = data.truth[agent.id]
        travels = []
        for mount in (Mount.LEFT_WHEEL, Mount.RIGHT_WHEEL):
            sensor = agent.sensor(mount)
            series = data.imu[sensor.id]
            rotation = wheel_rotation_deg(series.time_ns, signed_axis(series.gyro_dps, sensor.spin_axis))
            travel = travel_from_rotation_m(rotation, agent.wheel_diameter_m)
            travels.append(np.interp(truth.time_ns, series.time_ns, travel))
        rolled = np.abs(np.diff(chair_travel_m(*travels))).sum()
        path = np.hypot(np.diff(truth.x_m), np.diff(truth.y_m)).sum()
        assert path > 30.0
        assert rolled == pytest.approx(path, rel=0.02)


def test_camber_leak_has_the_documented_sign_and_cancels_in_the_mean():
    """A pure pivot (v = 0, yaw rate w): forward-positive left = w (sin c - T / 2r), right = the negative."""
    params = error_free()
    steps, yaw_rate = 400, 2.0
    zeros = np.zeros((steps, 1))
    pivot = Motion(time_s=np.arange(steps) / 200.0, x_m=zeros, y_m=zeros, heading_rad=zeros, speed_mps=zeros,
                   lateral_mps=zeros, yaw_roll_rps=zeros + yaw_rate, yaw_rate_rps=zeros + yaw_rate,
                   accel_forward_mps2=zeros, accel_left_mps2=zeros, team=np.zeros(1), top_speed_mps=np.ones(1))
    build = ChairBuild("chair01", 0.61, 0.61, 0.61, 17.0)
    sin_c, cos_c = math.sin(math.radians(17.0)), math.cos(math.radians(17.0))
    rolling = yaw_rate * params.chair.track_m / 2.0 / 0.305  # rad/s of each wheel, opposite senses
    left_gyro, left_accel = wheel_imu(pivot, 0, build, +1, params, 0.3)
    right_gyro, _ = wheel_imu(pivot, 0, build, -1, params, 1.1)
    left = np.radians(signed_axis(left_gyro, "+z"))
    right = np.radians(signed_axis(right_gyro, "-z"))
    np.testing.assert_allclose(left, -rolling + yaw_rate * sin_c, atol=1e-9)
    np.testing.assert_allclose(right, rolling - yaw_rate * sin_c, atol=1e-9)
    np.testing.assert_allclose((left + right) / 2.0, 0.0, atol=1e-9)
    # the rest of the yaw rotates with the wheel in the sensor's x-y plane
    np.testing.assert_allclose(np.hypot(*np.radians(left_gyro[:, :2]).T), yaw_rate * cos_c, rtol=1e-9)
    assert np.std(left_gyro[:, 0]) > 10.0
    # gravity: sin(c) on the outward-up axle axis, less the centripetal pull on the hub
    hub = params.chair.track_m / 2.0 - 0.305 * sin_c
    np.testing.assert_allclose(left_accel[:, 2], sin_c - cos_c * hub * yaw_rate**2 / STANDARD_GRAVITY, atol=1e-9)


def test_camber_leak_in_a_game_matches_geometry(ideal):
    data = ideal[0]
    track = data.session.source["params"]["chair"]["track_m"]
    for agent in data.session.agents:
        left, right, seat = (data.imu[agent.sensor(m).id] for m in (Mount.LEFT_WHEEL, Mount.RIGHT_WHEEL, Mount.SEAT))
        difference = signed_axis(left.gyro_dps, "+z") - signed_axis(right.gyro_dps, "-z")
        # away from contacts: their yaw skid turns the chair (seat gyro) without rolling the wheels
        calm = np.ones(len(seat.time_ns), dtype=bool)
        for contact in data.contacts:
            if agent.id in (contact.agent_id, contact.other_agent_id):
                calm &= np.abs(seat.time_ns - contact.time_ns) > 1e9
        slope = np.polyfit(seat.gyro_dps[calm, 2], difference[calm], 1)[0]
        sin_c = math.sin(math.radians(agent.camber_deg))
        assert slope == pytest.approx(2.0 * sin_c - track / (agent.wheel_diameter_m / 2.0), abs=0.02)


def test_seat_magnetometer_gives_the_true_heading_without_errors(ideal):
    data = ideal[0]
    north = math.radians(data.session.source["params"]["magnetic"]["court_azimuth_deg"])
    for agent in data.session.agents:
        seat = data.imu[agent.sensor(Mount.SEAT).id]
        truth = data.truth[agent.id]
        heading = north - np.arctan2(seat.mag_gauss[:, 1], seat.mag_gauss[:, 0])
        expected = np.interp(seat.time_ns, truth.time_ns, np.unwrap(truth.heading_rad))
        error = np.degrees(np.angle(np.exp(1j * (heading - expected))))
        assert np.percentile(np.abs(error), 99) < 2.0
        assert np.linalg.norm(seat.mag_gauss, axis=1).mean() == pytest.approx(0.46, abs=0.01)


def test_device_clocks_follow_their_documented_model(default_game, ideal):
    true_times = set(ideal[0].truth["chair01"].time_ns.tolist())
    assert true_times <= set(ideal[0].imu["chair01-seat"].time_ns.tolist())  # no clock error: true times
    data = default_game[0]
    epoch = data.session.source["params"]["clock"]["start_unix_s"] * 1_000_000_000
    offsets = []
    for sensor_id, series in data.imu.items():
        clock = data.session.source["truth"]["devices"][sensor_id]
        offsets.append(clock["clock_offset_s"])
        device_s = (series.time_ns - epoch) * 1e-9
        true_s = np.round((device_s - clock["clock_offset_s"]) / (1.0 + clock["clock_drift"]) * 200.0) / 200.0
        residual_s = device_s - ((1.0 + clock["clock_drift"]) * true_s + clock["clock_offset_s"])
        assert np.abs(residual_s).max() < 3 * 0.1e-3 + 1e-8  # jitter clipped at 3 SD
    assert len(set(offsets)) == len(offsets) and 0 < np.std(offsets) < 0.05


def test_beacons_are_heard_louder_under_their_goal(default_game):
    data = default_game[0]
    near, far = [], []
    for agent_id, seen in data.sightings.items():
        truth = data.truth[agent_id]
        at = np.clip(np.searchsorted(truth.time_ns, seen.time_ns), 0, len(truth.time_ns) - 1)
        goal_x = np.where(seen.beacon_id == "goal-a", 1.575, 26.425)
        distance = np.hypot(truth.x_m[at] - goal_x, truth.y_m[at] - 7.5)
        near += seen.rssi_dbm[distance < 2.0].tolist()
        far += seen.rssi_dbm[distance > 18.0].tolist()
    assert np.mean(near) > np.mean(far) + 10.0
    assert min(near + far) >= SimParams().radio.sensitivity_dbm


# -- contacts ---------------------------------------------------------------------------------------


def test_contacts_spike_both_seats_and_harder_ones_spike_more(ideal):
    data, summary = ideal
    assert summary.contacts >= 5
    seats = {a.id: data.imu[a.sensor(Mount.SEAT).id] for a in data.session.agents}
    peaks, closing = [], []
    near_contact = {agent: np.zeros(len(seat.time_ns), dtype=bool) for agent, seat in seats.items()}
    for contact in data.contacts:
        for agent in (contact.agent_id, contact.other_agent_id):
            window = np.abs(seats[agent].time_ns - contact.time_ns) < 0.05e9
            near_contact[agent] |= np.abs(seats[agent].time_ns - contact.time_ns) < 0.3e9
            peaks.append(_z(seats[agent].accel_g[window]).max())
            closing.append(contact.closing_speed_mps)
    quiet = max(np.percentile(_z(seat.accel_g[~near_contact[a]]), 99.9) for a, seat in seats.items())
    assert np.median(peaks) > 3.0 * quiet
    assert np.corrcoef(closing, peaks)[0, 1] > 0.3


def test_default_contact_rate_is_a_few_per_player_per_minute(default_game):
    assert 1.0 <= default_game[1].contacts_per_player_per_min <= 10.0
    assert default_game[1].jolts > 0  # non-contact spikes exist with default errors


# -- parameters -------------------------------------------------------------------------------------


def test_overrides_apply_and_bad_ones_name_the_key():
    params = params_with_overrides({"sensors.gyro_bias_dps": "0.25", "sensors.batch_samples": "10"})
    assert params.sensors.gyro_bias_dps == 0.25 and params.sensors.batch_samples == 10
    assert params.chair == SimParams().chair
    for overrides, message in (({"sensors.gyro_bias": "1"}, "sensors.gyro_bias"),
                               ({"sensor.gyro_bias_dps": "1"}, "unknown group 'sensor'"),
                               ({"sensors.gyro_bias_dps": "fast"}, "not a number"),
                               ({"sensors.batch_samples": "2.5"}, "not an integer"),
                               ({"sensors.gyro_bias_dps": "-1"}, "outside"),
                               ({"sensors.gyro_bias_dps": "nan"}, "finite"),
                               ({"game.possession_min_s": "30"}, "exceeds"),
                               ({"sensors.batch_samples": "1000"}, "uint32")):
        with pytest.raises(ConfigError, match=message):
            params_with_overrides(overrides)


def test_bad_arguments_are_config_errors(tmp_path: Path):
    for players, duration in ((0, 10.0), (100, 10.0), (2, 0.0), (2, math.inf)):
        with pytest.raises(ConfigError):
            simulate(players, duration, 1, tmp_path / "x.mcap")
    with pytest.raises(ConfigError, match="cannot write"):
        simulate(2, 1.0, 1, tmp_path / "missing" / "x.mcap")


@pytest.mark.parametrize("overrides", [
    {"sensors.rate_hz": "50", "sensors.batch_samples": "5"},
    {"court.length_m": "10", "court.width_m": "6"},
    {"radio.batch_loss_rate": "0.9", "radio.scan_efficiency": "0"},
    {"game.stoppage_probability": "1", "game.stoppage_max_s": "0", "game.stoppage_min_s": "0"},
])
def test_unusual_but_valid_parameters_give_a_readable_log(tmp_path: Path, overrides: dict[str, str]):
    path = tmp_path / "odd.mcap"
    params = params_with_overrides(overrides)
    summary = simulate(3, 6.0, 9, path, params)
    data = read_session(path)
    assert data.problems == [] and len(data.truth) == 3
    assert sum(len(series.time_ns) for series in data.imu.values()) == summary.imu_samples_written
    low, high = -params.court.run_off_m, params.court.length_m + params.court.run_off_m
    assert all(low <= t.x_m.min() and t.x_m.max() <= high for t in data.truth.values())


def test_error_free_zeroes_errors_but_keeps_the_game():
    params = error_free()
    assert params.sensors.gyro_bias_dps == 0 and params.radio.batch_loss_rate == 0 and params.clock.offset_ms == 0
    assert params.game == SimParams().game and params.impacts.contact_g_per_mps > 0


def test_docs_list_every_parameter_with_its_default():
    text = DOCS.read_text(encoding="utf-8")
    for key, value, unit, _ in describe():
        assert f"| `{key}` | {value} | {unit} |" in text, key
