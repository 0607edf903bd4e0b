"""The phone's sensors: the indoor magnetic field, and what a BMI160 / AK09911-class phone reports.

Field (venue frame, uT): Earth's field (intensity, inclination, declination; north at
`magnetic.north_deg`) times the floor's shielding factor 1 - mid_floor_loss x sin^2(pi floor /
storeys), plus a local anomaly: a sum of `ANOMALY_WAVES` plane waves in x, y with random vector
amplitudes (SD `anomaly_ut` per component in total) and wavelengths in [anomaly_min_m,
anomaly_max_m]. Drawn once per venue, so every walker meets the same anomalies.

Errors (drawn once per phone): one misalignment of the sensor package in the phone body; per
axis scale and turn-on bias for accelerometer, gyroscope and magnetometer (hard and soft iron
left after Android's calibration); per sample: gyro bias random walk, white noise (density x
sqrt(rate / 2)), then clipping at the range and rounding to the ADC step. Timestamps: the true
instant plus Gaussian jitter, kept strictly increasing; the phone's clock is the truth's clock
(as in a phone's own recording, e.g. the ILC walks).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim_devices.common import small_rotation
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


@dataclass(frozen=True)
class PhoneErrors:
    """One phone's sensor errors, drawn once."""

    misalignment: np.ndarray  # (3, 3) sensor-to-phone
    accel_scale: np.ndarray
    accel_bias_g: np.ndarray
    gyro_scale: np.ndarray
    gyro_bias_dps: np.ndarray
    mag_scale: np.ndarray
    mag_bias_ut: np.ndarray

    @classmethod
    def draw(cls, sensors: SensorParams, rng: np.random.Generator) -> "PhoneErrors":
        return cls(small_rotation(rng, sensors.misalignment_deg),
                   1.0 + rng.normal(0.0, sensors.accel_scale_error, 3), rng.normal(0.0, sensors.accel_bias_g, 3),
                   1.0 + rng.normal(0.0, sensors.gyro_scale_error, 3), rng.normal(0.0, sensors.gyro_bias_dps, 3),
                   1.0 + rng.normal(0.0, sensors.mag_scale_error, 3), rng.normal(0.0, sensors.mag_bias_ut, 3))

    def to_dict(self) -> dict[str, list[float]]:
        return {"accel_bias_g": self.accel_bias_g.tolist(), "accel_scale": self.accel_scale.tolist(),
                "gyro_bias_dps": self.gyro_bias_dps.tolist(), "gyro_scale": self.gyro_scale.tolist(),
                "mag_bias_ut": self.mag_bias_ut.tolist(), "mag_scale": self.mag_scale.tolist()}


def measure(accel_g: np.ndarray, gyro_dps: np.ndarray, field_ut: np.ndarray, errors: PhoneErrors,
            sensors: SensorParams, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reported (accel g, gyro deg/s, mag uT), (n, 3) each, from exact phone-frame signals."""
    n, rate = len(accel_g), sensors.rate_hz
    band = math.sqrt(rate / 2.0)
    turn = errors.misalignment.T  # phone frame to sensor frame
    accel = (accel_g @ turn.T) * errors.accel_scale + errors.accel_bias_g
    accel += rng.normal(0.0, sensors.accel_noise_g_per_sqrt_hz * band, (n, 3))
    walk = np.cumsum(rng.normal(0.0, sensors.gyro_bias_walk_dps_per_sqrt_s / math.sqrt(rate), (n, 3)), axis=0)
    gyro = (gyro_dps @ turn.T) * errors.gyro_scale + errors.gyro_bias_dps + walk
    gyro += rng.normal(0.0, sensors.gyro_noise_dps_per_sqrt_hz * band, (n, 3))
    mag = (field_ut @ turn.T) * errors.mag_scale + errors.mag_bias_ut + rng.normal(0.0, sensors.mag_noise_ut, (n, 3))
    mag = np.clip(np.round(mag / sensors.mag_step_ut) * sensors.mag_step_ut, -sensors.mag_range_ut,
                  sensors.mag_range_ut)
    return (_digitise(accel, sensors.accel_range_g, sensors.adc_bits),
            _digitise(gyro, sensors.gyro_range_dps, sensors.adc_bits), mag)


def _digitise(values: np.ndarray, full_scale: float, bits: int) -> np.ndarray:
    step = full_scale / 2 ** (bits - 1)
    return np.clip(np.round(values / step) * step, -full_scale, full_scale)


def stamps_ns(true_ns: np.ndarray, sensors: SensorParams, rng: np.random.Generator) -> np.ndarray:
    """Sample timestamps: the true instants plus jitter, strictly increasing."""
    jitter = np.round(rng.normal(0.0, sensors.timestamp_jitter_ms * 1e6, len(true_ns))).astype(np.int64)
    stamps = true_ns + jitter
    floor = np.maximum.accumulate(stamps - np.arange(len(stamps)))  # strictly increasing by at least 1 ns
    return floor + np.arange(len(stamps))
