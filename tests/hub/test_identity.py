"""Our streaming track-to-agent association (hub/identity/engine.py) on crafted scenes (tests/support/identity_scenes.py)."""

from __future__ import annotations

import numpy as np
import pytest

from hub.identity.engine import IdentityEngine, IdentitySettings
from support.identity_scenes import CROSSING, S, camera_frames, holder_at, imu_batches, run, session, waypoints_path


def test_the_walkers_window_solves_once_a_second_and_can_be_turned_off():
    tracks = [(1, "a", 0, 30), (2, "b", 0, 30), (3, "c", 0, 30)]
    engine, changes = run(CROSSING, tracks)
    assert 27 <= engine.counters.window_solves <= 30 and set(engine.windows) == {"cam1"}
    assert len(engine.windows["cam1"].tracks) == 3
    assert {(who, holder_at(changes, who, 29.0)) for who in "abc"} == {("a", 1), ("b", 2), ("c", 3)}
    off, same = run(CROSSING, tracks, settings=IdentitySettings(window_s=0.0))
    assert off.counters.window_solves == 0 and not off.windows
    assert {(who, holder_at(same, who, 29.0)) for who in "abc"} == {("a", 1), ("b", 2), ("c", 3)}
    crowd, _ = run(CROSSING, tracks, settings=IdentitySettings(window_max_walkers=2))  # 3 walkers: beyond it
    assert crowd.counters.window_solves == 0


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
    # no wrong identity at any time but a share: a's track ends at 14 s 0.3 m from c's, which is what a merge
    # looks like from the tracks, so a shares c's track until a track of its own appears (14.5 s)
    truth = {1: "a", 2: "b", 3: "c", 4: "b", 5: "a", 7: "a"}
    wrong = [(t, who, track) for t, who, track in changes if track and truth[track] != who]
    assert all((who, track) == ("a", 3) and 14.0 <= t <= 14.5 for t, who, track in wrong)
    assert engine.counters.shares >= len(wrong)
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
    assert 0 < counters.max_assignment_size <= 51 + 50  # one part's padded matrix, never more than the whole


def pose_from_paths(paths: dict, offset: dict | None = None):
    """A hub that places every agent on its true path (plus an offset), 0.1 m sure."""
    offset = offset or {}

    def pose_of(agent: str, time_ns: int):
        times, xy = paths[agent]
        t = time_ns / S
        where = np.array([np.interp(t, times, xy[:, 0]), np.interp(t, times, xy[:, 1])])
        return where + np.asarray(offset.get(agent, (0.0, 0.0))), 0.1
    return pose_of


def first_claim(changes: list, agent: str, track: int) -> float | None:
    return next((t for t, who, held in changes if who == agent and held == track), None)


def test_a_track_that_comes_back_under_a_new_id_inherits_its_identity_in_its_first_frame():
    # a's track 1 is lost 12-12.4 s (a is walking from (5, 2) towards (1, 0.6)); it comes back as track 8
    tracks = [(1, "a", 0, 12), (8, "a", 12.4, 30), (2, "b", 0, 30), (3, "c", 0, 30)]
    for pose_of in (None, pose_from_paths(CROSSING)):
        engine, changes = run(CROSSING, tracks, pose_of=pose_of)
        assert holder_at(changes, "a", 11.5) == 1
        assert first_claim(changes, "a", 8) <= 12.4 + 1.5 / 20  # its first frame (the stamps jitter by none here)
        assert engine.counters.continuations >= 1
        assert not [c for c in changes if c[1] == "a" and c[2] == 0 and 12.0 < c[0] < 20.0]  # never "no track" between


def test_a_new_track_where_the_hub_expects_someone_else_too_is_left_to_the_evidence():
    # a's track 1 ends at 12 s and a new track starts 0.6 m from where a was heading; but the hub (as a
    # chair's dead reckoning would) also places c, who has no track, right there: no inheritance
    paths = dict(CROSSING)
    tracks = [(1, "a", 0, 12), (8, "a", 12.4, 30), (2, "b", 0, 30), (3, "c", 0, 11.9)]
    a_at = np.array([np.interp(12.4, paths["a"][0], paths["a"][1][:, k]) for k in range(2)])
    c_at = np.array([np.interp(12.4, paths["c"][0], paths["c"][1][:, k]) for k in range(2)])
    offset = {"c": tuple(a_at - c_at + np.array([0.2, 0.0]))}  # the hub has c 0.2 m from where a reappears
    pose_of = pose_from_paths(paths, offset)
    _, changes = run(paths, tracks, pose_of=pose_of)
    claimed = first_claim(changes, "a", 8)
    assert claimed is None or claimed > 12.4 + 0.2  # not in its first frames: the evidence decides
    assert not any(who == "c" and held == 8 for _, who, held in changes)


