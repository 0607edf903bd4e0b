"""The map guard (hub/pedestrian/guard.py): on a plan that contradicts the walk the matched track
stays within 10 % of the dead reckoning's error; on a right plan it changes nothing.

The walk is the indoor-navigation paper's route over its corridor map, dead-reckoned with a
heading bias, drift and a step-length scale (tests/support/corridors.py).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
import shapely.affinity

from hub.pedestrian.guard import GuardSettings, MapGuard
from hub.pedestrian.matching import DeadReckonedPose, MatchedPose
from hub.pedestrian.particles import ParticleMatcher, ParticleSettings
from hub.pedestrian.walkable import WalkableArea
from support.corridors import PAPER_AREA, PAPER_POINTS, PAPER_ROUTE, dead_reckon, truth_walk

RIGHT = PAPER_AREA
START = (3.3, 33.55)  # point I, where the walk starts


def walk() -> tuple[np.ndarray, np.ndarray, list[DeadReckonedPose]]:
    time_ns, truth = truth_walk(PAPER_POINTS, PAPER_ROUTE)
    return time_ns, truth, dead_reckon(time_ns, truth)


def run(matcher: MapGuard | ParticleMatcher, time_ns: np.ndarray, truth: np.ndarray,
        poses: list[DeadReckonedPose]) -> list[MatchedPose]:
    matcher.reset(int(time_ns[0]), *truth[0])
    return [matcher.update(pose) for pose in poses[1:]]


def mean_error_m(track: list[DeadReckonedPose] | list[MatchedPose], truth: np.ndarray) -> float:
    return float(np.mean(np.hypot([p.x_m for p in track] - truth[:, 0], [p.y_m for p in track] - truth[:, 1])))


def guarded(area: WalkableArea) -> MapGuard:
    return MapGuard(ParticleMatcher(area, ParticleSettings(seed=0)), GuardSettings())


@pytest.fixture(scope="module")
def paper_walk():
    return walk()


CONTRADICTING = {
    # the whole plan 40 m east: the stand is off the map, so is every step
    "misses the walk": shapely.affinity.translate(RIGHT.geometry, 40.0, 0.0),
    # turned 90 deg about the stand: the stand is walkable, the walk leaves the corridors at once
    "turned about the stand": shapely.affinity.rotate(RIGHT.geometry, 90.0, origin=START),
    "mirrored about the stand": shapely.affinity.scale(RIGHT.geometry, -1.0, 1.0, origin=START),
}


@pytest.mark.parametrize("plan", sorted(CONTRADICTING))
def test_a_contradicting_plan_leaves_the_track_within_ten_percent_of_dead_reckoning(paper_walk, plan):
    time_ns, truth, poses = paper_walk
    area = WalkableArea(CONTRADICTING[plan])
    dead_reckoning_m = mean_error_m(poses[1:], truth[1:])
    unguarded_m = mean_error_m(run(ParticleMatcher(area, ParticleSettings(seed=0)), time_ns, truth, poses), truth[1:])
    assert unguarded_m > 1.5 * dead_reckoning_m  # the plan does contradict the walk: trusted, it misleads
    guard = guarded(area)
    track = run(guard, time_ns, truth, poses)
    assert mean_error_m(track, truth[1:]) <= 1.1 * dead_reckoning_m
    fallback = np.array([pose.fallback for pose in track])
    assert fallback.mean() > 0.8 and guard.diagnostics.fallback_steps == fallback.sum()
    assert guard.diagnostics.last_reason in ("recoveries", "fix off map")


def test_a_stand_off_the_map_is_counted_and_the_cloud_is_never_drawn_away_from_it(paper_walk):
    time_ns, truth, poses = paper_walk
    shifted = WalkableArea(shapely.affinity.translate(RIGHT.geometry, -2.5, 2.5))  # corridors 2.5 m off both ways
    assert not shifted.is_walkable(np.array([START[0]]), np.array([START[1]]))[0]
    guard = guarded(shifted)
    first = run(guard, time_ns[:2], truth[:2], poses[:2])[0]
    assert guard.diagnostics.fixes_off_map == 1 and first.fallback
    assert math.hypot(first.x_m - poses[1].x_m, first.y_m - poses[1].y_m) < 1e-9  # the edge's own step
    cloud = guard.matcher
    assert np.all(np.hypot(cloud.x_m - START[0], cloud.y_m - START[1]) <= GuardSettings().reacquire_radius_m + 1.0)


def test_on_the_right_plan_the_guard_changes_nothing(paper_walk):
    time_ns, truth, poses = paper_walk
    plain = run(ParticleMatcher(RIGHT, ParticleSettings(seed=0)), time_ns, truth, poses)
    guard = guarded(RIGHT)
    track = run(guard, time_ns, truth, poses)
    assert guard.diagnostics.fallback_steps == 0 and not any(pose.fallback for pose in track)
    assert [(p.x_m, p.y_m) for p in track] == [(p.x_m, p.y_m) for p in plain]
    assert mean_error_m(track, truth[1:]) < 0.2 * mean_error_m(poses[1:], truth[1:])


def test_the_matched_track_comes_back_once_the_map_agrees_again():
    # a straight corridor 60 m long with a 4 m block across it at x 20-24, the walk straight through:
    # the filter loses its cloud at the block, the guard falls back, and beyond the block the
    # shadow cloud follows the track again and the matched track returns, without a jump
    corridor = shapely.box(-1.0, -1.0, 60.0, 1.0).difference(shapely.box(20.0, -1.0, 24.0, 1.0))
    guard = MapGuard(ParticleMatcher(WalkableArea(corridor), ParticleSettings(seed=4)),
                     GuardSettings(max_recoveries=0))
    guard.reset(0, 0.0, 0.0, 0.0)
    track = [guard.update(DeadReckonedPose(step * 500_000_000, 0.7 * step, 0.0, 0.0, np.diag([0.1, 0.1, 0.01])))
             for step in range(1, 80)]
    x_m = np.array([pose.x_m for pose in track])
    fallback = np.array([pose.fallback for pose in track])
    assert fallback[(x_m > 21.0) & (x_m < 23.0)].all()  # inside the block: the edge's track
    assert not fallback[-5:].any() and guard.diagnostics.fallback_episodes >= 1
    back = int(np.flatnonzero(fallback)[-1]) + 1  # the first pose of the matched track again
    assert math.hypot(track[back].x_m - track[back - 1].x_m - 0.7, track[back].y_m - track[back - 1].y_m) \
        <= GuardSettings().return_distance_m
    assert all(0.3 < b.x_m - a.x_m < 1.1 for a, b in zip(track[back:], track[back + 1:]))  # walking on at its pace


def test_refined_poses_of_fallback_steps_are_the_fallback_poses(paper_walk):
    time_ns, truth, poses = paper_walk
    guard = MapGuard(ParticleMatcher(WalkableArea(CONTRADICTING["turned about the stand"]),
                                     ParticleSettings(seed=0, smoothing_lag_steps=10)), GuardSettings())
    guard.reset(int(time_ns[0]), *truth[0])
    live, refined = [], []
    for pose in poses[1:]:
        live.append(guard.update(pose))
        refined += guard.refined()
    refined += guard.flush()
    assert [p.time_ns for p in refined] == [p.time_ns for p in live]
    for live_pose, refined_pose in zip(live, refined):
        if live_pose.fallback:
            assert refined_pose.fallback and (refined_pose.x_m, refined_pose.y_m) == (live_pose.x_m, live_pose.y_m)


def test_guard_memory_is_fixed(paper_walk):
    time_ns, truth, poses = paper_walk
    guard = guarded(WalkableArea(CONTRADICTING["mirrored about the stand"]))
    run(guard, time_ns, truth, poses)
    assert len(guard.recent) <= guard.recent.maxlen and len(guard.agreed) <= guard.agreed.maxlen
    assert len(guard.recent_recoveries) <= guard.recent_recoveries.maxlen
