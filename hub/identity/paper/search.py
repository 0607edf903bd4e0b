"""The camera-identity paper as our baseline: fragments, eq. 1-3, and every permutation of people.

Kawai et al. (Doshisha Univ.), sec. 3.3. A camera track id is a fragment (ids are not reused).
For each person (a worn sensor) and fragment i, Mae_i is the mean absolute error between the
vertical acceleration predicted from the fragment's speed and the one the sensor measured over
the frames they share, L_i seconds. Fragments with Mae_i >= Ave + SD / sqrt(L_i) are pruned for
that person (eq. 1); the rest score e_i = 1 - Mae_i / max Mae (eq. 2) and eval_i = e_i * L_i
(eq. 3). A person's route is the chain of fragments with the largest total, lost stretches
bridged by virtual fragments (`best_chain`, hub/identity/paper/chain.py). People
are assigned one at a time, each removing the fragments it used; every order (permutation) is
tried and the largest sum over people wins. That is n! orders: `max_permutations` and
`max_transitions` stop the search and say so. See docs/identity.md for every reading taken.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import permutations
from typing import Mapping

import numpy as np

from hub.identity.paper.chain import Chain, best_chain
from hub.identity.paper.features import PaperModel
from hub.identity.paper.fragments import Fragments, TrackArrays, frame_period_s, on_frame_grid, split_fragments

# A tracker handing a person over to a new id may report both ids for a frame or two (0.1 s at
# 20 fps); a route may step between two such fragments.
OVERLAP_TOLERANCE_FRAMES = 2
# A lost stretch is charged Mae = Ave + 1 x SD per frame (the paper: "a standard absolute error, so
# that routes with a loss are not excessively favoured"). With Mae = Ave alone, bridging over any
# of the person's own fragments whose Mae is above average would score more than using it.
VIRTUAL_SD_MULTIPLE = 1.0
TIE_RELATIVE = 1e-9  # sums over people in another order differ by rounding only; keep the first


@dataclass(frozen=True)
class FragmentErrors:
    """Eq. 1-3 for every (person, fragment): rows follow `people`, columns `Fragments.track_id`."""

    people: tuple[str, ...]
    mae_g: np.ndarray  # (P, K) Mae_i; NaN where the person and the fragment share no frame
    frames: np.ndarray  # (P, K) frames with both a speed and a sensor value
    length_s: np.ndarray  # (P, K) L_i: those frames x the frame period
    kept: np.ndarray  # (P, K) survives eq. 1's pruning
    value: np.ndarray  # (P, K) eval_i = e_i * L_i (eq. 3)
    normalization_g: float  # max Mae_i over every person and fragment (eq. 2)
    virtual_e: float  # e of a virtual fragment: Mae = Ave + k SD (VIRTUAL_SD_MULTIPLE)
    frame_s: float  # the frame period: a lost stretch of n frames is a virtual fragment of n x frame_s


def fragment_errors(fragments: Fragments, verticals: np.ndarray, people: tuple[str, ...],
                    model: PaperModel, frame_s: float,
                    virtual_sd_multiple: float = VIRTUAL_SD_MULTIPLE) -> FragmentErrors:
    """Mae_i, pruning and scores; `verticals` is (P, frames) on the frame grid, NaN where unknown.

    frame_s is the frame period. virtual_sd_multiple k sets a virtual fragment's Mae = Ave + k SD.
    L_i is the fragment's length on the time axis in seconds (the paper gives no unit). For eq. 1
    that is the reading under which SD / sqrt(L_i) is a standard error: with features averaged
    over a 1 s window, a fragment holds about one independent sample per second, not per frame.
    """
    count = len(fragments.track_id)
    label = np.repeat(np.arange(count), np.diff(fragments.offsets))
    predicted = model.predict(fragments.speed_mps)  # P_eval
    measured = verticals[:, fragments.frame_index]  # S_eval, (P, N)
    error = np.abs(predicted[None, :] - measured)
    valid = np.isfinite(error)
    frames = np.zeros((len(people), count))
    sums = np.zeros((len(people), count))
    for p in range(len(people)):
        frames[p] = np.bincount(label, weights=valid[p], minlength=count)
        sums[p] = np.bincount(label, weights=np.where(valid[p], error[p], 0.0), minlength=count)
    with np.errstate(invalid="ignore", divide="ignore"):
        mae = np.where(frames > 0, sums / frames, np.nan)
        length_s = frames * frame_s
        kept = (frames > 0) & (mae < model.pruning_limit_g(length_s))  # eq. 1
    finite = mae[np.isfinite(mae)]
    # eq. 2's "maximum Mae_i observed this time": over all people and fragments, before pruning,
    # so e is on one scale for every person and does not depend on the order people are taken.
    normalization = float(finite.max()) if finite.size else 0.0
    scale = normalization if normalization > 0 else np.inf  # every Mae 0: every e is 1
    e = 1.0 - mae / scale  # eq. 2
    value = np.where(kept, e * length_s, 0.0)  # eq. 3
    virtual_mae = model.ave_abs_error_g + virtual_sd_multiple * model.sd_abs_error_g
    return FragmentErrors(people, mae, frames, length_s, kept, value, normalization,
                          float(1.0 - virtual_mae / scale), frame_s)


@dataclass(frozen=True)
class OrderResult:
    """People assigned one at a time in `order`: each route as fragment indices, and scores."""

    order: tuple[str, ...]
    routes: dict[str, tuple[int, ...]]
    scores: dict[str, float]
    total: float
    transitions: int


def assign_in_order(order: tuple[str, ...], fragments: Fragments, errors: FragmentErrors,
                    overlap_tolerance_frames: int = OVERLAP_TOLERANCE_FRAMES) -> OrderResult:
    """Best route for each person in turn; the fragments a route uses are gone for the next."""
    available = np.ones(len(fragments.track_id), dtype=bool)
    routes, scores, transitions = {}, {}, 0
    for name in order:
        p = errors.people.index(name)
        candidates = np.flatnonzero(errors.kept[p] & available)
        chain: Chain = best_chain(fragments.start_frame[candidates], fragments.end_frame[candidates],
                                  errors.value[p, candidates], errors.virtual_e * errors.frame_s,
                                  overlap_tolerance_frames)
        used = candidates[list(chain.fragments)]
        available[used] = False
        routes[name] = tuple(int(k) for k in used)
        scores[name] = chain.score
        transitions += chain.transitions
    return OrderResult(tuple(order), routes, scores, float(sum(scores.values())), transitions)


@dataclass(frozen=True)
class RouteLink:
    track_id: int
    start_ns: int
    end_ns: int
    frames: int
    length_s: float  # L_i
    mae_g: float
    score: float  # eval_i


@dataclass(frozen=True)
class PaperResult:
    """The winning order's routes, the work done, and whether the search was cut short."""

    routes: dict[str, tuple[RouteLink, ...]]
    order: tuple[str, ...]
    total_score: float
    person_scores: dict[str, float]
    permutations_tried: int
    permutations_needed: int
    transitions: int
    stopped: bool
    reason: str
    errors: FragmentErrors | None = field(default=None, repr=False)
    # per person: (time_ns, track_id, x_m, y_m) of the route's rows, time-sorted
    route_rows: dict[str, tuple[np.ndarray, ...]] = field(default_factory=dict, repr=False)

    def assignment(self, frame_ns: np.ndarray) -> dict[str, np.ndarray]:
        """Per person, the track id at each frame time: 0 where the route has no row (virtual)."""
        frames = np.asarray(frame_ns, dtype=np.int64)
        out = {}
        for name, (times, ids, _, _) in self.route_rows.items():
            ids_here = np.zeros(len(frames), dtype=np.int64)
            if times.size:
                k = np.minimum(np.searchsorted(times, frames), len(times) - 1)
                hit = times[k] == frames
                ids_here[hit] = ids[k[hit]]
            out[name] = ids_here
        return out

    def positions(self, frame_ns: np.ndarray) -> dict[str, np.ndarray]:
        """Per person, (F, 2) positions: the route's rows, linearly interpolated over lost stretches
        (the paper's linear interpolation); NaN before the route's first and after its last row."""
        frames = np.asarray(frame_ns, dtype=np.int64)
        out = {}
        for name, (times, _, x, y) in self.route_rows.items():
            xy = np.full((len(frames), 2), np.nan)
            if times.size:
                inside = (frames >= times[0]) & (frames <= times[-1])
                xy[inside, 0] = np.interp(frames[inside], times, x)
                xy[inside, 1] = np.interp(frames[inside], times, y)
            out[name] = xy
        return out


