"""What a MEMS IMU reports, from an error-free signal: one error model and digitiser for every venue.

An IMU is a set of triads (accelerometer, gyroscope, magnetometer), each described by its venue's
figures (`Triad`: scale error, turn-on bias, noise, range and step, in the triad's own unit). Per
triad, drawn once (`TriadErrors`): a response (per-axis 1 + scale error, or a 3 x 3 sensitivity
with cross-axis terms off the diagonal) and a turn-on bias. Per sample: a bias random walk (where
the triad has one), white noise, then the ADC clips at the range and rounds to its step, and a
device that reports in a coarser unit rounds to that. The order follows the physics: the sensor is
mounted (rotation), senses (response, bias, walk, noise), then the ADC clips and rounds.

Draw order is fixed, because a venue's seeded streams depend on it: the triads in the order the
venue lists them; within a triad, response then bias when drawn, walk then noise when sensed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class Triad:
    """One three-axis sensor's figures, in its own unit (g, deg/s or uT) unless named otherwise."""

    scale_error_sd: float  # per axis, of the sensitivity error (1)
    bias_sd: float  # per axis, of the turn-on bias
    noise_sd: float  # of the white noise, per sample
    full_scale: float  # the range: the output is clipped at +-this
    step: float  # the converter's step
    walk_sd: float | None = None  # of the bias random walk's increments, per sample; None: no walk
    cross_axis_sd: float | None = None  # of each off-diagonal sensitivity; None: per-axis scale only
    unit: float | None = None  # the unit the device reports in, rounded to after the converter; None: the step


def adc_step(full_scale: float, bits: int) -> float:
    """The step of a signed `bits`-bit converter over +-full_scale."""
    return full_scale / 2 ** (bits - 1)


def white_noise_sd(density_per_sqrt_hz: float, rate_hz: float) -> float:
    """SD per sample of white noise of this density sampled at `rate_hz` (over the Nyquist band)."""
    return density_per_sqrt_hz * math.sqrt(rate_hz / 2.0)


def walk_increment_sd(density_per_sqrt_s: float, rate_hz: float) -> float:
    """SD per sample of the increments of a random walk of this density sampled at `rate_hz`."""
    return density_per_sqrt_s / math.sqrt(rate_hz)


class MemsFigures(Protocol):
    """The accelerometer and gyroscope figures every venue's `SensorParams` carries."""

    @property
    def rate_hz(self) -> float: ...
    @property
    def adc_bits(self) -> int: ...
    @property
    def accel_range_g(self) -> float: ...
    @property
    def accel_scale_error(self) -> float: ...
    @property
    def accel_bias_g(self) -> float: ...
    @property
    def accel_noise_g_per_sqrt_hz(self) -> float: ...
    @property
    def gyro_range_dps(self) -> float: ...
    @property
    def gyro_scale_error(self) -> float: ...
    @property
    def gyro_bias_dps(self) -> float: ...
    @property
    def gyro_noise_dps_per_sqrt_hz(self) -> float: ...
    @property
    def gyro_bias_walk_dps_per_sqrt_s(self) -> float: ...


def accel_triad(sensors: MemsFigures, *, walk_g_per_sqrt_s: float | None = None,
                cross_axis_sd: float | None = None, unit_g: float | None = None) -> Triad:
    """The accelerometer (g): no bias walk unless a density is given."""
    walk = None if walk_g_per_sqrt_s is None else walk_increment_sd(walk_g_per_sqrt_s, sensors.rate_hz)
    return Triad(sensors.accel_scale_error, sensors.accel_bias_g,
                 white_noise_sd(sensors.accel_noise_g_per_sqrt_hz, sensors.rate_hz), sensors.accel_range_g,
                 adc_step(sensors.accel_range_g, sensors.adc_bits), walk, cross_axis_sd, unit_g)


def gyro_triad(sensors: MemsFigures, *, cross_axis_sd: float | None = None,
               unit_dps: float | None = None) -> Triad:
    """The gyroscope (deg/s), with its bias random walk."""
    return Triad(sensors.gyro_scale_error, sensors.gyro_bias_dps,
                 white_noise_sd(sensors.gyro_noise_dps_per_sqrt_hz, sensors.rate_hz), sensors.gyro_range_dps,
                 adc_step(sensors.gyro_range_dps, sensors.adc_bits),
                 walk_increment_sd(sensors.gyro_bias_walk_dps_per_sqrt_s, sensors.rate_hz), cross_axis_sd, unit_dps)


@dataclass(frozen=True)
class TriadErrors:
    """One triad's errors, drawn once."""

    response: np.ndarray  # (3,) 1 + scale error per axis, or (3, 3) sensitivity (scale on the diagonal)
    bias: np.ndarray  # (3,) turn-on bias, in the triad's unit

    @classmethod
    def draw(cls, triad: Triad, rng: np.random.Generator) -> "TriadErrors":
        if triad.cross_axis_sd is None:
            response = 1.0 + rng.normal(0.0, triad.scale_error_sd, 3)
        else:
            cross = rng.normal(0.0, triad.cross_axis_sd, (3, 3))
            np.fill_diagonal(cross, 0.0)
            response = np.diag(1.0 + rng.normal(0.0, triad.scale_error_sd, 3)) + cross
        return cls(response, rng.normal(0.0, triad.bias_sd, 3))


def sense(signal: np.ndarray, triad: Triad, errors: TriadErrors, rng: np.random.Generator,
          mounting: np.ndarray | None = None) -> np.ndarray:
    """(n, 3) sensed values before the converter, from an error-free (n, 3) signal.

    `mounting`: (3, 3) sensor-from-ideal rotation applied to the signal first; None where the
    signal is already in the sensor frame.
    """
    count = len(signal)
    turned = signal if mounting is None else signal @ mounting.T
    sensed = turned * errors.response if errors.response.ndim == 1 else turned @ errors.response.T
    sensed += errors.bias
    if triad.walk_sd is not None:
        sensed += np.cumsum(rng.normal(0.0, triad.walk_sd, (count, 3)), axis=0)
    sensed += rng.normal(0.0, triad.noise_sd, (count, 3))
    return sensed


def digitise(values: np.ndarray, triad: Triad) -> np.ndarray:
    """Clip to +-full_scale and round to the converter's step, then to the device's unit if it has one."""
    converted = np.clip(np.round(values / triad.step) * triad.step, -triad.full_scale, triad.full_scale)
    return converted if triad.unit is None else np.round(converted / triad.unit) * triad.unit


@dataclass(frozen=True)
class Imu:
    """One IMU as drawn: its triads (name -> figures, in draw order), their errors, its mounting."""

    triads: dict[str, Triad]
    errors: dict[str, TriadErrors]
    mounting: np.ndarray | None  # (3, 3) sensor-from-ideal; None: the signals come in the sensor frame

    @classmethod
    def draw(cls, triads: dict[str, Triad], rng: np.random.Generator,
             mounting: np.ndarray | None = None) -> "Imu":
        return cls(triads, {name: TriadErrors.draw(triad, rng) for name, triad in triads.items()}, mounting)

    def measure(self, signals: dict[str, np.ndarray], rng: np.random.Generator) -> dict[str, np.ndarray]:
        """Reported (n, 3) values per triad name from error-free signals, sensed in the triads' order.

        KeyError names a triad without a signal."""
        sensed = {name: sense(signals[name], triad, self.errors[name], rng, self.mounting)
                  for name, triad in self.triads.items()}
        return {name: digitise(values, self.triads[name]) for name, values in sensed.items()}
