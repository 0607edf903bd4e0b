"""Where a length's velocity is taken zero (edge/swim/edge.py: BACKWARD_MAX, pick_zero_end).

The velocity's drift is removed as a line in time between two zero-velocity rows. Ending that line
at the next push-off spreads the open turn's attitude leak (0.3-0.7 m/s in 1.2-2 s) over the
whole length; ending it at the touch does not.
"""

from __future__ import annotations

import numpy as np

from edge.swim.bins import T, BinSettings, BodyBinner
from edge.swim.edge import BACKWARD_MAX, pick_zero_end
from edge.swim.length import YawDrift, lane_reading, reckon_length
from edge.swim.paper import LengthEstimate
from protocol.session import Mount, Route
from sim_devices.swim.simulate import simulate_set


def _estimate(swum_m: float, backward: float) -> LengthEstimate:
    return LengthEstimate(0, 20 * 10**9, swum_m, 25.0, 1.0, 0.0, np.zeros(26), backward_share=backward)


def test_the_touch_is_kept_unless_its_swimmer_goes_backwards() -> None:
    touch, push = _estimate(27.9, 0.0), _estimate(27.0, 0.0)
    assert pick_zero_end([touch, push]) is touch  # equals: the touch
    touch = _estimate(27.9, 0.1)  # a kickboard's touch can leave this much
    assert pick_zero_end([touch, _estimate(27.0, 0.07)]) is touch
    # The touch leaves the swimmer going backwards for 0.4 of the way: the end going backwards least.
    touch, later = _estimate(27.9, 0.4), _estimate(27.5, 0.37)
    assert pick_zero_end([touch, later]) is later
    assert pick_zero_end([touch, _estimate(27.0, 0.45), later]) is later
    assert pick_zero_end([_estimate(27.9, BACKWARD_MAX + 0.01), _estimate(27.0, BACKWARD_MAX + 0.05)]).swum_distance_m == 27.9


def test_zero_velocity_at_the_touch_keeps_the_turns_leak_out_of_the_diagonal() -> None:
    # Seed 5's waist sensor (true walls, the drift about the vertical learnt as live): with the
    # velocity's zero at the next push-off its lengths come out -1.9, -2.1, -3.7, -1.9 %; at the
    # touch -0.2, +0.7, -0.3, -1.1 % (docs/swim-estimator.md, "What limits the diagonal").
    streams, truth = simulate_set("crawl", Route.DIAGONAL, [Mount.WAIST], 4, 5)
    rows = BodyBinner(BinSettings(1000.0, "+x", "+y")).push(streams[0].time_ns, streams[0].accel_g, streams[0].gyro_dps)
    errors: dict[str, list[float]] = {"touch": [], "push": []}
    for end in errors:
        drift = YawDrift()
        for k in range(4):
            push, touch = (int(i) for i in np.searchsorted(rows[:, T], [truth.push_ns[k], truth.touch_ns[k]]))
            following = int(np.searchsorted(rows[:, T], truth.push_ns[k + 1])) if k < 3 else touch + 200
            zero_at = touch if end == "touch" else following
            drift = drift.learn(lane_reading(rows, push, touch, zero_at, Route.DIAGONAL))
            estimate = reckon_length(rows, push, touch, zero_at, truth.pool_length_m, Route.DIAGONAL,
                                     drift_dps=drift.rate_dps)
            errors[end].append(100.0 * (estimate.swum_distance_m / truth.swum_m[k] - 1.0))
            if end == "touch":
                assert estimate.backward_share < 0.01  # a crawler never goes backwards
    touch_errors, push_errors = np.array(errors["touch"]), np.array(errors["push"])
    assert np.abs(touch_errors).max() < 1.5  # the issue's +-2 %
    assert np.abs(push_errors).max() > 3.0
    assert np.sqrt(np.mean(touch_errors ** 2)) < 0.5 * np.sqrt(np.mean(push_errors ** 2))
