"""The pedestrian hub on a building with a plan per floor: each pose's floor picks that floor's
matcher, which starts where the agent left the old floor; the old floor's refined poses come out
at the change; a floor without a map passes the edge's track on."""

from __future__ import annotations

import numpy as np

from hub.pedestrian.hub import PedestrianHub
from protocol import messages
from protocol.session import Agent, AgentKind, MapPoint, Mount, Sensor, Session, Venue

T0_NS = 1_000_000_000_000
# Floor 0: a corridor along x (y 3-7) from x 0 to 30 and a stairwell at its east end (x 26-30,
# y 3-20). Floor 1: the same stairwell and a corridor along y at x 26-30... and one along x at the top.
FLOOR_0 = [[[[0.0, 3.0], [30.0, 3.0], [30.0, 20.0], [26.0, 20.0], [26.0, 7.0], [0.0, 7.0]]]]
FLOOR_1 = [[[[26.0, 3.0], [30.0, 3.0], [30.0, 16.0], [60.0, 16.0], [60.0, 20.0], [26.0, 20.0]]]]


def session(plans=True, points=()):
    venue = Venue("tower", court_length_m=60.0, court_width_m=20.0, map_points=points,
                  floor_plan=tuple(FLOOR_0) if plans else (),
                  floor_plans=((1, tuple(FLOOR_1)),) if plans else ())
    agent = Agent("walker", AgentKind.PEDESTRIAN, sensors=(Sensor("walker-hand", Mount.HAND),))
    return Session(venue, (agent,))


def pose(time_s: float, x_m: float, y_m: float, floor: int = 0, heading_rad: float = 0.0):
    return messages.new("EstimatedPose", timestamp_ns=T0_NS + int(time_s * 1e9), agent_id="walker", x_m=x_m,
                        y_m=y_m, heading_rad=heading_rad, covariance=list(np.diag([0.1, 0.1, 0.01]).ravel()),
                        method="reckon", track=messages.Track.LIVE, correction_sequence=1, floor=floor)


def walk(hub, start_s, points, floor, heading_rad):
    out = []
    for i, (x, y) in enumerate(points):
        out += hub.on_message(pose(start_s + 0.5 * i, x, y, floor, heading_rad))
    return out


def test_each_floor_is_matched_on_its_own_plan():
    hub = PedestrianHub(session())
    out = walk(hub, 0.0, [(2.0 + 0.7 * i, 5.0) for i in range(38)], 0, 0.0)  # east along floor 0 to x 28
    before = [p for p in out if p.track == messages.Track.LIVE]
    assert all(p.floor == 0 for p in out) and before[-1].x_m > 26.0
    lag = hub.agents["walker"].matcher.refined_lag_steps
    # up the stairwell (north), then east along floor 1's top corridor: a walk through floor 0's wall at y 20
    up = [(28.0, 5.0 + 0.7 * i) for i in range(1, 18)]
    changed = walk(hub, 19.0, up[:1], 1, np.pi / 2)
    old_refined = [p for p in changed if p.track == messages.Track.REFINED and p.floor == 0]
    assert len(old_refined) == lag  # the old floor's lagging poses, at once
    new = [p for p in changed if p.floor == 1]
    assert new and abs(new[0].x_m - 28.0) < 1.0 and abs(new[0].y_m - 5.7) < 1.0
    out = changed + walk(hub, 19.5, up[1:], 1, np.pi / 2)
    out += walk(hub, 28.0, [(28.0 + 0.7 * i, 18.0) for i in range(1, 40)], 1, 0.0)
    live = [p for p in out if p.track == messages.Track.LIVE and p.floor == 1]
    assert live[-1].x_m > 50.0 and 16.0 - 0.5 < live[-1].y_m < 20.5
    assert not any(p.map_fallback for p in live)  # floor 1's plan allows it; floor 0's would not
    view = hub.agents["walker"]
    assert (view.floor, view.floor_changes) == (1, 1) and "1 floor changes (on floor 1)" in view.describe()
    # and back down: a fresh floor-0 matcher
    down = walk(hub, 60.0, [(28.0, 18.0 - 0.7 * i) for i in range(1, 10)], 0, -np.pi / 2)
    assert all(p.floor == 0 for p in down if p.track == messages.Track.LIVE)
    assert view.floor_changes == 2


def test_a_floor_without_a_map_passes_the_edge_track_on_and_the_map_returns():
    points = (MapPoint("A", 0.0, 5.0, (0.0,)), MapPoint("B", 30.0, 5.0, (180.0,)))
    hub = PedestrianHub(session(plans=False, points=points))
    walk(hub, 0.0, [(1.0 + 0.7 * i, 5.0) for i in range(10)], 0, 0.0)
    assert hub.agents["walker"].matcher is not None
    upstairs = walk(hub, 10.0, [(50.0, 50.0), (50.7, 50.0)], 1, 0.0)  # no map points on floor 1
    live = [p for p in upstairs if p.track == messages.Track.LIVE]
    assert [(p.x_m, p.y_m, p.floor) for p in live] == [(50.0, 50.0, 1), (50.7, 50.0, 1)]
    assert hub.agents["walker"].matcher is None
    walk(hub, 20.0, [(10.0, 5.0), (10.7, 5.0)], 0, 0.0)
    assert hub.agents["walker"].matcher is not None
