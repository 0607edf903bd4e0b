"""Our streaming track-to-agent association (hub/identity/engine.py) on crafted scenes (tests/support/identity_scenes.py)."""

from __future__ import annotations

import numpy as np
import pytest

from hub.identity.book import Track
from hub.identity.engine import IdentityEngine, IdentitySettings
from support.identity_scenes import CROSSING, S, camera_frames, imu_batches, session, waypoints_path


def run(paths: dict, tracks: list, seed: int = 1, end_s: float = 30.0, settings: IdentitySettings = IdentitySettings(),
        pose_of=None):
    """Feed a scene in arrival order; returns (engine, [(time s, agent, track id)] identity changes)."""
    rng = np.random.default_rng(seed)
    events = [e for p, (t, xy) in paths.items() for e in imu_batches(p, t, xy, rng)]
    events += camera_frames(paths, tracks, rng, end_s=end_s)
    events.sort(key=lambda e: e[0])
    engine = IdentityEngine(session(list(paths)), settings, pose_of=pose_of)
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


def _run_scene(paths: dict, wearers: list[str], tracks: list, end_s: float, settings: IdentitySettings = IdentitySettings(),
               heights: dict | None = None, chairs: bool = False, camera_shift_s: float = 0.0, seed: int = 1):
    """As run(), with people who wear no sensor (in `paths`, not in `wearers`), reported head heights and
    a camera clock `camera_shift_s` ahead of the venue's."""
    rng = np.random.default_rng(seed)
    events = [e for p in wearers for e in imu_batches(p, *paths[p], rng, chairs=chairs)]
    for arrival, frame in camera_frames(paths, tracks, rng, end_s=end_s, heights=heights):
        frame.timestamp_ns += int(camera_shift_s * S)
        events.append((arrival, frame))
    events.sort(key=lambda e: e[0])
    engine = IdentityEngine(session(wearers, chairs=chairs), settings)
    changes = [(o.timestamp_ns / S, o.agent_id, o.track_id) for _, m in events for o in engine.on_message(m)
               if o.DESCRIPTOR.name == "TrackIdentity"]
    return engine, changes


def test_a_broken_track_continues_on_the_new_track_of_its_own_height_not_a_bystanders():
    """a's track breaks off at 8 s; at 8.5 s two tracks start where it was heading: a's own and a bystander's
    (no sensor) who came into view beside a. By position alone a's continuation is ambiguous and waits;
    with the tracker's head heights (a 1.60 m, the bystander 1.78 m) only a's own track fits, at once."""
    paths = {"a": waypoints_path([(0, 0.5, 1.2), (2, 0.5, 1.2), (14, 5.3, 1.2), (16, 5.3, 1.2)]),
             "x": waypoints_path([(0, 3.9, 1.75), (8.5, 3.9, 1.75), (10.5, 5.2, 2.6), (16, 5.2, 2.6)])}
    tracks = [(1, "a", 0, 8), (2, "a", 8.5, 16), (3, "x", 8.5, 16)]
    heights = {"a": 1.60, "x": 1.78}
    engine, changes = _run_scene(paths, ["a"], tracks, 16, heights=heights)
    assert holder_at(changes, "a", 7.9) == 1
    assert holder_at(changes, "a", 8.6) == 2 and engine.counters.continuations == 1
    assert holder_at(changes, "a", 12.5) == 2 and all(track != 3 for t, _, track in changes if t < 12.5)
    _, blind = _run_scene(paths, ["a"], tracks, 16)  # the same scene without heights
    assert holder_at(blind, "a", 8.6) == 0


