"""People walking in the room: traits, activities and the waist's motion of every wearer, seeded.

`simulate_walk(people, duration_s, params, seed)` draws each person's traits (person.py), plans
everyone's activities together (activities.py: they avoid each other but still pass close, which is
what makes identification hard), then adds each person's steps, sway, rotation and sitting
(gait.py). Everything comes from children of `numpy.random.SeedSequence(seed)` in a fixed order, so
one seed gives one motion, and a person's gait draws do not depend on how many others there are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim_devices.room.activities import Activity, Plan, plan_paths
from sim_devices.room.gait import BodyMotion, body_motion
from sim_devices.room.params import RoomParams
from sim_devices.room.person import Person, draw_person


def person_id(index: int) -> str:
    """Agent id of wearer `index` (0-based): p01, p02, ..."""
    return f"p{index + 1:02d}"


@dataclass(frozen=True)
class Motion:
    """Every wearer's motion at the IMU rate."""

    time_s: np.ndarray  # (n,) from the session start
    persons: list[Person]
    plan: Plan
    bodies: list[BodyMotion]

    @property
    def room_m(self) -> tuple[float, float]:
        return self.plan.room_m

    def activity_share(self) -> dict[str, float]:
        """Share of person-time in each activity (over all wearers)."""
        codes = self.plan.activity
        return {kind.name.lower(): float(np.mean(codes == kind)) for kind in Activity}


def simulate_walk(people: int, duration_s: float, params: RoomParams, seed: np.random.SeedSequence) -> Motion:
    """The motion of `people` wearers over `duration_s` s (IMU-rate samples, both ends included)."""
    trait_seed, plan_seed, gait_seed = seed.spawn(3)
    trait_seeds = trait_seed.spawn(people)
    persons = [draw_person(person_id(i), params, np.random.default_rng(trait_seeds[i])) for i in range(people)]
    plan = plan_paths(persons, duration_s, params, np.random.default_rng(plan_seed))
    gait_seeds = gait_seed.spawn(people)
    bodies = [body_motion(plan, i, persons[i], params, np.random.default_rng(gait_seeds[i])) for i in range(people)]
    return Motion(plan.time_s, persons, plan, bodies)
