"""A swimmer's sensor samples -> attitude -> 100 Hz rows in the pool's horizontal plane.

Attitude is x-io's Fusion AHRS (the `imufusion` package: a quaternion complementary filter with
gyroscope offset tracking; no magnetometer, whose heading is useless beside pool steel). With the
quaternion, gravity leaves the forward axis whatever the body roll and pitch: the paper's method
integrates the raw sensor-x acceleration instead, and a 1 deg tilt there is 34 m over a 20 s
length (algorithms.md).

Each row sums `rate / BIN_HZ` samples (10 at 1000 Hz):
    t_ns          time of the row's last sample (device clock)
    dv_x, dv_y    earth-frame horizontal velocity change over the row (m/s), gravity removed
    head_x/y      the body's forward axis projected on the horizontal plane, at the row's end
                  (length < 1 when the body points up or down, ~0 mid-turn)
    yaw_dps       mean rotation rate about the vertical (the turn's signature: the strokes' roll
                  is about a horizontal axis)
    surge_g       mean forward (body x) specific force, raw: stroke surges show in it
    rate_dps      mean magnitude of the rotation rate (strokes roll the body: never near 0 in a length)
    gyro_x/y/z    mean rotation rate in the body frame, Fusion's gyroscope offset removed (dps): at rest,
                  what is left of the gyro's offset (edge/swim_length.RestGyro)
    up_x/y/z      the vertical in the body frame at the row's end (the axis the heading turns about)
While the AHRS is still settling (its first seconds) head_x/y are 0: no heading, no push-off.
Pure computation, no I/O; memory is the AHRS state and one row.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import imufusion
import numpy as np

from edge.mounting import seat_to_chair

G = 9.80665
BIN_HZ = 100.0
COLUMNS = ("t_ns", "dv_x", "dv_y", "head_x", "head_y", "yaw_dps", "surge_g", "rate_dps",
           "gyro_x", "gyro_y", "gyro_z", "up_x", "up_y", "up_z")
T, DV_X, DV_Y, HEAD_X, HEAD_Y, YAW, SURGE, RATE, GYRO_X, GYRO_Y, GYRO_Z, UP_X, UP_Y, UP_Z = range(len(COLUMNS))
# Fusion's defaults (gain 0.5, acceleration rejection 10 deg, 5 s recovery) suit a body whose
# accelerations average out over a stroke cycle; the turn and push-off (up to ~1.5 g) are
# rejected as disagreeing with gravity and do not tilt the estimate.
AHRS_GAIN = 0.5
ACCELERATION_REJECTION_DEG = 30.0
RECOVERY_S = 5.0
GYRO_RANGE_DPS = 2000.0


@dataclass(frozen=True)
class BinSettings:
    rate_hz: float
    forward_axis: str = "+x"
    left_axis: str = "+y"

    @property
    def samples_per_bin(self) -> int:
        return max(1, round(self.rate_hz / BIN_HZ))


class BodyBinner:
    """`push(time_ns, accel_g, gyro_dps) -> rows (k x len(COLUMNS))`, samples in the sensor frame."""

    def __init__(self, settings: BinSettings):
        self.settings = settings
        ahrs_settings = imufusion.AhrsSettings()
        ahrs_settings.gain = AHRS_GAIN
        ahrs_settings.acceleration_rejection = ACCELERATION_REJECTION_DEG
        ahrs_settings.gyroscope_range = GYRO_RANGE_DPS
        ahrs_settings.sample_rate = settings.rate_hz
        ahrs_settings.rejection_timeout = int(RECOVERY_S * settings.rate_hz)
        self.ahrs = imufusion.Ahrs()
        self.ahrs.set_settings(ahrs_settings)
        bias_settings = imufusion.BiasSettings()
        bias_settings.sample_rate = settings.rate_hz
        self.bias = imufusion.Bias()
        self.bias.set_settings(bias_settings)
        self.per_bin = settings.samples_per_bin
        self.dt = 1.0 / settings.rate_hz
        self._count = 0
        self._sum = np.zeros(4)  # earth acc x, earth acc y (g), surge (g), rotation rate (dps)
        self._gyro_sum = np.zeros(3)  # body frame, bias removed (dps)
        self.samples = 0

    def push(self, time_ns: np.ndarray, accel_g: np.ndarray, gyro_dps: np.ndarray) -> np.ndarray:
        accel = seat_to_chair(np.asarray(accel_g, dtype=float), self.settings.forward_axis, self.settings.left_axis)
        gyro = seat_to_chair(np.asarray(gyro_dps, dtype=float), self.settings.forward_axis, self.settings.left_axis)
        rows = []
        ahrs, bias, acc_sum, gyro_sum = self.ahrs, self.bias, self._sum, self._gyro_sum
        for i in range(len(time_ns)):
            corrected = bias.update(gyro[i])
            ahrs.update_no_magnetometer(corrected, accel[i])
            earth = ahrs.get_earth_acceleration()
            acc_sum[0] += earth[0]
            acc_sum[1] += earth[1]
            acc_sum[2] += accel[i, 0]
            acc_sum[3] += math.sqrt(corrected @ corrected)
            gyro_sum += corrected
            self._count += 1
            if self._count == self.per_bin:
                w, x, y, z = ahrs.get_quaternion()
                # rotation-matrix column 0 (body x in the earth frame) and row 2 (earth z in the body)
                head_x, head_y = 1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z)
                up = np.array([2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)])
                n = self._count
                if ahrs.get_flags().startup:
                    head_x = head_y = 0.0
                rows.append((int(time_ns[i]), acc_sum[0] * G * self.dt, acc_sum[1] * G * self.dt, head_x, head_y,
                             float(gyro_sum @ up) / n, acc_sum[2] / n, acc_sum[3] / n,
                             gyro_sum[0] / n, gyro_sum[1] / n, gyro_sum[2] / n, up[0], up[1], up[2]))
                acc_sum[:] = 0.0
                gyro_sum[:] = 0.0
                self._count = 0
        self.samples += len(time_ns)
        return np.array(rows, dtype=float).reshape(-1, len(COLUMNS))