def test_the_stature_profile_learns_which_head_height_moves_like_each_agent():
    from hub.identity.cues import StatureProfile

    rng = np.random.default_rng(2)
    profile = StatureProfile(2)
    # two tracks per bin: one at 1.62 m, one at 1.75 m; agent 0's motion matches the short one, agent 1's
    # the tall one (excess cost -0.7 for the right pair, +0.5 for the wrong one, noisy)
    for _ in range(300):  # 30 s of bins
        heights = np.vstack([1.62 + rng.normal(0, 0.02, 10), 1.75 + rng.normal(0, 0.02, 10)])
        motion = np.empty((2, 2, 10))
        motion[0, 0], motion[1, 1] = rng.normal(-0.7, 0.5, (2, 10))
        motion[0, 1], motion[1, 0] = rng.normal(0.5, 0.8, (2, 10))
        profile.learn(heights, motion, np.ones((2, 10), dtype=bool))
        # agent 0 also sits now and then (head 0.4 m lower, still matching its motion): a still track,
        # whose height is not its stature, teaches nothing
        profile.learn(np.full((1, 10), 1.22), rng.normal(-0.7, 0.5, (1, 2, 10)), np.zeros((1, 10), dtype=bool))
    cost = profile.cost(np.array([[1.62], [1.75], [np.nan], [1.22]]))  # (tracks, agents, bins)
    assert cost[0, 0, 0] < 0.1 and cost[1, 1, 0] < 0.1  # each agent's own height: about its lowest cost
    assert cost[1, 0, 0] > 0.6 and cost[0, 1, 0] > 0.6  # the other's
    assert cost[3, 0, 0] > 0.3  # the seated height was never learnt as agent 0's: nearer its mean than its lowest
    assert np.isnan(cost[2]).all()  # a track without a height gets no stature cue
    assert np.isnan(StatureProfile(2).cost(np.array([[1.62]]))).all()  # nothing learnt yet: no cue


def test_the_camera_lag_stays_within_its_bound_of_the_prior_however_the_searches_move():
    """The lag search moves at most max_lag_s from lag_prior_s in total (its moves used to add up without
    limit): a camera 0.9 s ahead, with the prior at 0, ends within 0.5 s of 0 (outside the bound it cannot
    find the offset: the prior must be within max_lag_s of the truth); with the prior at 0.7 s it finds it
    (within 0.2 s on this scene)."""
    tracks = [(1, "a", 0, 40), (2, "b", 0, 40), (3, "c", 0, 40)]
    long = {"a": waypoints_path([(0, 0.5, 1.0), (6, 5.0, 2.0), (10, 1.0, 0.6), (16, 4.5, 2.5), (22, 0.8, 2.0),
                                 (28, 5.0, 0.6), (34, 1.0, 2.6), (40, 4.0, 1.5)]),
            "b": waypoints_path([(0, 5.0, 1.0), (5, 0.6, 2.0), (11, 4.5, 2.5), (17, 1.0, 0.5), (23, 4.8, 1.5),
                                 (29, 0.5, 1.0), (35, 4.5, 2.8), (40, 2.0, 2.0)]),
            "c": waypoints_path([(0, 2.8, 0.4), (7, 2.0, 2.5), (12, 4.8, 1.0), (18, 1.5, 2.5), (24, 3.5, 0.4),
                                 (30, 1.0, 1.5), (36, 5.0, 2.0), (40, 3.0, 1.0)])}
    bound = IdentitySettings()
    engine, _ = _run_scene(long, list(long), tracks, 40, chairs=True, camera_shift_s=0.9)
    assert abs(engine.lag_bins.get("cam1", 0)) <= round(bound.max_lag_s / 0.1)  # the old search went on to +0.8 s
    engine, _ = _run_scene(long, list(long), tracks, 40, chairs=True, camera_shift_s=0.9,
                           settings=IdentitySettings(lag_prior_s=0.7))
    assert abs(engine.lag_bins["cam1"] - 9) <= 2  # 0.7 s prior; the true 0.9 s found within 0.2 s


