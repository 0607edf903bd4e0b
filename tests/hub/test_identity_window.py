"""The walkers' live window (hub/identity/window.py): bounded memory, a clear choice, no guess on stillness."""

from __future__ import annotations

import numpy as np
import pytest

from hub.identity.cues import BIN_S
from hub.identity.window import LiveWindow

HOP = 2  # bins per engine hop (0.2 s)


def _walk(rng: np.random.Generator, bins: int) -> np.ndarray:
    """A walker's speed per bin: stretches of walking (0.8-1.6 m/s) and standing, each 1-4 s."""
    speed = np.zeros(bins)
    k = 0
    while k < bins:
        length = int(rng.integers(10, 40))
        speed[k:k + length] = rng.uniform(0.8, 1.6) if rng.random() < 0.6 else 0.0
        k += length
    return speed


def _activity(speed: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The waist's RMS vertical acceleration for that speed: the live engine's prior line, plus noise."""
    return 0.03 + speed / 6.0 + rng.normal(0.0, 0.01, speed.shape)


def _feed(window: LiveWindow, tracks: dict[int, np.ndarray], activity: np.ndarray, upto: int, start: int = 0) -> None:
    for first in range(start, upto, HOP):
        keys = [("cam", t) for t in tracks]
        speed = np.array([s[first:first + HOP] for s in tracks.values()])
        window.add(keys, speed, activity[:, first:first + HOP], first)
        if window.due(first + HOP):
            window.solve(first + HOP)


def test_walkers_are_named_on_their_tracks_and_a_bystander_on_nobody():
    rng = np.random.default_rng(4)
    bins = 300
    walks = [_walk(rng, bins) for _ in range(3)]
    activity = np.array([_activity(w, rng) for w in walks])
    # walker 0 on track 10, walker 1 on 11, walker 2 on 12 then 13 (a break at 15 s), a bystander on 14
    tracks = {10: walks[0], 11: walks[1], 12: np.where(np.arange(bins) < 150, walks[2], np.nan),
              13: np.where(np.arange(bins) >= 152, walks[2], np.nan), 14: _walk(rng, bins)}
    window = LiveWindow([0, 1, 2], window_s=30.0, every_s=1.0, max_iterations=4)
    _feed(window, tracks, activity, bins)
    assert window.solves == pytest.approx(bins * BIN_S, abs=1)
    assert window.holders == {("cam", 10): 0, ("cam", 11): 1, ("cam", 12): 2, ("cam", 13): 2}  # 12 ended
    evidence = np.full((2, 4), 0.3)  # tracks 10 and 14 against the three walkers and a chair (index 3)
    steered = window.steer([("cam", 10), ("cam", 14)], evidence, weight=0.5)
    assert steered == pytest.approx(np.array([[-0.2, 0.8, 0.8, 0.3], [0.8, 0.8, 0.8, 0.3]]))


def test_people_standing_still_are_not_named():
    rng = np.random.default_rng(5)
    bins = 200
    activity = 0.03 + rng.normal(0.0, 0.005, (2, bins))
    tracks = {1: np.zeros(bins), 2: np.zeros(bins)}
    window = LiveWindow([0, 1], window_s=30.0, every_s=1.0, max_iterations=4)
    _feed(window, tracks, activity, bins)
    assert window.holders == {}
    assert window.steer([("cam", 1)], np.zeros((1, 2)), 0.5).tolist() == [[0.0, 0.0]]  # left to the engine


def test_memory_stays_bounded_by_the_window():
    """An hour of short tracks: the window keeps only those within its last 30 s, in fixed rings."""
    rng = np.random.default_rng(6)
    window = LiveWindow([0], window_s=30.0, every_s=1.0, max_iterations=1)
    sizes = []
    for first in range(0, 36_000, HOP):  # one hour of 0.1 s bins
        track = first // 50  # a new track every 5 s
        window.add([("cam", track)], np.full((1, HOP), 1.0), _activity(np.full((1, HOP), 1.0), rng), first)
        if window.due(first + HOP):
            window.solve(first + HOP)
        sizes.append(len(window.tracks))
    assert max(sizes) <= 30 / 5 + 2 and window.activity.shape == (1, 300)
    assert all(t.speed.shape == (300,) for t in window.tracks.values())
