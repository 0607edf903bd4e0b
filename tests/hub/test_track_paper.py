"""The camera-identity paper's baseline (hub.identity.paper.search*) on synthetic scenes built here with numpy."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from hub.identity.paper.search import assign_in_order, fragment_errors, identify
from hub.identity.paper.fragments import on_frame_grid, split_fragments, training_pairs
from hub.identity.paper.chain import best_chain
from hub.identity.paper.features import PaperModel, fit_model, track_speed, vertical_acceleration

FRAME_NS = 50_000_000  # 20 fps, as the paper's cameras
SLOPE, INTERCEPT = 0.12, 0.02  # g per m/s and g: the scenes' true speed -> vertical relation


@dataclass
class Tracks:
    frame_ns: np.ndarray
    time_ns: np.ndarray
    track_id: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray


def tracks_from(pieces: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]], frames: int) -> Tracks:
    """pieces: (track id, frame indices, x, y); rows sorted by time as CameraTracks holds them."""
    ids = np.concatenate([np.full(len(f), i) for i, f, _, _ in pieces]).astype(np.int64)
    frame = np.concatenate([f for _, f, _, _ in pieces])
    x = np.concatenate([p[2] for p in pieces])
    y = np.concatenate([p[3] for p in pieces])
    order = np.lexsort((ids, frame))
    return Tracks(np.arange(frames, dtype=np.int64) * FRAME_NS, frame[order] * FRAME_NS, ids[order], x[order], y[order])


def line(track_id: int, first: int, last: int, speed_mps: float) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """A fragment moving along x at constant speed: its fitted speed is exact."""
    frames = np.arange(first, last + 1)
    return track_id, frames, speed_mps * frames * FRAME_NS * 1e-9, np.full(len(frames), float(track_id))


def constant(value: float, frames: int) -> tuple[np.ndarray, np.ndarray]:
    return np.arange(frames, dtype=np.int64) * FRAME_NS, np.full(frames, value)


# ---- a scene: people walking, tracks fragmented, a false track, a person without a sensor ----

def walk(rng: np.random.Generator, frames: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Speed (m/s) that changes every 2-8 s between standing and brisk walking, and its path."""
    speed = np.empty(frames)
    k = 0
    while k < frames:
        length = int(rng.integers(40, 160))
        speed[k:k + length] = rng.choice([0.0, 0.3, 0.7, 1.1, 1.5])
        k += length
    speed = np.convolve(speed, np.ones(10) / 10, mode="same")  # people accelerate over ~0.5 s
    heading = np.cumsum(rng.normal(0, 0.05, frames))
    step = speed * FRAME_NS * 1e-9
    return speed, np.cumsum(step * np.cos(heading)), np.cumsum(step * np.sin(heading))


def vertical_of(rng: np.random.Generator, speed: np.ndarray) -> np.ndarray:
    noise = np.convolve(rng.normal(0, 0.06, len(speed)), np.ones(20) / 20, mode="same")
    return SLOPE * speed + INTERCEPT + noise


def fragment(rng: np.random.Generator, next_id: list[int], frames: np.ndarray, x: np.ndarray, y: np.ndarray,
             owner: str, labels: list[tuple[int, str]]) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """Cut one person's track every 6-15 s, drop 0-30 frames at each cut, give each piece a new id."""
    pieces, k = [], 0
    while k < len(frames):
        length = int(rng.integers(120, 300))
        part = slice(k, min(k + length, len(frames)))
        noisy_x = x[part] + rng.normal(0, 0.02, len(frames[part]))  # head-position noise, 2 cm
        noisy_y = y[part] + rng.normal(0, 0.02, len(frames[part]))
        pieces.append((next_id[0], frames[part], noisy_x, noisy_y))
        labels.append((next_id[0], owner))
        next_id[0] += 1
        k += length + int(rng.integers(0, 30))
    return pieces


