"""BLE beacon passes as fixes for pedestrians (hub/pedestrian/beacons.py, offset.py, hub.py): the
moment of closest approach from a smoothed RSSI peak, a level learned per beacon, the gate against
the track, distrust of a beacon that keeps disagreeing, floors, and constant memory."""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pytest

from hub.pedestrian.beacons import BeaconPasses, BeaconSettings, ProximityFix, free_space_level_dbm, gate
from hub.pedestrian.hub import PedestrianHub
from hub.pedestrian.matching import DeadReckonedPose
from hub.pedestrian.offset import OffsetMatcher
from protocol import messages
from protocol.session import Agent, AgentKind, Beacon, Mount, Sensor, Session, Venue

T0_NS = 1_000_000_000_000
BEACON = Beacon("b1", 20.0, 0.0, tx_power_dbm=-59.0, height_m=2.6)
SPEED_MPS = 1.3


def rssi_along(beacon: Beacon, x_m: np.ndarray, y_m: float, rng, exponent=2.5, offset_db=0.0, fading_db=3.0):
    slant = np.sqrt((x_m - beacon.x_m) ** 2 + (y_m - beacon.y_m) ** 2 + (beacon.height_m - 1.1) ** 2)
    return np.round(beacon.tx_power_dbm + offset_db - 10 * exponent * np.log10(slant) + rng.normal(0, fading_db, len(x_m)))


def sightings(beacon, start_s, x0_m, x1_m, y_m, rng, rate_hz=2.0, **radio):
    """A walk along y = y_m from x0 to x1 at SPEED_MPS: (time ns, rssi) heard at `rate_hz`."""
    duration = abs(x1_m - x0_m) / SPEED_MPS
    t = start_s + np.arange(0.0, duration, 1.0 / rate_hz)
    x = x0_m + np.sign(x1_m - x0_m) * SPEED_MPS * (t - start_s)
    return [(T0_NS + int(ti * 1e9), float(r)) for ti, r in zip(t, rssi_along(beacon, x, y_m, rng, **radio))]


def feed(passes, rows, beacon_id="b1"):
    out = []
    for time_ns, rssi in rows:
        out += passes.sight(time_ns, beacon_id, rssi)
    return out + passes.tick(rows[-1][0] + int(10e9))


def test_a_close_pass_gives_one_fix_at_the_closest_approach():
    rng = np.random.default_rng(1)
    passes = BeaconPasses((BEACON,))
    fixes = feed(passes, sightings(BEACON, 0.0, 0.0, 40.0, 0.5, rng))  # under the beacon at x 20: t 15.4 s
    assert len(fixes) == 1
    fix = fixes[0]
    assert (fix.x_m, fix.y_m, fix.beacon_id) == (20.0, 0.0, "b1")
    assert abs((fix.time_ns - T0_NS) * 1e-9 - 20.0 / SPEED_MPS) < 2.0  # within 2.6 m of walking


def test_the_level_is_learned_so_far_passes_give_no_fix_whatever_the_tx_power():
    rng = np.random.default_rng(2)
    # a hot beacon (+8 dB over its stated tx power): a pass 6 m away looks like a close one at first
    passes, fixes, start = BeaconPasses((BEACON,)), [], 0.0
    for y_m in (0.3, 0.5, 0.2, 0.4):  # close passes teach the level
        fixes += feed(passes, sightings(BEACON, start, 0.0, 40.0, y_m, rng, offset_db=8.0), "b1")
        start += 60.0
    level, learned = passes.level_dbm("b1")
    assert learned and level > free_space_level_dbm(BEACON, 2.0)
    far = []
    for _ in range(4):
        far += feed(passes, sightings(BEACON, start, 0.0, 40.0, 7.0, rng, offset_db=8.0), "b1")
        start += 60.0
    assert len(fixes) >= 3 and far == [] and passes.far >= 4


