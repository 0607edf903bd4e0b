"""A whole set on one time grid: rest at the wall, lengths, open turns, rest after the last touch.

The reference point (body centre) floats at the wall for `walls.rest_*` s, goes from upright to
horizontal in `walls.posture_change_s`, then swims `lengths` lengths (path.py); between lengths it
stays at the wall point while the body turns (open turn: touch, tuck with the trunk pitched up
`walls.turn_pitch_deg`, rotate about 180 deg, feet plant, push off on the side); after the last
touch it comes upright again and holds the wall. Flip turns are not simulated.

Besides the position, the timeline carries the *base* attitude every body segment shares (yaw =
heading of travel during lengths, the turning body in turns; the rest/turn pitch; the push-off
roll) and the stroke state (activity envelope, cycle phase, amplitude jitter, sightings), from
which attitude.py builds each segment's own motion. Every base curve between two key instants is
a quintic smoothstep, so angular rates are continuous and angular accelerations finite.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from protocol.errors import ConfigError
from protocol.session import DIAGONAL_TURN_DEG, Route
from sim_devices.swim.params import SwimParams
from sim_devices.swim.path import LengthPlan, SwumLength, smoothstep, swim_length
from sim_devices.swim.swimmer import Swimmer

REST_DEPTH_M = 0.4  # body centre below the surface when upright at the wall; assumption
TUCK_DEPTH_M = 0.2  # the body centre sinks this much more in the tuck of a turn; assumption
SIDE_CLEARANCE_M = 0.3  # a body centre closer than this to a side wall is an error
SIGHTING_MARGIN_M = (8.0, 5.0)  # a straight length's sighting: not in the first 8 m or the last 5 m


@dataclass(frozen=True)
class Timeline:
    """Reference point and shared body state over a set, sampled at the IMU rate from 0."""

    time_s: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    z_m: np.ndarray
    yaw_rad: np.ndarray  # heading of travel during lengths; the turning body in turns and rests
    pitch_rad: np.ndarray  # rest and turn pitch (segments add swim * their inclination)
    roll_rad: np.ndarray  # push-off on the side, rolled back during the glide
    swim: np.ndarray  # 0..1 weight of the swimming posture (inclination, head posture, board pitch)
    activity: np.ndarray  # 0..1 stroke motions on
    phase_rad: np.ndarray  # stroke cycle phase within a length (0 before its breakout)
    gain: np.ndarray  # (4, n) amplitude jitter (roll, yaw, pitch, surge)
    sighting: np.ndarray  # 0..1
    rest: np.ndarray  # 0..1 weight of the rest sway
    reach: np.ndarray  # 0..1 kickboard held at arm's length (1) or close (0)
    breath_offset: np.ndarray  # per sample: the length's stroke offset in the breathing pattern
    lengths: tuple[SwumLength, ...]
    push_s: np.ndarray  # per length, set time of the push-off start
    touch_s: np.ndarray  # per length, set time of the wall touch


def keyframes(time_s: np.ndarray, keys: list[tuple[float, float]]) -> np.ndarray:
    """Values over `time_s` moving between (time, value) keys with a quintic smoothstep; flat outside."""
    keys = sorted(keys)
    times = np.array([k[0] for k in keys])
    values = np.array([k[1] for k in keys])
    keep = np.concatenate(([True], np.diff(times) > 1e-9))
    times, values = times[keep], values[keep]
    if len(times) == 1:
        return np.full(len(time_s), values[0])
    index = np.clip(np.searchsorted(times, time_s, side="right") - 1, 0, len(times) - 2)
    u = (time_s - times[index]) / (times[index + 1] - times[index])
    return values[index] + (values[index + 1] - values[index]) * smoothstep(u)


def default_start_y(route: Route, params: SwimParams) -> float:
    """Centre of the pool for a straight set; for a diagonal, as far from the side the first length
    heads to as keeps the far end `pool.side_margin_m` from that side."""
    pool = params.pool
    if route is Route.DIAGONAL:
        return pool.side_margin_m + pool.length_m / 2.0 * math.tan(math.radians(DIAGONAL_TURN_DEG))
    return pool.width_m / 2.0


def build_timeline(route: Route, n_lengths: int, swimmer: Swimmer, params: SwimParams,
                   rng: np.random.Generator, start_y_m: float | None = None) -> Timeline:
    """Plan and sample a set: the draws come from `rng` in a fixed order."""
    walls, dt, pool = params.walls, 1.0 / params.sensors.rate_hz, params.pool
    figures = params.stroke(swimmer.stroke)
    y = default_start_y(route, params) if start_y_m is None else float(start_y_m)
    x = 0.0
    t = _grid(float(rng.uniform(walls.rest_min_s, walls.rest_max_s)) + walls.posture_change_s, dt)
    lengths: list[SwumLength] = []
    push, touch, turns, offsets = [], [], [], []
    for index in range(n_lengths):
        plan = _plan(index, route, x, y, swimmer, params, rng)
        length = swim_length(plan, swimmer, figures, params, rng)
        offsets.append(int(rng.integers(0, max(swimmer.breath_every, 1))))
        lengths.append(length)
        push.append(t)
        t = t + length.time_s[-1]
        touch.append(t)
        x, y = float(length.x_m[-1]), float(length.y_m[-1])
        if index + 1 < n_lengths:
            extra = walls.kick_turn_extra_s if swimmer.stroke == "kick" else 0.0
            turns.append(_grid(float(rng.uniform(walls.turn_min_s, walls.turn_max_s)) + extra, dt))
            t += turns[-1]
    end = touch[-1] + walls.posture_change_s + walls.rest_after_s
    time_s = np.arange(int(round(end / dt)) + 1) * dt
    timeline = _assemble(time_s, lengths, np.array(push), np.array(touch), turns, offsets, swimmer, params, rng)
    _check_inside(timeline, pool.width_m)
    return timeline


def _grid(seconds: float, dt: float) -> float:
    return round(seconds / dt) * dt


def _plan(index: int, route: Route, x: float, y: float, swimmer: Swimmer, params: SwimParams,
          rng: np.random.Generator) -> LengthPlan:
    path, walls, lane_m = params.path, params.walls, params.pool.length_m
    speed = swimmer.speed_mps * max(0.5, 1.0 + path.speed_spread * float(rng.normal()))
    glide = float(rng.uniform(walls.glide_min_s, walls.glide_max_s))
    arc = float(rng.uniform(path.turn_arc_min_m, path.turn_arc_max_m))
    # Mode k of heading amplitude b_k moves the path sideways by up to 2 b_k S / (pi k); equal RMS per mode.
    k = np.arange(1, path.wander_modes + 1)
    sd = swimmer.wander_m * math.pi * k / (lane_m * math.sqrt(1.5 * path.wander_modes))
    wander = rng.normal(0.0, 1.0, path.wander_modes) * sd
    sights = route is Route.DIAGONAL or rng.random() < path.sighting_probability
    where = float(rng.uniform(SIGHTING_MARGIN_M[0], lane_m - SIGHTING_MARGIN_M[1]))
    turn = math.radians(DIAGONAL_TURN_DEG) if route is Route.DIAGONAL else 0.0
    centre = lane_m / 2.0
    sighting = (centre - 1.0 if route is Route.DIAGONAL else where) if sights else None
    return LengthPlan(index, x, y, 0.0 if index % 2 == 0 else math.pi, turn, centre, arc, wander, speed, glide,
                      sighting)


def _assemble(time_s: np.ndarray, lengths: list[SwumLength], push: np.ndarray, touch: np.ndarray,
              turns: list[float], offsets: list[int], swimmer: Swimmer, params: SwimParams,
              rng: np.random.Generator) -> Timeline:
    walls, figures, dt = params.walls, params.stroke(swimmer.stroke), 1.0 / params.sensors.rate_hz
    n = len(time_s)
    x, y = np.empty(n), np.empty(n)
    yaw = np.empty(n)
    activity, phase, sighting = np.zeros(n), np.zeros(n), np.zeros(n)
    gain = np.ones((4, n))
    breath_offset = np.zeros(n, dtype=int)
    first = lengths[0]
    start = int(round(push[0] / dt))
    x[:start], y[:start], yaw[:start] = first.x_m[0], first.y_m[0], first.heading_rad[0]
    for j, length in enumerate(lengths):
        i0 = int(round(push[j] / dt))
        rows = slice(i0, i0 + len(length.time_s))
        x[rows], y[rows], yaw[rows] = length.x_m, length.y_m, length.heading_rad
        activity[rows], phase[rows], sighting[rows] = length.activity, length.phase_rad, length.sighting
        gain[:, rows] = length.gain
        breath_offset[rows] = offsets[j]
        i_end = i0 + len(length.time_s)
        next_start = int(round(push[j + 1] / dt)) if j + 1 < len(lengths) else n
        x[i_end:next_start], y[i_end:next_start] = length.x_m[-1], length.y_m[-1]
        if j + 1 < len(lengths):
            change = _turn_angle(float(length.heading_rad[-1]), lengths[j + 1].plan.heading0_rad, swimmer.turn_side)
            u = smoothstep((time_s[i_end:next_start] - touch[j]) / (push[j + 1] - touch[j]))
            yaw[i_end:next_start] = length.heading_rad[-1] + change * u
        else:
            yaw[i_end:] = length.heading_rad[-1]
    change_s, rest_pitch = walls.posture_change_s, math.radians(walls.rest_pitch_deg)
    prone_push = swimmer.stroke not in ("backstroke", "kick")
    pitch_keys = [(0.0, rest_pitch), (push[0] - change_s, rest_pitch), (push[0], 0.0)]
    roll_keys = [(0.0, 0.0), (push[0], 0.0)]
    swim_keys = [(0.0, 0.0), (push[0], 0.0)]
    reach_keys = [(0.0, 0.0), (push[0] - change_s, 0.0)]
    depth, glide_depth = walls.depth_m, walls.glide_depth_m
    z_keys = [(0.0, -REST_DEPTH_M), (push[0] - change_s, -REST_DEPTH_M), (push[0], -(depth + glide_depth))]
    for j, length in enumerate(lengths):
        breakout = push[j] + length.breakout_s
        swim_keys += [(breakout + walls.stroke_ramp_s, 1.0), (touch[j], 1.0)]
        reach_keys += [(push[j] + walls.push_s + 0.5, 1.0), (touch[j], 1.0)]
        z_keys += [(breakout, -depth), (touch[j], -depth)]
        if j + 1 < len(lengths):
            turn_s = push[j + 1] - touch[j]
            change = _turn_angle(float(length.heading_rad[-1]), lengths[j + 1].plan.heading0_rad, swimmer.turn_side)
            side = math.copysign(1.0, change) if prone_push else 0.0
            pitch_keys += [(touch[j], 0.0), (touch[j] + turn_s / 2.0, math.radians(walls.turn_pitch_deg)),
                           (push[j + 1], 0.0)]
            roll_keys += [(touch[j], 0.0), (push[j + 1], side * math.radians(walls.push_roll_deg)),
                          (push[j + 1] + lengths[j + 1].breakout_s, 0.0)]
            swim_keys += [(touch[j] + 0.3 * turn_s, 0.0), (push[j + 1], 0.0)]
            reach_keys += [(touch[j] + 0.4 * turn_s, 0.0), (push[j + 1], 0.0)]
            z_keys += [(touch[j] + turn_s / 2.0, -(depth + TUCK_DEPTH_M)), (push[j + 1], -(depth + glide_depth))]
    end_s = float(time_s[-1])
    pitch_keys += [(touch[-1], 0.0), (touch[-1] + change_s, rest_pitch), (end_s, rest_pitch)]
    roll_keys += [(touch[-1], 0.0)]
    swim_keys += [(touch[-1] + change_s / 2.0, 0.0)]
    reach_keys += [(touch[-1] + change_s, 0.0)]
    z_keys += [(touch[-1] + change_s, -REST_DEPTH_M), (end_s, -REST_DEPTH_M)]
    rest = keyframes(time_s, [(0.0, 1.0), (push[0] - change_s, 1.0), (push[0], 0.0), (touch[-1], 0.0),
                              (touch[-1] + change_s, 1.0)])
    heave = activity * figures.heave_m * gain[2] * np.sin(figures.strokes_per_cycle * phase + 0.8)
    bob = walls.rest_bob_m * np.sin(2.0 * math.pi * 0.3 * time_s + float(rng.uniform(0.0, 2.0 * math.pi)))
    z = keyframes(time_s, z_keys) + heave + rest * bob
    return Timeline(time_s, x, y, z, yaw, keyframes(time_s, pitch_keys), keyframes(time_s, roll_keys),
                    keyframes(time_s, swim_keys), activity, phase, gain, sighting, rest, keyframes(time_s, reach_keys),
                    breath_offset, tuple(lengths), push, touch)


def _turn_angle(end_heading: float, next_heading: float, side: int) -> float:
    """Rotation of an open turn (rad): the shorter way round; a straight reversal turns to `side`."""
    change = math.remainder(next_heading - end_heading, 2.0 * math.pi)
    if abs(abs(change) - math.pi) < 1e-3:
        return side * abs(change)
    return change


def _check_inside(timeline: Timeline, width_m: float) -> None:
    low, high = float(timeline.y_m.min()), float(timeline.y_m.max())
    if low < SIDE_CLEARANCE_M or high > width_m - SIDE_CLEARANCE_M:
        raise ConfigError(f"start_y_m: the path reaches y = {low:.2f}..{high:.2f} m, outside the pool's "
                          f"[{SIDE_CLEARANCE_M}, {width_m - SIDE_CLEARANCE_M}] m; choose a start further from the side")
