"""Sensor error model: what turns an error-free signal into what a MEMS IMU reports, and its clock.

Per sensor, drawn once (`sensors.*`): a mounting misalignment (small rotation, also the seat's
tilt), per-axis scale errors, turn-on biases. Per sample: a bias random walk (gyro), white noise
from the noise density over the Nyquist band, then saturation at the range and quantisation to
the ADC step. The order follows the physics: the sensor is mounted (rotation), senses (scale,
bias, noise), then the ADC clips and rounds.

Clock: each device stamps samples with its own clock, device = (1 + drift) * true + offset,
plus a small per-sample jitter (clipped so samples never swap order). Samples are taken
at the simulation's true instants; only their stamps carry the clock error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim_devices.common import small_rotation
from sim_devices.wheelchair.params import ClockParams, SensorParams

MAG_LSB_UT = 0.15  # AK8963 16-bit output step (datasheet), also AK09916 in the ICM-20948
JITTER_CLIP_SD = 3.0


@dataclass(frozen=True)
class ImuErrors:
    """The errors of one IMU, drawn once."""

    mounting: np.ndarray  # (3, 3) sensor-from-ideal rotation
    gyro_scale: np.ndarray  # (3,) 1 + error
    gyro_bias_dps: np.ndarray  # (3,) turn-on bias
    accel_scale: np.ndarray
    accel_bias_g: np.ndarray

    @classmethod
    def draw(cls, params: SensorParams, rng: np.random.Generator) -> "ImuErrors":
        return cls(small_rotation(rng, params.misalignment_deg),
                   1.0 + rng.normal(0.0, params.gyro_scale_error, 3), rng.normal(0.0, params.gyro_bias_dps, 3),
                   1.0 + rng.normal(0.0, params.accel_scale_error, 3), rng.normal(0.0, params.accel_bias_g, 3))


def measure(gyro_dps: np.ndarray, accel_g: np.ndarray, errors: ImuErrors, params: SensorParams,
            rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Reported (gyro deg/s, accel g), (steps, 3) each, from error-free signals in the ideal sensor frame."""
    steps = len(gyro_dps)
    bandwidth = math.sqrt(params.rate_hz / 2.0)  # white noise over the Nyquist band
    walk = np.cumsum(rng.normal(0.0, params.gyro_bias_walk_dps_per_sqrt_s / math.sqrt(params.rate_hz), (steps, 3)),
                     axis=0)
    gyro = (gyro_dps @ errors.mounting.T) * errors.gyro_scale + errors.gyro_bias_dps + walk
    gyro += rng.normal(0.0, params.gyro_noise_dps_per_sqrt_hz * bandwidth, (steps, 3))
    accel = (accel_g @ errors.mounting.T) * errors.accel_scale + errors.accel_bias_g
    accel += rng.normal(0.0, params.accel_noise_g_per_sqrt_hz * bandwidth, (steps, 3))
    return (digitise(gyro, params.gyro_range_dps, params.adc_bits),
            digitise(accel, params.accel_range_g, params.adc_bits))


def digitise(values: np.ndarray, full_scale: float, bits: int) -> np.ndarray:
    """Clip to +-full_scale and round to the step of a signed `bits`-bit converter over that range."""
    step = full_scale / 2 ** (bits - 1)
    return np.clip(np.round(values / step) * step, -full_scale, full_scale)


@dataclass(frozen=True)
class DeviceClock:
    """device time = (1 + drift) * true time + offset, stamped in ns from the session epoch."""

    epoch_ns: int
    offset_s: float
    drift: float
    jitter_s: float

    @classmethod
    def draw(cls, params: ClockParams, rng: np.random.Generator) -> "DeviceClock":
        return cls(params.start_unix_s * 1_000_000_000, float(rng.normal(0.0, params.offset_ms * 1e-3)),
                   float(rng.normal(0.0, params.drift_ppm * 1e-6)), params.jitter_ms * 1e-3)

    def stamp_ns(self, true_s: np.ndarray, rng: np.random.Generator | None = None,
                 period_s: float = math.inf) -> np.ndarray:
        """Device timestamps (int64 ns) of events at true times `true_s`.

        With `rng`, each stamp gets jitter clipped at 3 SD and at 0.45 `period_s`, so samples
        `period_s` apart keep their order.
        """
        device_s = (1.0 + self.drift) * np.asarray(true_s, dtype=np.float64) + self.offset_s
        if rng is not None and self.jitter_s > 0:
            limit = min(JITTER_CLIP_SD * self.jitter_s, 0.45 * period_s)
            device_s = device_s + np.clip(rng.normal(0.0, self.jitter_s, device_s.shape), -limit, limit)
        return self.epoch_ns + np.round(device_s * 1e9).astype(np.int64)
