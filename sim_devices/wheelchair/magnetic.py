"""Seat magnetometer: earth field, a building disturbance that varies over the court, chair iron.

Earth field (court frame, z up): horizontal part `field_ut * cos(inclination)` pointing to magnetic
north, vertical part `field_ut * sin(inclination)` pointing down (northern hemisphere). Court +x
has azimuth `court_azimuth_deg` clockwise from magnetic north, so north lies that many degrees
counter-clockwise from +x.

Building disturbance: each axis is an independent smooth random field over the court, a sum of
WAVES plane waves with random directions, wavelengths log-normal around
`disturbance_wavelength_m` and random phases, scaled to RMS `disturbance_ut` per axis. It is not
made curl-free (a real static field would be); for heading error only its horizontal size and
smoothness matter.

Chair: hard iron (a fixed vector in the sensor frame) and soft iron (a symmetric matrix near
identity acting on the external field), both drawn per chair; then white noise, saturation at
`range_gauss` and the AK8963 step. Output in gauss (1 gauss = 100 uT).
"""

from __future__ import annotations

import math

import numpy as np

from sim_devices.wheelchair.params import MagneticParams

MAG_LSB_UT = 0.15  # AK8963 16-bit output step (datasheet), also AK09916 in the ICM-20948
WAVES = 32  # plane waves per axis of the disturbance field
WAVELENGTH_SPREAD = 0.4  # log-normal SD of the wavelengths
UT_PER_GAUSS = 100.0


class CourtField:
    """The magnetic field (uT, court frame) at any court position."""

    def __init__(self, params: MagneticParams, rng: np.random.Generator):
        inclination = math.radians(params.inclination_deg)
        north = math.radians(params.court_azimuth_deg)  # north, counter-clockwise from court +x
        horizontal = params.field_ut * math.cos(inclination)
        self.earth_ut = np.array([horizontal * math.cos(north), horizontal * math.sin(north),
                                  -params.field_ut * math.sin(inclination)])
        wavelengths = params.disturbance_wavelength_m * np.exp(rng.normal(0.0, WAVELENGTH_SPREAD, (3, WAVES)))
        directions = rng.uniform(0.0, 2.0 * math.pi, (3, WAVES))
        self.wave_x = 2.0 * math.pi / wavelengths * np.cos(directions)
        self.wave_y = 2.0 * math.pi / wavelengths * np.sin(directions)
        self.phase = rng.uniform(0.0, 2.0 * math.pi, (3, WAVES))
        self.amplitude = params.disturbance_ut * math.sqrt(2.0 / WAVES)  # each cosine has variance A^2 / 2

    def field_ut(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """(N, 3) field at positions (N,), court frame."""
        result = np.tile(self.earth_ut, (len(x_m), 1))
        if self.amplitude > 0:
            for axis in range(3):
                argument = np.outer(x_m, self.wave_x[axis]) + np.outer(y_m, self.wave_y[axis]) + self.phase[axis]
                result[:, axis] += self.amplitude * np.cos(argument).sum(axis=1)
        return result


def seat_magnetometer(field_court_ut: np.ndarray, heading_rad: np.ndarray, mounting: np.ndarray,
                      params: MagneticParams, rng: np.random.Generator) -> np.ndarray:
    """Reported (N, 3) gauss of a seat magnetometer (sensor frame = chair frame after `mounting`).

    The chair's hard and soft iron are drawn here from `rng`, then per-sample noise.
    """
    cos_h, sin_h = np.cos(heading_rad), np.sin(heading_rad)
    chair = np.stack([cos_h * field_court_ut[:, 0] + sin_h * field_court_ut[:, 1],
                      -sin_h * field_court_ut[:, 0] + cos_h * field_court_ut[:, 1], field_court_ut[:, 2]], axis=1)
    hard_iron = rng.normal(0.0, params.hard_iron_ut, 3)
    soft = rng.normal(0.0, params.soft_iron, (3, 3))
    soft_iron = np.eye(3) + (soft + soft.T) / 2.0
    sensed = (chair @ mounting.T) @ soft_iron.T + hard_iron
    sensed += rng.normal(0.0, params.noise_ut, sensed.shape)
    gauss = np.round(sensed / MAG_LSB_UT) * (MAG_LSB_UT / UT_PER_GAUSS)
    return np.clip(gauss, -params.range_gauss, params.range_gauss)
