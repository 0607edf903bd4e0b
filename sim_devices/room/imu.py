"""The waist sensor: from a person's body motion to what an ICM-20948-class IMU on the belt reports.

Kinematics. The pelvis frame is x forward, y left, z up (Rz(yaw) Ry(pitch) Rx(roll), pitch positive
leaning forward). The sensor sits on the back of the belt, `LEVER_M` behind the pelvis centre, and
its frame is the pelvis frame turned by the mounting: R_sensor = R_pelvis Ry(belt pitch) M, with the
belt pitch drawn in +-`sensors.belt_pitch_deg` (the lumbar curve) and M a small random
misalignment (SD `sensors.misalignment_deg` per axis). Sensor axes are therefore x forward, y left,
z up when standing (Sensor forward_axis "+x", left_axis "+y"). Specific force = second difference
of the sensor position at the IMU rate plus the heel-strike transients plus g up, resolved in the
sensor frame, in g; angular rate = vee(R^T dR/dt) in the sensor frame, in deg/s.

Errors (`sim_devices.devices.imu`, drawn once per sensor): per-axis scale, turn-on biases; per
sample: gyro bias random walk and white noise (density x sqrt(rate / 2)); then the ADC clips at the
range and rounds to its 16-bit step. Clock (`sim_devices.devices.clock`): device time = (1 + drift)
x true time + offset (both drawn per sensor); samples are taken at true instants, only their stamps
carry the clock error. No magnetometer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim_devices.common import angular_rate, small_rotation
from sim_devices.devices.clock import DeviceClock
from sim_devices.devices.imu import Imu, Triad, accel_triad, gyro_triad
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


def draw_mounting(sensors: SensorParams, rng: np.random.Generator) -> tuple[float, np.ndarray]:
    """(belt pitch deg, (3, 3) sensor-to-pelvis rotation): the belt's pitch, then a small misalignment."""
    pitch = float(rng.uniform(-sensors.belt_pitch_deg, sensors.belt_pitch_deg))
    belt = rotation(np.zeros(1), np.radians([pitch]), np.zeros(1))[0]
    return pitch, belt @ small_rotation(rng, sensors.misalignment_deg)


def imu_triads(sensors: SensorParams) -> dict[str, Triad]:
    """The waist IMU's accelerometer, then gyroscope (the order their errors are drawn and sensed in)."""
    return {"accel": accel_triad(sensors), "gyro": gyro_triad(sensors)}


@dataclass(frozen=True)
class WaistImu:
    """Everything one waist sensor reports, in its own clock."""

    agent_id: str
    sensor_id: str
    clock: DeviceClock
    belt_pitch_deg: float
    mounting: np.ndarray  # (3, 3) sensor-to-pelvis rotation
    imu: Imu  # drawn errors (the mounting is in the exact signals)
    stamps_ns: np.ndarray  # (n,) int64, device clock
    accel_g: np.ndarray  # (n, 3) float32
    gyro_dps: np.ndarray


def waist_imu(agent_id: str, body: BodyMotion, time_s: np.ndarray, sensors: SensorParams, link: LinkParams,
              rng: np.random.Generator) -> WaistImu:
    """The waist sensor's stream for one person (draw order: mounting and errors, noise, clock)."""
    pitch, mounting = draw_mounting(sensors, rng)
    imu = Imu.draw(imu_triads(sensors), rng)
    accel, gyro = exact_signals(body, mounting, sensors.rate_hz)
    reported = imu.measure({"accel": accel, "gyro": gyro}, rng)
    clock = DeviceClock.draw(rng, start_unix_s=link.start_unix_s, offset_ms=link.clock_offset_ms,
                             drift_ppm=link.clock_drift_ppm)
    return WaistImu(agent_id, sensor_id(agent_id), clock, pitch, mounting, imu, clock.stamp_ns(time_s),
                    reported["accel"].astype(np.float32), reported["gyro"].astype(np.float32))


def sensor_id(agent_id: str) -> str:
    return f"{agent_id}-waist"
