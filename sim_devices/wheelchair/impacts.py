"""Accelerometer spikes and vibration: contacts, other jolts, rolling vibration (`impacts.*`, `sensors.*`).

An impact is a half-sine pulse of `impacts.pulse_ms` and peak P (g) along a direction in the
chair frame, followed by frame ringing (`ring_fraction` * P, `ring_hz`, decaying over
`ring_decay_ms`). The pulse is evaluated at the 200 Hz sample instants, so the sampled peak is
0.71-1.0 of P for a 10 ms pulse, as with a real accelerometer that samples a short impact.
With gravity on z, a horizontal pulse of P gives the paper's |sqrt(ax^2 + ay^2 + az^2) - 1| of
sqrt(1 + P^2) - 1, about P - 1 for large P.

Contacts (both chairs): median P = `contact_g_per_mps` * closing speed, log-normal spread
`contact_spread`, direction along the impulse the chair received (horizontal) with some vertical
part. Other jolts (bumps, ball hits, hard stops, caster landings): a Poisson process of
`noncontact_rate_per_min` per player, median `noncontact_median_g`, log-normal spread
`noncontact_spread`, mostly vertical. These distributions are assumptions shaped by the trend of
the paper's Fig. 5 (a 4-12 g threshold trades recall for precision), not fitted to any accuracy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim_devices.wheelchair.motion import Motion
from sim_devices.wheelchair.params import SimParams

CONTACT_VERTICAL_SD = 0.3  # vertical part of a contact pulse direction, relative to the horizontal 1
JOLT_HORIZONTAL_SD = 0.5  # horizontal part of a jolt direction, relative to the vertical 1
RING_DECAYS = 5.0  # ringing is dropped after this many decay times


@dataclass(frozen=True)
class Impact:
    """A spike on one chair's seat accelerometer."""

    time_s: float
    agent: int
    peak_g: float
    direction: tuple[float, float, float]  # unit vector, chair frame
    contact: bool


def contact_impacts(motion: Motion, params: SimParams, rng: np.random.Generator) -> list[Impact]:
    """Two impacts (one per chair) for every contact of `motion`."""
    impacts = []
    dt = motion.time_s[1] - motion.time_s[0] if len(motion.time_s) > 1 else 1.0
    for contact in motion.contacts:
        step = min(int(contact.time_s / dt), len(motion.time_s) - 1)
        for agent, sign in ((contact.first, -1.0), (contact.second, 1.0)):
            heading = motion.heading_rad[step, agent]
            nx, ny = sign * contact.normal[0], sign * contact.normal[1]
            local = np.array([nx * math.cos(heading) + ny * math.sin(heading),
                              -nx * math.sin(heading) + ny * math.cos(heading), rng.normal(0.0, CONTACT_VERTICAL_SD)])
            peak = params.impacts.contact_g_per_mps * contact.closing_mps * math.exp(
                rng.normal(0.0, params.impacts.contact_spread))
            impacts.append(Impact(contact.time_s, agent, peak, _unit(local), True))
    return impacts


def jolt_impacts(motion: Motion, agent: int, params: SimParams, rng: np.random.Generator) -> list[Impact]:
    """Non-contact jolts of one player: Poisson times, log-normal peaks, mostly vertical."""
    impacts_params = params.impacts
    duration = float(motion.time_s[-1]) if len(motion.time_s) else 0.0
    count = int(rng.poisson(impacts_params.noncontact_rate_per_min / 60.0 * duration))
    times = np.sort(rng.uniform(0.0, duration, count))
    impacts = []
    for time_s in times.tolist():
        peak = impacts_params.noncontact_median_g * math.exp(rng.normal(0.0, impacts_params.noncontact_spread))
        direction = np.array([rng.normal(0.0, JOLT_HORIZONTAL_SD), rng.normal(0.0, JOLT_HORIZONTAL_SD),
                              rng.choice([-1.0, 1.0])])
        impacts.append(Impact(time_s, agent, peak, _unit(direction), False))
    return impacts


def add_impacts(accel_g: np.ndarray, time_s: np.ndarray, impacts: list[Impact], params: SimParams) -> None:
    """Add each impact's pulse and ringing to `accel_g` (steps, 3) in place, sampled at `time_s`."""
    settings = params.impacts
    pulse_s, decay_s = settings.pulse_ms * 1e-3, settings.ring_decay_ms * 1e-3
    rate = params.sensors.rate_hz
    for impact in impacts:
        first = int(math.ceil(impact.time_s * rate))
        last = min(int((impact.time_s + pulse_s + RING_DECAYS * decay_s) * rate), len(time_s) - 1)
        if first > last:
            continue
        since = time_s[first:last + 1] - impact.time_s
        ring = since - pulse_s
        shape = np.where(since <= pulse_s, np.sin(np.pi * np.clip(since / pulse_s, 0.0, 1.0)),
                         settings.ring_fraction * np.exp(-np.maximum(ring, 0.0) / decay_s)
                         * np.sin(2.0 * np.pi * settings.ring_hz * ring))
        accel_g[first:last + 1] += impact.peak_g * np.outer(shape, impact.direction)


def add_vibration(accel_g: np.ndarray, speed_mps: np.ndarray, params: SimParams, rng: np.random.Generator) -> None:
    """Add white vibration with SD `vibration_g + vibration_g_per_mps * |speed|` per axis, in place."""
    sensors = params.sensors
    sd = sensors.vibration_g + sensors.vibration_g_per_mps * np.abs(speed_mps)
    accel_g += rng.normal(0.0, 1.0, accel_g.shape) * sd[:, None]


def _unit(vector: np.ndarray) -> tuple[float, float, float]:
    norm = float(np.linalg.norm(vector))
    x, y, z = (vector / norm).tolist() if norm > 0 else (0.0, 0.0, 1.0)
    return (x, y, z)
