"""Pedestrian map matching on synthetic corridors: the paper's turn snap and our particle filter.

The map is the indoor-navigation paper's table 5 (Chiba Tech building 2, cm -> m) and its route
I-J-G-H-L-K-E-F-B-C-G-H-D-A-E-F-I (278 m, 15 turns). The truth walks the corridor centre lines in
0.7 m steps at 1.8 steps/s; the dead reckoning has the paper's calibration error (3 deg, table 3),
a gyro drift of 0.1 deg/s, 8 % long steps, 2 deg of heading noise and 3 % of length noise per step.
Results on simulated and real walks are in docs/pdr-estimator.md (`reckon eval`).
"""

from __future__ import annotations

import ast
import importlib.util
import json
import math
import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import shapely

from hub.pedestrian.matching import DeadReckonedPose, MatchedPose, SnapStage
from hub.pedestrian.particles import ParticleMatcher, ParticleSettings
from hub.pedestrian.paper import PaperSnapMatcher, PaperSnapSettings
from hub.pedestrian.walkable import WalkableArea, corridor_graph, floor_plan_geometry
from protocol.session import MapPoint, Venue
from support.corridors import PAPER_AREA, PAPER_POINTS, PAPER_ROUTE, dead_reckon, truth_walk


def run(matcher: PaperSnapMatcher | ParticleMatcher, time_ns: np.ndarray, truth: np.ndarray,
        poses: list[DeadReckonedPose]) -> list[MatchedPose]:
    """Reset at the first true pose (the QR stand at the start), then every later pose."""
    matcher.reset(int(time_ns[0]), *truth[0])
    start = MatchedPose(int(time_ns[0]), *truth[0], covariance=np.zeros((3, 3)))
    return [start] + [matcher.update(pose) for pose in poses[1:]]


def errors_m(track: list[DeadReckonedPose] | list[MatchedPose], truth: np.ndarray) -> np.ndarray:
    return np.hypot(np.array([p.x_m for p in track]) - truth[:, 0], np.array([p.y_m for p in track]) - truth[:, 1])


def xy(track: list[MatchedPose]) -> tuple[np.ndarray, np.ndarray]:
    return np.array([p.x_m for p in track]), np.array([p.y_m for p in track])


@pytest.fixture(scope="module")
def paper_walk() -> tuple[np.ndarray, np.ndarray, list[DeadReckonedPose]]:
    time_ns, truth = truth_walk(PAPER_POINTS, PAPER_ROUTE)
    return time_ns, truth, dead_reckon(time_ns, truth)


def test_corridor_graph_of_table_5():
    corridors, dangling = corridor_graph(PAPER_POINTS)
    assert sorted("".join(sorted((c.start_id, c.end_id))) for c in corridors) == sorted(
        ["AB", "AE", "BC", "BF", "CD", "CG", "DH", "EF", "EK", "FG", "FI", "GH", "GJ", "HL", "IJ", "KL"])
    assert dangling == (("H", 0.0),)  # table 5 gives H an east corridor; nothing lies east of it


def test_grid_never_lets_a_move_through_a_thin_wall():
    # two rooms split by a 2 cm wall with a 0.5 m door at each end
    plan = ([[[0, 0], [10, 0], [10, 5], [0, 5]], [[4.99, 0.5], [5.01, 0.5], [5.01, 4.5], [4.99, 4.5]]],)
    geometry = floor_plan_geometry(plan)
    area = WalkableArea(geometry, cell_m=0.1)
    random = np.random.default_rng(7)
    start = random.uniform([0, 0], [10, 5], (20_000, 2))
    end = start + random.normal(0.0, 1.0, (20_000, 2))
    allowed = area.move_allowed(start[:, 0], start[:, 1], end[:, 0], end[:, 1])
    exact = shapely.covered_by(shapely.linestrings(np.stack([start, end], axis=1)), geometry)
    assert not np.any(allowed & ~exact)  # sound: never allowed where the exact geometry forbids
    assert allowed.sum() > 0.8 * exact.sum()  # and not much stricter (the 0.12 m wall clearance)
    assert area.move_allowed(np.array([4.0]), np.array([0.3]), np.array([6.0]), np.array([0.3]))[0]  # the door
    assert not area.move_allowed(np.array([4.0]), np.array([2.5]), np.array([6.0]), np.array([2.5]))[0]


