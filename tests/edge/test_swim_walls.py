"""Wall/turn detection without true wall times (edge/swim/walls.py, edge/swim/edge.py), and how
`reckon eval` scores it per mounting (reckon/evaluation/swim_eval.py).

Tolerances: a touch within 0.2 s (the issue's p90 goal) where the detector meets it (body-worn
sensors); the kickboard's touch within 1 s (the match window: its p90 is 0.3-0.4 s, a set's last
touch up to 0.5 s late, docs/swim-estimator.md); push-offs within 0.1 s.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from edge.swim import walls
from edge.swim.bins import BIN_HZ, COLUMNS, DV_X, G, HEAD_X, HEAD_Y, RATE, SURGE, YAW
from edge.swim.edge import SwimEdge, SwimTracker
from protocol.session import Mount, Route, Sensor
from reckon.evaluation.swim_eval import SwimReport, _score_detected, to_json, to_table
from sim_devices.swim import simulate_set


def _detect(stroke: str, route: Route, mount: Mount, lengths: int, seed: int):
    streams, truth = simulate_set(stroke, route, [mount], lengths, seed)
    stream = streams[0]
    tracker = SwimTracker(Sensor("s", mount, 1000.0, forward_axis="+x", left_axis="+y"), 25.0, route)
    found = tracker.push_samples(stream.time_ns, stream.accel_g, stream.gyro_dps) + tracker.flush()
    return found, truth, tracker.counters


def _rows(seconds: float) -> np.ndarray:
    rows = np.zeros((int(seconds * BIN_HZ), len(COLUMNS)))
    rows[:, HEAD_X] = 1.0
    return rows


def test_a_turn_is_the_rotation_about_the_vertical_even_when_the_heading_is_lost():
    rows = _rows(10.0)
    turn = slice(500, 650)  # 180 deg in 1.5 s
    rows[turn, YAW] = 180.0 / 1.5
    rows[turn, HEAD_X] = rows[turn, HEAD_Y] = 0.0  # pitched up in the tuck: no projected heading
    assert walls.reversed_at(rows, 649, since=0)
    assert not walls.reversed_at(rows, 499, since=0)
    assert not walls.reversed_at(rows, 649, since=400)  # never looks before the glide
    diagonal = _rows(10.0)
    diagonal[500:700, YAW] = -35.75 / 2.0  # the route's turn, over 2 s
    assert not walls.reversed_at(diagonal, 699, since=0)


def test_a_length_without_a_wall_is_dropped_counted_and_left_to_the_caller_to_log():
    tracker = SwimTracker(Sensor("s", Mount.WAIST, 1000.0, forward_axis="+x", left_axis="+y"), 25.0, Route.STRAIGHT,
                          max_length_s=1.0)  # a buffer of 1 + 13 s of margins
    edge = SwimEdge(SimpleNamespace(id="swimmer", sensors=[], route=Route.STRAIGHT), 25.0)
    edge.trackers["s"] = tracker
    assert tracker.push_rows(_rows(15.0)) == [] and tracker.counters.overlong == 1
    assert edge.warnings() == ["no wall for 14 s: dropping the length in progress"]
    assert edge.warnings() == []  # each drop is reported once


def test_rest_is_stiller_than_a_kickboards_kicking():
    kicking = _rows(3.0)
    kicking[:, RATE] = 9.5  # the least the board rotates while kicking (seed 1 session)
    kicking[:, SURGE] = 0.026 * np.sign(np.sin(2 * np.pi * 2.4 * np.arange(len(kicking)) / BIN_HZ))
    assert not walls.still_until(kicking, len(kicking) - 1)
    resting = _rows(3.0)
    resting[:, RATE] = 2.0
    resting[:, SURGE] = 0.005 * np.sin(2 * np.pi * 0.3 * np.arange(len(resting)) / BIN_HZ)
    assert walls.still_until(resting, len(resting) - 1)


def test_a_kickboards_touch_is_its_first_stop_not_the_pull_in_after_it():
    rows = _rows(3.0)
    t = np.arange(len(rows)) / BIN_HZ
    stop = -0.3 * np.exp(-((t - 1.0) / 0.1) ** 2)  # the board stops at the wall ...
    pull_in = -0.4 * np.exp(-((t - 1.5) / 0.1) ** 2)  # ... then is pulled in to the body
    rows[:, DV_X] = (stop + pull_in) * G / BIN_HZ
    board = walls.touch_in(rows, 0, len(rows) - 1, board=True) / BIN_HZ
    body = walls.touch_in(rows, 0, len(rows) - 1) / BIN_HZ
    assert 1.0 < board < 1.35  # where the first deceleration has eased, before the second
    assert body > 1.6  # a body-worn sensor's touch: the end of the strongest


def test_head_sensor_on_a_diagonal_set_finds_every_wall_on_time():
    found, truth, counters = _detect("crawl", Route.DIAGONAL, Mount.HEAD, 3, 2)
    assert len(found) == len(truth.touch_ns) == 3
    assert counters.turns == 2 and counters.stops == 1
    touch_s = np.abs(np.array([f.end_ns for f in found]) - truth.touch_ns) * 1e-9
    push_s = np.abs(np.array([f.start_ns for f in found]) - truth.push_ns) * 1e-9
    assert touch_s.max() < 0.2 and push_s.max() < 0.1


def test_kicking_with_a_board_is_not_taken_for_rest():
    found, truth, counters = _detect("kick", Route.STRAIGHT, Mount.KICKBOARD, 3, 2)
    assert len(found) == 3 and counters.turns == 2 and counters.stops == 1
    touch_s = np.abs(np.array([f.end_ns for f in found]) - truth.touch_ns) * 1e-9
    assert touch_s.max() < 1.0
    assert all(abs(f.swum_distance_m - s) < 0.5 for f, s in zip(found, truth.swum_m))


@pytest.mark.parametrize("route", list(Route))
def test_waist_crawl_walls_and_distances(route):
    found, truth, _ = _detect("crawl", route, Mount.WAIST, 3, 4)
    assert len(found) == 3
    touch_s = np.abs(np.array([f.end_ns for f in found]) - truth.touch_ns) * 1e-9
    assert touch_s.max() < 0.2
    errors = np.array([f.swum_distance_m / s - 1.0 for f, s in zip(found, truth.swum_m)])
    assert np.abs(errors).max() < (0.005 if route is Route.STRAIGHT else 0.07)


def test_eval_scores_walls_pooled_and_per_mounting():
    report = SwimReport(Path("x.mcap"), 25.0)

    def length(start_s: float, end_s: float, strokes: int = 20):
        return SimpleNamespace(start_ns=int(start_s * 1e9), end_ns=int(end_s * 1e9), timestamp_ns=int(end_s * 1e9),
                               swum_distance_m=25.0, stroke_count=strokes)

    truth = [length(5, 25), length(27, 47)]
    common = dict(agent_id="a", route="straight", stroke="crawl")
    _score_detected(report, [length(5.0, 25.1, 21), length(27.0, 47.1, 17)], truth,
                    dict(common, sensor_id="w", mounting="waist"))
    _score_detected(report, [length(5.0, 25.5), length(30.0, 40.0)], truth,
                    dict(common, sensor_id="k", mounting="kickboard"))
    out = to_json(report)
    # Stroke counts against TruthLength's, per length matched: the waist's +1 and -3.
    waist_lengths = next(r for r in out["results"] if r["mounting"] == "waist")
    assert waist_lengths["stroke_count_error"] == {"mean": -1.0, "max_abs": 3, "mean_abs_pct": 10.0}
    assert "strokes" in to_table(report).splitlines()[1]
    assert out["turns"]["true_walls"] == 4 and out["turns"]["matched"] == 3 and out["turns"]["false"] == 1
    waist, board = out["turns_by_mounting"]["waist"], out["turns_by_mounting"]["kickboard"]
    assert waist["precision"] == waist["recall"] == 1.0 and waist["timing_error_s_p90"] == pytest.approx(0.1)
    assert board["matched"] == 1 and board["missed"] == 1 and board["false"] == 1
