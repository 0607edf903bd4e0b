"""Simulated camera tracker: each effect on a crafted scene, presets, determinism, and `sim wheelchair --camera`."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from protocol.errors import ConfigError
from protocol.session_log import read_session
from reckon.cli import main
from sim_devices.camera import (COURT, ROOM, PersonPath, TrackerParams, camera_items, describe, extra_people,
                                params_with_overrides, simulate_tracks)

DOCS = Path(__file__).resolve().parents[2] / "docs" / "simulator-camera.md"
S = 1_000_000_000
AREA = (20.0, 10.0)


def _quiet(base: TrackerParams = COURT, **changes: str) -> TrackerParams:
    """`base` with every effect off (no noise, gaps, switches, merges, splits, false tracks, lost
    frames, jitter, offset), then `changes` ("group.key": value) applied."""
    off = {"camera.frame_jitter_ms": "0", "camera.clock_offset_ms": "0", "camera.frame_loss_rate": "0",
           "noise.white_sd_m": "0", "noise.correlated_sd_m": "0", "noise.height_sd_m": "0", "gaps.rate_per_min": "0",
           "gaps.occluded_rate_per_s": "0", "gaps.still_rate_per_s": "0", "switches.probability": "0",
           "merges.probability": "0", "splits.rate_per_min": "0", "false_tracks.rate_per_min": "0"}
    return params_with_overrides({**off, **{k.replace("__", "."): v for k, v in changes.items()}}, base)


def _line(person: str, start: tuple[float, float], end: tuple[float, float], seconds: float,
          height_m: float = 1.7) -> PersonPath:
    """A person walking a straight line at constant speed, sampled at 50 Hz from t = 0."""
    time_ns = np.arange(int(seconds * 50) + 1, dtype=np.int64) * (S // 50)
    share = time_ns / time_ns[-1]
    return PersonPath(person, time_ns, start[0] + share * (end[0] - start[0]), start[1] + share * (end[1] - start[1]),
                      height_m)


def _crossing(half_m: float = 3.0) -> list[PersonPath]:
    """a and b walk towards each other at 1.5 m/s, 0.3 m apart, and pass half way."""
    seconds = 2 * half_m / 1.5
    return [_line("a", (6.0 - half_m, 5.0), (6.0 + half_m, 5.0), seconds),
            _line("b", (6.0 + half_m, 5.3), (6.0 - half_m, 5.3), seconds)]


def _who(recording, track_id: int) -> list[str]:
    """The labels track `track_id` carries, frame by frame (in order, repeats collapsed)."""
    labels: list[str] = []
    for frame in recording.frames:
        for tid, label in zip(frame.track_id.tolist(), frame.person_id):
            if tid == track_id and (not labels or labels[-1] != label):
                labels.append(label)
    return labels


# -- effects on crafted scenes --------------------------------------------------------------------


def test_frames_follow_the_frame_rate_and_clock_offset():
    params = _quiet(camera__frame_rate_hz="10", camera__clock_offset_ms="250")
    recording = simulate_tracks([_line("a", (1.0, 1.0), (5.0, 1.0), 3.0)], AREA, params, np.random.default_rng(1))
    assert [f.frame for f in recording.frames] == list(range(1, 32))
    stamps = np.array([f.time_ns for f in recording.frames])
    assert stamps[0] == S // 4 and np.all(np.diff(stamps) == S // 10)
    jittery = _quiet(camera__frame_jitter_ms="5", camera__frame_loss_rate="0.2")
    recording = simulate_tracks([_line("a", (1.0, 1.0), (5.0, 1.0), 60.0)], AREA, jittery, np.random.default_rng(1))
    numbers = np.array([f.frame for f in recording.frames])
    stamps = np.array([f.time_ns for f in recording.frames])
    lost = 60 * 25 + 1 - len(numbers)
    assert lost == recording.counters["lost_frames"] and 0.15 < lost / (60 * 25) < 0.25
    residual = stamps - (numbers - 1) * (S // 25)
    assert np.all(np.diff(stamps) > 0) and 4e6 < residual.std() < 6e6  # jitter SD 5 ms, stamps still increase


def test_noise_matches_the_stated_position_sd():
    params = _quiet(noise__white_sd_m="0.05", noise__correlated_sd_m="0.05", noise__correlation_s="0.5")
    person = _line("a", (1.0, 2.0), (19.0, 8.0), 300.0)
    recording = simulate_tracks([person], AREA, params, np.random.default_rng(2))
    times = np.array([f.time_ns for f in recording.frames])
    error_x = np.array([f.x_m[0] for f in recording.frames]) - np.interp(times, person.time_ns, person.x_m)
    error_y = np.array([f.y_m[0] for f in recording.frames]) - np.interp(times, person.time_ns, person.y_m)
    assert recording.position_sd_m == pytest.approx(np.hypot(0.05, 0.05))
    assert np.sqrt(np.mean(error_x ** 2 + error_y ** 2) / 2) == pytest.approx(recording.position_sd_m, rel=0.15)
    lag1 = np.corrcoef(error_x[:-1], error_x[1:])[0, 1]
    assert 0.3 < lag1 < 0.7  # half white, half correlated over 0.5 s at 25 fps (0.96): about 0.48


@pytest.mark.parametrize("probability, expected", [(1.0, ["a", "b"]), (0.0, ["a"])])
def test_a_crossing_switches_the_tracks_when_the_probability_says_so(probability, expected):
    params = _quiet(switches__probability=str(probability))
    recording = simulate_tracks(_crossing(), AREA, params, np.random.default_rng(3))
    first = int(recording.frames[0].track_id[recording.frames[0].person_id.index("a")])
    assert _who(recording, first) == expected
    assert recording.counters["switches"] == int(probability)
    assert recording.counters["tracks"] == 2


def test_switch_rate_over_many_crossings_matches_the_probability():
    params = _quiet(switches__probability="0.3")
    rng = np.random.default_rng(4)
    switched = sum(simulate_tracks(_crossing(1.0), AREA, params, rng).counters["switches"] for _ in range(300))
    assert abs(switched / 300 - 0.3) < 3 * np.sqrt(0.3 * 0.7 / 300)


def test_people_walking_together_merge_into_one_track_labelled_a_plus_b():
    params = _quiet(merges__probability="1", merges__distance_m="0.5")
    together = [_line("b", (2.0, 5.0), (8.0, 5.0), 6.0), _line("a", (2.0, 5.4), (8.0, 5.4), 6.0)]
    apart = [_line("b", (8.0, 5.0), (14.0, 2.0), 4.0), _line("a", (8.0, 5.4), (14.0, 8.0), 4.0)]
    people = [PersonPath(p.person_id, np.concatenate([p.time_ns, q.time_ns[1:] + p.time_ns[-1]]),
                         np.concatenate([p.x_m, q.x_m[1:]]), np.concatenate([p.y_m, q.y_m[1:]]))
              for p, q in zip(together, apart)]
    recording = simulate_tracks(people, AREA, params, np.random.default_rng(5))
    middle = recording.frames[75]  # t = 3 s
    assert middle.person_id == ["a+b"] and len(middle.track_id) == 1
    assert (middle.x_m[0], middle.y_m[0]) == pytest.approx((5.0, 5.2))  # the centroid
    end = recording.frames[-1]
    assert sorted(end.person_id) == ["a", "b"]
    assert int(middle.track_id[0]) in end.track_id.tolist()  # one of them keeps the merged id
    assert recording.counters["merges"] == 1 and recording.counters["tracks"] == 2


def test_the_field_of_view_cuts_tracks_and_a_return_is_a_new_track():
    params = _quiet(ROOM, camera__fov_margin_m="0")
    out_and_back = [_line("a", (-2.0, 1.5), (8.0, 1.5), 5.0), _line("a", (8.0, 1.5), (3.0, 1.5), 2.5)]
    person = PersonPath("a", np.concatenate([out_and_back[0].time_ns, out_and_back[1].time_ns[1:] + 5 * S]),
                        np.concatenate([out_and_back[0].x_m, out_and_back[1].x_m[1:]]),
                        np.concatenate([out_and_back[0].y_m, out_and_back[1].y_m[1:]]))
    recording = simulate_tracks([person], (5.6, 3.0), params, np.random.default_rng(6))
    xs = np.concatenate([f.x_m for f in recording.frames])
    assert xs.min() >= 0.0 and xs.max() <= 5.6
    empty = [f for f in recording.frames if not len(f.track_id)]
    assert len(empty) > 20  # frames that saw nobody are still reported
    ids = {int(t) for f in recording.frames for t in f.track_id}
    assert len(ids) == 2 and recording.counters["exits"] == 1
    assert all(f.height_m is not None and np.all(f.height_m == 1.7) for f in recording.frames)  # ROOM reports heads


def test_a_head_that_moves_down_is_reported_lower():
    """A person's head_m (sitting down half way) reaches the frames; without it, the stature throughout."""
    walker = _line("a", (1.0, 1.5), (4.0, 1.5), 4.0, height_m=1.7)
    head = np.where(walker.time_ns < 2 * S, 1.7, 1.3)
    sitting = dataclasses.replace(walker, head_m=head)
    recording = simulate_tracks([sitting], (5.6, 3.0), _quiet(ROOM), np.random.default_rng(1))
    times = np.array([f.time_ns for f in recording.frames])
    heights = np.array([f.height_m[0] for f in recording.frames])
    assert np.all(heights[times < 1.9 * S] == 1.7) and np.all(heights[times > 2.1 * S] == 1.3)
    with pytest.raises(ConfigError, match="head_m"):
        simulate_tracks([dataclasses.replace(walker, head_m=head[:-1])], (5.6, 3.0), _quiet(ROOM),
                        np.random.default_rng(1))


