"""Ours in hindsight (hub/identity/hindsight.py): the global fragment assignment and the label-free fit."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from hub.identity.hindsight import PRIOR, Samples, assign, identify_hindsight, refit, solve
from hub.identity.paper.features import PaperModel, vertical_acceleration
from protocol.session_log import read_session
from reckon.evaluation import identity_eval
from reckon.evaluation.reckon_run import log_inputs
from support.identity_scenes import CROSSING, write_scene

# (track id, person, start s, end s): a and b swap tracks at 6 s, a's track breaks twice, a bystander's track
TRACKS = [(1, "a", 0, 6), (2, "b", 0, 6), (3, "c", 0, 30), (4, "b", 6, 30), (5, "a", 6, 14), (6, "", 10, 14),
          (7, "a", 14.5, 30)]


def _feasible(pairs: list[tuple[int, int]], start: np.ndarray, end: np.ndarray, tolerance: int) -> bool:
    fragments = [k for _, k in pairs]
    if len(set(fragments)) != len(fragments):
        return False
    for p in {p for p, _ in pairs}:
        mine = sorted((start[k], end[k]) for q, k in pairs if q == p)
        if any(s2 <= max(e1 - tolerance, s1) for (s1, e1), (s2, _) in zip(mine, mine[1:])):
            return False
    return True


def _brute_force(gain: np.ndarray, start: np.ndarray, end: np.ndarray, tolerance: int) -> float:
    """The best total over every way of giving each fragment to one person or nobody."""
    people, count = gain.shape
    best = 0.0
    for owners in itertools.product(range(-1, people), repeat=count):
        pairs = [(p, k) for k, p in enumerate(owners) if p >= 0]
        if all(gain[p, k] > 0 for p, k in pairs) and _feasible(pairs, start, end, tolerance):
            best = max(best, sum(gain[p, k] for p, k in pairs))
    return best


@pytest.mark.parametrize("seed", range(12))
def test_assignment_is_the_best_feasible_one(seed: int):
    rng = np.random.default_rng(seed)
    people, count = int(rng.integers(2, 4)), int(rng.integers(4, 8))
    start = rng.integers(0, 60, count)
    end = start + rng.integers(1, 40, count)
    gain = rng.normal(1.0, 2.0, (people, count)) * (end - start)
    pairs, total, gap = assign(gain, start, end, overlap_tolerance_frames=2)
    assert _feasible(pairs, start, end, 2)
    assert all(gain[p, k] > 0 for p, k in pairs)
    assert total == pytest.approx(sum(gain[p, k] for p, k in pairs))
    assert total == pytest.approx(_brute_force(gain, start, end, 2), rel=1e-9, abs=1e-9)
    assert gap >= -1e-9


def test_assignment_shares_nothing_and_takes_no_loss():
    start, end = np.array([0, 0, 49, 47]), np.array([49, 49, 99, 99])
    # person 0 fits fragments 0 and 2 (a hand-over: one frame of both, within the tolerance; fragment 3
    # overlaps fragment 0 by three frames), person 1 fits 1
    gain = np.array([[10.0, 1.0, 8.0, 3.0], [6.0, 7.0, -1.0, -5.0]])
    pairs, total, _ = assign(gain, start, end, overlap_tolerance_frames=2)
    assert sorted(pairs) == [(0, 0), (0, 2), (1, 1)] and total == pytest.approx(25.0)
    pairs, total, _ = assign(gain, start, end, overlap_tolerance_frames=0)  # no tolerance: 0 and 2 conflict
    assert sorted(pairs) == [(0, 0), (1, 1)] and total == pytest.approx(17.0)
    assert assign(-np.abs(gain), start, end) == ([], 0.0, 0.0)  # every pair worse than losing the person


def test_refit_keeps_the_previous_line_when_the_assignment_says_nothing():
    samples = Samples(np.zeros(100, dtype=np.int64), np.zeros(100), np.full((1, 100), 0.05), np.array([0]),
                      np.array([99]), 0.05)
    previous = PaperModel(0.1, 0.01, 0.02, 0.02)
    assert refit([], samples, previous) is previous
    assert refit([(0, 0)], samples, previous) is previous  # a still track: no speed spread
    short = Samples(samples.label[:40], np.linspace(0, 1.5, 40), samples.measured_g[:, :40],
                    np.array([0]), np.array([39]), 0.05)
    assert refit([(0, 0)], short, previous) is previous  # 2 s of pairs: too few to learn a line from


def test_the_refit_line_does_not_flatten_with_wrong_pairs():
    """Half the pairs taken wrong (a wearer's activity against someone else's speed): least squares would halve
    the slope; the reduced major axis keeps it, and it is never flatter than walking allows."""
    rng = np.random.default_rng(3)
    speed = rng.uniform(0.0, 1.6, 4000)
    right = 0.12 * speed + 0.01 + rng.normal(0, 0.01, 4000)
    wrong = 0.12 * rng.permutation(speed) + 0.01 + rng.normal(0, 0.01, 4000)
    label = np.repeat([0, 1], 2000)
    samples = Samples(label, speed, np.vstack([np.r_[right[:2000], wrong[2000:]]]),
                      np.array([0, 2000]), np.array([1999, 3999]), 0.05)
    line = refit([(0, 0), (0, 1)], samples, PRIOR)
    assert line.slope_g_per_mps == pytest.approx(0.12, rel=0.05)
    assert np.polyfit(speed, samples.measured_g[0], 1)[0] < 0.09  # what least squares would have taken
    flat = Samples(label, speed, np.full((1, 4000), 0.02) + rng.normal(0, 0.002, (1, 4000)),
                   samples.start, samples.end, 0.05)
    assert refit([(0, 0), (0, 1)], flat, PRIOR).slope_g_per_mps == pytest.approx(0.06)


def _crossing(tmp_path: Path):
    path = tmp_path / "crossing.mcap"
    write_scene(path, CROSSING, TRACKS, end_s=30)
    data = read_session(path)
    imu = identity_eval._people(data, log_inputs(path), ["a", "b", "c"])
    tracks = data.cameras["cam1"]
    people = {a: (tracks.frame_ns, vertical_acceleration(t, acc, tracks.frame_ns)) for a, (t, acc) in imu.items()}
    return data, tracks, people


@pytest.mark.parametrize("slope", [0.1, PRIOR.slope_g_per_mps, 0.2])
def test_names_every_fragment_without_labels(tmp_path: Path, slope: float):
    data, tracks, people = _crossing(tmp_path)
    prior = PaperModel(slope, PRIOR.intercept_g, PRIOR.ave_abs_error_g, PRIOR.sd_abs_error_g)
    result = identify_hindsight(tracks, people, prior)
    solution = result.solution
    held = {(result.people[p], int(result.fragments.track_id[k])) for p, k in solution.chosen}
    truth = {(person, track) for track, person, _, _ in TRACKS if person}
    assert held == truth  # the swap at 6 s, both of a's breaks, and the bystander's track left alone
    assert solution.converged and solution.model.slope_g_per_mps > 0 and solution.likelihood_ratio > 0
    assert solution.relaxation_gap == pytest.approx(0.0, abs=1e-6)
    assignment = result.assignment(tracks.frame_ns)
    at = lambda s: int(np.searchsorted(tracks.frame_ns, tracks.frame_ns[0] + int(s * 1e9)))
    assert assignment["a"][at(3)] == 1 and assignment["a"][at(8)] == 5 and assignment["a"][at(20)] == 7
    assert assignment["b"][at(3)] == 2 and assignment["b"][at(20)] == 4
    assert assignment["a"][at(14.2)] == 0  # between two of a's tracks: nobody's


def test_a_bad_iteration_count_is_refused(tmp_path: Path):
    _, tracks, people = _crossing(tmp_path)
    with pytest.raises(ValueError, match="max_iterations 0"):
        identify_hindsight(tracks, people, max_iterations=0)


def test_the_live_identities_count_as_evidence(tmp_path: Path):
    """A live engine that held a on b's track and b on a's from 6 s (a swap it missed) pulls the choice its way
    as far as its weight goes: lightly, the motion still wins; heavily, the held pairs are taken."""
    _, tracks, people = _crossing(tmp_path)
    wrong = {"a": np.where(tracks.frame_ns >= tracks.frame_ns[0] + 6 * 10**9, 4, 1),
             "b": np.where(tracks.frame_ns >= tracks.frame_ns[0] + 6 * 10**9, 5, 2),
             "c": np.full(len(tracks.frame_ns), 3)}
    truth = {(person, track) for track, person, _, _ in TRACKS if person}

    def held_pairs(weight: float) -> set[tuple[str, int]]:
        result = identify_hindsight(tracks, people, held=wrong, held_weight_g=weight)
        return {(result.people[p], int(result.fragments.track_id[k])) for p, k in result.solution.chosen}

    assert held_pairs(0.0) == truth and held_pairs(0.001) == truth
    assert {("a", 4), ("b", 5)} <= held_pairs(10.0)
