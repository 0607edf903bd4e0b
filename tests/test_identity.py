"""Our streaming track-to-agent association (hub/identity.py) on crafted scenes (tests/identity_scenes.py)."""

from __future__ import annotations

import numpy as np
import pytest

from hub.identity import IdentityEngine, IdentitySettings
from identity_scenes import S, camera_frames, imu_batches, session, waypoints_path


def run(paths: dict, tracks: list, seed: int = 1, end_s: float = 30.0, settings: IdentitySettings = IdentitySettings()):
    """Feed a scene in arrival order; returns (engine, [(time s, agent, track id)] identity changes)."""
    rng = np.random.default_rng(seed)
    events = [e for p, (t, xy) in paths.items() for e in imu_batches(p, t, xy, rng)]
    events += camera_frames(paths, tracks, rng, end_s=end_s)
    events.sort(key=lambda e: e[0])
    engine = IdentityEngine(session(list(paths)), settings)
    changes = []
    for _, message in events:
        for out in engine.on_message(message):
            if out.DESCRIPTOR.name == "TrackIdentity":
                changes.append((out.timestamp_ns / S, out.agent_id, out.track_id))
    return engine, changes


def holder_at(changes: list, agent: str, time_s: float) -> int:
    """The track id the agent had at time_s (0: none)."""
    held = 0
    for t, who, track in changes:
        if who == agent and t <= time_s:
            held = track
    return held


CROSSING = {
    "a": waypoints_path([(0, 0.5, 1.0), (2, 0.5, 1.0), (8, 5.0, 2.0), (11, 5.0, 2.0), (16, 1.0, 0.6), (20, 1.0, 0.6),
                         (26, 4.5, 2.5), (30, 4.5, 2.5)]),
    "b": waypoints_path([(0, 5.0, 1.0), (3, 5.0, 1.0), (9, 0.6, 2.0), (12, 2.5, 2.5), (15, 2.5, 2.5), (21, 5.0, 0.5),
                         (30, 5.0, 0.5)]),
    "c": waypoints_path([(0, 2.8, 0.4), (5, 2.8, 0.4), (7, 2.0, 1.5), (13, 2.0, 1.5), (18, 4.0, 1.0), (24, 1.5, 2.5),
                         (30, 1.5, 2.5)]),
}


def test_identities_follow_a_switch_at_a_crossing_and_ignore_a_false_track():
    # a and b cross at about 6 s; the tracker swaps them there: a continues as track 5, b as 4;
    # a is lost 14-14.5 s and comes back as track 7; track 6 is nobody
    tracks = [(1, "a", 0, 6), (2, "b", 0, 6), (3, "c", 0, 30), (4, "b", 6, 30), (5, "a", 6, 14), (6, "", 10, 14),
              (7, "a", 14.5, 30)]
    engine, changes = run(CROSSING, tracks)
    assert all(track != 6 for _, _, track in changes)
    assert (holder_at(changes, "a", 5.5), holder_at(changes, "b", 5.5), holder_at(changes, "c", 5.5)) == (1, 2, 3)
    assert (holder_at(changes, "a", 10.0), holder_at(changes, "b", 10.0)) == (5, 4)  # within 4 s of the swap
    assert holder_at(changes, "a", 18.0) == 7 and holder_at(changes, "c", 29.0) == 3
    # no wrong identity at any time
    truth = {1: "a", 2: "b", 3: "c", 4: "b", 5: "a", 7: "a"}
    assert all(track == 0 or truth[track] == who for _, who, track in changes)
    assert engine.counters.fixes > 0


def test_people_standing_still_get_no_guessed_identity():
    paths = {p: waypoints_path([(0, x, 1.5), (20, x, 1.5)]) for p, x in (("a", 1.0), ("b", 3.0))}
    _, changes = run(paths, [(1, "a", 0, 20), (2, "b", 0, 20)], end_s=20)
    assert changes == []


def test_a_merged_track_then_a_split_ends_with_the_right_identities():
    # a and b walk side by side 0.4 m apart: the tracker merges them (track 3, at their centroid) from
    # 6 to 12 s, then they part and come back as tracks 4 and 5
    paths = {
        "a": waypoints_path([(0, 0.5, 0.5), (2, 0.5, 0.5), (6, 2.5, 1.3), (12, 4.5, 1.3), (16, 5.0, 0.4), (24, 5.0, 0.4)]),
        "b": waypoints_path([(0, 0.5, 2.5), (4, 0.5, 2.5), (6, 2.5, 1.7), (12, 4.5, 1.7), (14, 4.5, 2.6), (18, 2.0, 2.6),
                             (24, 0.8, 1.0)]),
    }
    tracks = [(1, "a", 0, 6), (2, "b", 0, 6), (3, "a+b", 6, 12), (4, "a", 12.2, 24), (5, "b", 12.2, 24)]
    _, changes = run(paths, tracks, end_s=24)
    assert holder_at(changes, "a", 23.5) == 4 and holder_at(changes, "b", 23.5) == 5
    assert all(track != 3 or who in ("a", "b") for _, who, track in changes)
    truth = {1: "a", 2: "b", 4: "a", 5: "b"}
    assert all(track in (0, 3) or truth[track] == who for _, who, track in changes)


def test_work_per_hop_is_tracks_times_agents_times_bins_at_50_agents():
    rng = np.random.default_rng(5)
    people = [f"p{k}" for k in range(50)]
    paths = {}
    for p in people:
        start = rng.uniform([0, 0], [30, 20])
        points = [(0.0, *start)]
        for k in range(1, 6):
            start = np.clip(start + rng.normal(0, 3, 2), 0, [30, 20])
            points.append((2.0 * k, *start))
        paths[p] = waypoints_path(points)
    tracks = [(k + 1, p, 0, 10) for k, p in enumerate(people)] + [(100, "", 2, 10)]
    settings = IdentitySettings()
    engine, _ = run(paths, tracks, end_s=10, settings=settings)
    hop_bins = int(round(settings.hop_s / 0.1))
    counters = engine.counters
    assert counters.updates >= 10
    assert counters.max_pair_bins <= 51 * 50 * (hop_bins + 1)  # polynomial: tracks x agents x new bins
    assert counters.solves <= counters.updates * (1 + settings.max_claims)


@pytest.mark.parametrize("field,value", [("hop_s", 0.0), ("forget_per_s", 1.5), ("nobody_cost", -1.0)])
def test_settings_out_of_range_are_refused_with_the_name(field, value):
    with pytest.raises(ValueError, match=field):
        IdentitySettings(**{field: value})
