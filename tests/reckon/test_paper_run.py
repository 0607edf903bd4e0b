"""The paper's correction loop on small hand-made inputs."""

from __future__ import annotations

import numpy as np
import pytest

from hub.chair.paper import Collision
from protocol.session import Agent, Beacon, Venue
from protocol.session_log import Sightings
from reckon.evaluation.inputs import AgentInputs, EvalInputs
from reckon.evaluation.paper_run import reception_from_sightings, reception_from_truth, run_paper, zone_threshold_dbm

GRID = np.arange(0, 20 * 200 + 1) * 5_000_000  # 20 s at 200 Hz
VENUE = Venue(name="court", beacons=(Beacon("goal", 5.0, 0.0, radius_m=1.0),))


def agent_moving_east(agent_id: str, speed_mps: float, scale: float = 1.0, y_m: float = 0.0) -> AgentInputs:
    """Truth: constant speed along +x from x = 0; the wheels report `scale` times the true travel."""
    t = (GRID - GRID[0]) * 1e-9
    x = speed_mps * t
    travel = np.diff(x) * scale
    return AgentInputs(Agent(agent_id), travel, x, np.full_like(t, y_m), np.zeros_like(t), None, None, None, None, {})


def inputs(*agents: AgentInputs) -> EvalInputs:
    return EvalInputs(GRID, list(agents))


def test_dead_reckoning_alone_follows_the_wheels():
    data = inputs(agent_moving_east("a", 0.5, scale=1.1))
    est = run_paper(data, [a.truth_heading_rad for a in data.agents], frozenset(), VENUE, {}, [], np.random.default_rng(0))
    assert est.x_m[0, -1] == pytest.approx(0.5 * 20 * 1.1, rel=1e-6)  # 10 % long, never corrected
    assert est.corrections_applied == 0


def test_beacon_zone_moves_the_stretch_heard_under_the_goal():
    data = inputs(agent_moving_east("a", 0.5, scale=1.1))
    zones = {"beacon_zone": np.array([reception_from_truth(a.truth_x_m[data.frame_index], a.truth_y_m[data.frame_index], VENUE)
                                      for a in data.agents])}
    est = run_paper(data, [a.truth_heading_rad for a in data.agents], frozenset({"beacon_zone"}), VENUE, zones, [],
                    np.random.default_rng(0))
    assert est.corrections_applied == 1
    heard = zones["beacon_zone"][0] == 0  # true x in [4, 6]: frames 80..120
    centroid = est.x_m[0, heard].mean()
    assert centroid == pytest.approx(5.0, abs=1e-9)  # eq. 6: the stretch's centroid sits under the goal
    # afterwards the error is only what the 10 % scale adds after the zone
    assert abs(est.x_m[0, -1] - 10.0) < abs(0.5 * 20 * 1.1 - 10.0)


def test_weighted_collision_pulls_both_chairs_together():
    a = agent_moving_east("a", 0.5, scale=1.2)
    b = agent_moving_east("b", 0.5, scale=1.0, y_m=0.0)
    data = inputs(a, b)
    collision = Collision(int(10e9), "a", "b")
    est = run_paper(data, [x.truth_heading_rad for x in data.agents], frozenset({"collision"}), VENUE, {}, [collision],
                    np.random.default_rng(0))
    k = 100  # the frame at 10 s
    assert est.x_m[0, k] == pytest.approx(est.x_m[1, k])  # both on one point (eq. 8)
    assert est.corrections_applied == 1


def test_video_fixes_reset_a_random_chair_to_truth():
    data = inputs(agent_moving_east("a", 0.5, scale=1.5))
    est = run_paper(data, [x.truth_heading_rad for x in data.agents], frozenset({"video"}), VENUE, {}, [],
                    np.random.default_rng(3))
    assert est.corrections_applied >= 1  # 200 frames at 1/200: about one fix
    truth = data.agents[0].truth_x_m[data.frame_index]
    fixed = np.flatnonzero(np.isclose(est.x_m[0], truth) & (truth > 1.0))
    assert len(fixed) >= 1


def test_rssi_reception_uses_the_zone_edge_level():
    beacon = VENUE.beacons[0]
    level = zone_threshold_dbm(beacon)
    frames = np.arange(0, 10) * 100_000_000
    sightings = Sightings(np.array([150_000_000, 450_000_000]), np.array(["goal", "goal"]),
                          np.array([level + 1.0, level - 1.0]))
    zone = reception_from_sightings(frames, sightings, VENUE)
    # in zone from the strong sighting at 0.15 s for the 1 s hold; the weak one does not count
    assert list(zone) == [-1, -1] + [0] * 8