def test_a_chairs_direction_of_travel_tells_two_chairs_of_one_speed_apart():
    """Two chairs at the same speed, one going +x and one +y: speed, moving and turn rate cannot tell their
    tracks apart, the direction of the edge's dead-reckoned velocity can (its heading stays within a few
    degrees: docs/identity.md). Slow bins give no direction."""
    from support.identity_scenes import edge_poses

    times = np.arange(0, 4, 0.01)
    paths = {"a": np.column_stack([1.0 + 1.5 * times, np.full_like(times, 1.0)]),
             "b": np.column_stack([np.full_like(times, 1.0), 1.0 + 1.5 * times])}
    engine = IdentityEngine(session(list(paths), chairs=True))
    for agent, xy in paths.items():
        for _, pose in edge_poses(agent, times, xy, (0.0, 0.0)):
            engine.on_message(pose)
    blocks = engine._agent_windows(20, 10)  # bins 2.0-2.9 s
    track_v = np.array([[1.5, 0.0], [0.0, 1.5], [0.2, 0.0]])  # a's direction, b's, and a slow track
    tvx = np.repeat(track_v[:, :1], 10, axis=1)
    tvy = np.repeat(track_v[:, 1:], 10, axis=1)
    cost = engine._course_cost([Track(None, None, None) for _ in range(3)], tvx, tvy, blocks["vx"], blocks["vy"], 10)
    assert cost[0, 0].max() < 0.1 and cost[1, 1].max() < 0.1  # the right pairs: the same direction
    assert cost[0, 1].min() == cost[1, 0].min() == engine.settings.clip  # 90 degrees apart: clipped at 3 sigma
    assert np.isnan(cost[2]).all()  # too slow to have a direction


def test_bins_are_scored_once_every_live_agents_data_is_in_and_a_silent_device_holds_none_back():
    """IMU batches that arrive 0.5 s late (after 2 s on time, from which the hub learnt the clock offsets) make
    the engine score later (a bin scored before an agent's data is in would count nothing for it, for good)
    and the identities still come; a device that falls silent holds the scoring back by at most max_delay_s."""
    tracks = [(1, "a", 0, 30), (2, "b", 0, 30), (3, "c", 0, 30)]

    def scored(late_s: float, silent_after_s: float, settings: IdentitySettings = IdentitySettings()
               ) -> tuple[list[tuple[float, float]], list]:
        rng = np.random.default_rng(1)
        events = []
        for p, (t, xy) in CROSSING.items():
            for arrival, batch in imu_batches(p, t, xy, rng):
                if p == "c" and arrival > silent_after_s * S:
                    continue
                batch.received_ns = arrival + int(late_s * S) * (arrival > 2 * S)
                events.append((batch.received_ns, batch))
        events += camera_frames(CROSSING, tracks, rng, end_s=30)
        events.sort(key=lambda e: e[0])
        engine = IdentityEngine(session(list(CROSSING)), settings)
        delays, changes = [], []
        for _, message in events:
            hops = len(engine.delays_s)
            for out in engine.on_message(message):
                if out.DESCRIPTOR.name == "TrackIdentity":
                    changes.append((out.timestamp_ns / S, out.agent_id, out.track_id))
            if len(engine.delays_s) > hops:
                delays.append((message.timestamp_ns / S, engine.delays_s[-1]))
        return delays, changes

    delays, changes = scored(0.5, 99.0)
    assert all(0.3 - 1e-9 <= d <= engine_max() for t, d in delays if t > 3.0)  # an agent's cues are compared 0.2 s earlier
    assert (holder_at(changes, "a", 5.5), holder_at(changes, "b", 5.5), holder_at(changes, "c", 5.5)) == (1, 2, 3)
    _, fixed = scored(0.5, 99.0, IdentitySettings(max_delay_s=0.2))  # scoring at 0.2 s whatever has arrived
    assert not [change for change in fixed if change[0] > 3.0]  # compares nothing after 2 s: no identity comes
    delays, _ = scored(0.0, 10.0)
    assert all(d <= 0.5 for t, d in delays if t < 10.0)
    assert all(d <= engine_max() for t, d in delays) and all(d <= 0.5 for t, d in delays if t > 12.0)


def engine_max() -> float:
    return IdentitySettings().max_delay_s + 1e-9