def test_paper_snap_fixes_every_turn(paper_walk):
    time_ns, truth, poses = paper_walk
    track = run(PaperSnapMatcher(PAPER_POINTS), time_ns, truth, poses)
    snaps = [p.snap for p in track[1:] if p.snap is not None]
    positions = [s for s in snaps if s.stage is SnapStage.POSITION]
    assert "".join(s.point_id for s in positions) == PAPER_ROUTE[1:-1]
    assert all(s.valid and s.applied for s in positions)
    where = {p.id: np.array([p.x_m, p.y_m]) for p in PAPER_POINTS}
    expected_deg = [math.degrees(math.atan2(*(where[b] - where[a])[::-1])) % 360.0
                    for a, b in zip(PAPER_ROUTE[1:-1], PAPER_ROUTE[2:])]
    assert [s.direction_deg for s in snaps if s.stage is SnapStage.HEADING] == pytest.approx(expected_deg)
    dead_reckoned, snapped = errors_m(poses, truth), errors_m(track, truth)
    assert snapped.mean() < 0.3 * dead_reckoned.mean() and snapped[-1] < 0.3 * dead_reckoned[-1]


def test_particle_filter_stays_in_corridors_and_beats_dead_reckoning(paper_walk):
    time_ns, truth, poses = paper_walk
    matcher = ParticleMatcher(PAPER_AREA, ParticleSettings(particles=300, seed=0))
    track = run(matcher, time_ns, truth, poses)
    assert PAPER_AREA.is_walkable(*xy(track[1:])).all()
    dead_reckoned, matched = errors_m(poses, truth), errors_m(track, truth)
    assert matched[-1] < 0.2 * dead_reckoned[-1] and matched.mean() < 0.2 * dead_reckoned.mean()
    assert matched.max() < 1.5  # never further off than a corridor's width
    assert matcher.diagnostics.recoveries == 0
    assert all(np.all(np.linalg.eigvalsh(p.covariance) >= -1e-12) for p in track[1:])


def test_refined_track_lags_by_its_steps_stays_walkable_and_is_no_worse(paper_walk):
    time_ns, truth, poses = paper_walk
    lag = 15
    matcher = ParticleMatcher(PAPER_AREA, ParticleSettings(particles=300, seed=0, smoothing_lag_steps=lag))
    matcher.reset(int(time_ns[0]), *truth[0])
    live, refined = [], []
    for pose in poses[1:]:
        live.append(matcher.update(pose))
        refined += matcher.refined()
        assert len(refined) == max(0, len(live) - lag)  # each refined pose `lag` poses behind
    refined += matcher.flush()
    assert [p.time_ns for p in refined] == [p.time_ns for p in live]
    assert PAPER_AREA.is_walkable(*xy(refined)).all()
    live_error, refined_error = errors_m(live, truth[1:]), errors_m(refined, truth[1:])
    assert refined_error.mean() <= live_error.mean() and np.percentile(refined_error, 90) <= np.percentile(live_error, 90)
    assert matcher.lag is not None and matcher.lag.x_m.shape == (lag, 300)


def test_published_covariance_adds_the_dead_reckonings_share_to_the_clouds(paper_walk):
    """The cloud alone understates the error (docs/pdr-estimator.md): live and refined poses carry
    the cloud's spread plus `edge_covariance_share` of the pose's own covariance; where they are
    is untouched by it."""
    time_ns, truth, poses = paper_walk
    with_covariance = [DeadReckonedPose(p.time_ns, p.x_m, p.y_m, p.heading_rad,
                                        np.diag([0.1 + 0.01 * i, 0.2 + 0.01 * i, 0.003]))
                       for i, p in enumerate(poses[:200])]
    tracks = {}
    for share in (0.0, 0.5):
        matcher = ParticleMatcher(PAPER_AREA, ParticleSettings(particles=300, seed=0, smoothing_lag_steps=10,
                                                               edge_covariance_share=share))
        live = run(matcher, time_ns, truth, with_covariance)[1:]
        tracks[share] = (live, matcher.refined() + matcher.flush())
    (live0, refined0), (live5, refined5) = tracks[0.0], tracks[0.5]
    assert [(p.x_m, p.y_m) for p in live0] == [(p.x_m, p.y_m) for p in live5]
    assert [(p.x_m, p.y_m) for p in refined0] == [(p.x_m, p.y_m) for p in refined5]
    for a, b, pose in zip(live0, live5, with_covariance[1:]):
        np.testing.assert_allclose(b.covariance - a.covariance, 0.5 * pose.covariance, atol=1e-12)
    assert len(refined5) == len(live5)
    for a, b, pose in zip(refined0, refined5, with_covariance[1:]):
        np.testing.assert_allclose(b.covariance - a.covariance, 0.5 * pose.covariance, atol=1e-12)


