"""One person's body and gait traits, drawn once from the documented ranges (params.PeopleParams, GaitParams)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from sim_devices.room.params import RoomParams

MIN_HEIGHT_M = 1.4  # stature draws are clipped to adult limits (3 SD covers 1.41-1.89 m)
MAX_HEIGHT_M = 2.0
SPEED_FACTOR_LIMITS = (0.6, 1.5)


@dataclass(frozen=True)
class Person:
    """Traits of one person (a wearer)."""

    person_id: str
    female: bool
    height_m: float
    leg_length_m: float  # pendulum length l (greater trochanter height)
    sensor_height_m: float  # waist sensor above the floor, standing
    speed_factor: float  # multiplies every cruise speed drawn for this person
    walk_ratio_m_per_spm: float  # step length (m) / cadence (steps/min)
    bounce_factor: float  # multiplies the pendulum bounce (person-to-person amplitude)
    sway_factor: float  # multiplies lateral sway and pelvis rotation
    heel_strike_factor: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def draw_person(person_id: str, params: RoomParams, rng: np.random.Generator) -> Person:
    """A person's traits; the draw order is fixed (determinism)."""
    people, gait = params.people, params.gait
    female = bool(rng.random() < people.female_share)
    mean = people.female_height_m if female else people.male_height_m
    height = float(np.clip(rng.normal(mean, people.height_sd_m), MIN_HEIGHT_M, MAX_HEIGHT_M))
    speed_factor = float(np.clip(rng.normal(1.0, people.speed_factor_sd), *SPEED_FACTOR_LIMITS))
    walk_ratio = draw_walk_ratio(height, params, rng)
    bounce = float(math.exp(rng.normal(0.0, gait.bounce_person_sd)))
    sway = float(math.exp(rng.normal(0.0, 0.2)))  # assumption: +-20 % between people, like the bounce
    heel = float(math.exp(rng.normal(0.0, 0.3)))  # assumption: heel strikes differ more (footwear, style)
    return Person(person_id, female, height, people.leg_length_ratio * height, people.sensor_height_ratio * height,
                  speed_factor, walk_ratio, bounce, sway, heel)


def draw_walk_ratio(height_m: float, params: RoomParams, rng: np.random.Generator) -> float:
    """A person's walk ratio (m per step/min): it follows stature a little (taller people take longer
    steps at one cadence), spread by walk_ratio_sd, clipped to +-40 % of the figure."""
    gait = params.gait
    walk_ratio = gait.walk_ratio_m_per_spm * height_m / 1.65 + rng.normal(0.0, gait.walk_ratio_sd)
    return float(np.clip(walk_ratio, 0.6 * gait.walk_ratio_m_per_spm, 1.4 * gait.walk_ratio_m_per_spm))


def step_frequency_hz(speed_mps: np.ndarray, walk_ratio_m_per_spm: np.ndarray | float, step_ratio: np.ndarray | float,
                      params: RoomParams) -> np.ndarray:
    """Step frequency (Hz) at walking speed (m/s): constant walk ratio W = L / C gives C = sqrt(60 v / W)
    steps/min; `step_ratio` shortens the step for backward and sideways walking (same cadence, shorter
    step: W x ratio). Clipped to [min_step_frequency_hz, max_step_frequency_hz]."""
    gait = params.gait
    ratio = np.asarray(walk_ratio_m_per_spm) * np.asarray(step_ratio)
    cadence_spm = np.sqrt(60.0 * np.maximum(speed_mps, 0.0) / ratio)
    return np.clip(cadence_spm / 60.0, gait.min_step_frequency_hz, gait.max_step_frequency_hz)


def bounce_m(step_length_m: np.ndarray, leg_length_m: np.ndarray | float, params: RoomParams) -> np.ndarray:
    """Peak-to-peak vertical pelvis excursion h (m) for a step length (m): the inverted pendulum of
    Zijlstra & Hof (2003), step = 2 K sqrt(2 l h - h^2), solved for h = l - sqrt(l^2 - (step / 2K)^2)."""
    half = np.minimum(np.asarray(step_length_m) / (2.0 * params.gait.pendulum_correction), 0.9 * np.asarray(leg_length_m))
    return np.asarray(leg_length_m) - np.sqrt(np.asarray(leg_length_m) ** 2 - half ** 2)
