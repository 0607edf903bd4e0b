"""Which track id follows whom, frame by frame: occlusion gaps, switches, merges, splits, false tracks.

`IdentityModel.step` takes one frame of truth (who is in view, pairwise distances, speeds) and
returns the tracks the tracker reports in that frame, each with the people it covers. Order of
events within a frame:
1. gaps: a tracked person's hazard (base + occluded + still) may start a gap; hidden people and
   people out of view lose their track (a person who is seen again gets a new id);
2. merges: a pair closer than `merges.distance_m` decides once per encounter whether it fuses;
   fused pairs (linked transitively) form one group until a link stretches past the release distance;
3. switches: two single people closer than `switches.distance_m` decide once per encounter, at the
   closest approach (the first frame their distance grows), whether their tracks swap;
4. ids: each group keeps the oldest unclaimed id among its members' tracks (a group that breaks up
   leaves the id to one part, chosen at random), or gets a new id;
5. splits: a single tracked person may grow a second track for a while; when it ends, either the
   second track dies or it lives on and the first one dies (`splits.takeover_probability`);
6. false tracks: Poisson births inside the view, exponential lifetimes, random walks.
Random draws happen in a fixed order, so a seed gives one outcome.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import numpy as np

from sim_devices.camera.params import TrackerParams

Pair = tuple[int, int]
COUNTERS = ("tracks", "gaps", "exits", "switches", "merges", "splits", "split_takeovers", "false_tracks")


@dataclass
class _Split:
    track_id: int
    left_s: float
    offset_m: tuple[float, float]


@dataclass
class _FalseTrack:
    track_id: int
    x_m: float
    y_m: float
    height_m: float
    left_s: float


@dataclass(frozen=True)
class FrameTracks:
    """One frame's tracks: person groups (id, person indices), splits (id, person, offset), false tracks."""

    groups: list[tuple[int, list[int]]]
    splits: list[tuple[int, int, tuple[float, float]]]
    false_tracks: list[tuple[int, float, float, float]]  # (id, x, y, height)


