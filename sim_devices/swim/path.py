"""The swimmer's reference point (body centre) over one length: path geometry and speed in time.

Length frame: u along the length's start heading (the lane direction), w to its left. The path
is given by its heading against arc length s,

    psi(s) = -turn * S5((s - s_c + a / 2) / a)  +  sum_k b_k sin(pi k s / S)        (k = 1..K)

where S5 is the quintic smoothstep (0 -> 1 with zero slope and curvature at both ends), the
first term the diagonal's right turn of 35.75 deg made over an arc of a metres centred on the
half-length line s_c = L / 2 (0 on a straight route), the sum the slow lateral wander (half-sine
heading modes that vanish at both walls, so the heading is the route's at the push-off and at
the touch). S is the arc length at which u reaches the pool length L exactly (found on a 1 mm
grid, iterated because the modes use S).

Speed along the path: a push-off ramp to the push speed (S5 over `walls.push_s`), an exponential
glide decay to the length's swimming speed, stroke surges that start at the breakout, and a last
reach in which the speed falls to 0 at the touch (`walls.finish_s`). The finish window is placed
so the distance swum is S; the speed is then scaled by the tiny factor (< 1e-3) that makes the
sampled integral exactly S. Position comes from integrating (cos psi, sin psi) along s with the
midpoint rule, then the along-lane coordinate is scaled (by < 1e-6) so the lane extent is L.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim_devices.swim.params import StrokeParams, SwimParams
from sim_devices.swim.swimmer import Swimmer

FINE_STEP_M = 0.001  # path grid for finding S
# Surge shape per stroke: (harmonic of the cycle, weight, phase rad), scaled to the swimmer's CV.
SURGE: dict[str, tuple[tuple[int, float, float], ...]] = {
    "crawl": ((2, 1.0, 0.0), (1, 0.25, 0.7)),  # one surge per arm, a little left/right asymmetry
    "backstroke": ((2, 1.0, 0.0), (1, 0.25, 0.7)),
    "breaststroke": ((1, 1.0, 0.0), (2, 0.5, -0.6)),  # one large kick-driven surge per cycle
    "butterfly": ((2, 1.0, 0.0), (1, 0.6, 0.4)),  # kick + arm pull, unequal
    "kick": ((2, 1.0, 0.0),),  # one surge per leg beat
}
MIN_SPEED_SHARE = 0.05  # surges never stop the swimmer completely


def smoothstep(u: np.ndarray | float) -> np.ndarray:
    """Quintic smoothstep on [0, 1] (clipped): zero slope and curvature at both ends."""
    x = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
    return x * x * x * (10.0 + x * (-15.0 + 6.0 * x))


def smooth_knots(position: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """Values at integer `position`s from `knots`, blended with a raised cosine in between (C1)."""
    index = np.clip(np.floor(position).astype(int), 0, len(knots) - 2)
    frac = np.clip(position - index, 0.0, 1.0)
    weight = 0.5 - 0.5 * np.cos(math.pi * frac)
    return knots[index] * (1.0 - weight) + knots[index + 1] * weight


@dataclass(frozen=True)
class LengthPlan:
    """What is decided before a length is swum (length frame: u along heading0, w to its left)."""

    index: int
    x0_m: float
    y0_m: float
    heading0_rad: float  # lane direction: 0 (+x) or pi (-x)
    turn_rad: float  # right turn of the route (positive = to the right; 0 straight)
    turn_centre_m: float
    turn_arc_m: float
    wander_rad: np.ndarray  # b_k, heading amplitude of mode k
    speed_mps: float
    glide_s: float
    sighting_m: float | None  # arc length of a sighting, if any


@dataclass(frozen=True)
class SwumLength:
    """One length sampled from the push-off start (local time 0) to the touch (last sample)."""

    plan: LengthPlan
    path_m: float  # S: body-centre path length, push-off to touch
    time_s: np.ndarray  # local, 0 .. duration
    x_m: np.ndarray
    y_m: np.ndarray
    heading_rad: np.ndarray  # path heading (world)
    speed_mps: np.ndarray
    activity: np.ndarray  # 0..1: stroke motions (surge, roll, breathing) on
    phase_rad: np.ndarray  # stroke cycle phase from the breakout (0 before it)
    gain: np.ndarray  # (4, n) cycle-to-cycle amplitude factors (roll, yaw, pitch, surge)
    sighting: np.ndarray  # 0..1 pulse
    breakout_s: float
    strokes: int


def heading_rel(plan: LengthPlan, s: np.ndarray, path_m: float) -> np.ndarray:
    """psi(s) relative to heading0 (rad): the route's turn plus the wander modes (module docstring)."""
    s = np.asarray(s, dtype=float)
    psi = np.zeros_like(s)
    if plan.turn_rad:
        psi -= plan.turn_rad * smoothstep((s - plan.turn_centre_m + plan.turn_arc_m / 2.0) / plan.turn_arc_m)
    u = np.clip(s / path_m, 0.0, 1.0)
    for k, amplitude in enumerate(plan.wander_rad, start=1):
        psi += amplitude * np.sin(math.pi * k * u)
    return psi