def test_gaps_come_at_the_stated_rate_and_each_gives_a_new_id():
    params = _quiet(gaps__rate_per_min="6", gaps__median_s="0.2", gaps__spread="0")
    recording = simulate_tracks([_line("a", (1.0, 1.0), (19.0, 9.0), 600.0)], AREA, params, np.random.default_rng(7))
    gaps = recording.counters["gaps"]
    assert abs(gaps - 60) < 3 * np.sqrt(60)
    assert recording.counters["tracks"] == gaps + 1
    assert sum(not len(f.track_id) for f in recording.frames) == pytest.approx(gaps * 0.2 * 25, abs=gaps)


def test_a_still_person_is_lost_until_moving_again_in_the_room_preset():
    params = _quiet(ROOM, gaps__still_rate_per_s="1")
    walk = _line("a", (1.0, 1.0), (2.0, 1.0), 1.0)
    stand = _line("a", (2.0, 1.0), (2.0, 1.0), 10.0)
    again = _line("a", (2.0, 1.0), (4.0, 2.0), 2.0)
    person = PersonPath("a", np.concatenate([walk.time_ns, stand.time_ns[1:] + S, again.time_ns[1:] + 11 * S]),
                        np.concatenate([walk.x_m, stand.x_m[1:], again.x_m[1:]]),
                        np.concatenate([walk.y_m, stand.y_m[1:], again.y_m[1:]]))
    recording = simulate_tracks([person], (5.6, 3.0), params, np.random.default_rng(8))
    seen = np.array([len(f.track_id) > 0 for f in recording.frames])
    assert seen[:20].all() and not seen[150:220].any() and seen[-10:].all()
    assert recording.counters["gaps"] == 1