def test_assignment_in_parts_and_the_exchange_bound_agree_with_the_whole_problem():
    from scipy.optimize import linear_sum_assignment

    from hub.identity.assign import components, exclusion_margin, padded, swap_bound

    engine = IdentityEngine(session(["a", "b"]))
    nobody = engine.settings.nobody_cost
    rng = np.random.default_rng(7)
    for _ in range(200):
        n_tracks, n_agents = rng.integers(1, 9, 2)
        cost = rng.uniform(-1.0, 3.0, (n_tracks, n_agents))
        whole = padded(cost, nobody)
        rows, cols = linear_sum_assignment(whole)
        best = whole[rows, cols].sum()
        total = (n_tracks + n_agents) * 0.0
        for part_rows, part_cols in components(cost, nobody):
            matrix = padded(cost[np.ix_(part_rows, part_cols)], nobody)
            r, c = linear_sum_assignment(matrix)
            total += matrix[r, c].sum() - engine.settings.nobody_cost * 0  # parts' own nobodies included
            for k in range(len(part_rows)):
                if c[k] < len(part_cols):  # a pair of the solution: the bound never undercuts the exact margin
                    exact = exclusion_margin(matrix, matrix[r, c].sum(), k, c[k])
                    assert swap_bound(matrix, c, k, c[k]) >= exact - 1e-9
        linked = {int(t) for part_rows, _ in components(cost, nobody) for t in part_rows}
        linked_agents = {int(a) for _, part_cols in components(cost, nobody) for a in part_cols}
        # what no part holds takes "nobody" on its own
        total += engine.settings.nobody_cost * ((n_tracks - len(linked)) + (n_agents - len(linked_agents)))
        assert abs(total - best) < 1e-9


@pytest.mark.parametrize("field,value", [("hop_s", 0.0), ("forget_per_s", 1.5), ("nobody_cost", -1.0)])
def test_settings_out_of_range_are_refused_with_the_name(field, value):
    with pytest.raises(ValueError, match=field):
        IdentitySettings(**{field: value})


def test_a_track_that_ends_inside_a_merged_one_shares_it_until_they_part():
    # as the merge above, but the tracker keeps a's id 1 for the merged "a+b" track and ends b's track 2
    paths = {
        "a": waypoints_path([(0, 0.5, 0.5), (2, 0.5, 0.5), (6, 2.5, 1.3), (12, 4.5, 1.3), (16, 5.0, 0.4), (24, 5.0, 0.4)]),
        "b": waypoints_path([(0, 0.5, 2.5), (4, 0.5, 2.5), (6, 2.5, 1.7), (12, 4.5, 1.7), (14, 4.5, 2.6), (18, 2.0, 2.6),
                             (24, 0.8, 1.0)]),
    }
    tracks = [(1, "a", 0, 6), (1, "a+b", 6, 12), (2, "b", 0, 6), (4, "a", 12.2, 24), (5, "b", 12.2, 24)]
    engine, changes = run(paths, tracks, end_s=24)
    assert engine.counters.shares >= 1
    assert holder_at(changes, "a", 7.5) == 1 and holder_at(changes, "b", 7.5) == 1  # both on the merged track
    assert holder_at(changes, "a", 23.5) == 4 and holder_at(changes, "b", 23.5) == 5
    truth = {2: "b", 4: "a", 5: "b"}
    assert all(track in (0, 1) or truth[track] == who for _, who, track in changes)
    _, alone = run(paths, tracks, end_s=24, settings=IdentitySettings(share_merges=False))
    assert holder_at(alone, "b", 7.5) == 0  # one to one: b waits for its own track


