"""A population of rooms: the camera-identity scene's error sources and people drawn from documented ranges.

`room_world(K)` is room world K: world 0 is today's room (`RoomParams()` and the ROOM tracker, the
scene the identity engine was tuned in); every K >= 1 draws each row of ROOM_WORLD_RANGES once, in
table order, from a generator seeded by K alone (independent of the motion seed). A row sets a
dotted figure of `RoomParams` or, prefixed `tracker.`, of the ROOM `TrackerParams`. The rows cover
what issue 19 names: the tracker's fragmentation, fusions and swaps, head-height and position noise,
false tracks and its clock, how often people sit, how their speeds spread, how many bystanders.
Ranges and sources are rendered in docs/simulator-room.md (`describe_room_worlds`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from protocol.errors import ConfigError
from sim_devices.camera import ROOM, TrackerParams
from sim_devices.camera.params import params_with_overrides as tracker_with_overrides
from sim_devices.room.params import RoomParams, params_with_overrides

ROOM_WORLD_ENTROPY = 0x12_00_19  # mixed with K: room worlds never coincide with the chair worlds or a seed
MAX_WORLD = 1_000_000
TRACKER = "tracker."


@dataclass(frozen=True)
class RoomWorldRange:
    name: str
    key: str  # dotted figure of RoomParams, or "tracker." + one of the ROOM TrackerParams
    unit: str
    low: float
    high: float
    law: str  # "uniform" or "log" (log-uniform)
    source: str


ROOM_WORLD_RANGES: tuple[RoomWorldRange, ...] = (
    RoomWorldRange("track breaks", "tracker.gaps.rate_per_min", "1/min", 0.2, 3.0, "log",
                   "per person-minute in view: COURT 0.4 (calibrated), ROOM 0.6 (assumption); SportsMOT's "
                   "ByteTrack changes identity about 4.5 times a person-minute (docs/simulator-camera.md)"),
    RoomWorldRange("lost while standing", "tracker.gaps.still_rate_per_s", "1/s", 0.0, 0.2, "uniform",
                   "0: a detector that finds still people (COURT); 0.1: frame differencing loses them in about "
                   "10 s (ROOM, the paper's tracker)"),
    RoomWorldRange("swaps at a close pass", "tracker.switches.probability", "1", 0.0, 0.3, "uniform",
                   "ROOM 0 (calibrated on the paper's result), COURT 0.1; 0.3 the harshest setting measured in "
                   "docs/simulator-camera.md"),
    RoomWorldRange("fusions at a close pass", "tracker.merges.probability", "1", 0.0, 0.3, "uniform",
                   "ROOM 0.1 (calibrated; the paper's own result allows about 0.05 or less); 0.3 measured there"),
    RoomWorldRange("head-height noise", "tracker.noise.height_sd_m", "m", 0.01, 0.08, "log",
                   "stereo depth along the vertical: Bumblebee2 geometry 2-9 cm at 3-6 m, StereoSORT 5 cm median"),
    RoomWorldRange("position noise", "tracker.noise.white_sd_m", "m", 0.02, 0.09, "log",
                   "the same stereo depth figures, horizontally"),
    RoomWorldRange("false tracks", "tracker.false_tracks.rate_per_min", "1/min", 0.2, 3.0, "log",
                   "ROOM 1 per camera-minute (frame differencing picks up anything that moves; assumption)"),
    RoomWorldRange("camera clock offset", "tracker.camera.clock_offset_ms", "ms", 50.0, 250.0, "uniform",
                   "ROOM 150 ms (the paper aligned video and sensor logs afterwards: a few frames)"),
    RoomWorldRange("sitting", "activity.sit_weight", "1", 0.0, 0.3, "uniform",
                   "relative chance of sitting down next: 0.12 by default (the paper's subject A sat, Fig. 8); "
                   "from a room where nobody sits to one where people sit 2.5 times as often"),
    RoomWorldRange("walking speed spread", "people.speed_factor_sd", "1", 0.04, 0.25, "uniform",
                   "SD of a person's speed factor: 0.12 by default (assumption from the 0.8-2.0 m/s spread of "
                   "free walking in a Fukuoka survey, params.py); a third to twice that"),
    RoomWorldRange("bystanders per wearer", "extra.extra_per_wearer", "1", 0.0, 1.5, "uniform",
                   "0.67 by default (2 with the paper's 3; the paper gives no count)"),
)


def draw_room_world(world: int) -> dict[str, float]:
    """The dotted figures room world `world` sets (empty for world 0), in ROOM_WORLD_RANGES order."""
    _check(world)
    if world == 0:
        return {}
    rng = np.random.default_rng(np.random.SeedSequence([ROOM_WORLD_ENTROPY, world]))
    return {row.key: _draw(row, rng) for row in ROOM_WORLD_RANGES}


def room_world(world: int, base: RoomParams | None = None,
               tracker: TrackerParams = ROOM) -> tuple[RoomParams, TrackerParams]:
    """(room params, tracker params) of world `world`: `base` and `tracker` with every figure it draws."""
    figures = draw_room_world(world)
    room = {k: repr(v) for k, v in figures.items() if not k.startswith(TRACKER)}
    camera = {k[len(TRACKER):]: repr(v) for k, v in figures.items() if k.startswith(TRACKER)}
    return params_with_overrides(room, base), tracker_with_overrides(camera, tracker)


def describe_room_worlds() -> list[tuple[str, str, str, str, str, str]]:
    """(source of error, figure, range, unit, law, where the range comes from) per ROOM_WORLD_RANGES row."""
    return [(row.name, row.key, f"{row.low:g} - {row.high:g}", row.unit, row.law, row.source)
            for row in ROOM_WORLD_RANGES]


def _draw(row: RoomWorldRange, rng: np.random.Generator) -> float:
    if row.law == "uniform":
        return float(rng.uniform(row.low, row.high))
    if row.law == "log":
        return float(math.exp(rng.uniform(math.log(row.low), math.log(row.high))))
    raise ValueError(f"room world range {row.name!r}: unknown law {row.law!r}")


def _check(world: int) -> None:
    if isinstance(world, bool) or not isinstance(world, int) or not 0 <= world <= MAX_WORLD:
        raise ConfigError(f"room world: {world!r} is not an integer in [0, {MAX_WORLD}]")