def scene(seed: int, frames: int = 1200):
    rng = np.random.default_rng(seed)
    next_id, labels, pieces, people = [1], [], [], {}
    all_frames = np.arange(frames)
    for name in ("ann", "bob", "cho", "nosensor"):
        speed, x, y = walk(rng, frames)
        pieces += fragment(rng, next_id, all_frames, x, y, name, labels)
        if name != "nosensor":
            people[name] = (all_frames * FRAME_NS, vertical_of(rng, speed))
    speed, x, y = walk(rng, 300)  # a false track (a reflection) for 15 s
    pieces.append((999, all_frames[500:800], x, y))
    labels.append((999, ""))
    tracks = tracks_from(pieces, frames)
    owner = dict(labels)
    row_person = np.array([owner[int(i)] for i in tracks.track_id], dtype=object)
    return tracks, people, row_person


def trained_model() -> PaperModel:
    tracks, people, row_person = scene(seed=101)
    speeds, verticals, ids = training_pairs(tracks, row_person, people, window_s=1.0)
    return fit_model(speeds, verticals, ids)


# ---- features ----

def test_vertical_acceleration_is_mean_absolute_vertical_under_tilt():
    rate_hz, seconds, amplitude_g = 100, 20, 0.2
    t = np.arange(rate_hz * seconds) / rate_hz
    world = np.column_stack([0.3 * np.sin(2 * np.pi * 1.0 * t + 0.4),  # forward sway at the stride rate
                             0.1 * np.sin(2 * np.pi * 1.0 * t),
                             1.0 + amplitude_g * np.sin(2 * np.pi * 2.0 * t)])  # gravity + bounce per step
    tilt_x, tilt_y = np.radians(8.0), np.radians(-5.0)
    rot_x = np.array([[1, 0, 0], [0, np.cos(tilt_x), -np.sin(tilt_x)], [0, np.sin(tilt_x), np.cos(tilt_x)]])
    rot_y = np.array([[np.cos(tilt_y), 0, np.sin(tilt_y)], [0, 1, 0], [-np.sin(tilt_y), 0, np.cos(tilt_y)]])
    sensor = world @ (rot_x @ rot_y)  # world -> tilted sensor axes
    time_ns = (t * 1e9).astype(np.int64)
    frame_ns = np.arange(100, 300) * FRAME_NS  # 5-15 s: windows lie well inside the record
    feature = vertical_acceleration(time_ns, sensor, frame_ns)
    np.testing.assert_allclose(feature, 2 * amplitude_g / np.pi, rtol=0.03)  # mean |A sin| = 2A / pi
    assert np.isnan(vertical_acceleration(time_ns, sensor, np.array([60 * 10**9]))[0])  # no sample near


def test_track_speed_averages_position_noise_at_20_fps():
    rng = np.random.default_rng(1)
    frames = np.arange(200)
    x = 1.2 * frames * 0.05 + rng.normal(0, 0.02, 200)
    y = 0.5 + rng.normal(0, 0.02, 200)
    speed = track_speed(frames * FRAME_NS, x, y)
    assert abs(np.median(speed) - 1.2) < 0.03
    assert np.isnan(track_speed(np.array([0]), np.array([0.0]), np.array([0.0]))[0])  # one row: no speed


def test_fit_recovers_slope_and_error_statistics():
    rng = np.random.default_rng(2)
    speeds = rng.uniform(0, 2, 5000)
    noise = rng.normal(0, 0.02, 5000)
    model = fit_model(speeds, SLOPE * speeds + INTERCEPT + noise)
    assert model.slope_g_per_mps == pytest.approx(SLOPE, abs=0.003)
    assert model.intercept_g == pytest.approx(INTERCEPT, abs=0.003)
    assert model.ave_abs_error_g == pytest.approx(0.02 * np.sqrt(2 / np.pi), rel=0.05)  # E|N(0, s)|
    assert model.sd_abs_error_g == pytest.approx(0.02 * np.sqrt(1 - 2 / np.pi), rel=0.05)
    assert model.correlation > 0.9