def test_splits_show_one_person_as_two_tracks_for_a_while():
    params = _quiet(splits__rate_per_min="10", splits__mean_s="1", splits__offset_m="0.4")
    recording = simulate_tracks([_line("a", (1.0, 1.0), (19.0, 9.0), 300.0)], AREA, params, np.random.default_rng(9))
    doubled = [f for f in recording.frames if len(f.track_id) == 2]
    assert all(f.person_id == ["a", "a"] for f in doubled)
    assert all(np.hypot(*np.diff(np.c_[f.x_m, f.y_m], axis=0)[0]) == pytest.approx(0.4) for f in doubled)
    splits = recording.counters["splits"]
    expected = (10 / 60 * 300) / (1 + 10 / 60 * 1.0)  # the hazard runs only while the person is not split
    assert abs(splits - expected) < 3 * np.sqrt(expected)
    assert len(doubled) / 25 == pytest.approx(splits * 1.0, rel=0.3)
    assert 0.2 < recording.counters["split_takeovers"] / splits < 0.8


def test_false_tracks_are_short_random_walks_labelled_nobody():
    params = _quiet(false_tracks__rate_per_min="30", false_tracks__mean_s="2", false_tracks__min_s="0.2")
    recording = simulate_tracks([_line("a", (1.0, 1.0), (1.0, 1.0), 120.0)], AREA, params, np.random.default_rng(10))
    lifetimes: dict[int, int] = {}
    for frame in recording.frames:
        for tid, label in zip(frame.track_id.tolist(), frame.person_id):
            if label != "a":
                assert label == ""
                lifetimes[tid] = lifetimes.get(tid, 0) + 1
    assert len(lifetimes) == recording.counters["false_tracks"]
    assert abs(len(lifetimes) - 60) < 3 * np.sqrt(60)
    assert 1.2 < np.mean(list(lifetimes.values())) / 25 < 2.6  # about 2 s (walking out of view ends some early)