def test_the_waist_tells_seated_from_upright_by_its_tilt_from_how_it_walks():
    """The belt sensor's gravity direction while walking is upright; seated, the pelvis tilts back (~10-20
    deg) and the stature cue looks for the head ~0.4 m lower. Unknown until the agent has walked."""
    from hub.identity.cues import AgentCues

    rng = np.random.default_rng(3)
    cues = AgentCues("a", "a-waist", 100.0)
    belt = np.radians(6.0)  # the sensor sits pitched on the lumbar curve: upright is not its z axis
    up = np.array([np.sin(belt), 0.0, np.cos(belt)])

    def push(start_s: float, seconds: float, gravity: np.ndarray, bounce_g: float) -> None:
        t = start_s + np.arange(int(seconds * 100)) / 100
        accel = gravity[None] * (1.0 + bounce_g * np.sin(2 * np.pi * 1.9 * t))[:, None] + rng.normal(0, 0.005, (len(t), 3))
        cues.push_imu((t * S).astype(np.int64), accel, rng.normal(0, 0.5, (len(t), 3)))

    push(0.0, 3.0, up, 0.0)  # standing still first: nothing known yet
    assert np.isnan(cues.ring.window("tilt", 10, 10)).all()
    push(3.0, 10.0, up, 0.25)  # walking
    back = np.radians(6.0 - 12.0)  # then seated: the pelvis 12 deg back
    push(13.0, 10.0, np.array([np.sin(back), 0.0, np.cos(back)]), 0.0)
    walking, seated = cues.ring.window("tilt", 100, 20), cues.ring.window("tilt", 210, 20)
    assert np.nanmax(walking) < 2.0 and np.nanmin(seated) > 10.0


def test_a_seated_wearers_stature_is_looked_for_lower_than_a_standing_ones():
    """Agent a (1.70 m) sits: its head is at ~1.32 m. Read at the track's height, a's stature cue would call
    its own track someone else's; read 0.33-0.43 m higher (a's waist is tilted), it fits. b (1.55 m),
    standing, is not a 1.32 m head either way."""
    rng = np.random.default_rng(4)
    engine = IdentityEngine(session(["a", "b"]))
    for _ in range(300):
        heights = np.vstack([1.70 + rng.normal(0, 0.02, 10), 1.55 + rng.normal(0, 0.02, 10)])
        motion = np.empty((2, 2, 10))
        motion[0, 0], motion[1, 1] = rng.normal(-0.7, 0.5, (2, 10))
        motion[0, 1], motion[1, 0] = rng.normal(0.5, 0.8, (2, 10))
        engine.statures.learn(heights, motion, np.ones((2, 10), dtype=bool))
    seated_head = np.array([[1.32]])
    upright = engine._stature_cost(seated_head, np.array([[0.0], [0.0]]))
    a_seated = engine._stature_cost(seated_head, np.array([[12.0], [0.0]]))
    assert upright[0, 0, 0] > 0.3 and a_seated[0, 0, 0] < 0.1  # a: far from its stature, unless it sits
    assert upright[0, 1, 0] == a_seated[0, 1, 0] > 0.3  # b standing: not b


def test_the_hubs_pose_of_a_chair_grows_doubtful_while_its_poses_have_not_arrived():
    """The identity engine asks the hub where a chair was at a camera time; if the chair's newest pose is
    older (its link stalled, a burst), the chair may have moved since: the sd grows at STALE_MPS."""
    from hub.venue import STALE_MPS, VenueHub
    from support.identity_scenes import edge_poses

    hub = VenueHub(session(["a"], chairs=True))
    times = np.arange(0, 2.0, 0.01)
    for arrival, pose in edge_poses("a", times, np.column_stack([1.0 + times, np.full_like(times, 1.0)]), (0.0, 0.0)):
        hub.on_message(pose, arrival)
    fresh = hub._pose_of("a", int(1.96 * S))
    stale = hub._pose_of("a", int(3.96 * S))  # 2 s after its newest pose
    assert fresh[1] < 1.0 and np.allclose(stale[0], [1.0 + 1.96, 1.0], atol=0.05)
    assert stale[1] == pytest.approx(np.hypot(fresh[1], 2.0 * STALE_MPS), rel=0.05)


