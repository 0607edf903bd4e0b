"""The pedestrian's edge (edge/pedestrian/edge.py), the magnetometer aid (edge/pedestrian/magnetic.py) and the
hub's map matching per pedestrian (hub/pedestrian/hub.py), on crafted phone signals."""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pytest

from edge.pedestrian.estimator import PdrEstimator, PhoneSample
from edge.pedestrian.edge import PedestrianEdge, phone_samples
from edge.pedestrian.magnetic import MagneticAid, VenueField
from hub.pedestrian.hub import PedestrianHub
from hub.pedestrian.walkable import PLAN_TOLERANCE_M
from protocol import messages
from protocol.session import session_from_dict

RATE_HZ = 50.0
CADENCE_HZ = 1.8
T0_NS = 1_700_000_000_000_000_000
FIELD_UT, DIP_DEG, NORTH_DEG = 48.8, 46.0, 95.7  # ILC site 1's WMM field; magnetic north in the venue frame


def walk_rows(seconds: float, phone_heading_rad: float = 0.0, field_scale: float = 1.0,
              start_s: float = 0.0) -> list[PhoneSample]:
    """A phone held flat, walking straight at CADENCE_HZ, its top (+y) pointing at venue heading
    `phone_heading_rad`; its magnetometer sees the venue's field (times `field_scale`)."""
    rows = []
    # the field in the venue frame (x, y, up): horizontal towards magnetic north, dipping down
    horizontal, down = FIELD_UT * field_scale * math.cos(math.radians(DIP_DEG)), FIELD_UT * field_scale * math.sin(
        math.radians(DIP_DEG))
    north = math.radians(NORTH_DEG)
    venue_field = np.array([horizontal * math.cos(north), horizontal * math.sin(north), -down])
    # phone axes in the venue frame: +y (top) along the heading, +x to its right, +z up
    top = np.array([math.cos(phone_heading_rad), math.sin(phone_heading_rad), 0.0])
    right = np.array([math.sin(phone_heading_rad), -math.cos(phone_heading_rad), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    mag = (float(venue_field @ right), float(venue_field @ top), float(venue_field @ up))
    for i in range(int(seconds * RATE_HZ)):
        t = start_s + i / RATE_HZ
        bounce = 2.5 * math.sin(2.0 * math.pi * CADENCE_HZ * t)
        rows.append(PhoneSample(T0_NS + int(round(t * 1e9)), (0.0, 0.3 * math.cos(2 * math.pi * CADENCE_HZ * t),
                                                               9.81 + bounce), (0.0, 0.0, 0.0), mag))
    return rows


def batch_of(rows: list[PhoneSample], sensor_id: str = "phone", sequence: int = 0):
    return messages.new("ImuBatch", timestamp_ns=rows[0].time_ns, agent_id="walker", sensor_id=sensor_id,
                        sequence=sequence, sample_offset_ns=[r.time_ns - rows[0].time_ns for r in rows],
                        accel_g=[v / 9.80665 for r in rows for v in r.accel_ms2],
                        gyro_dps=[math.degrees(v) for r in rows for v in r.gyro_rads],
                        mag_gauss=[v / 100.0 for r in rows for v in r.mag_ut])


def scan(time_ns: int, heading_deg: float = 0.0, accepted: bool = True, heading_sd_deg: float = 0.0):
    return messages.new("StandScan", timestamp_ns=time_ns, agent_id="walker", sensor_id="phone", stand_id="s",
                        x_m=2.0, y_m=5.0, heading_rad=math.radians(heading_deg), accepted=accepted,
                        heading_sd_rad=math.radians(heading_sd_deg), reason="" if accepted else "refused")


def session(magnetic: bool = False, floor_plan: bool = False):
    venue = {"name": "hall"}
    if magnetic:
        venue.update(magnetic_north_deg=NORTH_DEG, magnetic_field_ut=FIELD_UT, magnetic_dip_deg=DIP_DEG)
    if floor_plan:  # a corridor along +x, 4 m wide
        venue["floor_plan"] = [[[[-1.0, 3.0], [60.0, 3.0], [60.0, 7.0], [-1.0, 7.0]]]]
    return session_from_dict({"venue": venue, "agents": [
        {"id": "walker", "kind": "pedestrian", "sensors": [{"id": "phone", "mount": "hand", "rate_hz": RATE_HZ}]}]})


def run_edge(edge: PedestrianEdge, rows: list[PhoneSample], batch: int = 25) -> list:
    out = []
    for start in range(0, len(rows), batch):
        out += edge.push(batch_of(rows[start:start + batch], sequence=start // batch))
    return out


def test_batches_become_samples_in_phone_units():
    rows = walk_rows(1.0)
    back = phone_samples(batch_of(rows))
    assert [r.time_ns for r in back] == [r.time_ns for r in rows]
    np.testing.assert_allclose([r.accel_ms2 for r in back], [r.accel_ms2 for r in rows], atol=1e-5)
    np.testing.assert_allclose([r.mag_ut for r in back], [r.mag_ut for r in rows], atol=1e-4)
    broken = batch_of(rows)
    broken.accel_g[4] = math.nan
    assert len(phone_samples(broken)) == len(rows) - 1  # the NaN sample is dropped, the rest kept


def test_nothing_before_a_stand_then_one_pose_per_step():
    edge = PedestrianEdge(session().agents[0], session().venue)
    before = run_edge(edge, walk_rows(3.0))
    assert before == [] and edge.counters.before_first_scan >= 3
    edge.scan(scan(T0_NS + 3_000_000_000, accepted=False))
    assert edge.counters.scans_refused == 1 and run_edge(edge, walk_rows(1.0, start_s=3.0)) == []
    edge.scan(scan(T0_NS + 4_000_000_000, heading_deg=0.0))
    poses = run_edge(edge, walk_rows(10.0, start_s=4.0))
    assert abs(len(poses) - CADENCE_HZ * 10.0) <= 2
    assert all(p.correction_sequence == 1 and p.method == "reckon" and len(p.covariance) == 9 for p in poses)
    xs = [p.x_m for p in poses]
    assert xs[0] > 2.0 and all(b > a for a, b in zip(xs, xs[1:]))  # walking along +x from the stand at x 2
    assert all(abs(p.y_m - 5.0) < 0.3 for p in poses)
    assert edge.push(batch_of(walk_rows(1.0, start_s=14.0), sensor_id="watch")) == []
    assert edge.counters.other_sensor_batches == 1


def test_magnetometer_pulls_a_wrong_stand_heading_back():
    """The stand says 20 deg but the phone points at 0 deg: with the venue's field stated, the
    magnetometer brings the heading back within a few degrees; a field halved by steel is gated
    out and the wrong heading stays."""
    for field_scale, expect_fixed in ((1.0, True), (0.5, False)):
        estimator_edge = PedestrianEdge(session(magnetic=True).agents[0], session(magnetic=True).venue)
        run_edge(estimator_edge, walk_rows(1.0))
        estimator_edge.scan(scan(T0_NS + 1_000_000_000, heading_deg=20.0, heading_sd_deg=15.0))
        poses = run_edge(estimator_edge, walk_rows(40.0, field_scale=field_scale, start_s=1.0))
        final = math.degrees(poses[-1].heading_rad)
        aid = estimator_edge.estimator.magnetic
        if expect_fixed:
            assert abs(final) < 4.0, final
            assert aid.used > 40
        else:
            assert abs(final - 20.0) < 1.0, final
            assert aid.used == 0 and aid.rejected > 40


def test_magnetic_gate_checks_strength_and_dip():
    aid = MagneticAid(VenueField(math.radians(90.0), 50.0, math.radians(45.0)))
    level = np.eye(3)
    aid.add(level, (0.0, 50 * math.cos(math.radians(45)), -50 * math.sin(math.radians(45))))  # clean, north along +y
    assert aid.measurement() == pytest.approx(0.0, abs=1e-9)  # magnetic north at 90 deg in both frames
    aid.add(level, (0.0, 50 * math.cos(math.radians(70)), -50 * math.sin(math.radians(70))))  # dip 70: bent
    aid.add(level, (0.0, 30.0, -30.0))  # 42 uT: 15 % weak
    assert aid.measurement() is None and aid.rejected == 1


def test_estimator_memory_does_not_grow():
    estimator = PdrEstimator()
    rows = walk_rows(20.0)
    estimator.reset_to_stand(rows[0].time_ns, 0.0, 0.0, 0.0)
    for row in rows[:10]:
        estimator.step(row)
    tracemalloc.start()
    before = tracemalloc.take_snapshot()
    for lap in range(20):  # 20 000 samples, 720 steps
        for row in rows:
            estimator.step(PhoneSample(row.time_ns + lap * 20_000_000_000 + 20_000_000_000, row.accel_ms2,
                                       row.gyro_rads, row.mag_ut))
    after = tracemalloc.take_snapshot()
    tracemalloc.stop()
    grown = sum(stat.size_diff for stat in after.compare_to(before, "filename") if "edge" in str(stat.traceback))
    assert estimator.steps.count > 700
    assert grown < 4096, grown


def pose(time_s: float, x_m: float, y_m: float, sequence: int = 1):
    return messages.new("EstimatedPose", timestamp_ns=T0_NS + int(time_s * 1e9), agent_id="walker", x_m=x_m,
                        y_m=y_m, heading_rad=0.0, covariance=list(np.diag([0.1, 0.1, 0.01]).ravel()),
                        method="reckon", track=messages.Track.LIVE, correction_sequence=sequence)


def test_hub_restarts_the_matcher_from_the_pose_itself_and_keeps_it_in_the_corridor():
    hub = PedestrianHub(session(floor_plan=True))
    first = hub.on_message(pose(0.0, 2.0, 5.0))  # the first pose after the stand (sequence 1)
    assert [(p.x_m, p.y_m, p.track) for p in first] == [(2.0, 5.0, messages.Track.LIVE),
                                                        (2.0, 5.0, messages.Track.REFINED)]
    out = []
    for i in range(1, 30):  # the dead reckoning drifts towards the wall at y 7 (0.2 m per step)
        out += hub.on_message(pose(0.5 * i, 2.0 + 0.7 * i, 5.0 + 0.2 * i))
    live = [p for p in out if p.track == messages.Track.LIVE]
    refined = [p for p in out if p.track == messages.Track.REFINED]
    # the corridor as the hub reads the plan: a drawn wall is good to PLAN_TOLERANCE_M
    assert len(live) == 29 and all(3.0 - PLAN_TOLERANCE_M < p.y_m < 7.0 + PLAN_TOLERANCE_M for p in out)
    assert live[-1].x_m > 15.0
    lag = hub.agents["walker"].matcher.refined_lag_steps
    assert [p.timestamp_ns for p in refined] == [p.timestamp_ns for p in live[:len(live) - lag]]
    assert hub.on_message(pose(1.0, 9.0, 5.0)) == [] and hub.agents["walker"].out_of_order == 1
    restarted = hub.on_message(pose(20.0, 40.0, 4.0, sequence=2))  # a second stand, its scan not yet arrived
    finished = [p for p in restarted if p.correction_sequence == 1]  # the old stand's track ends at once
    assert [p.timestamp_ns for p in finished] == [p.timestamp_ns for p in live[len(live) - lag:]]
    assert all(p.track == messages.Track.REFINED for p in finished)
    new = [p for p in restarted if p.correction_sequence == 2]
    assert [(p.x_m, p.y_m, p.track) for p in new] == [(40.0, 4.0, messages.Track.LIVE),
                                                      (40.0, 4.0, messages.Track.REFINED)]
    assert hub.key_for(new[0]) == "reckon/hall/walker/pose/live"
    assert hub.key_for(new[1]) == "reckon/hall/walker/pose/refined"
    hub.on_message(pose(20.5, 40.7, 4.0, sequence=2))
    assert [p.timestamp_ns for p in hub.flush()] == [pose(20.5, 0, 0).timestamp_ns]  # end: what waits comes out


def test_hub_without_a_map_passes_poses_on():
    hub = PedestrianHub(session())
    out = hub.on_message(pose(1.0, 3.0, 4.0))
    assert (out[0].x_m, out[0].y_m) == (3.0, 4.0) and hub.agents["walker"].matcher is None


def test_a_wrong_step_length_stretches_the_track_and_the_covariance_says_how_far():
    """K's error is shared by every step: after a straight walk the along-track SD grows with the
    distance walked (step_scale_sd of it), the cross-track SD does not; the heading, x and y are
    what they were without the term (it only adds to the covariance)."""
    estimator = PdrEstimator()
    rows = walk_rows(30.0)
    estimator.step(rows[0])
    estimator.reset_to_stand(rows[0].time_ns, 2.0, 5.0, 0.0)
    steps = [step for row in rows[1:] for step in estimator.step(row)]
    walked_m = math.hypot(steps[-1].x_m - 2.0, steps[-1].y_m - 5.0)
    assert walked_m > 20.0
    covariance = steps[-1].covariance
    assert covariance.shape == (3, 3)
    scale_sd = estimator.settings.step_scale_sd
    along_sd, cross_sd = math.sqrt(covariance[0, 0]), math.sqrt(covariance[1, 1])  # walking along +x
    assert along_sd == pytest.approx(math.hypot(scale_sd * walked_m, along_sd_without_scale(steps)), rel=0.05)
    assert cross_sd < 0.5 * along_sd
    assert estimator.snapshot().step_scale_sd == pytest.approx(scale_sd)


def along_sd_without_scale(steps: list) -> float:
    """The along-track SD the per-step scatter and the stand give (independent per step)."""
    fraction = PdrEstimator().settings.step_length_sd_fraction
    stand_sd = PdrEstimator().settings.stand_position_sd_m
    return math.sqrt(stand_sd ** 2 + sum((fraction * step.step_length_m) ** 2 for step in steps))


def test_the_scale_error_survives_a_stand_and_shrinks_when_k_is_learned():
    """A stand restarts the position, not K's error; a second stand far enough away re-learns K
    and its error becomes the learned one's (the stands' positions over the distance), blended."""
    estimator = PdrEstimator()
    rows = walk_rows(20.0)
    estimator.step(rows[0])
    estimator.reset_to_stand(rows[0].time_ns, 2.0, 5.0, 0.0)
    for row in rows[1:]:
        estimator.step(row)
    settings = estimator.settings
    walked_m = estimator.x_m - 2.0
    assert walked_m > settings.step_gain_min_displacement_m
    # a stand as far as the walk went, 20 % further: K is learned from it
    surveyed_m = 1.2 * walked_m
    estimator.reset_to_stand(rows[-1].time_ns, 2.0 + surveyed_m, 5.0, 0.0)
    weight = settings.step_gain_smoothing
    expected = math.sqrt((1 - weight) ** 2 * settings.step_scale_sd ** 2
                         + weight ** 2 * 2 * settings.stand_position_sd_m ** 2 / surveyed_m ** 2)
    assert estimator.snapshot().step_scale_sd == pytest.approx(expected)
    assert estimator.snapshot().covariance[0, 0] == pytest.approx(settings.stand_position_sd_m ** 2)
    # a stand right after (too close to learn from) keeps it
    estimator.reset_to_stand(rows[-1].time_ns, 2.0 + surveyed_m, 5.0, 0.0)
    assert estimator.snapshot().step_scale_sd == pytest.approx(expected)


def test_hub_starts_a_walkers_track_again_after_a_clock_jump_and_refuses_poses_that_are_not_numbers():
    hub = PedestrianHub(session(floor_plan=True))
    for i in range(10):
        hub.on_message(pose(0.5 * i, 2.0 + 0.7 * i, 5.0))
    hub.on_message(pose(1e6, 9.0, 5.0))  # one pose eleven days ahead (a clock glitch)
    again = hub.on_message(pose(5.0, 9.5, 5.0))  # the stream goes on where it was
    view = hub.agents["walker"]
    assert view.clock_restarts == 1 and view.out_of_order == 0
    assert [p.track for p in again if p.timestamp_ns == pose(5.0, 0, 0).timestamp_ns][:1] == [messages.Track.LIVE]
    later = hub.on_message(pose(5.5, 9.9, 5.0))
    assert any(p.track == messages.Track.LIVE for p in later) and "1 clock restarts" in view.describe()
    bad = pose(6.0, float("inf"), 5.0)
    with pytest.raises(ValueError, match=r"EstimatedPose of walker at .*x_m inf.*must be finite"):
        hub.on_message(bad)
    assert view.poses == 13