def test_extra_people_walk_plausibly_inside_the_area():
    people = extra_people(3, (28.0, 15.0), 0, 120 * S, np.random.default_rng(11), prefix="referee")
    assert [p.person_id for p in people] == ["referee1", "referee2", "referee3"]
    for person in people:
        dt = np.diff(person.time_ns) * 1e-9
        speed = np.hypot(np.diff(person.x_m), np.diff(person.y_m)) / dt
        accel = np.abs(np.diff(speed)) / dt[1:]
        assert speed.max() <= COURT.extras.speed_max_mps + 0.01 and accel.max() < 4.0
        assert 0.3 < speed.mean() < 1.5
        margin = COURT.extras.margin_m + 0.1
        assert -margin <= person.x_m.min() and person.x_m.max() <= 28.0 + margin
        assert -margin <= person.y_m.min() and person.y_m.max() <= 15.0 + margin
        assert person.height_m == COURT.extras.height_m


# -- determinism, messages, parameters ------------------------------------------------------------


def _crowd(seed: int, params: TrackerParams):
    rng = np.random.default_rng(seed)
    people = extra_people(6, (5.6, 3.0), 0, 30 * S, rng, params.extras)
    return simulate_tracks(people, (5.6, 3.0), params, rng)


def test_same_seed_same_tracks_and_items_another_seed_differs():
    first, again, other = _crowd(12, ROOM), _crowd(12, ROOM), _crowd(13, ROOM)
    assert first.counters == again.counters and first.counters["tracks"] > 6
    items = [(t, o, k, m.SerializeToString()) for t, o, k, m in camera_items(first, "room")]
    assert items == [(t, o, k, m.SerializeToString()) for t, o, k, m in camera_items(again, "room")]
    assert first.counters != other.counters
    assert [k for _, _, k, _ in items[:2]] == ["reckon/room/camera/tracks/cam1", "reckon/room/camera/truth_tracks/cam1"]
    assert all(a[:2] <= b[:2] for a, b in zip(items, items[1:]))  # in log-time order, as write_merged needs


def test_presets_and_overrides():
    assert (ROOM.camera.frame_rate_hz, COURT.camera.frame_rate_hz) == (20.0, 25.0)
    assert ROOM.camera.reports_height == 1 and COURT.camera.reports_height == 0
    assert params_with_overrides({"merges.distance_m": "0.7"}, ROOM).merges.distance_m == 0.7
    for overrides, message in (({"merges.nope": "1"}, "unknown key 'nope'"), ({"gaps.spread": "x"}, "not a number"),
                               ({"extras.speed_min_mps": "3"}, "exceeds extras.speed_max_mps")):
        with pytest.raises(ConfigError, match=re.escape(message)):
            params_with_overrides(overrides)
    with pytest.raises(ConfigError, match="duplicate person id"):
        simulate_tracks([_line("a", (0, 0), (1, 1), 1.0)] * 2, AREA, COURT, np.random.default_rng(1))


