"""A walker's traits, drawn once per person: stature, cadence, step length, how they hold a phone."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from sim_devices.pedestrian.params import GaitParams, PeopleParams

PAPER_HEIGHTS_M = (1.69, 1.74, 1.79)  # the paper's three walkers (tables 1-2)
MIN_HEIGHT_M, MAX_HEIGHT_M = 1.45, 2.05  # clip of drawn statures (about +-4 SD)


@dataclass(frozen=True)
class Person:
    person_id: str
    height_m: float
    cadence_hz: float  # preferred step frequency
    step_length_m: float  # at cruise speed and the preferred cadence
    step_ratio_factor: float  # the person's own step length / the stature model's

    @property
    def speed_mps(self) -> float:
        return self.cadence_hz * self.step_length_m

    def to_dict(self) -> dict[str, Any]:
        return {"height_m": self.height_m, "cadence_hz": self.cadence_hz, "step_length_m": self.step_length_m,
                "speed_mps": self.speed_mps, "step_ratio_factor": self.step_ratio_factor}


def model_step_length_m(height_m: float, cadence_hz: float, gait: GaitParams) -> float:
    """Step length of the stature-and-cadence model (before the person's own factor)."""
    return height_m * gait.step_height_ratio * (cadence_hz / gait.step_reference_hz) ** gait.step_cadence_exponent


def draw_person(index: int, people: PeopleParams, gait: GaitParams, rng: np.random.Generator) -> Person:
    """Person `index` (0-based): the first three have the paper's statures, later ones are drawn."""
    drawn = float(np.clip(rng.normal(people.height_mean_m, people.height_sd_m), MIN_HEIGHT_M, MAX_HEIGHT_M))
    height = PAPER_HEIGHTS_M[index] if index < len(PAPER_HEIGHTS_M) else drawn
    cadence = float(rng.uniform(gait.cadence_min_hz, gait.cadence_max_hz))
    factor = float(math.exp(rng.normal(0.0, gait.step_ratio_person_sd)))
    return Person(person_id(index), height, cadence, model_step_length_m(height, cadence, gait) * factor, factor)


def person_id(index: int) -> str:
    return f"p{index + 1:02d}"
