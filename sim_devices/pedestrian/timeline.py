"""When a walker is where: the speed along the path, stops at stands and pauses, and the step phase.

Speed. On a 1 cm grid of arc length, the cruise speed (cadence x step length) times a per-step
random factor is limited by corners (down to `turn_speed_ratio` of cruise for a 90 deg corner,
scaled with the angle, tapering over `turn_slow_distance_m` either side) and by stops (v <=
sqrt(2 a d) for the distance d to the nearest stop: constant acceleration `acceleration_mps2`).
Time is the integral of ds / v; each stop adds its dwell. The phase of the step cycle advances at
the cadence x sqrt(v / cruise) (slower walking shortens both step length and step time) with a
per-step time error; phase 0 is mid-stance (body highest and slowest), 0.5 the next heel strike.

Stairs (a path with heights): on a flight and its landing the speed is limited to the stair's
horizontal speed (FloorParams' vertical speed up or down / the flight's slope), reached from and
left to the walking speed at `acceleration_mps2`; each step there is one tread, so the step phase
advances at the horizontal speed / `stair_tread_m`.

The position along the path is the base position minus the surge term (forward speed swing within
a step, zero at step boundaries and at rest), so step lengths in the truth follow the step model.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from protocol.session import Stand
from sim_devices.pedestrian.params import FloorParams, GaitParams, StandParams
from sim_devices.pedestrian.path import SmoothPath
from sim_devices.pedestrian.person import Person

GRID_M = 0.01
STAND_MATCH_M = 0.05  # a route passes a stand when it comes this close ...
STAND_MATCH_DEG = 2.0  # ... heading the stand's way within this


@dataclass(frozen=True)
class Stop:
    """A standstill at arc length `s_m`: at a stand (`stand_id`) or a pause (`stand_id` empty)."""

    s_m: float
    dwell_s: float
    stand_id: str = ""
    start_s: float = 0.0  # filled by the timeline: time of arrival, s from the walker's start


@dataclass(frozen=True)
class Timeline:
    """A walker's progress sampled at the IMU rate, from its own start (time 0)."""

    time_s: np.ndarray  # (n,) from 0, regular
    s_m: np.ndarray  # position along the path, with the surge
    speed_mps: np.ndarray  # base speed (no within-step swing)
    phase: np.ndarray  # step cycles since the start (0 = mid-stance)
    stops: tuple[Stop, ...]  # with arrival times
    cruise_mps: float

    @property
    def speed_share(self) -> np.ndarray:
        """Base speed / cruise speed, in [0, ~1.1]: scales every gait oscillation."""
        return self.speed_mps / self.cruise_mps

    def cut(self, duration_s: float | None) -> "Timeline":
        """The timeline up to `duration_s` (None: whole), with the stops begun by then."""
        if duration_s is None or duration_s >= self.time_s[-1]:
            return self
        keep = self.time_s <= duration_s
        return dataclasses.replace(self, time_s=self.time_s[keep], s_m=self.s_m[keep],
                                   speed_mps=self.speed_mps[keep], phase=self.phase[keep],
                                   stops=tuple(stop for stop in self.stops if stop.start_s <= duration_s))


def stand_stops(path: SmoothPath, stands: tuple[Stand, ...], n_phones: int, stand: StandParams,
                floor_height_m: float = 0.0) -> list[Stop]:
    """A stop at each stand the path passes (close to it, heading its way, on its floor), first passage only."""
    dwell = n_phones * (stand.place_s + stand.still_s + stand.pick_s)
    stops = []
    for item in stands:
        distance = np.hypot(path.x_m - item.x_m, path.y_m - item.y_m)
        heading_off = np.degrees(np.abs(np.remainder(path.heading_rad - math.radians(item.heading_deg) + math.pi,
                                                     2 * math.pi) - math.pi))
        near = (distance < STAND_MATCH_M) & (heading_off < STAND_MATCH_DEG)
        if path.height_knots is not None:
            near &= np.abs(path.height_at(path.s_m) - item.floor * floor_height_m) < 1e-6
        hits = np.flatnonzero(near)
        if len(hits):
            run = hits[: int(np.argmax(np.diff(np.append(hits, hits[-1] + 2)) > 1)) + 1]  # first passage
            stops.append(Stop(float(path.s_m[run[np.argmin(distance[run])]]), dwell, item.id))
    return stops