def test_fit_on_a_labelled_scene_recovers_the_slope():
    model = trained_model()
    assert model.slope_g_per_mps == pytest.approx(SLOPE, abs=0.01)
    assert model.intercept_g == pytest.approx(INTERCEPT, abs=0.01)


# ---- the dynamic programming over fragments ----

def test_best_chain_hand_worked():
    starts, ends = np.array([0, 40, 20, 75]), np.array([29, 69, 59, 99])
    values = np.array([25.0, 25.0, 30.0, 20.0])
    # 0 -> 1 -> 3: 25 + 10 gap frames x 0.5 + 25 + 5 x 0.5 + 20 = 77.5; 2 overlaps 0 and 1 by 10 frames;
    # 2 -> 3: 30 + 7.5 + 20 = 57.5; 0 -> 3: 25 + 22.5 + 20 = 67.5
    chain = best_chain(starts, ends, values, 0.5, overlap_tolerance_frames=2)
    assert chain.fragments == (0, 1, 3)
    assert chain.score == pytest.approx(77.5)
    assert chain.transitions == 6  # 4 fragments: 4 x 3 / 2 pairs
    # frames 28-29 shared: within the tolerance of 2, no bridge
    touching = best_chain(np.array([0, 28]), np.array([29, 50]), np.array([1.0, 1.0]), 0.5, 2)
    assert touching.fragments == (0, 1) and touching.score == pytest.approx(2.0)
    assert best_chain(np.array([0, 27]), np.array([29, 50]), np.array([1.0, 2.0]), 0.5, 2).fragments == (1,)


def test_dp_two_people_four_fragments_hand_worked():
    tracks = tracks_from([line(11, 0, 29, 1.0), line(12, 40, 69, 1.0), line(13, 20, 59, 0.5),
                          line(14, 75, 99, 0.5)], 100)
    model = PaperModel(slope_g_per_mps=0.1, intercept_g=0.0, ave_abs_error_g=0.02, sd_abs_error_g=0.02)
    people = {"p": constant(0.11, 100), "q": constant(0.045, 100)}
    result = identify(tracks, people, model, max_permutations=10)
    errors = result.errors
    # Mae: p 0.01 on 11, 12 and 0.06 on 13, 14; q 0.055 on 11, 12 and 0.005 on 13, 14.
    # L: 1.5, 1.5, 2.0, 1.25 s; eq. 1: alpha = 0.02 + 0.02 / sqrt(L) = 0.0363, 0.0363, 0.0341, 0.0379
    np.testing.assert_allclose(errors.mae_g, [[0.01, 0.01, 0.06, 0.06], [0.055, 0.055, 0.005, 0.005]], atol=1e-9)
    np.testing.assert_allclose(errors.length_s[0], [1.5, 1.5, 2.0, 1.25])
    np.testing.assert_array_equal(errors.kept, [[True, True, False, False], [False, False, True, True]])
    assert errors.normalization_g == pytest.approx(0.06)
    assert errors.virtual_e == pytest.approx(1 / 3)  # 1 - (Ave + SD) / max Mae
    # p: 1.5 s x 5/6 + 10 lost frames (0.5 s) x 1/3 + 1.5 s x 5/6
    assert result.person_scores["p"] == pytest.approx(1.25 + 0.5 / 3 + 1.25)
    # q: 2 s x 11/12 + 15 lost frames (0.75 s) x 1/3 + 1.25 s x 11/12
    assert result.person_scores["q"] == pytest.approx(2 * 11 / 12 + 0.25 + 1.25 * 11 / 12)
    assert result.total_score == pytest.approx(result.person_scores["p"] + result.person_scores["q"])
    assert [link.track_id for link in result.routes["p"]] == [11, 12]
    assert [link.track_id for link in result.routes["q"]] == [13, 14]
    ids = result.assignment(tracks.frame_ns)
    assert ids["p"][0] == 11 and ids["p"][35] == 0 and ids["p"][50] == 12 and ids["p"][80] == 0
    xy = result.positions(tracks.frame_ns)["p"]
    # lost stretch (frames 30-39): linear interpolation between frame 29 (x 1.45) and frame 40 (x 2.0)
    assert xy[35, 0] == pytest.approx(1.45 + 0.55 * 6 / 11)
    assert np.isnan(xy[80, 0])  # after the route's last row
    assert result.permutations_tried == 2 and not result.stopped


