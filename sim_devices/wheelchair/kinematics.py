"""Error-free IMU signals of the three sensors of a chair, from its true motion (vectorised over time).

Frames. Chair: x forward, y left, z up. Court: z up, heading counter-clockwise from +x.

Wheels. Side sign s = +1 (left), -1 (right). Camber c tilts the top of each wheel towards the
chair, so the outward axle direction is n = (0, s cos c, sin c): it points out and *up*. The
axle IMU's z axis is n (left sensor z out to the left: `spin_axis="+z"`; right sensor z out to
the right: `spin_axis="-z"`); its x, y axes lie in the wheel plane and turn with the wheel by
the angle phi (phi' = spin about n). In-plane basis at phi = 0: a = chair x, b = n x a =
(0, sin c, -s cos c).

A wheel rolls at the speed of its ground contact point, v_s = v - s * yaw_roll * track / 2
(left wheel slower in a left turn), with effective rolling radius r: forward spin v_s / r. The
wheel's angular velocity is that spin about n plus the chair's yaw rate w about z, and z =
sin c n - s cos c b. So the gyro reads, in its own frame,
    z: s * v_s / r + w sin c          x: -s w cos c sin(phi)          y: -s w cos c cos(phi)
Read forward-positive (z for the left wheel, -z for the right), the spin axes give
    left  = v_l / r + w sin c,        right = v_r / r - w sin c:
the camber leak of yaw is opposite on the two wheels and cancels in their mean (the chair travel
of the paper's eq. 5), while their difference is w (2 sin c - track / r) instead of -w track / r.
The accelerometer at the hub reads the specific force f = a_hub + g z (chair frame; a_hub adds
the yaw terms of the hub's lateral offset), resolved on a, b, n and rotated by phi, plus the
centripetal and tangential terms of a sensor centre `chair.wheel_sensor_offset_m` off the axis.

Seat. The seat IMU sits at the chair's reference point (axle midpoint), sensor frame = chair
frame (its mounting tilt is the sensor misalignment drawn in `devices`): gyro (0, 0, w), accel
(a_forward, a_left, g) / g.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim_devices.wheelchair.motion import Motion
from sim_devices.wheelchair.params import SimParams

STANDARD_GRAVITY = 9.80665  # m/s^2 per g


@dataclass(frozen=True)
class ChairBuild:
    """One chair's geometry as built (true), and as measured (what the session description says)."""

    agent_id: str
    measured_diameter_m: float  # what the team measured and the session records
    left_diameter_m: float  # effective rolling diameters (tyre deflection, spread)
    right_diameter_m: float
    camber_deg: float


def wheel_spin_rps(motion: Motion, agent: int, build: ChairBuild, side: int, params: SimParams) -> np.ndarray:
    """Forward-positive spin (rad/s) of one wheel relative to the chair; side +1 left, -1 right.

    Slip (`wheels.slip_accel` / `slip_brake`): the wheel turns more than the ground travel while
    accelerating hard and less while braking hard, in proportion to the share of the limit used.
    Scrub (`wheels.slip_turn`): in a pivot the wheels' differential rotation exceeds the chair's
    yaw, in proportion to the share of the yaw-rate limit used.
    """
    chair, wheels = params.chair, params.wheels
    speed = motion.speed_mps[:, agent]
    yaw_rate = motion.yaw_rate_rps[:, agent]
    rolling_accel = motion.accel_forward_mps2[:, agent] + motion.lateral_mps[:, agent] * yaw_rate
    driving = rolling_accel * np.sign(speed)
    slip = (1.0 + wheels.slip_accel * np.clip(driving / chair.accel_mps2, 0.0, 1.0)
            - wheels.slip_brake * np.clip(-driving / chair.brake_mps2, 0.0, 1.0))
    yaw_roll = motion.yaw_roll_rps[:, agent]
    if wheels.slip_turn > 0:
        yaw_roll = yaw_roll * (1.0 + wheels.slip_turn * np.clip(np.abs(yaw_roll) / math.radians(chair.yaw_rate_max_dps),
                                                                0.0, 1.0))
    contact_speed = speed - side * yaw_roll * chair.track_m / 2.0
    diameter = build.left_diameter_m if side > 0 else build.right_diameter_m
    return contact_speed * slip / (diameter / 2.0)


def wheel_imu(motion: Motion, agent: int, build: ChairBuild, side: int, params: SimParams,
              start_angle_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """Error-free (gyro deg/s, accel g), each (steps, 3), of the axle IMU on one wheel (sensor frame)."""
    dt = 1.0 / params.sensors.rate_hz
    camber = math.radians(build.camber_deg)
    sin_c, cos_c = math.sin(camber), math.cos(camber)
    spin = side * wheel_spin_rps(motion, agent, build, side, params)  # about n
    angle = start_angle_rad + np.concatenate([[0.0], np.cumsum(spin[:-1]) * dt])
    sin_a, cos_a = np.sin(angle), np.cos(angle)
    yaw_rate = motion.yaw_rate_rps[:, agent]
    gyro = np.stack([-side * yaw_rate * cos_c * sin_a, -side * yaw_rate * cos_c * cos_a,
                     spin + yaw_rate * sin_c], axis=1)
    radius = (build.left_diameter_m if side > 0 else build.right_diameter_m) / 2.0
    hub_offset = side * (params.chair.track_m / 2.0 - radius * sin_c)  # hub y in the chair frame
    yaw_accel = np.gradient(yaw_rate, dt) if len(yaw_rate) > 1 else np.zeros_like(yaw_rate)
    forward = motion.accel_forward_mps2[:, agent] - hub_offset * yaw_accel
    leftward = motion.accel_left_mps2[:, agent] - hub_offset * yaw_rate**2
    along_a = forward
    along_b = leftward * sin_c - side * cos_c * STANDARD_GRAVITY
    along_n = side * cos_c * leftward + sin_c * STANDARD_GRAVITY
    offset = params.chair.wheel_sensor_offset_m
    spin_accel = np.gradient(spin, dt) if len(spin) > 1 else np.zeros_like(spin)
    accel = np.stack([along_a * cos_a + along_b * sin_a - spin**2 * offset,
                      -along_a * sin_a + along_b * cos_a + spin_accel * offset, along_n], axis=1)
    return np.degrees(gyro), accel / STANDARD_GRAVITY


def seat_imu(motion: Motion, agent: int) -> tuple[np.ndarray, np.ndarray]:
    """Error-free (gyro deg/s, accel g), each (steps, 3), of the seat IMU (chair frame), without impacts."""
    steps = len(motion.time_s)
    gyro = np.zeros((steps, 3))
    gyro[:, 2] = np.degrees(motion.yaw_rate_rps[:, agent])
    accel = np.stack([motion.accel_forward_mps2[:, agent], motion.accel_left_mps2[:, agent],
                      np.full(steps, STANDARD_GRAVITY)], axis=1)
    return gyro, accel / STANDARD_GRAVITY