def _gait_scene(settings: IdentitySettings) -> list:
    """a and b stand, then from 10 s walk side by side at one speed and one height, a quarter of a step
    apart in phase; c walks alone from the start, so the engine holds c's track from its other cues
    and learns the lag from it while a and b stand."""
    paths = {"a": waypoints_path([(0, 0.5, 1.0), (10, 0.5, 1.0), (30, 20.5, 1.0)]),
             "b": waypoints_path([(0, 0.5, 2.0), (10, 0.5, 2.0), (30, 20.5, 2.0)]),
             "c": waypoints_path([(0, 0.5, 6.0), (30, 30.5, 6.0)])}
    phases = {"a": 0.0, "b": np.pi / 2, "c": 1.0}
    tracks = [(1, "a", 0, 30), (2, "b", 0, 30), (3, "c", 0, 30)]
    rng = np.random.default_rng(3)
    events = [e for p in paths for e in imu_batches(p, *paths[p], rng, phase_rad=phases[p])]
    events += camera_frames(paths, tracks, rng, end_s=30, heights={p: 1.70 for p in paths}, bob_m=0.03, phases=phases,
                            height_noise_m=0.03)
    events.sort(key=lambda e: e[0])
    engine = IdentityEngine(session(list(paths)), settings)
    return [(o.timestamp_ns / S, o.agent_id, o.track_id) for _, m in events for o in engine.on_message(m)
            if o.DESCRIPTOR.name == "TrackIdentity"], engine


def test_two_walkers_alike_in_all_but_their_step_timing_are_told_apart_by_the_heads_bob():
    """Same speed, course, turn rate and stature: only the steps' phase differs, which the camera sees as the
    head's bob. With the gait cue both are named right once it has learnt the lag from c; without it the
    engine cannot tell a from b."""
    changes, engine = _gait_scene(IdentitySettings())
    assert engine.gait.calibrated and engine.gait.reference > 0.2
    assert holder_at(changes, "c", 10.0) == 3
    assert all(holder_at(changes, "a", t) == 1 and holder_at(changes, "b", t) == 2 for t in (20.0, 25.0, 29.5))
    blind, _ = _gait_scene(IdentitySettings(gait_weight=0.0))
    assert not all(holder_at(blind, "a", t) == 1 and holder_at(blind, "b", t) == 2 for t in (20.0, 25.0, 29.5))


def test_the_waists_vertical_acceleration_per_bin_is_the_mean_of_its_samples_across_batches():
    """A bin that two batches share gets the mean of all its samples, not of the last batch's part."""
    from hub.identity.cues import BIN_NS, AgentCues

    cues = AgentCues("a", "a-waist", 100.0)
    times = np.arange(0, 60) * 10_000_000 + 5 * BIN_NS  # 0.6 s at 100 Hz from bin 5
    vertical = np.sin(np.arange(60) * 0.7) * 0.2
    accel = np.column_stack([np.zeros(60), np.zeros(60), 1.0 + vertical])  # upright: vertical is z - 1 g
    cues.push_imu(times[:15], accel[:15], np.zeros((15, 3)))  # the batch ends inside bin 6
    cues.push_imu(times[15:], accel[15:], np.zeros((45, 3)))
    got = cues.ring.window("vertical", 5, 6)
    # the gravity low-pass starts at the first sample and barely moves in 0.6 s: vertical ~ z - |gravity|
    expected = [vertical[k * 10:(k + 1) * 10].mean() for k in range(6)]
    assert np.allclose(got, expected, atol=0.01)