def test_virtual_fragment_at_ave_would_skip_an_own_fragment():
    # One person, three own fragments; the middle one fits a little worse than average (Mae 0.01 > Ave
    # 0.008) but passes eq. 1. A false track (Mae 0.2) sets max Mae.
    tracks = tracks_from([line(1, 0, 29, 1.0), line(2, 35, 64, 0.9), line(3, 70, 99, 1.0), line(9, 0, 99, 3.0)], 100)
    model = PaperModel(slope_g_per_mps=0.1, intercept_g=0.0, ave_abs_error_g=0.008, sd_abs_error_g=0.02)
    people = {"p": constant(0.1, 100)}
    literal = identify(tracks, people, model, max_permutations=1, virtual_sd_multiple=0.0)
    assert [link.track_id for link in literal.routes["p"]] == [1, 3]  # the lost stretch outscores fragment 2
    ours = identify(tracks, people, model, max_permutations=1)  # virtual Mae = Ave + SD
    assert [link.track_id for link in ours.routes["p"]] == [1, 2, 3]


# ---- the permutations ----

def greedy_trap():
    # Fragment 1 suits both a and b, fragment 2 only a (a little worse), fragment 3 only c. All are 5 s, so
    # alpha = 0.02 + 0.05 / sqrt(5) = 0.042. Mae: a 0.008, 0.022, 0.108; b 0.035, 0.065, 0.065; c 0.1, 0.13, 0.
    tracks = tracks_from([line(1, 0, 99, 1.0), line(2, 0, 99, 0.7), line(3, 0, 99, 2.0)], 100)
    model = PaperModel(slope_g_per_mps=0.1, intercept_g=0.0, ave_abs_error_g=0.02, sd_abs_error_g=0.05)
    people = {"a": constant(0.092, 100), "b": constant(0.135, 100), "c": constant(0.2, 100)}
    return tracks, people, model


def test_every_permutation_beats_a_greedy_order():
    tracks, people, model = greedy_trap()
    result = identify(tracks, people, model, max_permutations=6)
    routes = {name: [link.track_id for link in links] for name, links in result.routes.items()}
    assert routes == {"a": [2], "b": [1], "c": [3]}
    assert result.permutations_tried == 6 == result.permutations_needed  # 3!
    assert result.transitions > 0 and not result.stopped
    # eval (eq. 3, max Mae 0.13): a 4.69 on 1 or 4.15 on 2, b 3.65 on 1, c 5 on 3. Taking people
    # alphabetically, or best individual score first (c, a, b), a takes 1 and b is left with nothing.
    fragments = split_fragments(tracks, model.window_s)
    verticals = np.array([on_frame_grid(tracks.frame_ns, n, *people[n]) for n in ("a", "b", "c")])
    errors = fragment_errors(fragments, verticals, ("a", "b", "c"), model, frame_s=0.05)
    for order in (("a", "b", "c"), ("c", "a", "b")):
        greedy = assign_in_order(order, fragments, errors)
        assert greedy.routes["b"] == () and greedy.total == pytest.approx(result.total_score - 4.154 - 3.654 + 4.692,
                                                                           abs=0.01)