U_POINTS = (MapPoint("A", 0.0, 0.0, (0.0,)), MapPoint("B", 20.0, 0.0, (180.0, 90.0)),
            MapPoint("C", 20.0, 4.0, (270.0, 180.0)), MapPoint("D", 0.0, 4.0, (0.0,)))


def test_particle_filter_never_matches_across_a_wall():
    # a U of 2 m corridors 4 m apart: a 2 m wall between the legs; the dead reckoning veers 12 deg
    # left and crosses into the upper leg long before the bend
    area = WalkableArea.from_venue(Venue("u", map_points=U_POINTS))
    time_ns, truth = truth_walk(U_POINTS, "ABCD")
    poses = dead_reckon(time_ns, truth, bias_deg=12.0, drift_deg_per_s=0.0, scale=1.0)
    dead_reckoned_x, dead_reckoned_y = xy(poses)
    assert np.any((dead_reckoned_y > 3.0) & (dead_reckoned_x < 18.0))  # the dead reckoning cut across
    track = run(ParticleMatcher(area, ParticleSettings(seed=3)), time_ns, truth, poses)
    x_m, y_m = xy(track)
    assert area.is_walkable(x_m[1:], y_m[1:]).all()
    assert area.move_allowed(x_m[1:-1], y_m[1:-1], x_m[2:], y_m[2:]).all()  # no output-to-output jump through the wall
    assert errors_m(track, truth).max() < 2.0


def test_validity_rule_refuses_an_ambiguous_snap():
    # B and B2 are 1.2 m apart; coming 30 m from A, X tan 3 deg = 1.57 m covers both
    points = (MapPoint("A", 0.0, 0.0, (0.0,)), MapPoint("B", 30.0, 0.0, (180.0, 90.0)),
              MapPoint("B2", 30.0, 1.2, (270.0, 0.0)), MapPoint("C", 30.0, 10.0, (270.0,)))
    time_ns, truth = truth_walk(points, "ABC")
    poses = dead_reckon(time_ns, truth, drift_deg_per_s=0.0)
    track = run(PaperSnapMatcher(points), time_ns, truth, poses)
    snaps = [p.snap for p in track[1:] if p.snap is not None]
    assert len(snaps) == 1 and not snaps[0].valid and not snaps[0].applied
    assert snaps[0].rule_radius_m == pytest.approx(30.0 * math.tan(math.radians(3.0)), abs=0.1)
    assert {snaps[0].point_id, snaps[0].conflicting_point_id} == {"B", "B2"}
    assert errors_m(track, truth) == pytest.approx(errors_m(poses, truth))  # nothing moved
    paper_as_printed = run(PaperSnapMatcher(points, PaperSnapSettings(enforce_validity_rule=False)),
                           time_ns, truth, poses)
    assert [p.snap.applied for p in paper_as_printed[1:] if p.snap is not None] == [True, True]


def test_far_turn_is_not_snapped_with_the_papers_suggested_fix():
    points = (MapPoint("A", 0.0, 0.0, (0.0,)), MapPoint("B", 10.0, 0.0, (180.0, 90.0)),
              MapPoint("C", 10.0, 10.0, (270.0,)))
    time_ns, truth = truth_walk(points, "ABC")
    poses = dead_reckon(time_ns, truth, scale=1.5, drift_deg_per_s=0.0)  # overshoots B by 5 m
    track = run(PaperSnapMatcher(points, PaperSnapSettings(max_snap_distance_m=3.0)), time_ns, truth, poses)
    snaps = [p.snap for p in track[1:] if p.snap is not None]
    assert len(snaps) == 1 and snaps[0].valid and not snaps[0].applied and snaps[0].distance_m > 3.0


