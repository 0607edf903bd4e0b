"""The waist sensor: from a person's body motion to what an ICM-20948-class IMU on the belt reports.

Kinematics. The pelvis frame is x forward, y left, z up (Rz(yaw) Ry(pitch) Rx(roll), pitch positive
leaning forward). The sensor sits on the back of the belt, `LEVER_M` behind the pelvis centre, and
its frame is the pelvis frame turned by the mounting: R_sensor = R_pelvis Ry(belt pitch) M, with the
belt pitch drawn in +-`sensors.belt_pitch_deg` (the lumbar curve) and M a small random
misalignment (SD `sensors.misalignment_deg` per axis). Sensor axes are therefore x forward, y left,
z up when standing (Sensor forward_axis "+x", left_axis "+y"). Specific force = second difference
of the sensor position at the IMU rate plus the heel-strike transients plus g up, resolved in the
sensor frame, in g; angular rate = vee(R^T dR/dt) in the sensor frame, in deg/s.

Errors (drawn once per sensor): per-axis scale, turn-on biases; per sample: gyro bias random walk
and white noise (density x sqrt(rate / 2)); then the ADC clips at the range and rounds to its
16-bit step. Clock: device time = (1 + drift) x true time + offset (both drawn per sensor); samples
are taken at true instants, only their stamps carry the clock error. No magnetometer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim_devices.common import small_rotation
from sim_devices.room.gait import STANDARD_GRAVITY, BodyMotion
from sim_devices.room.params import LinkParams, SensorParams

LEVER_M = np.array([-0.10, 0.0, 0.0])  # belt sensor on the lower back, behind the pelvis centre; assumption


def rotation(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(n, 3, 3) body-to-world rotations Rz(yaw) Ry(pitch) Rx(roll); pitch > 0 tips x down."""
    cy, sy, cp, sp, cr, sr = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    out = np.empty((len(yaw), 3, 3))
    out[:, 0, 0], out[:, 0, 1], out[:, 0, 2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
    out[:, 1, 0], out[:, 1, 1], out[:, 1, 2] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
    out[:, 2, 0], out[:, 2, 1], out[:, 2, 2] = -sp, cp * sr, cp * cr
    return out


def angular_rate(rotations: np.ndarray, rate_hz: float) -> np.ndarray:
    """Body-frame angular velocity (rad/s) of (n, 3, 3) body-to-world rotations sampled at `rate_hz`."""
    change = np.empty_like(rotations)
    change[1:-1] = rotations[2:] - rotations[:-2]
    change[0], change[-1] = 2.0 * (rotations[1] - rotations[0]), 2.0 * (rotations[-1] - rotations[-2])
    w = np.einsum("nji,njk->nik", rotations, change) * (rate_hz / 2.0)
    return np.stack([w[:, 2, 1] - w[:, 1, 2], w[:, 0, 2] - w[:, 2, 0], w[:, 1, 0] - w[:, 0, 1]], axis=1) / 2.0


def exact_signals(body: BodyMotion, mounting: np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Error-free (specific force g, angular rate deg/s), (n, 3) each, in the sensor frame."""
    pelvis = rotation(body.yaw_rad, body.pitch_rad, body.roll_rad)
    position = body.pelvis_m + pelvis @ LEVER_M
    accel = np.empty_like(position)
    accel[1:-1] = (position[2:] - 2.0 * position[1:-1] + position[:-2]) * rate_hz * rate_hz
    accel[0], accel[-1] = accel[1], accel[-2]
    accel[:, 2] += STANDARD_GRAVITY + body.heel_strike_mps2
    sensor = pelvis @ mounting
    specific = np.einsum("nji,nj->ni", sensor, accel) / STANDARD_GRAVITY
    return specific, np.degrees(angular_rate(sensor, rate_hz))


@dataclass(frozen=True)
class ImuErrors:
    """One sensor's mounting and errors, drawn once."""

    belt_pitch_deg: float
    mounting: np.ndarray  # (3, 3) sensor-to-pelvis rotation
    accel_scale: np.ndarray  # (3,) 1 + error
    accel_bias_g: np.ndarray
    gyro_scale: np.ndarray
    gyro_bias_dps: np.ndarray

    @classmethod
    def draw(cls, sensors: SensorParams, rng: np.random.Generator) -> "ImuErrors":
        pitch = float(rng.uniform(-sensors.belt_pitch_deg, sensors.belt_pitch_deg))
        belt = rotation(np.zeros(1), np.radians([pitch]), np.zeros(1))[0]
        mounting = belt @ small_rotation(rng, sensors.misalignment_deg)
        return cls(pitch, mounting, 1.0 + rng.normal(0.0, sensors.accel_scale_error, 3),
                   rng.normal(0.0, sensors.accel_bias_g, 3), 1.0 + rng.normal(0.0, sensors.gyro_scale_error, 3),
                   rng.normal(0.0, sensors.gyro_bias_dps, 3))


def measure(accel_g: np.ndarray, gyro_dps: np.ndarray, errors: ImuErrors, sensors: SensorParams,
            rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Reported (accel g, gyro deg/s), (n, 3) each, from exact sensor-frame signals (draw order fixed)."""
    n, rate = len(accel_g), sensors.rate_hz
    band = math.sqrt(rate / 2.0)  # white noise over the Nyquist band
    accel = accel_g * errors.accel_scale + errors.accel_bias_g
    accel += rng.normal(0.0, sensors.accel_noise_g_per_sqrt_hz * band, (n, 3))
    walk = np.cumsum(rng.normal(0.0, sensors.gyro_bias_walk_dps_per_sqrt_s / math.sqrt(rate), (n, 3)), axis=0)
    gyro = gyro_dps * errors.gyro_scale + errors.gyro_bias_dps + walk
    gyro += rng.normal(0.0, sensors.gyro_noise_dps_per_sqrt_hz * band, (n, 3))
    return (_digitise(accel, sensors.accel_range_g, sensors.adc_bits),
            _digitise(gyro, sensors.gyro_range_dps, sensors.adc_bits))


def _digitise(values: np.ndarray, full_scale: float, bits: int) -> np.ndarray:
    step = full_scale / 2 ** (bits - 1)
    return np.clip(np.round(values / step) * step, -full_scale, full_scale)


@dataclass(frozen=True)
class DeviceClock:
    """device time = (1 + drift) x true time + offset, stamped in ns from the session epoch."""

    epoch_ns: int
    offset_s: float
    drift: float

    @classmethod
    def draw(cls, link: LinkParams, rng: np.random.Generator) -> "DeviceClock":
        return cls(link.start_unix_s * 1_000_000_000, float(rng.normal(0.0, link.clock_offset_ms * 1e-3)),
                   float(rng.normal(0.0, link.clock_drift_ppm * 1e-6)))

    def stamp_ns(self, true_s: np.ndarray) -> np.ndarray:
        device_s = (1.0 + self.drift) * np.asarray(true_s, dtype=np.float64) + self.offset_s
        return self.epoch_ns + np.round(device_s * 1e9).astype(np.int64)


@dataclass(frozen=True)
class WaistImu:
    """Everything one waist sensor reports, in its own clock."""

    agent_id: str
    sensor_id: str
    clock: DeviceClock
    errors: ImuErrors
    stamps_ns: np.ndarray  # (n,) int64, device clock
    accel_g: np.ndarray  # (n, 3) float32
    gyro_dps: np.ndarray


def waist_imu(agent_id: str, body: BodyMotion, time_s: np.ndarray, sensors: SensorParams, link: LinkParams,
              rng: np.random.Generator) -> WaistImu:
    """The waist sensor's stream for one person (draw order: mounting and errors, noise, clock)."""
    errors = ImuErrors.draw(sensors, rng)
    accel, gyro = exact_signals(body, errors.mounting, sensors.rate_hz)
    accel, gyro = measure(accel, gyro, errors, sensors, rng)
    clock = DeviceClock.draw(link, rng)
    return WaistImu(agent_id, sensor_id(agent_id), clock, errors, clock.stamp_ns(time_s), accel.astype(np.float32),
                    gyro.astype(np.float32))


def sensor_id(agent_id: str) -> str:
    return f"{agent_id}-waist"