def pause_stops(path: SmoothPath, taken: list[Stop], gait: GaitParams, rng: np.random.Generator) -> list[Stop]:
    """Pauses before some corners (chance `pause_chance` each), never within 3 m of another stop."""
    stops = []
    for corner in path.corners:
        chance, length = rng.random(), rng.uniform(gait.pause_min_s, gait.pause_max_s)
        if abs(corner.turn_rad) < math.radians(10.0) or chance >= gait.pause_chance:
            continue
        s = corner.start_m - 0.3
        if s > 0.5 and all(abs(s - other.s_m) > 3.0 for other in taken + stops):
            stops.append(Stop(float(s), float(length)))
    return stops


def stair_cells(path: SmoothPath, grid: np.ndarray, floor_height_m: float) -> np.ndarray:
    """True where the grid lies on a stair (a flight or its landing: between two floors)."""
    level = path.height_at(grid) / floor_height_m
    return np.abs(level - np.round(level)) > 1e-6


def stair_limit(path: SmoothPath, grid: np.ndarray, floors: FloorParams, acceleration_mps2: float) -> np.ndarray:
    """Speed limit from the stairs: the stair's horizontal speed on each flight and landing, rising at
    `acceleration_mps2` with the distance from it."""
    limit = np.full(len(grid), np.inf)
    on = stair_cells(path, grid, floors.height_m)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], on.astype(np.int8), [0]])))
    height = path.height_at(grid)
    for first, end in zip(edges[::2], edges[1::2]):
        last = end - 1
        slope = float(np.max(np.abs(np.gradient(height[first:end + 1], grid[first:end + 1]))))
        up = height[min(end, len(grid) - 1)] > height[max(first - 1, 0)]
        vertical = floors.stair_up_vertical_mps if up else floors.stair_down_vertical_mps
        horizontal = vertical / max(slope, 1e-3)
        distance = np.maximum(np.maximum(grid[first] - grid, grid - grid[last]), 0.0)
        limit = np.minimum(limit, np.sqrt(horizontal ** 2 + 2.0 * acceleration_mps2 * distance))
    return limit