def test_the_block_reads_equal_the_signal_by_signal_cues():
    from hub.identity.cues import (BIN_NS, TRACK_DELAY_BINS, AgentCues, TrackCues, agent_hop_blocks, track_hop_cues,
                                   turn_rate)

    rng = np.random.default_rng(3)
    tracks = []
    for k in range(4):
        cues = TrackCues(k + 1)
        xy = np.cumsum(rng.normal(0, 0.08, (300, 2)), axis=0)
        for f, (x, y) in enumerate(xy):
            if not 100 <= f < 110 or k != 2:  # one track with a hole
                cues.push(int(f * 0.04 * S), float(x), float(y))
        tracks.append(cues)
    first, count = 38, 10  # track 3's hole covers bins 40-43
    block = track_hop_cues(tracks, first, count)
    assert np.isfinite(block["speed"]).sum() > 20 and np.isfinite(block["yaw"]).any() and np.isnan(block["x"][2, 3])
    for row, cues in enumerate(tracks):
        np.testing.assert_array_equal(block["speed"][row], cues.speed(first, count))
        np.testing.assert_array_equal(block["yaw"][row], cues.turn_rate(first, count))
        np.testing.assert_array_equal(block["x"][row], cues.ring.window("x", first, count))
    agents = []
    for k in range(3):
        cues = AgentCues(f"a{k}", f"s{k}", 100.0)
        times = np.arange(0, 3000) * 10_000_000
        accel = np.column_stack([rng.normal(0, 0.05, 3000), rng.normal(0, 0.05, 3000), 1 + rng.normal(0, 0.1, 3000)])
        gyro = rng.normal(0, 20, (3000, 3))
        for batch in range(0, 3000, 20):  # in time order, as they arrive: 0.2 s of IMU, then the poses in it
            part = slice(batch, batch + 20)
            cues.push_imu(times[part], accel[part], gyro[part])
            for t in range(int(times[batch]), int(times[batch]) + 200_000_000, 40_000_000):
                cues.push_pose(t, t * 1e-9, 0.5 * t * 1e-9, 0.1 * t * 1e-9)
        agents.append(cues)
    first = 250
    block = agent_hop_blocks(agents, first, count, TRACK_DELAY_BINS)
    assert all(np.isfinite(block[name]).all() for name in ("activity", "speed_dr", "yaw", "yaw_dr"))
    start = first - TRACK_DELAY_BINS
    for row, cues in enumerate(agents):
        ring = cues.ring
        np.testing.assert_array_equal(block["activity"][row], ring.window("activity", first, count))
        np.testing.assert_array_equal(block["speed_dr"][row], ring.window("speed_dr", start, count))
        np.testing.assert_allclose(block["yaw"][row], turn_rate(lambda b, n: ring.window("heading", b, n), start, count))
        np.testing.assert_allclose(block["yaw_dr"][row],
                                   turn_rate(lambda b, n: ring.window("heading_dr", b, n), start, count))
    assert BIN_NS == 100_000_000


def test_chairs_are_named_in_the_first_frame_of_play_where_they_start():
    """Before any edge pose has reached the hub, a chair is where its edge starts it (the session's start):
    a new track there, with no other chair expected near, is that chair's at once (births); two chairs
    starting side by side are left to the evidence."""
    from dataclasses import replace

    starts = {"a": (1.0, 1.0), "b": (4.0, 1.0), "c": (2.5, 2.5), "d": (2.9, 2.5)}  # c and d 0.4 m apart
    paths = {p: waypoints_path([(0, x, y), (3, x, y), (8, x + 0.5, y - 0.3), (12, x + 0.5, y - 0.3)])
             for p, (x, y) in starts.items()}
    tracks = [(k + 1, p, 0, 12) for k, p in enumerate(starts)]
    base = session(list(starts), chairs=True)
    chairs = replace(base, agents=tuple(replace(a, start_x_m=starts[a.id][0], start_y_m=starts[a.id][1])
                                        for a in base.agents))
    hub = pose_from_paths(paths)

    def pose_of(agent: str, time_ns: int):  # the edges' first poses reach the hub after 1 s
        return hub(agent, time_ns) if time_ns >= 1 * S else None

    rng = np.random.default_rng(1)
    events = [e for p, (t, xy) in paths.items() for e in imu_batches(p, t, xy, rng, chairs=True)]
    events += camera_frames(paths, tracks, rng, end_s=12)
    events.sort(key=lambda e: e[0])
    engine = IdentityEngine(chairs, IdentitySettings(), pose_of=pose_of)
    changes = [(o.timestamp_ns / S, o.agent_id, o.track_id) for _, m in events for o in engine.on_message(m)
               if o.DESCRIPTOR.name == "TrackIdentity"]
    assert (holder_at(changes, "a", 0.1), holder_at(changes, "b", 0.1)) == (1, 2)
    assert holder_at(changes, "c", 0.1) == 0 and holder_at(changes, "d", 0.1) == 0
    assert engine.counters.births == 2
    assert all(track == 0 or tracks[track - 1][1] == who for _, who, track in changes)  # never a wrong one


def test_a_fix_is_where_the_track_was_at_the_newest_scored_bin_not_its_newest_frame():
    """A tracker's swap in the last delay_s is not yet in the evidence: a fix from there could be someone else's."""
    rng = np.random.default_rng(1)
    events = [e for p, (t, xy) in CROSSING.items() for e in imu_batches(p, t, xy, rng)]
    events += camera_frames(CROSSING, [(1, "a", 0, 30), (2, "b", 0, 30), (3, "c", 0, 30)], rng, end_s=30)
    events.sort(key=lambda e: e[0])
    settings = IdentitySettings()
    engine = IdentityEngine(session(list(CROSSING)), settings, pose_of=pose_from_paths(CROSSING))
    lags = []
    for _, message in events:
        for out in engine.on_message(message):
            if out.DESCRIPTOR.name == "PositionFix":
                lags.append((message.timestamp_ns - out.timestamp_ns) / S)
    assert lags and min(lags) >= settings.delay_s - 0.1 and max(lags) <= settings.delay_s + settings.hop_s + 0.1
