"""True paths the simulated tracker looks at: `PersonPath`, and walkers without sensors (`extra_people`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from protocol.errors import ConfigError
from sim_devices.camera.params import COURT, ExtrasParams

WALK_RATE_HZ = 50.0  # extra people's path samples, the truth rate of the venue simulators
WALK_RESPONSE_S = 0.5  # velocity follows the wanted velocity with this time constant (smooth starts and turns)
ARRIVE_M = 0.3  # a waypoint is reached this close
SEATED_HEAD_HEIGHT_M = 1.2  # a wheelchair player's head top, seated (issue)


@dataclass(frozen=True)
class PersonPath:
    """Truth of one person, at any rate at least the camera's (linear interpolation in between).

    Outside [time_ns[0], time_ns[-1]] the person is not there (no track)."""

    person_id: str
    time_ns: np.ndarray  # int64, true clock, increasing
    x_m: np.ndarray
    y_m: np.ndarray
    height_m: float = 1.7  # head-top height; a wheelchair player seated about 1.2
    head_m: np.ndarray | None = None  # head-top height per sample when it changes (sitting down), else None


def check_path(path: PersonPath) -> None:
    """ConfigError naming the person when the arrays disagree in length, are empty or time does not increase."""
    where = f"person {path.person_id!r}"
    if not path.person_id or "+" in path.person_id:
        raise ConfigError(f"{where}: id must be non-empty and without '+' (it joins merged labels)")
    count = len(path.time_ns)
    if count == 0 or len(path.x_m) != count or len(path.y_m) != count:
        raise ConfigError(f"{where}: time_ns, x_m, y_m need the same non-zero length "
                          f"({count}, {len(path.x_m)}, {len(path.y_m)})")
    if path.head_m is not None and (len(path.head_m) != count or not np.all(np.isfinite(path.head_m))):
        raise ConfigError(f"{where}: head_m needs one finite height per time ({len(path.head_m)} for {count})")
    if count > 1 and np.any(np.diff(path.time_ns) <= 0):
        raise ConfigError(f"{where}: time_ns must increase")
    if not (np.all(np.isfinite(path.x_m)) and np.all(np.isfinite(path.y_m))):
        raise ConfigError(f"{where}: positions must be finite")


def extra_people(count: int, area_m: tuple[float, float], start_ns: int, end_ns: int, rng: np.random.Generator,
                 params: ExtrasParams | None = None, prefix: str = "extra") -> list[PersonPath]:
    """`count` people without sensors walking between random waypoints, sampled at WALK_RATE_HZ.

    Waypoints are uniform over the area (0..length, 0..width) grown by `params.margin_m`; each leg
    has its own speed in [speed_min_mps, speed_max_mps]; the walker pauses up to `pause_max_s` at
    each waypoint. Velocity follows the wanted velocity with a WALK_RESPONSE_S lag, so starts,
    stops and turns are smooth (no step in velocity). Ids are `<prefix>1`, `<prefix>2`, ...
    """
    params = params or COURT.extras
    if count < 0 or end_ns <= start_ns:
        raise ConfigError(f"extra_people: count {count} must be >= 0 and end_ns {end_ns} after start_ns {start_ns}")
    steps = int((end_ns - start_ns) * 1e-9 * WALK_RATE_HZ) + 1
    time_ns = start_ns + np.round(np.arange(steps) * (1e9 / WALK_RATE_HZ)).astype(np.int64)
    return [PersonPath(f"{prefix}{n + 1}", time_ns, *_walk(steps, area_m, rng, params), height_m=params.height_m)
            for n in range(count)]


def _walk(steps: int, area_m: tuple[float, float], rng: np.random.Generator,
          params: ExtrasParams) -> tuple[np.ndarray, np.ndarray]:
    dt = 1.0 / WALK_RATE_HZ
    low = np.array([-params.margin_m, -params.margin_m])
    high = np.array([area_m[0] + params.margin_m, area_m[1] + params.margin_m])
    high = np.maximum(high, low)  # a negative margin larger than half the area leaves a point
    position = rng.uniform(low, high)
    velocity = np.zeros(2)
    target, speed, pause_s = rng.uniform(low, high), rng.uniform(params.speed_min_mps, params.speed_max_mps), 0.0
    blend = 1.0 - math.exp(-dt / WALK_RESPONSE_S)
    out = np.empty((steps, 2))
    for step in range(steps):
        out[step] = position
        to_go = target - position
        distance = float(np.hypot(*to_go))
        if pause_s > 0.0:
            pause_s -= dt
            wanted = np.zeros(2)
            if pause_s <= 0.0:
                target = rng.uniform(low, high)
                speed = rng.uniform(params.speed_min_mps, params.speed_max_mps)
        elif distance < ARRIVE_M:
            pause_s = rng.uniform(0.0, params.pause_max_s) + dt
            wanted = np.zeros(2)
        else:
            # slow down over the last metre so the walker does not overshoot the waypoint
            wanted = to_go / distance * speed * min(1.0, distance)
        velocity += (wanted - velocity) * blend
        position = position + velocity * dt
    return out[:, 0].copy(), out[:, 1].copy()
