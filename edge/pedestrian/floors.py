"""A pedestrian's floor from a barometer: the floor of the last fix plus the changes counted since.

Pressure falls about 0.12 hPa per metre near the ground (hypsometric relation, `height_m`), so one
floor (3-5 m) is 0.36-0.6 hPa, while a phone barometer is steady to about 0.01-0.02 hPa RMS and
accurate to 0.5-1 hPa absolute (Bosch BMP280/BMP388 datasheets). The absolute level is useless
(weather moves it by up to 1 hPa an hour, and every phone has its own offset); a change of height
within a minute is not. So `step` follows a height relative to the last fix and:

- smooths it (`smoothing_s`, an exponential filter: the sensor's noise and a door's gust);
- while level, lets a reference follow the height slowly (`drift_s`): weather and a building's
  HVAC drift (0.1-1 hPa/h, about 1-8 m/h) move the reference, not the floor;
- once the height leaves the reference by more than `start_m`, a climb has begun: the reference
  stops following; when the height has been steady again (`settled_m` within `settle_s`), the
  change is counted as round(change / floor height) floors; under half a floor (a landing
  between flights, a ramp, a gust, a lift that came back) counts none and keeps the reference,
  so the next flight counts from the floor, not from the landing.

While a climb is under way, `current_floor` already names the floor the height is nearer to, once
it is `shown_at` of a storey past the last one (the landing half-way between two floors is the
upper floor's, as the IPIN truth counts it, and a flight of stairs is followed within a second or
two instead of after the settling); the count itself is only changed once the height has settled.

A fix that names the floor (a stand) sets the floor and the reference (`at_fix`). The storey
height is the building's, not ours: two fixes on different floors within `learn_within_s` (before
the weather has moved the level by more than a few tenths of a metre) give it as their height
difference over their floor difference, used from then on where it is plausible (2.4-8 m);
until then `floor_height_m`. State: a frozen dataclass of fixed fields; memory does not grow.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

STANDARD_TEMPERATURE_K = 288.15  # the hypsometric scale height at 15 C: 8.43 km
SCALE_HEIGHT_M = 287.05 * STANDARD_TEMPERATURE_K / 9.80665


def height_m(pressure_hpa: float, reference_hpa: float) -> float:
    """Height above the level where the pressure was `reference_hpa` (hypsometric, isothermal)."""
    return SCALE_HEIGHT_M * math.log(reference_hpa / pressure_hpa)


@dataclass(frozen=True)
class FloorSettings:
    floor_height_m: float = 4.0  # storey height: offices 3.5-4 m, malls and halls 4-6 m (assumption)
    smoothing_s: float = 1.0  # the barometer's noise to about 0.1 m; a step of stairs takes 0.5 s
    drift_s: float = 60.0  # the reference follows slow changes: 8 m/h of weather moves it 0.13 m a minute
    start_m: float = 1.0  # a climb has begun: more than weather and noise, under a third of a floor
    settled_m: float = 0.4  # ... and ended when the height holds within this
    settle_s: float = 4.0  # ... for this long (a landing between flights is shorter)
    max_gap_s: float = 10.0  # a longer gap in the readings: the level is taken afresh
    learn_within_s: float = 900.0  # two fixes closer than this in time teach the storey height
    rate_smoothing_s: float = 1.5  # the vertical speed: a flight of stairs takes 5-8 s
    stair_rate_mps: float = 0.1  # on a stair during a climb: stairs rise 0.25-0.35 m/s (a ramp far less)

    def __post_init__(self) -> None:
        for name in ("floor_height_m", "smoothing_s", "drift_s", "start_m", "settled_m", "settle_s", "max_gap_s",
                     "learn_within_s", "rate_smoothing_s", "stair_rate_mps"):
            value = getattr(self, name)
            if not (0.0 < value < math.inf):
                raise ValueError(f"FloorSettings.{name} {value!r} must be finite and > 0")


@dataclass(frozen=True)
class FloorState:
    floor: int | None = None  # None: no fix has named a floor yet
    time_ns: int | None = None  # the last reading
    origin_hpa: float = math.nan  # heights are relative to this pressure (the first reading)
    height_m: float = math.nan  # smoothed
    rate_mps: float = 0.0  # the smoothed height's rate of change, smoothed again over rate_smoothing_s
    reference_m: float = math.nan  # the level of the floor we are on
    climbing: bool = False
    steady_since_ns: int = 0  # while climbing: when the height last moved by more than settled_m
    steady_m: float = math.nan  # ... and where it was then
    changes: int = 0  # floor changes counted
    unresolved: int = 0  # climbs that ended between floors (far from a whole number of floors)
    storey_m: float = math.nan  # the storey height two fixes taught; nan: the settings'
    fix_floor: int | None = None  # the last fix: its floor, height and time
    fix_height_m: float = math.nan
    fix_time_ns: int = 0

    def storey(self, settings: "FloorSettings") -> float:
        return self.storey_m if math.isfinite(self.storey_m) else settings.floor_height_m


def on_stairs(state: FloorState, settings: FloorSettings = FloorSettings()) -> bool:
    """Climbing or descending a stair now: a climb under way and the height still moving. (An
    escalator or a lift moves the height too; their steps are not the walker's.)"""
    return state.climbing and abs(state.rate_mps) > settings.stair_rate_mps


SHOWN_AT = 0.6  # of a storey: a climb names the next floor this far past the last one (a landing is 0.5)


def current_floor(state: FloorState, settings: FloorSettings = FloorSettings()) -> int | None:
    """The floor now: the counted one, or during a climb the one the height is nearest to beyond SHOWN_AT."""
    if state.floor is None or not state.climbing:
        return state.floor
    storeys = (state.height_m - state.reference_m) / state.storey(settings)
    return state.floor + int(math.copysign(math.floor(abs(storeys) + 1.0 - SHOWN_AT), storeys))


STOREY_RANGE_M = (2.4, 8.0)  # a storey height outside this is two fixes that disagree, not a building


def at_fix(state: FloorState, time_ns: int, floor: int, settings: FloorSettings = FloorSettings()) -> FloorState:
    """A fix (a stand) named the floor: we are on it, at the present height."""
    storey_m = state.storey_m
    if (state.fix_floor is not None and floor != state.fix_floor and math.isfinite(state.height_m)
            and (time_ns - state.fix_time_ns) * 1e-9 < settings.learn_within_s):
        learned = (state.height_m - state.fix_height_m) / (floor - state.fix_floor)
        if STOREY_RANGE_M[0] <= learned <= STOREY_RANGE_M[1]:
            storey_m = learned
    return replace(state, floor=floor, reference_m=state.height_m, climbing=False, storey_m=storey_m,
                   fix_floor=floor, fix_height_m=state.height_m, fix_time_ns=time_ns)


def step(state: FloorState, time_ns: int, pressure_hpa: float, settings: FloorSettings = FloorSettings()
         ) -> FloorState:
    """The state after one barometer reading (readings in time order; an older one is ignored)."""
    if not (math.isfinite(pressure_hpa) and 100.0 < pressure_hpa < 1200.0):
        raise ValueError(f"pressure {pressure_hpa!r} hPa is outside 100-1200 hPa")
    if state.time_ns is not None and time_ns <= state.time_ns:
        return state
    if state.time_ns is None or (time_ns - state.time_ns) * 1e-9 > settings.max_gap_s:
        origin = pressure_hpa if state.time_ns is None else state.origin_hpa
        height = height_m(pressure_hpa, origin)
        return replace(state, time_ns=time_ns, origin_hpa=origin, height_m=height, reference_m=height,
                       climbing=False)
    dt_s = (time_ns - state.time_ns) * 1e-9
    raw = height_m(pressure_hpa, state.origin_hpa)
    height = state.height_m + (raw - state.height_m) * (1.0 - math.exp(-dt_s / settings.smoothing_s))
    rate = state.rate_mps + ((height - state.height_m) / dt_s - state.rate_mps) * (
        1.0 - math.exp(-dt_s / settings.rate_smoothing_s))
    state = replace(state, time_ns=time_ns, height_m=height, rate_mps=rate)
    if not state.climbing:
        if abs(height - state.reference_m) > settings.start_m:
            return replace(state, climbing=True, steady_since_ns=time_ns, steady_m=height)
        follow = 1.0 - math.exp(-dt_s / settings.drift_s)
        return replace(state, reference_m=state.reference_m + (height - state.reference_m) * follow)
    if abs(height - state.steady_m) > settings.settled_m:
        return replace(state, steady_since_ns=time_ns, steady_m=height)
    if (time_ns - state.steady_since_ns) * 1e-9 < settings.settle_s:
        return state
    change_m = height - state.reference_m
    storey_m = state.storey(settings)
    floors = round(change_m / storey_m)
    off_m = abs(change_m - floors * storey_m)
    if floors == 0:  # a landing half-way keeps the reference: the next flight counts from the floor
        return replace(state, climbing=False)
    state = replace(state, climbing=False, reference_m=height)
    if off_m > 0.35 * storey_m:  # between floors: a mezzanine, or a storey height we do not know
        return replace(state, unresolved=state.unresolved + 1)
    return replace(state, floor=None if state.floor is None else state.floor + floors,
                   changes=state.changes + abs(floors))
