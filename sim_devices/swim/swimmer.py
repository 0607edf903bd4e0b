"""One swimmer's traits, drawn once from the documented [min, max] ranges of `SwimParams`.

Body traits (how each mount's sensor sits on this body, the side an open turn rotates to, the
push-off) come from the swimmer's own seed, so one person's sets share them; stroke traits come
from a child of it per stroke. Everything is a uniform draw inside the documented range.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from sim_devices.swim.params import STROKES, SwimParams

MOUNT_GROUPS = ("waist", "back", "head", "kickboard")


@dataclass(frozen=True)
class Swimmer:
    """Traits of one swimmer doing one stroke (angles in degrees, amplitudes each side)."""

    stroke: str
    speed_mps: float  # mean swimming speed between walls (glide excluded)
    cycle_hz: float  # stroke cycles per second (kick cycles for "kick")
    ivv: float  # coefficient of variation of the forward speed within a cycle
    hip_roll_deg: float
    shoulder_roll_deg: float
    hip_yaw_deg: float
    shoulder_yaw_deg: float
    breath_every: int  # arm strokes per breath (0: no breathing motion)
    head_pitch_deg: float  # head on trunk between breaths
    inclination_deg: float  # mean trunk pitch, head up
    board_pitch_deg: float  # kickboard nose-up pitch ("kick" only)
    push_speed_mps: float
    wander_m: float  # RMS lateral wander per length
    turn_side: int  # +1: open turns rotate to the left (counter-clockwise), -1: right
    tilt_deg: dict[str, float]  # per mount group: sensor x pitch relative to the segment's long axis

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def draw_swimmer(stroke: str, params: SwimParams, body_rng: np.random.Generator,
                 stroke_rng: np.random.Generator) -> Swimmer:
    """Draw a swimmer: body traits from `body_rng` (fixed order), stroke traits from `stroke_rng`."""
    figures = params.stroke(stroke)
    walls, path = params.walls, params.path

    def uniform(rng: np.random.Generator, low: float, high: float) -> float:
        return float(rng.uniform(low, high)) if high > low else float(low)

    tilts = {name: uniform(body_rng, getattr(params, name).tilt_min_deg, getattr(params, name).tilt_max_deg)
             for name in MOUNT_GROUPS}
    turn_side = 1 if body_rng.random() < 0.5 else -1
    push_speed = uniform(body_rng, walls.push_speed_min_mps, walls.push_speed_max_mps)
    wander = uniform(body_rng, path.wander_min_m, path.wander_max_m)
    if stroke == "kick":
        wander *= path.kick_wander_factor
    breath_every = int(stroke_rng.integers(figures.breath_every_min, figures.breath_every_max + 1))
    return Swimmer(
        stroke=stroke,
        speed_mps=uniform(stroke_rng, figures.speed_min_mps, figures.speed_max_mps),
        cycle_hz=uniform(stroke_rng, figures.cycle_rate_min_per_min, figures.cycle_rate_max_per_min) / 60.0,
        ivv=uniform(stroke_rng, figures.ivv_min, figures.ivv_max),
        hip_roll_deg=uniform(stroke_rng, figures.hip_roll_min_deg, figures.hip_roll_max_deg),
        shoulder_roll_deg=uniform(stroke_rng, figures.shoulder_roll_min_deg, figures.shoulder_roll_max_deg),
        hip_yaw_deg=uniform(stroke_rng, figures.hip_yaw_min_deg, figures.hip_yaw_max_deg),
        shoulder_yaw_deg=uniform(stroke_rng, figures.shoulder_yaw_min_deg, figures.shoulder_yaw_max_deg),
        breath_every=breath_every,
        head_pitch_deg=uniform(stroke_rng, figures.head_pitch_min_deg, figures.head_pitch_max_deg),
        inclination_deg=uniform(stroke_rng, figures.inclination_min_deg, figures.inclination_max_deg),
        board_pitch_deg=uniform(stroke_rng, figures.board_pitch_min_deg, figures.board_pitch_max_deg),
        push_speed_mps=push_speed, wander_m=wander, turn_side=turn_side, tilt_deg=tilts)


def swimmer_rngs(stroke: str, seed: int) -> tuple[np.random.Generator, np.random.Generator]:
    """(body, stroke) generators of the swimmer with seed `seed`: fixed children of its SeedSequence."""
    if stroke not in STROKES:
        raise ValueError(f"stroke {stroke!r} is not one of {', '.join(STROKES)}")
    body = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0,)))
    per_stroke = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(1, STROKES.index(stroke))))
    return body, per_stroke