def test_particle_filter_recovers_when_every_particle_dies():
    area = WalkableArea.from_venue(Venue("line", map_points=(MapPoint("A", 0.0, 0.0, (0.0,)),
                                                             MapPoint("B", 30.0, 0.0, (180.0,)))))
    matcher = ParticleMatcher(area, ParticleSettings(seed=1))
    matcher.reset(0, 1.0, 0.0, 0.0)
    for step in range(1, 11):
        matcher.update(DeadReckonedPose(step * 500_000_000, 1.0 + 0.7 * step, 0.0, 0.0))
    jump = matcher.update(DeadReckonedPose(11 * 500_000_000, 8.0, 3.0, 0.0))  # 3 m sideways: into the wall
    assert matcher.diagnostics.recoveries == 1
    assert area.is_walkable(np.array([jump.x_m]), np.array([jump.y_m]))[0]
    for step in range(12, 20):
        last = matcher.update(DeadReckonedPose(step * 500_000_000, 8.0 + 0.7 * (step - 11), 3.0, 0.0))
    assert matcher.diagnostics.recoveries == 1 and abs(last.y_m) < 1.0 and last.x_m == pytest.approx(13.6, abs=1.5)


def test_reset_reseeds_at_the_fix():
    matcher = ParticleMatcher(PAPER_AREA, ParticleSettings(seed=2))
    matcher.reset(0, 3.3, 10.0, math.pi / 2)
    matched = matcher.update(DeadReckonedPose(500_000_000, 3.3, 10.7, math.pi / 2))
    assert matched.x_m == pytest.approx(3.3, abs=0.3) and matched.y_m == pytest.approx(10.7, abs=0.3)


def test_particle_memory_and_count_are_fixed(paper_walk):
    time_ns, truth, poses = paper_walk
    matcher = ParticleMatcher(PAPER_AREA, ParticleSettings(particles=200, seed=5))
    laps = 3
    lap_ns = int(time_ns[-1] + 500_000_000)
    matcher.reset(0, *truth[0])
    tracemalloc.start()
    for pose in poses[1:11]:
        matcher.update(pose)
    after_few, _ = tracemalloc.get_traced_memory()
    for lap in range(laps):  # the closed route again and again: ~1,200 steps with resamples
        matcher.reset(lap * lap_ns, *truth[0])
        for pose in poses[1:]:
            matcher.update(DeadReckonedPose(pose.time_ns + lap * lap_ns, pose.x_m, pose.y_m, pose.heading_rad))
    after_many, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert after_many - after_few < 16_384
    arrays = (matcher.x_m, matcher.y_m, matcher.offset_rad, matcher.scale, matcher.weight)
    assert all(array.shape == (200,) for array in arrays) and matcher.diagnostics.resamples > 10


def test_cores_import_no_io():
    modules = ["hub.pedestrian.matching", "hub.pedestrian.walkable", "hub.pedestrian.paper", "hub.pedestrian.particles"]
    code = (f"import importlib, json, sys\nfor name in {modules!r}: importlib.import_module(name)\n"
            "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))")
    loaded = set(json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                           check=True).stdout))
    assert not loaded & {"zenoh", "mcap", "asyncio", "serial", "bleak", "socket"}
    for name in modules:  # `time` is loaded by numpy anyway: check that these modules do not read a clock
        tree = ast.parse(Path(importlib.util.find_spec(name).origin).read_text(encoding="utf-8"))
        imported = {alias.name.split(".")[0] for node in ast.walk(tree) if isinstance(node, ast.Import)
                    for alias in node.names}
        imported |= {node.module.split(".")[0] for node in ast.walk(tree)
                     if isinstance(node, ast.ImportFrom) and node.module}
        assert not imported & {"time", "datetime", "zenoh", "mcap", "asyncio"}, name


ILC_FLOOR = Path(__file__).resolve().parents[3] / "shared" / "data" / "pdr" / "ilc-site1-F1"