class IdentityModel:
    """Track-id state over `people` persons; `fov` = (x_min, y_min, x_max, y_max) for false tracks."""

    def __init__(self, params: TrackerParams, rng: np.random.Generator, people: int, dt_s: float,
                 fov: tuple[float, float, float, float]):
        self.params, self.rng, self.dt, self.fov = params, rng, dt_s, fov
        self.owner = np.zeros(people, dtype=np.int64)  # track id following each person; 0: none
        self.gap_left_s = np.zeros(people)
        self.gap_until_moving = np.zeros(people, dtype=bool)
        self.visible = np.zeros(people, dtype=bool)
        self.links: set[Pair] = set()  # fused pairs
        self.merge_decided: dict[Pair, bool] = {}
        self.encounters: dict[Pair, list[float]] = {}  # switch encounters: [closest distance so far, decided 0/1]
        self.splits: dict[int, _Split] = {}
        self.false_tracks: list[_FalseTrack] = []
        self.next_id = 1
        self.counters: Counter[str] = Counter({name: 0 for name in COUNTERS})

    def _new_id(self, counter: str) -> int:
        self.next_id += 1
        self.counters[counter] += 1
        return self.next_id - 1

    def step(self, in_view: np.ndarray, distance_m: np.ndarray, speed_mps: np.ndarray) -> FrameTracks:
        """Advance one frame. `in_view` (P,) bool, `distance_m` (P, P) true distances, `speed_mps` (P,)."""
        visible = self._gaps(in_view, distance_m, speed_mps)
        self._merges(visible, distance_m)
        groups = self._components(visible)
        single = np.zeros(len(visible), dtype=bool)
        for members in groups:
            if len(members) == 1:
                single[members[0]] = True
        self._switches(visible, single, distance_m)
        tracks = self._assign(groups)
        splits = self._splits(visible, single)
        return FrameTracks(tracks, splits, self._false_tracks())

    def _gaps(self, in_view: np.ndarray, distance_m: np.ndarray, speed_mps: np.ndarray) -> np.ndarray:
        gaps, dt = self.params.gaps, self.dt
        draws = self.rng.random(len(in_view))
        moving = speed_mps >= gaps.still_speed_mps
        self.gap_left_s[~in_view] = 0.0  # a gap belongs to a stay in view
        self.gap_until_moving[~in_view] = False
        self.gap_left_s = np.maximum(self.gap_left_s - dt, 0.0)
        hold = self.gap_until_moving & ~moving  # lost while still: back only once moving again
        self.gap_left_s[hold] = np.maximum(self.gap_left_s[hold], dt)
        self.gap_until_moving &= self.gap_left_s > 0.0
        near = (distance_m < gaps.occlusion_distance_m) & in_view[None, :] & in_view[:, None]
        np.fill_diagonal(near, False)
        still_hazard = gaps.still_rate_per_s * ~moving
        hazard = gaps.rate_per_min / 60.0 + gaps.occluded_rate_per_s * near.any(axis=1) + still_hazard
        tracked = in_view & (self.owner != 0) & (self.gap_left_s <= 0.0)
        for person in np.flatnonzero(tracked & (draws < -np.expm1(-hazard * dt))).tolist():
            duration = self.rng.lognormal(math.log(gaps.median_s), gaps.spread)
            self.gap_left_s[person] = min(max(duration, dt), gaps.max_s)
            self.gap_until_moving[person] = bool(self.rng.random() * hazard[person] < still_hazard[person])
            self.counters["gaps"] += 1
        visible = in_view & (self.gap_left_s <= 0.0)
        self.counters["exits"] += int(np.sum(self.visible & ~in_view & (self.owner != 0)))
        self.owner[~visible] = 0
        self.visible = visible
        return visible

    def _merges(self, visible: np.ndarray, distance_m: np.ndarray) -> None:
        merges = self.params.merges
        release_m = merges.distance_m * merges.release_factor
        for pair in list(self.merge_decided):
            if not (visible[pair[0]] and visible[pair[1]]) or distance_m[pair] > release_m:
                del self.merge_decided[pair]
                self.links.discard(pair)
        for pair in _close_pairs(visible, distance_m, merges.distance_m):
            if pair not in self.merge_decided:
                fused = bool(self.rng.random() < merges.probability)
                self.merge_decided[pair] = fused
                if fused:
                    self.links.add(pair)
                    self.counters["merges"] += 1

    def _components(self, visible: np.ndarray) -> list[list[int]]:
        parent = list(range(len(visible)))

        def root(node: int) -> int:
            while parent[node] != node:
                parent[node] = parent[parent[node]]
                node = parent[node]
            return node

        for first, second in sorted(self.links):
            parent[root(first)] = root(second)
        groups: dict[int, list[int]] = {}
        for person in np.flatnonzero(visible).tolist():
            groups.setdefault(root(person), []).append(person)
        return sorted(groups.values())

    def _switches(self, visible: np.ndarray, single: np.ndarray, distance_m: np.ndarray) -> None:
        switches = self.params.switches
        release_m = switches.distance_m * switches.release_factor
        for pair in list(self.encounters):
            if not (visible[pair[0]] and visible[pair[1]]) or distance_m[pair] > release_m:
                del self.encounters[pair]
        for pair in _close_pairs(visible, distance_m, switches.distance_m):
            self.encounters.setdefault(pair, [math.inf, 0.0])
        for (first, second), state in self.encounters.items():
            now = float(distance_m[first, second])
            if state[1] or now <= state[0]:
                state[0] = min(state[0], now)
                continue
            state[1] = 1.0  # past the closest approach: decide once
            owners = self.owner[first], self.owner[second]
            if single[first] and single[second] and 0 not in owners and owners[0] != owners[1]:
                if self.rng.random() < switches.probability:
                    self.owner[first], self.owner[second] = owners[1], owners[0]
                    self.counters["switches"] += 1

    def _assign(self, groups: list[list[int]]) -> list[tuple[int, list[int]]]:
        claimed: set[int] = set()
        tracks = []
        for index in self.rng.permutation(len(groups)).tolist():
            members = groups[index]
            candidates = sorted({int(self.owner[m]) for m in members} - claimed - {0})
            track_id = candidates[0] if candidates else self._new_id("tracks")
            self.owner[members] = track_id
            claimed.add(track_id)
            tracks.append((track_id, members))
        return sorted(tracks)

    def _splits(self, visible: np.ndarray, single: np.ndarray) -> list[tuple[int, int, tuple[float, float]]]:
        splits, dt = self.params.splits, self.dt
        draws = self.rng.random(len(visible))
        for person, split in list(self.splits.items()):
            split.left_s -= dt
            if not (visible[person] and single[person]):
                del self.splits[person]
            elif split.left_s <= 0.0:
                del self.splits[person]
                if self.rng.random() < splits.takeover_probability:
                    self.owner[person] = split.track_id  # the first track ends, the second goes on
                    self.counters["split_takeovers"] += 1
        start = visible & single & (self.owner != 0) & (draws < -math.expm1(-splits.rate_per_min / 60.0 * dt))
        for person in np.flatnonzero(start).tolist():
            if person in self.splits:
                continue
            angle = self.rng.uniform(0.0, 2.0 * math.pi)
            offset = (splits.offset_m * math.cos(angle), splits.offset_m * math.sin(angle))
            self.splits[person] = _Split(self._new_id("splits"), max(self.rng.exponential(splits.mean_s), dt), offset)
        return [(split.track_id, person, split.offset_m) for person, split in sorted(self.splits.items())]

    def _false_tracks(self) -> list[tuple[int, float, float, float]]:
        false, dt = self.params.false_tracks, self.dt
        x_min, y_min, x_max, y_max = self.fov
        step_m = false.walk_mps * math.sqrt(dt)
        alive = []
        for track in self.false_tracks:
            track.left_s -= dt
            track.x_m += self.rng.normal(0.0, step_m)
            track.y_m += self.rng.normal(0.0, step_m)
            if track.left_s > 0.0 and x_min <= track.x_m <= x_max and y_min <= track.y_m <= y_max:
                alive.append(track)
        for _ in range(int(self.rng.poisson(false.rate_per_min / 60.0 * dt))):
            life = max(self.rng.exponential(false.mean_s), false.min_s, dt)
            alive.append(_FalseTrack(self._new_id("false_tracks"), self.rng.uniform(x_min, x_max),
                                     self.rng.uniform(y_min, y_max), self.rng.uniform(1.0, 1.9), life))
        self.false_tracks = alive
        return [(t.track_id, t.x_m, t.y_m, t.height_m) for t in alive]


def _close_pairs(visible: np.ndarray, distance_m: np.ndarray, limit_m: float) -> list[Pair]:
    """(i, j), i < j, both visible and closer than `limit_m`, in index order."""
    close = np.triu(distance_m < limit_m, 1) & visible[None, :] & visible[:, None]
    first, second = np.nonzero(close)
    return list(zip(first.tolist(), second.tolist()))
