"""One person's route through the fragment network: the paper's dynamic programming (sec. 3.3).

A route is a chain of fragments ordered in time that must not overlap (beyond a tolerance of a
frame or two, for trackers that hand a person over to a new id with one frame in common). Its
score is the sum of eval_i = e_i * L_i (eq. 3) over its fragments plus, for every lost stretch
between two consecutive fragments, a virtual fragment scored as if it had the standard absolute
error Ave: e_virtual * (frames in the gap). Nothing is added before the first or after the last
fragment: the paper puts virtual fragments only where a route breaks off and later resumes.

With fragments sorted by start, best[i] = eval_i + max(0, max_j best[j] + bridge(j, i)) over the
earlier fragments j that end before i starts: O(n^2) transitions for n candidate fragments.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Chain:
    """Indices (into the arrays given to `best_chain`) in time order, the route's score, the work."""

    fragments: tuple[int, ...]
    score: float
    transitions: int  # (earlier, later) fragment pairs examined


def best_chain(start_frame: np.ndarray, end_frame: np.ndarray, value: np.ndarray,
               virtual_value_per_frame: float, overlap_tolerance_frames: int) -> Chain:
    """The chain of fragments with the largest total score.

    start_frame, end_frame: first and last frame index of each fragment (inclusive); value: its
    eval_i (eq. 3). A chain may go from j to i when j starts before i, ends before i ends, and the
    two share at most `overlap_tolerance_frames` frames. The bridge between them scores
    virtual_value_per_frame for each frame strictly between them. An empty chain scores 0, so a
    chain is returned only when its score is positive. Ties go to the earliest fragments.
    """
    starts = np.asarray(start_frame, dtype=np.int64)
    ends = np.asarray(end_frame, dtype=np.int64)
    values = np.asarray(value, dtype=float)
    if not (len(starts) == len(ends) == len(values)):
        raise ValueError(f"best_chain: {len(starts)} starts, {len(ends)} ends and {len(values)} values differ")
    if np.any(ends < starts):
        raise ValueError(f"best_chain: fragment {int(np.flatnonzero(ends < starts)[0])} ends before it starts")
    count = len(starts)
    if count == 0:
        return Chain((), 0.0, 0)
    order = np.lexsort((ends, starts))
    starts, ends, values = starts[order], ends[order], values[order]
    best = np.empty(count)
    previous = np.full(count, -1, dtype=np.int64)
    for i in range(count):
        best[i] = values[i]
        if i == 0:
            continue
        earlier = slice(0, i)
        shared = ends[earlier] - starts[i] + 1  # frames both fragments cover
        allowed = (starts[earlier] < starts[i]) & (ends[earlier] < ends[i]) & (shared <= overlap_tolerance_frames)
        if not allowed.any():
            continue
        gap = np.maximum(starts[i] - ends[earlier] - 1, 0)
        through = np.where(allowed, best[earlier] + virtual_value_per_frame * gap, -np.inf)
        j = int(np.argmax(through))
        if through[j] > 0:  # otherwise starting the route here is better
            best[i] += through[j]
            previous[i] = j
    transitions = count * (count - 1) // 2
    last = int(np.argmax(best))
    if best[last] <= 0:
        return Chain((), 0.0, transitions)
    chain = []
    while last >= 0:
        chain.append(int(order[last]))
        last = int(previous[last])
    return Chain(tuple(reversed(chain)), float(best[int(np.argmax(best))]), transitions)