def identify(tracks: TrackArrays, people: Mapping[str, tuple[np.ndarray, np.ndarray]], model: PaperModel,
             max_permutations: int, max_transitions: int | None = None,
             overlap_tolerance_frames: int = OVERLAP_TOLERANCE_FRAMES,
             virtual_sd_multiple: float = VIRTUAL_SD_MULTIPLE) -> PaperResult:
    """The paper's identification: every permutation of people, best total of eq. 3 wins.

    people: name -> (time_ns, vertical acceleration in g per frame, from `vertical_acceleration`).
    Permutations are taken in lexicographic order of the names. The search stops, keeping the best
    order found so far and setting `stopped`, once `max_permutations` orders have been tried or
    (checked between orders) `max_transitions` DP transitions have been spent.
    """
    if max_permutations < 1:
        raise ValueError(f"max_permutations {max_permutations} must be >= 1")
    fragments = split_fragments(tracks, model.window_s)
    frames = np.asarray(tracks.frame_ns, dtype=np.int64)
    names = tuple(sorted(people))
    verticals = np.array([on_frame_grid(frames, n, *people[n]) for n in names]).reshape(len(names), len(frames))
    errors = fragment_errors(fragments, verticals, names, model, frame_period_s(frames), virtual_sd_multiple)
    needed = math.factorial(len(names))
    best = OrderResult((), {n: () for n in names}, {n: 0.0 for n in names}, 0.0, 0)  # if no order runs
    first = True
    tried = transitions = 0
    reason = ""
    for order in permutations(names):
        if tried >= max_permutations:
            reason = f"{len(names)} people need {needed} permutations; stopped at max_permutations={max_permutations}"
            break
        if max_transitions is not None and transitions >= max_transitions:
            reason = (f"{transitions} DP transitions reached max_transitions={max_transitions} "
                      f"after {tried} of {needed} permutations")
            break
        result = assign_in_order(order, fragments, errors, overlap_tolerance_frames)
        tried += 1
        transitions += result.transitions
        if first or result.total > best.total + TIE_RELATIVE * max(abs(best.total), 1.0):
            best, first = result, False
    routes, rows = _routes(best, fragments, errors, tracks)
    return PaperResult(routes, best.order, best.total, best.scores, tried, needed, transitions,
                       bool(reason), reason, errors, rows)


