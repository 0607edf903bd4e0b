"""Wall events from the 100 Hz rows of edge/swim_bins.py: push-offs, turns, stops, touches.

The swimming paper cut its lengths by hand and left detection as future work. What marks a wall
(algorithms.md, Ganzevles 2017; the simulator's turn, docs/simulator-swim.md):
- a push-off: the strongest forward acceleration of a length (the legs extend against the wall,
  about 1 g for a few tenths of a second), from near standstill;
- an open turn: the body's heading reverses (about 180 deg about the vertical) within a second or
  two, between the touch and the next push-off. Strokes roll the body about its long axis, which
  is horizontal, so they hardly move the heading; the diagonal route's 35.75 deg turn is far below
  the threshold;
- the end of a set: the swimmer stays still at the wall.
The touch is where the deceleration into the wall ends (the hand takes the last of the speed),
just before the turn's rotation or the rest.
These are pure functions of the rows (index arithmetic on one buffer), no state.
"""

from __future__ import annotations

import math

import numpy as np

from edge.swim_bins import BIN_HZ, DV_X, DV_Y, G, HEAD_X, HEAD_Y, RATE, SURGE, YAW

PUSH_G = 0.6  # forward acceleration of a push-off (smoothed over SMOOTH rows)
PUSH_ONSET_G = 0.1  # where the push-off begins, searching back from its peak
REVERSAL_DEG = 120.0  # heading change of a turn
TURN_YAW_DPS = 45.0  # rotation rate about the vertical that marks the turn
STILL_RATE_DPS = 15.0  # at rest: hardly any rotation (strokes roll the body at 50-200 deg/s) ...
STILL_SURGE_G = 0.03  # ... nor surge (strokes: 0.1-0.5 g)
STILL_S = 2.0
REFERENCE_S = (5.0, 2.5)  # the heading before a turn: rows this long ago
SMOOTH = 10  # rows (0.1 s)
TOUCH_SEARCH_S = 1.5  # the touch lies this close before the turn's rotation
TOUCH_END_G = 0.05  # the deceleration into the wall has ended
VALID_HEADING = 0.5  # forward axis projection below this: pointing up or down, heading undefined


def rows_for(seconds: float) -> int:
    return int(round(seconds * BIN_HZ))


def forward_accel_g(rows: np.ndarray) -> np.ndarray:
    """Horizontal earth-frame acceleration along the body's heading (g), per row, smoothed."""
    head = rows[:, [HEAD_X, HEAD_Y]]
    norm = np.hypot(head[:, 0], head[:, 1])
    along = (rows[:, DV_X] * head[:, 0] + rows[:, DV_Y] * head[:, 1]) / np.maximum(norm, 1e-6) * BIN_HZ / G
    along[norm < VALID_HEADING] = 0.0  # pointing up or down (or the AHRS still settling): no push-off
    if len(along) < SMOOTH:
        return along
    return np.convolve(along, np.ones(SMOOTH) / SMOOTH, mode="same")


def find_push(rows: np.ndarray, first: int, last: int) -> tuple[int, int] | None:
    """(onset, peak) of the first push-off whose peak lies in rows[first..last], or None."""
    lo = max(0, first - rows_for(1.0))
    accel = forward_accel_g(rows[lo:last + 1])
    above = np.flatnonzero(accel[first - lo:] >= PUSH_G)
    if not len(above):
        return None
    start = first - lo + int(above[0])
    end = start
    while end + 1 < len(accel) and accel[end + 1] >= PUSH_G:
        end += 1
    if end + 1 >= len(accel):
        return None  # the push-off is still going on: wait for its peak
    peak = start + int(np.argmax(accel[start:end + 1]))
    onset = peak
    while onset > 0 and accel[onset - 1] > PUSH_ONSET_G:
        onset -= 1
    return lo + onset, lo + peak


def heading(rows: np.ndarray, first: int, last: int) -> float | None:
    """Circular mean heading over rows[first..last] where it is defined, or None."""
    part = rows[max(0, first):last + 1]
    if not len(part):
        return None
    norm = np.hypot(part[:, HEAD_X], part[:, HEAD_Y])
    good = part[norm >= VALID_HEADING]
    if len(good) < len(part) // 2:
        return None
    return math.atan2(float(good[:, HEAD_Y].sum()), float(good[:, HEAD_X].sum()))


def reversed_at(rows: np.ndarray, i: int, since: int) -> bool:
    """Has the heading at row i turned by more than REVERSAL_DEG from its value a few seconds
    before (never looking before row `since`, the length's glide)?"""
    far, near = rows_for(REFERENCE_S[0]), rows_for(REFERENCE_S[1])
    if i - far < since:
        return False
    before = heading(rows, i - far, i - near)
    now = heading(rows, i - rows_for(0.3), i)
    if before is None or now is None:
        return False
    return abs(math.degrees(math.remainder(now - before, 2 * math.pi))) > REVERSAL_DEG


def still_until(rows: np.ndarray, i: int) -> bool:
    """Have the last STILL_S seconds up to row i been at rest (no stroke rolls the body, no surge)?"""
    n = rows_for(STILL_S)
    if i + 1 < n:
        return False
    part = rows[i + 1 - n:i + 1]
    return bool(part[:, RATE].mean() < STILL_RATE_DPS and part[:, SURGE].std() < STILL_SURGE_G)


def rotation_onset(rows: np.ndarray, event: int, since: int) -> int:
    """Where the turn's rotation about the vertical began, searching back from row `event`."""
    yaw = np.abs(rows[since:event + 1, YAW])
    if len(yaw) >= SMOOTH:
        yaw = np.convolve(yaw, np.ones(SMOOTH) / SMOOTH, mode="same")
    start = len(yaw) - 1
    while start > 0 and yaw[start - 1] > TURN_YAW_DPS:
        start -= 1
    return since + start


def touch_in(rows: np.ndarray, first: int, last: int) -> int:
    """The wall touch in rows[first..last]: the hand takes the last of the speed, a deceleration
    that ends when the body has stopped at the wall: the strongest deceleration in the window, then
    forward to where it has ended."""
    first = max(first, 0)
    accel = forward_accel_g(rows[first:last + 1])
    if not len(accel):
        return last
    touch = int(np.argmin(accel))
    while touch + 1 < len(accel) and accel[touch + 1] < -TOUCH_END_G:
        touch += 1
    return first + touch


def touch_before_turn(rows: np.ndarray, reversal: int, since: int) -> int:
    onset = rotation_onset(rows, reversal, since)
    return touch_in(rows, max(since, onset - rows_for(TOUCH_SEARCH_S)), onset)


def touch_before_rest(rows: np.ndarray, still_from: int, since: int) -> int:
    return touch_in(rows, max(since, still_from - rows_for(TOUCH_SEARCH_S + 1.0)), still_from)
