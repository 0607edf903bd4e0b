"""`reckon eval` on pedestrians: the map guard's fall-back poses are counted, the truth
positions are checked against the walkable area the hub matches on, and each track's covariance
is scored (NEES)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import shapely
import shapely.affinity

from protocol.session_log import read_session
from reckon.evaluation.pdr_eval import Track, evaluate_pedestrians, to_json, to_table
from sim_devices.pedestrian import simulate_pedestrian


@pytest.fixture(scope="module")
def office_walk(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("pdr-eval") / "office.mcap"
    simulate_pedestrian(path, seed=1, people=1, preset="floorplan", mount="hand", duration_s=40.0)
    return path


def moved_plan(plan, dx_m: float, dy_m: float):
    return tuple([[[x + dx_m, y + dy_m] for x, y in ring] for ring in polygon] for polygon in plan)


def test_right_plan_no_fallback_and_every_truth_position_walkable(office_walk: Path):
    report = evaluate_pedestrians([(read_session(office_walk), office_walk)])
    result = to_json(report)
    matched = next(r for r in result["results"] if r["method"] == "reckon" and r["map_matching"]
                   and r["track"] == "live")
    assert matched["map_fallback"]["poses"] == 0 and matched["map_fallback"]["of_live_poses"] > 40
    [walkable] = result["walkable_truth"]
    assert walkable["positions"] > 50 and walkable["outside"] == 0
    assert f"truth positions walkable for the hub: {walkable['positions']} of {walkable['positions']}" \
        in to_table(report)


def test_a_plan_that_misses_the_walk_is_reported_and_the_track_is_the_edges(office_walk: Path):
    data = read_session(office_walk)
    venue = dataclasses.replace(data.session.venue, floor_plan=moved_plan(data.session.venue.floor_plan, 60.0, 0.0))
    data = dataclasses.replace(data, session=dataclasses.replace(data.session, venue=venue))
    report = evaluate_pedestrians([(data, office_walk)])
    result = to_json(report)
    rows = {(r["track"], r["map_matching"]): r for r in result["results"] if r["method"] == "reckon"}
    fallback = rows[("live", True)]["map_fallback"]
    assert fallback["poses"] == fallback["of_live_poses"] > 40  # the stand is off the map: all on the edge's track
    # ... so the matched track is the edge's own
    assert rows[("live", True)]["waypoint_error_m"] == rows[("live", False)]["waypoint_error_m"]
    [walkable] = result["walkable_truth"]
    assert walkable["outside"] == walkable["positions"] and walkable["farthest_outside_m"] > 10.0
    table = to_table(report)
    assert "live poses on the edge's track" in table and "truth positions walkable for the hub: 0 of" in table


def test_the_walkable_area_is_the_same_for_the_simulator_and_the_hub(office_walk: Path):
    from hub.pedestrian.walkable import WalkableArea, plan_area
    from sim_devices.pedestrian.venues import layout, walkable_geometry

    venue = read_session(office_walk).session.venue
    simulated = walkable_geometry(layout("floorplan", 1))
    assert shapely.equals(shapely.normalize(simulated), shapely.normalize(plan_area(venue.floor_plan)))
    hub = WalkableArea.from_venue(venue).geometry
    assert hub.covers(simulated)  # the hub's reads the plan's lines as good to its tolerance


def test_nees_scores_each_track_against_its_own_covariance(office_walk: Path):
    """e' P^-1 e with the covariance of the last pose at or before each waypoint; none before the
    first pose with one; every reckon row has its median, the table a column."""
    track = Track()
    track.add(0, 0.0, 0.0, 0.0)  # a stand: no covariance
    track.add(10, 1.0, 0.0, 0.0, covariance=[4.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.1])
    track.add(20, 2.0, 0.0, 0.0, covariance=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.1])
    nees = track.nees(np.array([5, 15, 25]), np.array([1.0, 2.0, 1.0]), np.array([0.0, 1.0, -2.0]))
    assert np.isnan(nees[0]) and nees[1] == pytest.approx(2.0 ** 2 / 4.0 + 1.0) and nees[2] == pytest.approx(5.0)
    result = to_json(evaluate_pedestrians([(read_session(office_walk), office_walk)]))
    for row in result["results"]:
        if row["method"] == "reckon":
            assert 0.0 < row["nees_median"] < 1e3