def test_a_weak_beacon_still_gives_fixes_once_learned_and_a_tail_is_no_pass():
    rng = np.random.default_rng(3)
    passes, fixes, start = BeaconPasses((BEACON,)), [], 0.0
    for _ in range(6):  # 12 dB below its stated power: under the free-space floor at first
        fixes += feed(passes, sightings(BEACON, start, 0.0, 40.0, 0.3, rng, offset_db=-12.0, fading_db=1.0), "b1")
        start += 60.0
    assert fixes == []  # never weaker than the free-space level minus floor_db: nothing learned can lower that
    # walking away from under the beacon: the level only falls, no rise to a peak, no pass
    away = feed(BeaconPasses((BEACON,)), sightings(BEACON, 0.0, 20.0, 60.0, 0.3, rng, fading_db=0.5))
    assert away == []


def test_unknown_and_bad_sightings_are_counted_and_old_ones_ignored():
    passes = BeaconPasses((BEACON,))
    assert passes.sight(T0_NS, "nope", -60.0) == [] and passes.sight(T0_NS, "b1", math.nan) == []
    assert passes.unknown == 2
    passes.sight(T0_NS + 10, "b1", -60.0)
    before = (passes.records["b1"].smoothed_dbm, passes.records["b1"].last_ns)
    assert passes.sight(T0_NS + 5, "b1", -90.0) == []
    assert (passes.records["b1"].smoothed_dbm, passes.records["b1"].last_ns) == before


@pytest.mark.parametrize("name", ["smoothing_s", "drop_db", "fix_sd_m"])
def test_settings_are_checked(name):
    with pytest.raises(ValueError, match=name):
        BeaconSettings(**{name: -1.0})


def test_the_gate_refuses_a_fix_far_outside_the_track():
    fix = ProximityFix("b1", T0_NS, 20.0, 0.0, 2.0, -60.0, -62.0)
    assert gate(fix, 21.0, 1.0, np.eye(2) * 0.1)
    assert not gate(fix, 30.0, 0.0, np.eye(2) * 0.1)
    assert gate(fix, 30.0, 0.0, np.eye(2) * 100.0)  # an unsure track takes it


def test_passes_hold_constant_memory():
    rng = np.random.default_rng(4)
    passes = BeaconPasses((BEACON,))
    feed(passes, sightings(BEACON, 0.0, 0.0, 40.0, 0.3, rng))
    tracemalloc.start()
    before = tracemalloc.take_snapshot()
    for k in range(40):
        feed(passes, sightings(BEACON, 100.0 * (k + 1), 0.0, 40.0, 0.3, rng))
    after = tracemalloc.take_snapshot()
    tracemalloc.stop()
    grown = sum(s.size_diff for s in after.compare_to(before, "filename") if "beacons.py" in str(s.traceback))
    assert grown < 2048, grown


def test_the_offset_matcher_moves_to_a_fix_as_far_as_the_covariances_say_and_learns_their_honesty():
    matcher = OffsetMatcher()
    matcher.reset(T0_NS, 0.0, 0.0, 0.0)
    pose = DeadReckonedPose(T0_NS + int(20e9), 20.0, 0.0, 0.0, np.diag([1.0, 1.0, 0.01]))
    assert (matcher.update(pose).x_m, matcher.update(pose).y_m) == (20.0, 0.0)
    matcher.observe(22.0, 0.0, 1.0)  # equal variances: half-way
    assert matcher.update(pose).x_m == pytest.approx(21.0)
    # an edge that says 1 m but is 4 m off again and again: the factor grows
    for k in range(10):
        far = DeadReckonedPose(T0_NS + int((30 + 10 * k) * 1e9), 20.0, 0.0, 0.0, np.diag([1.0 + 1.0 * (k + 1)] * 2 + [0.01]))
        here = matcher.update(far)
        matcher.observe(here.x_m + 4.0, 0.0, 1.0)
    assert matcher.inflation > 3.0


# -- the hub ---------------------------------------------------------------------------------------


def session(beacons, plan=False):
    venue = Venue("hall", court_length_m=60.0, court_width_m=10.0, beacons=beacons,
                  floor_plan=(((( -1.0, -3.0), (61.0, -3.0), (61.0, 3.0), (-1.0, 3.0)),),) if plan else ())
    return Session(venue, (Agent("walker", AgentKind.PEDESTRIAN, sensors=(Sensor("walker-hand", Mount.HAND),)),))