def speed_limit(path: SmoothPath, person: Person, gait: GaitParams, rng: np.random.Generator,
                floors: FloorParams | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(arc-length grid, speed limit from cruise, per-step variation and corners) before stops."""
    grid = np.arange(0.0, path.length_m + GRID_M / 2, GRID_M)
    # step length CV = combined speed and step-time variation: the speed part carries the rest
    speed_cv = math.sqrt(max(gait.step_length_cv ** 2 - gait.step_time_cv ** 2, 0.0))
    knots = np.arange(0.0, path.length_m + person.step_length_m, person.step_length_m)
    factor = np.interp(grid, knots, 1.0 + rng.normal(0.0, speed_cv, len(knots)))
    limit = person.speed_mps * factor
    for corner in path.corners:
        angle = abs(corner.turn_rad)
        if angle < math.radians(1.0):
            continue
        low = max(0.2, 1.0 - (1.0 - gait.turn_speed_ratio) * angle / (math.pi / 2))
        before = np.clip((corner.start_m - grid) / max(gait.turn_slow_distance_m, 1e-6), 0.0, 1.0)
        after = np.clip((grid - corner.end_m) / max(gait.turn_slow_distance_m, 1e-6), 0.0, 1.0)
        outside = np.maximum(before, after)  # 0 inside the arc, 1 far from it
        taper = 0.5 - 0.5 * np.cos(math.pi * outside)
        limit = np.minimum(limit, person.speed_mps * factor * (low + (1.0 - low) * taper))
    if floors is not None and path.height_knots is not None:
        limit = np.minimum(limit, stair_limit(path, grid, floors, gait.acceleration_mps2))
    return grid, limit


def walk_timeline(path: SmoothPath, person: Person, stops: list[Stop], gait: GaitParams, rate_hz: float,
                  rng: np.random.Generator, floors: FloorParams | None = None) -> Timeline:
    """The walker's progress along `path` with `stops` (sorted by arc length; one at the end is added);
    `floors` for a path with stairs."""
    grid, limit = speed_limit(path, person, gait, rng, floors)
    ordered = sorted(stops, key=lambda stop: stop.s_m)
    marks = np.array([0.0] + [stop.s_m for stop in ordered] + [path.length_m])
    middle = (grid[1:] + grid[:-1]) / 2
    # distance to the nearest stop, at least half a cell (a stop may fall on a cell's middle)
    nearest = np.maximum(np.min(np.abs(middle[:, None] - marks[None, :]), axis=1), GRID_M / 2)
    speed = np.minimum((limit[1:] + limit[:-1]) / 2, np.sqrt(2.0 * gait.acceleration_mps2 * nearest))
    elapsed = np.concatenate([[0.0], np.cumsum(GRID_M / speed)])
    # each stop's dwell: later grid points move later, and the stop holds its arc length meanwhile
    stop_s = np.array([stop.s_m for stop in ordered])
    dwell = np.concatenate([[0.0], np.cumsum([stop.dwell_s for stop in ordered])])
    t_grid = elapsed + dwell[np.searchsorted(stop_s, grid, side="left")]
    arrive = np.interp(stop_s, grid, elapsed) + dwell[:-1]
    timed = tuple(Stop(stop.s_m, stop.dwell_s, stop.stand_id, float(a)) for stop, a in zip(ordered, arrive))
    all_t = np.concatenate([t_grid, arrive, arrive + np.diff(dwell)])
    all_s = np.concatenate([grid, stop_s, stop_s])
    order = np.lexsort((all_t, all_s))
    t_nodes, s_nodes = all_t[order], all_s[order]
    time = np.arange(0.0, t_nodes[-1], 1.0 / rate_hz)
    base = np.interp(time, t_nodes, s_nodes)
    base_speed = np.gradient(base, 1.0 / rate_hz)
    base_speed[base_speed < 1e-3] = 0.0
    tread_hz = None
    if floors is not None and path.height_knots is not None:  # on a stair, one step per tread
        tread_hz = np.where(stair_cells(path, base, floors.height_m), base_speed / floors.stair_tread_m, np.nan)
    phase = _phase(base_speed, person, gait, rate_hz, rng, tread_hz)
    share = base_speed / person.speed_mps
    surge_m = gait.surge_ratio * person.step_length_m / (2.0 * math.pi)
    position = np.clip(base - surge_m * share * np.sin(2.0 * math.pi * phase), 0.0, path.length_m)
    return Timeline(time, position, base_speed, phase, timed, person.speed_mps)


def _phase(speed: np.ndarray, person: Person, gait: GaitParams, rate_hz: float,
           rng: np.random.Generator, tread_hz: np.ndarray | None = None) -> np.ndarray:
    """Step cycles since the start; each step's duration varies by `step_time_cv`. `tread_hz`: the
    step rate on stairs (NaN elsewhere)."""
    rate = person.cadence_hz * np.sqrt(np.clip(speed / person.speed_mps, 0.0, 2.0)) / rate_hz
    if tread_hz is not None:
        rate = np.where(np.isnan(tread_hz), rate, np.nan_to_num(tread_hz) / rate_hz)
    errors = 1.0 + rng.normal(0.0, gait.step_time_cv, int(np.sum(rate)) + 16)
    phase = np.empty(len(speed))
    value = 0.0
    for i, step in enumerate(rate.tolist()):
        phase[i] = value
        value += step / errors[min(int(value), len(errors) - 1)]
    return phase
