"""The population of simulated worlds: world 0 is the defaults, every other world draws each error
source from its documented range, independently of the game seed; the new error sources act."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from protocol.errors import ConfigError
from protocol.session_log import read_session
from reckon.cli import main
from sim_devices.wheelchair import SimParams, error_free, params_with_overrides, simulate
from sim_devices.wheelchair.kinematics import ChairBuild, wheel_spin_rps
from sim_devices.wheelchair.motion import simulate_motion
from sim_devices.wheelchair.worlds import (FLOOR_HEIGHT_M, WORLD_RANGES, describe_worlds, draw_world, parse_worlds,
                                           world_params)


def test_world_zero_is_the_defaults_and_worlds_are_fixed_by_their_number():
    assert world_params(0) == SimParams() and draw_world(0) == {}
    assert world_params(7) == world_params(7)
    assert world_params(7) != world_params(8)
    base = params_with_overrides({"sensors.rate_hz": "100"})
    assert world_params(7, base).sensors.rate_hz == 100.0  # a world changes only what it draws


def test_every_drawn_figure_is_accepted_by_the_parameter_table():
    for world in range(1, 41):
        figures = draw_world(world)
        # the same figures through --set validation: each within its field's accepted range
        checked = params_with_overrides({key: repr(value) for key, value in figures.items()})
        assert checked == world_params(world)


def test_each_range_is_covered_over_many_worlds():
    draws = [world_params(world) for world in range(1, 201)]
    heading = [math.degrees(math.atan(p.magnetic.disturbance_ut / (46.0 * math.cos(math.radians(49.0)))))
               for p in draws]
    assert 0.0 <= min(heading) < 2.0 and 23.0 < max(heading) <= 25.0
    bias = [p.sensors.gyro_bias_dps for p in draws]
    assert 0.05 <= min(bias) < 0.07 and 0.8 < max(bias) <= 1.0
    assert np.median(bias) < 0.35  # log-uniform: the median near the geometric mean 0.22, not 0.5
    height = np.array([p.court.beacon_height_m for p in draws])
    on_floor = height == FLOOR_HEIGHT_M
    assert 0.15 < on_floor.mean() < 0.35 and ((height[~on_floor] >= 2.0) & (height[~on_floor] <= 4.0)).all()
    # the venue file keeps the nominal figures: truth + listed error is 2.9 m and -59 dBm in every world
    assert all(p.court.beacon_height_m + p.court.listed_height_error_m == pytest.approx(2.9) for p in draws)
    assert all(p.court.beacon_tx_power_dbm + p.court.listed_tx_error_db == pytest.approx(-59.0) for p in draws)
    assert max(abs(p.court.listed_tx_error_db) for p in draws) > 5.0
    contact = [2 * p.chair.radius_m for p in draws]
    assert 0.6 <= min(contact) < 0.65 and 1.15 < max(contact) <= 1.2
    parked = [p.game.parked_start for p in draws]
    assert set(parked) == {0, 1} and 60 < sum(parked) < 140
    assert {row[0] for row in describe_worlds()} == {row.name for row in WORLD_RANGES}


def test_parse_worlds_names_bad_text():
    assert parse_worlds("11-13") == [11, 12, 13] and parse_worlds("4") == [4]
    for text, message in (("3-1", "0 <= A <= B"), ("a-b", "K or A-B"), ("-2", "K or A-B")):
        with pytest.raises(ConfigError, match=message):
            parse_worlds(text)
    with pytest.raises(ConfigError, match="world: 2000000"):
        parse_worlds("1-2000000")


def test_a_worlds_log_keeps_the_nominal_venue_file_and_records_the_world(tmp_path):
    world = next(w for w in range(1, 50) if world_params(w).court.beacon_height_m == FLOOR_HEIGHT_M)
    path = tmp_path / "world.mcap"
    assert main(["-q", "sim", "wheelchair", "--world", str(world), "--players", "2", "--duration", "4",
                 "--set", "radio.batch_loss_rate=0", "-o", str(path)]) == 0
    data = read_session(path)
    source = data.session.source
    assert source["world"] == world
    assert source["params"]["court"]["beacon_height_m"] == FLOOR_HEIGHT_M  # the truth the radio used
    assert source["params"]["radio"]["batch_loss_rate"] == 0.0  # --set applies on top of the world
    for beacon in data.session.venue.beacons:
        assert beacon.height_m == pytest.approx(2.9) and beacon.tx_power_dbm == pytest.approx(-59.0)


def test_without_a_parked_start_the_chairs_move_from_the_first_second():
    def first_second_path(parked: int) -> float:
        params = params_with_overrides({"game.parked_start": str(parked)})
        motion = simulate_motion(4, 2.0, params, np.random.default_rng(5))
        steps = int(params.sensors.rate_hz)
        return float(np.hypot(np.diff(motion.x_m[:steps], axis=0), np.diff(motion.y_m[:steps], axis=0)).sum())

    assert first_second_path(1) == 0.0  # the tip-off rest lasts at least game.stoppage_min_s = 3 s
    assert first_second_path(0) > 0.5


def test_the_gyro_warm_up_moves_the_bias_with_its_time_constant(tmp_path):
    path = tmp_path / "warm.mcap"
    params = params_with_overrides({"sensors.gyro_warmup_dps": "1.0", "sensors.gyro_warmup_s": "2.0",
                                    "game.stoppage_min_s": "12", "game.stoppage_max_s": "12"}, error_free())
    simulate(1, 10.0, 2, path, params)
    data = read_session(path)
    seat = data.imu["chair01-seat"]
    change = data.session.source["truth"]["devices"]["chair01-seat"]["gyro_warmup_dps"]
    t = (seat.time_ns - seat.time_ns[0]) * 1e-9
    early, late = seat.gyro_dps[t < 0.2, 2].mean(), seat.gyro_dps[t > 8.0, 2].mean()
    assert abs(change[2]) > 0.1  # a real change was drawn (seed 2)
    assert abs(early) < 0.15 * abs(change[2])
    assert late == pytest.approx(change[2], abs=0.1 * abs(change[2]))


def test_scrub_makes_the_wheels_see_more_turn_than_the_chair():
    base = error_free()
    motion = simulate_motion(2, 20.0, base, np.random.default_rng(3))
    build = ChairBuild("chair01", 0.61, 0.61, 0.61, 15.0)
    scrub = dataclasses.replace(base, wheels=dataclasses.replace(base.wheels, slip_turn=0.05))

    def differential(params: SimParams) -> np.ndarray:
        return wheel_spin_rps(motion, 0, build, -1, params) - wheel_spin_rps(motion, 0, build, 1, params)

    plain, scrubbed = differential(base), differential(scrub)
    pivot = np.abs(motion.yaw_roll_rps[:, 0]) > 0.5 * math.radians(base.chair.yaw_rate_max_dps)
    assert pivot.sum() > 10
    ratio = scrubbed[pivot] / plain[pivot]
    assert (ratio > 1.02).all() and (ratio <= 1.05 + 1e-9).all()
    still_turning = (np.abs(motion.yaw_roll_rps[:, 0]) > 0.01) & ~pivot
    assert (scrubbed[still_turning] / plain[still_turning] < 1.025 + 1e-9).all()
