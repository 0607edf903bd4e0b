"""A chair's three sensors' sample streams, made up: (sensor, time_ns, accel_g, gyro_dps, mag_gauss) tuples."""

from __future__ import annotations

import math

from protocol.session import Agent, Mount, Sensor

AGENT = Agent("chair01", sensors=(Sensor("left", Mount.LEFT_WHEEL, spin_axis="+z"),
                                  Sensor("right", Mount.RIGHT_WHEEL, spin_axis="-y"),
                                  Sensor("seat", Mount.SEAT, forward_axis="-x", left_axis="+y")))
DT = 5_000_000


def streams(n: int = 200):
    """Left wheel 90 deg/s on +z, right 180 deg/s on -y, seat yawing 10 deg/s, mounted backwards."""
    seat = [("seat", i * DT + 1_000_000, (0.0, 0.0, -1.0), (0.0, 0.0, -10.0), (0.2, 0.0, 0.3)) for i in range(n)]
    left = [("left", i * DT, (0.0, 0.0, 0.0), (0.0, 0.0, 90.0), None) for i in range(n + 2)]
    right = [("right", i * DT + 2_000_000, (0.0, 0.0, 0.0), (0.0, -180.0, 0.0), None) for i in range(n + 2)]
    return seat, left, right


def yawing_streams(n: int, yaw_dps, camber_deg: float = 17.0, spin_dps: float = 200.0):
    """A chair turning at `yaw_dps` (or `yaw_dps(i)` at sample i) with both wheels rolling: each axle IMU reads the yaw in its wheel's
    plane (rotating with the wheel) and gravity's reaction there, as sim_devices' kinematics does; the
    left one spins about +z, the right one about -y (its plane is x, z)."""
    cos_c, sin_c = math.cos(math.radians(camber_deg)), math.sin(math.radians(camber_deg))
    rate = yaw_dps if callable(yaw_dps) else (lambda i: yaw_dps)
    seat = [("seat", i * DT + 1_000_000, (0.0, 0.0, -1.0), (0.0, 0.0, -rate(i)), None) for i in range(n)]
    left, right = [], []
    for i in range(n + 2):
        yaw_dps = rate(i)
        a = math.radians(spin_dps) * i * DT * 1e-9
        for side, out in ((1, left), (-1, right)):
            gyro_plane = (-side * yaw_dps * cos_c * math.sin(a), -side * yaw_dps * cos_c * math.cos(a))
            force_plane = (-side * cos_c * math.sin(a), -side * cos_c * math.cos(a))
            spin = side * spin_dps + yaw_dps * sin_c
            if side == 1:
                out.append(("left", i * DT, (*force_plane, sin_c), (*gyro_plane, spin), None))
            else:
                out.append(("right", i * DT + 2_000_000, (force_plane[0], -sin_c, force_plane[1]),
                            (gyro_plane[0], -spin, gyro_plane[1]), None))
    return seat, left, right


def pivoting(i: int) -> float:
    """A chair pivoting back and forth (deg/s at sample i): reversals every second or so, as in play."""
    t = i * DT * 1e-9
    return 300.0 * math.sin(2.0 * math.pi * 0.7 * t) + 120.0 * math.sin(2.0 * math.pi * 0.23 * t + 1.0)


def shifted(stream, offset_ns: int):
    return [(sensor, t + offset_ns, *rest) for sensor, t, *rest in stream]