def test_room_preset_is_calibrated_against_the_papers_result():
    """ROOM: no swaps and rare fusions (calibrated against the paper's Table 2, docs/simulator-camera.md);
    a close pass then never exchanges two people's ids, and fusions stay in the calibrated band."""
    assert ROOM.switches.probability == 0.0 and ROOM.merges.probability == pytest.approx(0.1)
    assert "calibrated" in describe(ROOM, "room")[[k for k, *_ in describe(ROOM, "room")].index("switches.probability")][3]
    quiet = _quiet(ROOM, merges__probability="0")
    for seed in range(20):
        recording = simulate_tracks(_crossing(), AREA, quiet, np.random.default_rng(seed))
        assert recording.counters["switches"] == 0
        assert all(len(set(_who(recording, tid))) == 1 for tid in {t for f in recording.frames for t in f.track_id.tolist()})
    fused = sum(simulate_tracks(_crossing(), AREA, _quiet(ROOM, merges__probability="0.1"),
                                np.random.default_rng(seed)).counters["merges"] for seed in range(200))
    assert 8 <= fused <= 35  # 200 close passes at 0.1: 20 expected


def test_docs_list_every_parameter_with_both_presets_and_sources():
    text = DOCS.read_text(encoding="utf-8")
    for (key, room, unit, room_source), (_, court, _, court_source) in zip(describe(ROOM, "room"), describe(COURT)):
        assert f"| `{key}` | {room} | {court} | {unit} |" in text, key
        assert room_source and court_source
        assert court_source in text and room_source in text, key


def test_reference_game_is_realistically_fragmented():
    """The documented COURT figure: identity changes per chair-minute in a crowded 60 s game."""
    from sim_devices.wheelchair.motion import simulate_motion
    from sim_devices.wheelchair.params import SimParams

    motion = simulate_motion(10, 60.0, SimParams(), np.random.default_rng(1))
    steps = np.arange(0, len(motion.time_s), 4)
    stamps = np.round(motion.time_s[steps] * 1e9).astype(np.int64)
    chairs = [PersonPath(f"c{i}", stamps, motion.x_m[steps, i], motion.y_m[steps, i], 1.2) for i in range(10)]
    recording = simulate_tracks(chairs, (28.0, 15.0), COURT, np.random.default_rng(2))
    fragments: dict[str, set[int]] = {c.person_id: set() for c in chairs}
    for frame in recording.frames:
        for tid, label in zip(frame.track_id.tolist(), frame.person_id):
            for person in filter(None, label.split("+")):
                fragments[person].add(tid)
    per_minute = sum(len(ids) - 1 for ids in fragments.values()) / 10.0
    assert 1.0 < per_minute < 5.0  # docs: about 2.4 over 317 s games


# -- the wheelchair session with --camera ---------------------------------------------------------


def _records(path: Path) -> list[tuple[str, int, bytes]]:
    with open(path, "rb") as stream:
        return [(channel.topic, message.log_time, message.data)
                for _, channel, message in make_reader(stream).iter_messages(log_time_order=False)]


def test_sim_wheelchair_camera_labels_match_the_truth(tmp_path: Path, capsys):
    with_camera, without = tmp_path / "camera.mcap", tmp_path / "plain.mcap"
    base = ["-q", "sim", "wheelchair", "--players", "3", "--duration", "20", "--seed", "5"]
    assert main([*base, "--camera", "-o", str(with_camera)]) == 0
    assert "camera:" in capsys.readouterr().out
    assert main([*base, "-o", str(without)]) == 0
    plain = _records(without)
    assert [r for r in _records(with_camera) if "/camera/" not in r[0]] == plain  # the other streams are unchanged
    data = read_session(with_camera)
    camera = data.cameras["cam1"]
    about = data.session.source["camera"]
    assert about["extra_people"] == ["referee1", "referee2"] and camera.height_m is None
    assert len(camera.frame_ns) == pytest.approx(20 * 25, abs=3)
    assert set(camera.person_id) >= {"chair01", "chair02", "chair03", "referee1", "referee2"}
    capture = camera.time_ns - int(about["clock_offset_s"] * 1e9)
    for agent, truth in data.truth.items():
        mine = camera.person_id == agent
        dx = camera.x_m[mine] - np.interp(capture[mine], truth.time_ns, truth.x_m)
        dy = camera.y_m[mine] - np.interp(capture[mine], truth.time_ns, truth.y_m)
        assert mine.sum() > 300
        assert np.sqrt(np.mean(np.r_[dx, dy] ** 2)) < 2 * camera.position_sd_m
        assert np.abs(np.r_[dx, dy]).max() < 6 * camera.position_sd_m
