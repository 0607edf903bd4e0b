"""From segment motion to what a TSND121 on that segment reports: exact signals, then sensor errors.

Kinematics. The sensor point is the body centre plus a lever arm carried by the segment:
waist p + R_pelvis r, back p + R_trunk r, head p + R_trunk (NECK, 0, 0) + R_head (r - (NECK, 0, 0))
(the head turns about the neck, not the body centre), kickboard p + Rz(board yaw) (reach r_x, 0, r_z)
with the reach shortened to `CLOSE_REACH_M` in turns and rests (the board is held close at the
wall). The sensor frame is the segment's turned by the mounting: R_sensor = R_segment Ry(-tilt) M,
tilt the swimmer's pitch of that mount, M a random misalignment. Specific force = second difference
of the sensor position (sampled at the IMU rate; every curve is smooth, so this is the kinematic
acceleration to well under the noise) plus g up, resolved in the sensor frame, in g; angular rate
= vee(R_k^T (R_k+1 - R_k-1) / 2 dt) in the sensor frame, in deg/s.

Errors (`sim_devices.devices.imu`, per sensor, drawn once per set): per-axis scale and cross-axis
sensitivity (one 3 x 3 matrix), turn-on biases, bias random walks, white noise (density x
sqrt(rate / 2)); then the ADC clips at the range and rounds to its 16-bit step, and the output is
rounded to the TSND121's units (0.1 mg, 0.01 deg/s). The order is the physics: mounted, sensed
(scale, cross-axis, bias, noise), then digitised.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from protocol.session import Mount
from sim_devices.common import angular_rate
from sim_devices.devices.imu import Triad, accel_triad, gyro_triad
from sim_devices.swim.attitude import Angles, rotation
from sim_devices.swim.params import MountParams, SensorParams, SwimParams
from sim_devices.swim.timeline import Timeline

STANDARD_GRAVITY = 9.80665  # m/s^2 per g
NECK_FORWARD_M = 0.55  # body centre to the base of the skull along the trunk; assumption (adult 1.6-1.9 m)
CLOSE_REACH_M = 0.35  # kickboard held close to the chest in turns and at rest; assumption
SEGMENT = {Mount.WAIST: "pelvis", Mount.BACK: "trunk", Mount.HEAD: "head", Mount.KICKBOARD: "board"}


def mount_group(mount: Mount) -> str:
    """The SwimParams group (and Swimmer.tilt_deg key) of a mount."""
    return mount.value


def mount_params(params: SwimParams, mount: Mount) -> MountParams:
    return getattr(params, mount_group(mount))


@dataclass(frozen=True)
class SensorMotion:
    """A sensor's exact motion: position (n, 3) m, sensor-to-world rotation (n, 3, 3), true signals."""

    position_m: np.ndarray
    rotation: np.ndarray
    accel_g: np.ndarray
    gyro_dps: np.ndarray


def sensor_motion(timeline: Timeline, angles: dict[str, Angles], mount: Mount, tilt_deg: float,
                  mounting: np.ndarray, params: SwimParams) -> SensorMotion:
    """Exact position, attitude, specific force (g) and angular rate (deg/s) of the sensor at `mount`."""
    lever = mount_params(params, mount)
    centre = np.stack([timeline.x_m, timeline.y_m, timeline.z_m], axis=1)
    segment = angles[SEGMENT[mount]].matrices()
    if mount is Mount.HEAD:
        trunk = angles["trunk"].matrices()
        position = (centre + trunk[:, :, 0] * NECK_FORWARD_M
                    + segment[:, :, 0] * (lever.lever_forward_m - NECK_FORWARD_M) + segment[:, :, 2] * lever.lever_up_m)
    elif mount is Mount.KICKBOARD:
        heading = rotation(angles["board"].yaw, np.zeros(len(centre)), np.zeros(len(centre)))
        reach = CLOSE_REACH_M + (lever.lever_forward_m - CLOSE_REACH_M) * timeline.reach
        position = centre + heading[:, :, 0] * reach[:, None] + heading[:, :, 2] * lever.lever_up_m
    else:
        position = centre + segment[:, :, 0] * lever.lever_forward_m + segment[:, :, 2] * lever.lever_up_m
    tilt = rotation(np.zeros(1), np.array([math.radians(tilt_deg)]), np.zeros(1))[0]
    sensor = segment @ (tilt @ mounting)
    rate = params.sensors.rate_hz
    accel = _second_difference(position) * rate * rate
    accel[:, 2] += STANDARD_GRAVITY
    specific = np.einsum("nji,nj->ni", sensor, accel) / STANDARD_GRAVITY
    return SensorMotion(position, sensor, specific, np.degrees(angular_rate(sensor, rate)))


def _second_difference(values: np.ndarray) -> np.ndarray:
    out = np.empty_like(values)
    out[1:-1] = values[2:] - 2.0 * values[1:-1] + values[:-2]
    out[0], out[-1] = out[1], out[-2]
    return out


def imu_triads(sensors: SensorParams) -> dict[str, Triad]:
    """The TSND121's accelerometer, then gyroscope (the order their errors are drawn and sensed in):
    cross-axis sensitivity, an accelerometer bias walk, and the output rounded to the device's units."""
    return {"accel": accel_triad(sensors, walk_g_per_sqrt_s=sensors.accel_bias_walk_g_per_sqrt_s,
                                 cross_axis_sd=sensors.cross_axis, unit_g=sensors.accel_unit_g),
            "gyro": gyro_triad(sensors, cross_axis_sd=sensors.cross_axis, unit_dps=sensors.gyro_unit_dps)}