def walk_hub(hub, beacons, seed=5, scale=0.9, floor=0, walk=0):
    """The walker goes along y 0 from x 0 to 60 at SPEED_MPS from a stand at x 0 (`walk`: how many
    walks before, each 100 s later); the edge's steps are `scale` too short. Returns the final live
    pose's x and the true final x."""
    rng = np.random.default_rng(seed)
    events = []
    for step in range(0, 85):
        t = 0.55 * step + 100.0 * walk
        x_true = SPEED_MPS * (t - 100.0 * walk)
        cov = np.diag([0.05 + 0.01 * step, 0.05 + 0.01 * step, 0.001]).ravel().tolist()
        events.append((T0_NS + int(t * 1e9), 0, messages.new(
            "EstimatedPose", timestamp_ns=T0_NS + int(t * 1e9), agent_id="walker", x_m=scale * x_true, y_m=0.0,
            heading_rad=0.0, covariance=cov, method="reckon", track=messages.Track.LIVE, correction_sequence=1 + walk,
            floor=floor)))
    for beacon in beacons:
        for time_ns, rssi in sightings(beacon, 100.0 * walk, 0.0, 60.0, 0.3, rng):
            events.append((time_ns, 1, messages.new("BeaconSighting", timestamp_ns=time_ns, agent_id="walker",
                                                    sensor_id="walker-hand", beacon_id=beacon.id, rssi_dbm=rssi)))
    live = []
    for _, _, message in sorted(events, key=lambda e: (e[0], e[1])):
        live += [p for p in hub.on_message(message) if p.track == messages.Track.LIVE]
    return live[-1].x_m, SPEED_MPS * 0.55 * 84


@pytest.mark.parametrize("plan", [False, True])
def test_beacon_passes_pull_a_short_stepping_track_forward(plan):
    beacons = (Beacon("b1", 20.0, 0.0, height_m=2.6), Beacon("b2", 40.0, 0.0, height_m=2.6))
    blind_x, true_x = walk_hub(PedestrianHub(session(beacons, plan), beacons=False), beacons)
    hub = PedestrianHub(session(beacons, plan))
    fixed_x, _ = walk_hub(hub, beacons)
    view = hub.agents["walker"]
    assert view.fixes_taken >= 2 and view.fixes_refused == 0
    # the edge claims 0.2-0.9 m of sd against a fix's 2 m: the fixes move it part of the way only
    assert abs(fixed_x - true_x) < abs(blind_x - true_x) - 0.5
    assert f"beacon fixes {view.fixes_taken} taken, 0 refused" in view.describe()


def test_a_beacon_on_another_floor_or_in_the_wrong_place_is_not_taken():
    upstairs = (Beacon("b1", 20.0, 0.0, height_m=2.6, floor=1),)
    hub = PedestrianHub(session(upstairs))
    walk_hub(hub, upstairs)
    assert hub.agents["walker"].fixes_taken == 0 and hub.agents["walker"].fixes_elsewhere >= 1
    # the venue file puts the beacons 15 m from where they hang: refused, then distrusted
    hanging = tuple(Beacon(f"b{k}", 20.0, 0.0, height_m=2.6) for k in range(1))
    stated = tuple(Beacon(f"b{k}", 35.0, 0.0, height_m=2.6) for k in range(1))
    hub = PedestrianHub(session(stated))
    blind = PedestrianHub(session(stated), beacons=False)
    for walk in range(5):
        moved_x, true_x = walk_hub(hub, hanging, seed=walk, scale=1.0, walk=walk)
        blind_x, _ = walk_hub(blind, hanging, seed=walk, scale=1.0, walk=walk)
    view = hub.agents["walker"]
    assert view.fixes_taken == 0 and view.fixes_refused >= 3
    assert view.passes.records["b0"].distrusted(view.passes.settings)
    assert abs(moved_x - true_x) <= abs(blind_x - true_x) + 0.5