def path_length(plan: LengthPlan, lane_m: float) -> float:
    """Arc length S at which the along-lane coordinate reaches `lane_m` (1 mm grid, iterated)."""
    nominal = lane_m / math.cos(plan.turn_rad) if plan.turn_rad else lane_m
    path_m = lane_m if not plan.turn_rad else plan.turn_centre_m + (lane_m - plan.turn_centre_m) / math.cos(plan.turn_rad)
    for _ in range(3):
        s = np.arange(0.0, 1.3 * nominal + 2.0, FINE_STEP_M)
        cos_psi = np.cos(heading_rel(plan, s, path_m))
        u = np.concatenate(([0.0], np.cumsum((cos_psi[1:] + cos_psi[:-1]) * 0.5 * FINE_STEP_M)))
        path_m = float(np.interp(lane_m, u, s))
    return path_m


def swim_length(plan: LengthPlan, swimmer: Swimmer, figures: StrokeParams, params: SwimParams,
                rng: np.random.Generator) -> SwumLength:
    """Sample one length at `sensors.rate_hz` from the push-off start to the touch."""
    walls, dt = params.walls, 1.0 / params.sensors.rate_hz
    lane_m = params.pool.length_m
    path_m = path_length(plan, lane_m)
    breakout_s = walls.push_s + plan.glide_s
    finish = np.arange(int(round(walls.finish_s / dt)) + 1)
    fade = 1.0 - smoothstep(finish / finish[-1])
    duration_s = breakout_s + 3.0 * path_m / plan.speed_mps + 10.0
    time_s = np.arange(int(duration_s / dt)) * dt
    knots = rng.normal(0.0, 1.0, (5, int(duration_s * swimmer.cycle_hz) + 3))
    cycles = time_s * swimmer.cycle_hz
    rate = swimmer.cycle_hz * (1.0 + params.path.rate_jitter * smooth_knots(cycles, knots[0]))
    phase = 2.0 * math.pi * np.concatenate(([0.0], np.cumsum(rate[:-1]) * dt))
    phase = np.maximum(phase - np.interp(breakout_s, time_s, phase), 0.0)
    activity = smoothstep((time_s - breakout_s) / walls.stroke_ramp_s)
    gain = 1.0 + params.path.amplitude_jitter * np.stack([smooth_knots(cycles, knots[i]) for i in (1, 2, 3, 4)])
    harmonics = SURGE[swimmer.stroke]
    norm = math.sqrt(sum(w * w for _, w, _ in harmonics))
    surge = sum(w * np.sin(h * phase + delta) for h, w, delta in harmonics) * swimmer.ivv * math.sqrt(2.0) / norm
    push = walls.push_s
    base = np.where(time_s < push, swimmer.push_speed_mps * smoothstep(time_s / push),
                    plan.speed_mps + (swimmer.push_speed_mps - plan.speed_mps)
                    * np.exp(-(time_s - push) / walls.glide_decay_s))
    speed = base * np.maximum(1.0 + activity * gain[3] * surge, MIN_SPEED_SHARE)
    travelled = np.concatenate(([0.0], np.cumsum((speed[1:] + speed[:-1]) * 0.5 * dt)))
    in_finish = np.convolve(speed, fade[::-1], mode="valid") * dt  # distance of a finish starting at i
    total = travelled[:len(in_finish)] + in_finish
    start = int(np.searchsorted(total, path_m))
    if start >= len(in_finish):
        raise RuntimeError(f"length {plan.index}: {path_m:.2f} m not reached in {duration_s:.0f} s")
    end = start + len(finish)  # exclusive; the touch is sample end - 1
    speed, activity, phase, gain = speed[:end].copy(), activity[:end].copy(), phase[:end], gain[:, :end]
    time_s = time_s[:end]
    speed[start:] *= fade
    activity[start:] *= fade
    distance = np.concatenate(([0.0], np.cumsum((speed[1:] + speed[:-1]) * 0.5 * dt)))
    speed *= path_m / distance[-1]
    distance *= path_m / distance[-1]
    strokes = 0
    if time_s[start] > breakout_s:
        strokes = int(math.floor(phase[start] / (2.0 * math.pi / figures.strokes_per_cycle) - 1e-9)) + 1
    x, y, heading = _positions(plan, distance, path_m, lane_m)
    sighting = np.zeros(len(time_s))
    if plan.sighting_m is not None:
        centre = float(np.interp(plan.sighting_m, distance, time_s))
        u = (time_s - centre) / params.path.sighting_s + 0.5
        sighting = np.where((u > 0) & (u < 1), np.sin(math.pi * np.clip(u, 0, 1)) ** 2, 0.0)
    return SwumLength(plan, path_m, time_s, x, y, heading, speed, activity, phase, gain, sighting,
                      breakout_s, strokes)


def _positions(plan: LengthPlan, distance: np.ndarray, path_m: float,
               lane_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World x, y and path heading along `distance` (midpoint rule; lane extent scaled to exactly L)."""
    step = np.diff(distance)
    psi_mid = heading_rel(plan, 0.5 * (distance[1:] + distance[:-1]), path_m)
    u = np.concatenate(([0.0], np.cumsum(step * np.cos(psi_mid))))
    w = np.concatenate(([0.0], np.cumsum(step * np.sin(psi_mid))))
    u *= lane_m / u[-1]
    cos0, sin0 = math.cos(plan.heading0_rad), math.sin(plan.heading0_rad)
    x = plan.x0_m + cos0 * u - sin0 * w
    y = plan.y0_m + sin0 * u + cos0 * w
    return x, y, plan.heading0_rad + heading_rel(plan, distance, path_m)