def test_gait_phase_learns_the_lag_from_held_pairs_and_ranks_the_one_in_step_first():
    """Three walkers at one cadence, a third of a cycle apart; a track shows the first one's head bob two
    bins late under noise. Uncalibrated the cue says nothing; once held pairs have taught it the lag,
    the walker in step costs least; a standing agent and a short track are handled as documented."""
    from hub.identity.gait import LAGS, PAD_BINS, WINDOW_BINS, GaitPhase

    rng = np.random.default_rng(5)
    read = WINDOW_BINS + PAD_BINS
    span = int(LAGS.max() - LAGS.min())
    gait = GaitPhase(weight=4.0)
    first = None
    for hop in range(40):
        t = (hop * 2 + np.arange(-int(LAGS.max()), read + span - int(LAGS.max()))) * 0.1  # the agents' bins
        phases = np.array([0.0, 2.1, 4.2])[:, None]
        vertical = 0.1 * np.sin(2 * np.pi * 1.8 * t[None, :] + phases) + rng.normal(0, 0.01, (3, len(t)))
        activity = np.full((3, len(t)), 0.15)
        activity[2] = 0.02  # the third stands (its vertical is not a walk's)
        track_t = (hop * 2 + np.arange(read)) * 0.1
        # the head is highest when the waist's acceleration is most negative; seen two bins late
        heights = np.vstack([1.7 - 0.03 * np.sin(2 * np.pi * 1.8 * (track_t - 0.2) + phases[0]),
                             1.7 - 0.03 * np.sin(2 * np.pi * 1.8 * (track_t - 0.2) + phases[1])])
        heights = heights + rng.normal(0, 0.01, heights.shape)
        heights[1, :-14] = np.nan  # the second track is new: 1.4 s of it
        correlations = gait.correlations(heights, vertical, activity)
        if first is None:
            first = gait.cost(correlations)
        gait.learn(correlations, [(0, 0)])
    assert np.isnan(first).all()  # nothing learnt yet: no vote
    assert gait.calibrated and gait.lag == 2
    cost = gait.cost(correlations)
    assert cost[0, 0] < 0.5 * gait.weight * gait.reference  # in step: about 0
    assert cost[0, 1] > cost[0, 0] + 1.0
    assert np.isnan(cost[:, 2]).all()  # a standing agent is not compared
    assert gait.bins[0] == WINDOW_BINS and gait.bins[1] == 12  # the short track over its longest window
    assert np.argmin(cost[1, :2]) == 1  # ... and still finds its walker
    correlation = correlations[1, :2, int(np.flatnonzero(LAGS == 2)[0])]
    assert np.allclose(cost[1, :2], gait.weight * (gait.reference - correlation) * 12 / WINDOW_BINS)  # weighing less


def test_a_camera_row_that_is_not_numbers_is_left_out_and_a_frame_of_unequal_columns_refused():
    """A tracker's NaN row (the false track 6's, every frame) leaves the rest of the frame to name as before."""
    tracks = [(1, "a", 0, 6), (2, "b", 0, 6), (3, "c", 0, 30), (4, "b", 6, 30), (5, "a", 6, 14), (6, "", 10, 14),
              (7, "a", 14.5, 30)]
    rng = np.random.default_rng(1)
    events = [e for p, (t, xy) in CROSSING.items() for e in imu_batches(p, t, xy, rng)]
    frames = camera_frames(CROSSING, tracks, rng, end_s=30.0)
    for _, frame in frames:
        for k, track in enumerate(frame.track_id):
            if track == 6:
                frame.x_m[k] = float("nan")
    events = sorted(events + frames, key=lambda e: e[0])
    engine = IdentityEngine(session(list(CROSSING)))
    changes = []
    for _, message in events:
        changes += [(o.timestamp_ns / S, o.agent_id, o.track_id) for o in engine.on_message(message)
                    if o.DESCRIPTOR.name == "TrackIdentity"]
    assert engine.counters.rows_not_numbers == 80  # 4 s of track 6 at 20 frames a second
    assert ("cam1", 6) not in engine.tracks and all(track != 6 for _, _, track in changes)
    assert holder_at(changes, "a", 18.0) == 7 and holder_at(changes, "b", 10.0) == 4
    frame = frames[0][1]
    del frame.y_m[-1]
    with pytest.raises(ValueError, match=r"CameraFrame cam1 frame \d+: track_id has 3 entries, x_m 3, y_m 2"):
        engine.on_message(frame)