def _routes(best: OrderResult, fragments: Fragments, errors: FragmentErrors,
            tracks: TrackArrays) -> tuple[dict[str, tuple[RouteLink, ...]], dict[str, tuple[np.ndarray, ...]]]:
    times = np.asarray(tracks.time_ns, dtype=np.int64)
    x, y = np.asarray(tracks.x_m, dtype=float), np.asarray(tracks.y_m, dtype=float)
    routes, rows = {}, {}
    for name, used in best.routes.items():
        p = errors.people.index(name)
        links, chosen = [], []
        for k in used:
            own = fragments.rows[fragments.offsets[k]:fragments.offsets[k + 1]]
            links.append(RouteLink(int(fragments.track_id[k]), int(times[own[0]]), int(times[own[-1]]),
                                   int(errors.frames[p, k]), float(errors.length_s[p, k]),
                                   float(errors.mae_g[p, k]), float(errors.value[p, k])))
            chosen.append(own)
        own_rows = np.concatenate(chosen) if chosen else np.zeros(0, dtype=np.int64)
        ids = np.repeat([link.track_id for link in links], [len(c) for c in chosen]).astype(np.int64)
        order = np.argsort(times[own_rows], kind="stable")
        sorted_times = times[own_rows][order]
        # where two route fragments overlap (the tolerance), the later fragment holds the frame
        last = np.r_[sorted_times[1:] != sorted_times[:-1], True] if len(order) else np.zeros(0, bool)
        rows[name] = (sorted_times[last], ids[order][last], x[own_rows][order][last], y[own_rows][order][last])
        routes[name] = tuple(links)
    return routes, rows
