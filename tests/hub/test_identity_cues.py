"""Our track-to-agent association's cues on crafted scenes (tests/support/identity_scenes.py): stature,
posture, gait phase, direction of travel, when bins are scored, stale poses, bad camera rows
(association itself: tests/hub/test_identity.py)."""

from __future__ import annotations

import numpy as np
import pytest

from hub.identity.book import Track
from hub.identity.engine import IdentityEngine, IdentitySettings
from support.identity_scenes import CROSSING, S, camera_frames, holder_at, imu_batches, session, waypoints_path


def _run_scene(paths: dict, wearers: list[str], tracks: list, end_s: float, settings: IdentitySettings = IdentitySettings(),
               heights: dict | None = None, chairs: bool = False, camera_shift_s: float = 0.0, seed: int = 1):
    """As identity_scenes.run(), with people who wear no sensor (in `paths`, not in `wearers`), reported head heights and
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
