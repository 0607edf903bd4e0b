"""`reckon eval` on a simulated building of two floors: floors scored from the truth's, the IPIN
score (p75 of error + 15 m per floor wrong), every truth position checked on its own floor's plan."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from protocol.session_log import read_session
from reckon.evaluation.pdr_eval import FLOOR_PENALTY_M, evaluate_pedestrians, to_json, to_table
from sim_devices.pedestrian import simulate_pedestrian


@pytest.fixture(scope="module")
def two_floors(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("floors") / "floors.mcap"
    simulate_pedestrian(path, seed=1, people=1, preset="floors", mount="hand", duration_s=80.0)  # up, then floor 1
    return path


def test_floors_and_the_ipin_score(two_floors: Path):
    data = read_session(two_floors)
    truth = data.truth["p01"]
    assert truth.floor is not None and set(np.unique(truth.floor).tolist()) == {0, 1}
    report = evaluate_pedestrians([(data, two_floors)])
    result = {(r["method"], r["matcher"], r["track"]): r for r in to_json(report)["results"]}
    ours = result[("reckon", "none", "live")]
    assert ours["floors"]["right_floor"] > 0.9  # the edge's barometer count, a second or two behind the stairs
    assert ours["floors"]["ipin_score_m"] >= ours["waypoint_error_m"]["p75"]
    for row in report.rows:  # the score is the p75 of error + 15 m per floor wrong, nothing else
        score = np.percentile(row.errors_m + FLOOR_PENALTY_M * row.floor_errors, 75)
        assert row.floors_in_truth and len(row.floor_errors) == len(row.errors_m)
        assert score >= np.percentile(row.errors_m, 75)
    matched = result[("reckon", "particle filter", "live")]
    assert matched["waypoint_error_m"]["p75"] <= ours["waypoint_error_m"]["p75"] * 1.1
    assert "right floor" in to_table(report) and "IPIN score" in to_table(report)
    assert to_json(report)["walkable_truth"][0]["outside"] == 0  # floor 1's positions on floor 1's plan


def test_a_one_floor_session_scores_no_floors(tmp_path: Path):
    path = tmp_path / "office.mcap"
    simulate_pedestrian(path, seed=1, people=1, preset="floorplan", mount="hand", duration_s=30.0)
    data = read_session(path)
    assert data.truth["p01"].floor is None
    report = evaluate_pedestrians([(data, path)])
    assert not any(r.floors_in_truth for r in report.rows)
    assert "IPIN score" not in to_table(report)
    assert all(r["floors"]["right_floor"] == 1.0 for r in to_json(report)["results"])


@pytest.fixture(scope="module")
def whole_walk(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("floors") / "whole.mcap"
    simulate_pedestrian(path, seed=5, people=1, preset="floors", mount="hand")  # the whole tour, both floors
    return path


def _p75(report, matcher):
    return next(r for r in to_json(report)["results"] if r["matcher"] == matcher and r["track"] == "live"
                )["waypoint_error_m"]["p75"]


def test_beacon_fixes_side_by_side_and_a_venue_file_with_the_beacons_wrong(whole_walk: Path):
    import dataclasses

    data = read_session(whole_walk)
    report = evaluate_pedestrians([(data, whole_walk)])
    assert report.beacon_fixes.taken >= 5
    assert "particle filter + beacons" in to_table(report) and "fixes taken" in to_table(report)
    right = _p75(report, "particle filter + beacons")
    assert right <= _p75(report, "particle filter") * 1.1
    # every beacon stated 12 m from where it hangs: refused by the gate, the track no worse than without
    venue = data.session.venue
    moved = tuple(dataclasses.replace(b, x_m=b.x_m + (12.0 if i % 2 else -12.0)) for i, b in enumerate(venue.beacons))
    wrong = dataclasses.replace(data, session=dataclasses.replace(data.session, venue=dataclasses.replace(
        venue, beacons=moved)))
    misled = evaluate_pedestrians([(wrong, whole_walk)])
    assert misled.beacon_fixes.refused > misled.beacon_fixes.taken
    assert _p75(misled, "particle filter + beacons") <= _p75(misled, "particle filter") * 1.1
