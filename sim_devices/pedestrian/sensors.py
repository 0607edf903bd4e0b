"""The phone's sensors: the indoor magnetic field, and the figures of a BMI160 / AK09911-class phone.

Field (venue frame, uT): Earth's field (intensity, inclination, declination; north at
`magnetic.north_deg`) times the floor's shielding factor 1 - mid_floor_loss x sin^2(pi floor /
storeys), plus a local anomaly: a sum of `ANOMALY_WAVES` plane waves in x, y with random vector
amplitudes (SD `anomaly_ut` per component in total) and wavelengths in [anomaly_min_m,
anomaly_max_m]. Drawn once per venue, so every walker meets the same anomalies.

Errors (`sim_devices.devices.imu`, drawn once per phone): one misalignment of the sensor package
in the phone body; per axis scale and turn-on bias for accelerometer, gyroscope and magnetometer
(hard and soft iron left after Android's calibration); per sample: gyro bias random walk, white
noise (density x sqrt(rate / 2)), then clipping at the range and rounding to the ADC step.
Timestamps (`sim_devices.devices.clock.jittered_stamps_ns`): the true instant plus Gaussian
jitter, kept strictly increasing; the phone's clock is the truth's clock (as in a phone's own
recording, e.g. the ILC walks).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim_devices.common import small_rotation
from sim_devices.devices.imu import Imu, Triad, accel_triad, gyro_triad
from sim_devices.pedestrian.params import MagneticParams, SensorParams

ANOMALY_WAVES = 24


@dataclass(frozen=True)
class MagneticField:
    earth_ut: np.ndarray  # (3,) venue frame, after the floor's shielding
    amplitudes_ut: np.ndarray  # (k, 3)
    wavevectors: np.ndarray  # (k, 2) rad/m
    phases: np.ndarray  # (k,)
    floor_factor: float

    @classmethod
    def draw(cls, magnetic: MagneticParams, rng: np.random.Generator) -> "MagneticField":
        factor = 1.0 - magnetic.mid_floor_loss * math.sin(math.pi * magnetic.floor / magnetic.storeys) ** 2
        north = math.radians(magnetic.north_deg - magnetic.declination_deg)  # declination: east positive
        dip = math.radians(magnetic.inclination_deg)
        earth = magnetic.field_ut * np.array([math.cos(dip) * math.cos(north), math.cos(dip) * math.sin(north),
                                              -math.sin(dip)])
        wavelengths = rng.uniform(magnetic.anomaly_min_m, magnetic.anomaly_max_m, ANOMALY_WAVES)
        directions = rng.uniform(0.0, 2 * math.pi, ANOMALY_WAVES)
        wavevectors = (2 * math.pi / wavelengths)[:, None] * np.column_stack([np.cos(directions), np.sin(directions)])
        amplitudes = rng.normal(0.0, magnetic.anomaly_ut * math.sqrt(2.0 / ANOMALY_WAVES), (ANOMALY_WAVES, 3))
        return cls(factor * earth, amplitudes, wavevectors, rng.uniform(0.0, 2 * math.pi, ANOMALY_WAVES), factor)

    def at(self, position_m: np.ndarray) -> np.ndarray:
        """(n, 3) field in uT, venue frame, at (n, >= 2) positions."""
        waves = np.cos(position_m[:, :2] @ self.wavevectors.T + self.phases[None, :])
        return self.earth_ut[None, :] + waves @ self.amplitudes_ut


def phone_triads(sensors: SensorParams) -> dict[str, Triad]:
    """The phone's accelerometer, gyroscope, then magnetometer (the order their errors are drawn and
    sensed in); the magnetometer has no bias walk and its own step and range."""
    magnetometer = Triad(sensors.mag_scale_error, sensors.mag_bias_ut, sensors.mag_noise_ut, sensors.mag_range_ut,
                         sensors.mag_step_ut)
    return {"accel": accel_triad(sensors), "gyro": gyro_triad(sensors), "mag": magnetometer}


def draw_phone(sensors: SensorParams, rng: np.random.Generator) -> Imu:
    """One phone's sensors: the package's misalignment in the phone body, then every triad's errors."""
    misalignment = small_rotation(rng, sensors.misalignment_deg)  # sensor-to-phone
    return Imu.draw(phone_triads(sensors), rng, mounting=misalignment.T)  # signals come in the phone frame


def error_record(phone: Imu) -> dict[str, list[float]]:
    """The drawn biases and scales, as the session's source records them."""
    accel, gyro, mag = phone.errors["accel"], phone.errors["gyro"], phone.errors["mag"]
    return {"accel_bias_g": accel.bias.tolist(), "accel_scale": accel.response.tolist(),
            "gyro_bias_dps": gyro.bias.tolist(), "gyro_scale": gyro.response.tolist(),
            "mag_bias_ut": mag.bias.tolist(), "mag_scale": mag.response.tolist()}