def test_budget_stops_the_search_and_says_so():
    tracks, people, model = greedy_trap()
    result = identify(tracks, people, model, max_permutations=2)
    assert result.stopped and result.permutations_tried == 2 and result.permutations_needed == 6
    assert "max_permutations=2" in result.reason
    by_work = identify(tracks, people, model, max_permutations=100, max_transitions=1)
    assert by_work.stopped and by_work.permutations_tried == 1 and "max_transitions=1" in by_work.reason


# ---- a fragmented scene with a false track and a person without a sensor ----

def test_scene_identified_and_false_track_pruned():
    model = trained_model()
    tracks, people, row_person = scene(seed=7)
    result = identify(tracks, people, model, max_permutations=6)
    assert result.permutations_tried == 6 and not result.stopped
    fragments = split_fragments(tracks, model.window_s)
    owner = {int(t): str(p) for t, p in zip(tracks.track_id, row_person)}
    fragment_owner = np.array([owner[int(t)] for t in fragments.track_id])
    assert not result.errors.kept[:, fragment_owner == ""].any()  # the false track: pruned for everyone
    ids = result.assignment(tracks.frame_ns)
    for p, name in enumerate(result.errors.people):
        named = ids[name][ids[name] != 0]
        assert np.mean([owner[int(t)] == name for t in named]) > 0.95, f"{name}: another's track in the route"
        mine = row_person == name
        frames, truth = tracks.time_ns[mine] // FRAME_NS, tracks.track_id[mine]
        correct = np.mean(ids[name][frames] == truth)
        # eq. 1 is a one-standard-error test: it drops some of a person's own fragments (about 1 in 4
        # here); every own fragment that survives must be in the route
        own_kept = result.errors.kept[p] & (fragment_owner == name)
        kept_share = result.errors.frames[p][own_kept].sum() / result.errors.frames[p][fragment_owner == name].sum()
        assert correct == pytest.approx(kept_share, abs=0.02) and correct > 0.7, f"{name}: {correct:.2f} correct"


# ---- bad input ----

def test_bad_input_raises_naming_the_value():
    time_ns = np.arange(10, dtype=np.int64) * 10_000_000
    with pytest.raises(ValueError, match="accel_g has 9 rows, expected 10"):
        vertical_acceleration(time_ns, np.zeros((9, 3)), time_ns)
    backwards = time_ns.copy()
    backwards[5] = backwards[3]
    with pytest.raises(ValueError, match="imu time_ns does not increase at index 5"):
        vertical_acceleration(backwards, np.zeros((10, 3)), time_ns)
    with pytest.raises(ValueError, match="verticals_g has 4 rows, expected 5"):
        fit_model(np.arange(5.0), np.arange(4.0))
    tracks = tracks_from([line(1, 0, 9, 1.0)], 10)
    model = PaperModel(0.1, 0.0, 0.02, 0.1)
    short = Tracks(tracks.frame_ns, tracks.time_ns, tracks.track_id, tracks.x_m[:-1], tracks.y_m)
    with pytest.raises(ValueError, match="tracks x_m has 9 rows, expected 10"):
        identify(short, {}, model, 1)
    reversed_rows = Tracks(tracks.frame_ns, tracks.time_ns[::-1].copy(), tracks.track_id, tracks.x_m, tracks.y_m)
    with pytest.raises(ValueError, match="tracks time_ns goes backwards at index 1"):
        identify(reversed_rows, {}, model, 1)
    with pytest.raises(ValueError, match="people\\['p'\\] time_ns does not increase"):
        identify(tracks, {"p": (backwards, np.zeros(10))}, model, 1)
    twice = Tracks(tracks.frame_ns, np.r_[tracks.time_ns, tracks.time_ns[-1]], np.r_[tracks.track_id, 1],
                   np.r_[tracks.x_m, 0.0], np.r_[tracks.y_m, 0.0])
    with pytest.raises(ValueError, match="track_id 1 has two rows at time_ns 450000000"):
        identify(twice, {}, model, 1)
    with pytest.raises(ValueError, match="max_permutations 0"):
        identify(tracks, {}, model, 0)
