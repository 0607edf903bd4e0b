"""Ours in hindsight, live: the last `window_s` of every walker's activity and every track's speed, solved at once.

The live engine (hub/identity/engine.py) weighs each track against each agent with evidence that
forgets within seconds, one hop at a time; in a crowd of walkers whose cues are weak per bin that
is a guess among many (docs/identity.md). This keeps the same per-bin signals the engine already
computes, a walker's waist activity (RMS vertical acceleration, `AgentCues`) and a track's speed
(`TrackCues`), for the last `window_s` of every track, ended ones included, and every `every_s`
names the window's fragments all at once as hub/identity/hindsight.py does for a whole session
(the line from activity to speed learnt again from the population prior each time, so a bad
window never carries over). The engine then leans its evidence for walkers towards that choice
(`steer`); a track born since the last solve is left to the engine's own cues and rules.

Memory is bounded by the window: a fixed ring per walker, one per track seen in the window.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hub.identity.cues import BIN_S, MOVING_MPS, NO_BIN
from hub.identity.hindsight import PRIOR, Samples, solve

TrackKey = tuple[str, int]  # (camera, track id), as the engine keys its tracks
CANDIDATES = 10  # walkers considered per fragment, its best-fitting ones: bounds the program in a crowd
STEER_AFTER_S = 1.0  # a choice made on less of the walker moving on the track is left to the
# engine: two people standing still fit any still track alike, and a second or two names nobody


@dataclass
class _TrackBins:
    last: int  # the newest bin with a speed
    speed: np.ndarray  # ring over bins, NaN unknown
    bins: np.ndarray = field(repr=False)  # the bin number each slot holds


class LiveWindow:
    """The walkers' window for one camera; `walkers` are the engine's agent indices of people on foot."""

    def __init__(self, walkers: list[int], window_s: float, every_s: float, max_iterations: int):
        self.walkers = list(walkers)
        self.capacity = max(int(round(window_s / BIN_S)), 1)
        self.every = max(int(round(every_s / BIN_S)), 1)
        self.max_iterations = max_iterations
        self.activity = np.full((len(walkers), self.capacity), np.nan)
        self.activity_bins = np.full(self.capacity, NO_BIN, dtype=np.int64)
        self.tracks: dict[TrackKey, _TrackBins] = {}
        self.next_solve = NO_BIN
        self.holders: dict[TrackKey, int] = {}  # the last solve: track -> engine agent index
        self.seen: set[TrackKey] = set()  # ... and the tracks it has seen long enough to steer
        self.solves = 0

    def add(self, keys: list[TrackKey], speed: np.ndarray, activity: np.ndarray, first: int) -> None:
        """Bins first .. first + count - 1: speed (tracks, count) of `keys`, activity (all agents, count)."""
        count = activity.shape[1]
        bins = np.arange(first, first + count)
        slots = bins % self.capacity
        self.activity_bins[slots] = bins
        self.activity[:, slots] = activity[self.walkers]
        for key, row in zip(keys, speed):
            known = np.flatnonzero(np.isfinite(row))
            if not len(known):
                continue
            track = self.tracks.get(key)
            if track is None:
                track = self.tracks[key] = _TrackBins(int(bins[known[-1]]), np.full(self.capacity, np.nan),
                                                      np.full(self.capacity, NO_BIN, dtype=np.int64))
            track.last = max(track.last, int(bins[known[-1]]))
            track.speed[slots[known]] = row[known]
            track.bins[slots[known]] = bins[known]

    def due(self, end: int) -> bool:
        if self.next_solve == NO_BIN:
            self.next_solve = end + self.every
        return end >= self.next_solve

    def solve(self, end: int) -> None:
        """Name the fragments of bins end - capacity .. end - 1 (the engine's scored bins)."""
        self.next_solve = end + self.every
        low = end - self.capacity
        for key in [k for k, t in self.tracks.items() if t.last < low]:
            del self.tracks[key]
        keys, labels, times, speeds, starts, ends = [], [], [], [], [], []
        for key, track in self.tracks.items():
            inside = np.flatnonzero((track.bins >= low) & (track.bins < end) & np.isfinite(track.speed))
            if not len(inside):
                continue
            order = inside[np.argsort(track.bins[inside])]
            labels.append(np.full(len(order), len(keys)))
            times.append(track.bins[order])
            speeds.append(track.speed[order])
            starts.append(int(track.bins[order[0]]))
            ends.append(int(track.bins[order[-1]]))
            keys.append(key)
        self.solves += 1
        self.seen = {key for key, t in zip(keys, times) if len(t) * BIN_S >= STEER_AFTER_S}
        self.holders = {}
        if not keys or not self.walkers:
            return
        time = np.concatenate(times)
        slots = time % self.capacity
        measured = np.where((self.activity_bins[slots] == time)[None, :], self.activity[:, slots], np.nan)
        samples = Samples(np.concatenate(labels), np.concatenate(speeds), measured, np.array(starts), np.array(ends),
                          BIN_S)
        solution = solve(samples, PRIOR, self.max_iterations, overlap_tolerance=1, candidates=CANDIDATES)
        label, speed = samples.label, samples.speed_mps
        with np.errstate(invalid="ignore"):
            moving = (speed > MOVING_MPS)[None, :] & np.isfinite(measured)  # (walkers, samples)
        for p, k in solution.chosen:
            if np.count_nonzero(moving[p, label == k]) * BIN_S < STEER_AFTER_S:
                self.seen.discard(keys[k])  # chosen on stillness (or a moment) alone: a guess, no nudge
            else:
                self.holders[keys[k]] = self.walkers[p]

    def steer(self, keys: list[TrackKey], evidence: np.ndarray, weight: float) -> np.ndarray:
        """The engine's evidence (tracks, agents), on the tracks the last solve saw: `weight` less for the walker
        it chose, `weight` more for every other walker. A nudge, not an override: evidence the engine has
        gathered over minutes (a walker's stature, its gait) can still outweigh one window."""
        out = evidence.copy()
        for row, key in enumerate(keys):
            if key not in self.seen:
                continue
            out[row, self.walkers] += weight
            holder = self.holders.get(key)
            if holder is not None:
                out[row, holder] -= 2 * weight
        return out
