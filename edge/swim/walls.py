"""Wall events from the 100 Hz rows of edge/swim/bins.py: push-offs, turns, stops, touches.

The swimming paper cut its lengths by hand and left detection as future work. What marks a wall
(algorithms.md, Ganzevles 2017; the simulator's turn, docs/simulator-swim.md):
- a push-off: the strongest forward acceleration of a length (the legs extend against the wall,
  about 1 g for a few tenths of a second), from near standstill;
- an open turn: the body turns about 180 deg about the vertical within a second or two, between
  the touch and the next push-off: the rotation rate about the vertical, integrated over the last
  few seconds. Strokes roll the body about its long axis, which is horizontal, so they hardly turn
  it; the diagonal route's 35.75 deg turn is far below the threshold. (The projected heading
  itself is no good here: a sensor pitched up in the turn's tuck, the head's 10-30 deg tilt plus
  50 deg, loses it just when it turns.)
- the end of a set: the swimmer stays still at the wall, and not in the glide after a push-off.
The touch is where the deceleration into the wall ends (the hand takes the last of the speed),
just before the turn's rotation or the rest.
These are pure functions of the rows (index arithmetic on one buffer), no state.
"""

from __future__ import annotations

import numpy as np

from edge.swim.bins import BIN_HZ, DV_X, DV_Y, G, HEAD_X, HEAD_Y, RATE, SURGE, YAW

PUSH_G = 0.6  # forward acceleration of a push-off (smoothed over SMOOTH rows)
PUSH_ONSET_G = 0.1  # where the push-off begins, searching back from its peak
REVERSAL_DEG = 120.0  # rotation about the vertical of a turn, within REVERSAL_S
REVERSAL_S = 3.0  # seed 1 session, 3 s windows: swimming turns at most 48 deg (waist, back), 91 (head,
# breathing about a tilted axis), 39 (kickboard); every open turn 178 or more (kickboard: 140)
TURN_YAW_DPS = 45.0  # rotation rate about the vertical that marks the turn
# At rest (seed 1 session, 2 s windows): rotation at most 2 deg/s, surge SD at most 0.005 g, every
# mounting. Swimming: at least 9.5 deg/s and 0.026 g (the kickboard: its board hardly rolls and the
# kick's surge is small); strokes 20-200 deg/s and 0.08-0.25 g. The thresholds sit between.
STILL_RATE_DPS = 5.0  # at rest: hardly any rotation ...
STILL_SURGE_G = 0.012  # ... nor surge
STILL_S = 2.0
GLIDE_MAX_S = 3.5  # push-off (0.35 s) and glide (up to 2.5 s) and the strokes' start: not a rest
SMOOTH = 10  # rows (0.1 s)
TOUCH_SEARCH_S = 1.5  # the touch lies this close before the turn's rotation
TOUCH_END_G = 0.05  # the deceleration into the wall has ended
BOARD_TOUCH_G = 0.2  # a kickboard's stop at the wall (kicking: within +-0.1 g)
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


def reversed_at(rows: np.ndarray, i: int, since: int) -> bool:
    """Has the body turned by more than REVERSAL_DEG about the vertical over the REVERSAL_S up to
    row i (never looking before row `since`, the length's glide)?"""
    first = i + 1 - rows_for(REVERSAL_S)
    if first < since or first < 0:
        return False
    return abs(float(rows[first:i + 1, YAW].sum())) / BIN_HZ > REVERSAL_DEG


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


def touch_in(rows: np.ndarray, first: int, last: int, board: bool = False) -> int:
    """The wall touch in rows[first..last]: the hand takes the last of the speed, a deceleration
    that ends when the body has stopped at the wall: the strongest deceleration in the window, then
    forward to where it has ended. A kickboard (`board`) is pulled in to the body after the touch,
    a second deceleration of the board, often the stronger: its touch is where the first
    deceleration of at least BOARD_TOUCH_G stops deepening and eases (its first local maximum)."""
    first = max(first, 0)
    accel = forward_accel_g(rows[first:last + 1])
    if not len(accel):
        return last
    if board and (accel <= -BOARD_TOUCH_G).any():
        touch = int(np.argmax(accel <= -BOARD_TOUCH_G))
        while touch + 1 < len(accel) and accel[touch + 1] <= accel[touch]:
            touch += 1  # to the deepest point
        while touch + 1 < len(accel) and accel[touch + 1] > accel[touch] and accel[touch] < -TOUCH_END_G:
            touch += 1  # easing, until it deepens again (the pull-in) or has ended
        return first + touch
    touch = int(np.argmin(accel))
    while touch + 1 < len(accel) and accel[touch + 1] < -TOUCH_END_G:
        touch += 1
    return first + touch


def touch_before_turn(rows: np.ndarray, reversal: int, since: int, board: bool = False) -> int:
    onset = rotation_onset(rows, reversal, since)
    return touch_in(rows, max(since, onset - rows_for(TOUCH_SEARCH_S)), onset, board)


def touch_before_rest(rows: np.ndarray, still_from: int, since: int, board: bool = False) -> int:
    return touch_in(rows, max(since, still_from - rows_for(TOUCH_SEARCH_S + 1.0)), still_from, board)
