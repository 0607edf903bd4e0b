"""The heading's drift about the vertical, learnt from the pool (edge/swim_length.YawDrift) and read
at rest before a set (RestGyro)."""

from __future__ import annotations

import math

import numpy as np

from edge.swim.bins import COLUMNS, GYRO_X, GYRO_Y, GYRO_Z, RATE, T, BinSettings, BodyBinner
from edge.swim.length import LaneReading, RestGyro, YawDrift, lane_reading, reckon_length
from protocol.session import Mount, Route
from sim_devices.swim.simulate import simulate_set


def readings(rate_dps: float, lengths: int, within_noise_dps: float, seed: int = 0) -> list[LaneReading]:
    """Lane headings of lengths swum back and forth every 25 s in a frame drifting at rate_dps."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(lengths):
        t_s = 10.0 + 25.0 * k
        heading = 0.3 + k * math.pi + math.radians(rate_dps * t_s + rng.normal(0.0, 0.5))
        out.append(LaneReading(math.remainder(heading, 2 * math.pi), int(t_s * 1e9),
                               rate_dps + rng.normal(0.0, within_noise_dps)))
    return out


def test_drift_is_learnt_from_lane_reversals() -> None:
    drift = YawDrift()
    for lane in readings(0.4, 6, within_noise_dps=0.3):
        drift = drift.learn(lane)
    assert abs(drift.rate_dps - 0.4) < 0.05
    assert drift.variance < 0.05 ** 2


def test_first_length_uses_its_own_turn_and_wild_readings_are_refused() -> None:
    first = readings(-0.5, 1, within_noise_dps=0.0)[0]
    assert -0.5 < YawDrift().learn(first).rate_dps < -0.25  # shrunk towards the prior's 0
    settled = YawDrift()
    for lane in readings(0.2, 4, within_noise_dps=0.0):
        settled = settled.learn(lane)
    on_lane = settled.last.heading_rad + math.pi + math.radians(25.0 * 0.2)
    wild = LaneReading(on_lane, settled.last.time_ns + 25 * 10**9, 12.0)
    assert abs(settled.learn(wild).rate_dps - settled.rate_dps) < 0.01  # a kickboard's hand turn, not a drift
    # Not a reversal onto the same lane (the swimmer crossed lanes): no pair reading.
    sideways = LaneReading(settled.last.heading_rad + math.pi / 2, settled.last.time_ns + 25 * 10**9, math.nan)
    assert settled.learn(sideways).rate_dps == settled.rate_dps


def test_drift_learnt_on_a_simulated_diagonal_set_corrects_its_lengths() -> None:
    # Seed 3's waist sensor leaves +0.55 deg/s about the vertical after the attitude filter
    # (its heading error grows 0.51-0.57 deg/s over each length against the simulator's truth).
    streams, truth = simulate_set("crawl", Route.DIAGONAL, [Mount.WAIST], 4, 3)
    rows = BodyBinner(BinSettings(1000.0, "+x", "+y")).push(streams[0].time_ns, streams[0].accel_g, streams[0].gyro_dps)
    drift, with_drift, without = YawDrift(), [], []
    for k in range(4):
        push, touch = (int(i) for i in np.searchsorted(rows[:, T], [truth.push_ns[k], truth.touch_ns[k]]))
        stop = int(np.searchsorted(rows[:, T], truth.push_ns[k + 1])) if k < 3 else min(touch + 200, len(rows) - 1)
        drift = drift.learn(lane_reading(rows, push, touch, stop, Route.DIAGONAL))
        for errors, rate in ((with_drift, drift.rate_dps), (without, 0.0)):
            estimate = reckon_length(rows, push, touch, stop, truth.pool_length_m, Route.DIAGONAL, drift_dps=rate)
            errors.append(100.0 * (estimate.swum_distance_m / truth.swum_m[k] - 1.0))
    assert 0.45 < drift.rate_dps < 0.65
    assert max(abs(e) for e in with_drift[1:]) < 2.5  # lengths 2-4 have the pair readings
    assert min(abs(e) for e in without[1:]) > 3.0


def _rest_rows(seconds: float, rate_dps: float, gyro_dps: tuple[float, float, float]) -> np.ndarray:
    rows = np.zeros((int(seconds * 100), len(COLUMNS)))
    rows[:, RATE] = rate_dps
    rows[:, [GYRO_X, GYRO_Y, GYRO_Z]] = gyro_dps
    return rows


def test_the_rest_before_a_set_reads_the_gyro_offset_once() -> None:
    rest = RestGyro()
    rest.add(_rest_rows(1.0, 1.0, (9.0, 9.0, 9.0)))  # too short a rest
    rest.add(_rest_rows(0.1, 60.0, (0.0, 0.0, 0.0)))
    assert rest.take() is None
    rest.add(_rest_rows(3.0, 1.0, (0.1, 0.2, -0.3)))
    assert rest.offset_dps is None  # still resting: not over yet
    rest.add(_rest_rows(0.1, 60.0, (50.0, 0.0, 0.0)))  # comes horizontal to push off
    assert np.allclose(rest.take(), (0.1, 0.2, -0.3))
    assert rest.take() is None  # the set's first length only
    assert rest.total.shape == (3,)  # fixed-size, however long the rest


def test_the_rest_reads_a_simulated_sets_drift_before_its_first_length() -> None:
    # Seed 3 (as above, +0.55 deg/s): floating still at the wall before the set (pitched 70 deg)
    # every gyro axis reads its offset, and projected on the swimming vertical it is the drift.
    streams, truth = simulate_set("crawl", Route.DIAGONAL, [Mount.WAIST], 1, 3)
    rows = BodyBinner(BinSettings(1000.0, "+x", "+y")).push(streams[0].time_ns, streams[0].accel_g, streams[0].gyro_dps)
    push, touch = (int(i) for i in np.searchsorted(rows[:, T], [truth.push_ns[0], truth.touch_ns[0]]))
    rest = RestGyro()
    rest.add(rows[:push])
    lane = lane_reading(rows, push, touch, touch, Route.DIAGONAL, rest_offset_dps=rest.take())
    assert abs(lane.rest_dps - 0.55) < 0.15  # 0.66: the rest's sway; DRIFT_REST_SD_DPS is 0.15
    first = YawDrift().learn(lane)
    assert abs(first.rate_dps - 0.55) < 0.1 and first.variance < 0.15 ** 2  # not shrunk to the prior's 0
