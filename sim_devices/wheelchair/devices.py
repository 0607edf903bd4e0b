"""One chair's devices: build the chair, then synthesise its three IMU streams with their errors.

Per chair: the measured wheel diameter (0.61 m, or 0.67 m for round(`chair.large_wheel_fraction`
* players) chairs, like the paper's players), each wheel's effective rolling diameter
(`wheels.diameter_bias` +- `diameter_spread`), and a camber in [`camber_min_deg`, `camber_max_deg`].
Per sensor: error-free signal (`kinematics`), impacts and vibration (`impacts`), then the sensor's
errors (`sim_devices.devices.imu`: a mounting misalignment, the gyroscope's then the
accelerometer's scale and bias; per sample gyro bias walk and noise, accelerometer noise,
saturation, quantisation), a gyro warm-up (the bias moves by a drawn change with time constant
`sensors.gyro_warmup_s` after power-on) and its clock (`sim_devices.devices.clock`: offset, drift, jitter); the
seat also gets its magnetometer (`magnetic`). Wheel sensors have no magnetometer stream: on a
spinning wheel beside steel spokes and hub its reading is dominated by the wheel's own rotation and
iron, and the estimator takes heading from the seat.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim_devices.common import small_rotation
from sim_devices.devices.clock import DeviceClock
from sim_devices.devices.imu import Imu, Triad, accel_triad, digitise, gyro_triad
from sim_devices.wheelchair.impacts import Impact, add_impacts, add_vibration
from sim_devices.wheelchair.kinematics import ChairBuild, seat_imu, wheel_imu
from sim_devices.wheelchair.magnetic import CourtField, seat_magnetometer
from sim_devices.wheelchair.motion import Motion
from sim_devices.wheelchair.params import SensorParams, SimParams

LEFT, RIGHT = 1, -1


@dataclass
class ImuStream:
    """Everything one IMU reports, sample by sample, in its own clock."""

    agent_id: str
    sensor_id: str
    clock: DeviceClock
    imu: Imu  # its mounting and drawn errors
    stamps_ns: np.ndarray  # (steps,) int64, device clock
    gyro_dps: np.ndarray  # (steps, 3) float32
    accel_g: np.ndarray
    mag_gauss: np.ndarray | None
    gyro_warmup_dps: np.ndarray  # (3,) the bias change the warm-up reaches, deg/s


def agent_id(index: int) -> str:
    return f"chair{index + 1:02d}"


def sensor_ids(agent: str) -> tuple[str, str, str]:
    """(left wheel, right wheel, seat) sensor ids of an agent."""
    return f"{agent}-left", f"{agent}-right", f"{agent}-seat"


def build_chairs(players: int, params: SimParams, rng: np.random.Generator) -> list[ChairBuild]:
    chair, wheels = params.chair, params.wheels
    large = set(rng.permutation(players)[:int(round(chair.large_wheel_fraction * players))].tolist())
    builds = []
    for index in range(players):
        measured = chair.large_wheel_diameter_m if index in large else chair.wheel_diameter_m
        left, right = measured * (1.0 + wheels.diameter_bias + rng.normal(0.0, wheels.diameter_spread, 2))
        camber = float(rng.uniform(chair.camber_min_deg, chair.camber_max_deg))
        builds.append(ChairBuild(agent_id(index), measured, float(left), float(right), camber))
    return builds


def chair_streams(motion: Motion, agent: int, build: ChairBuild, field: CourtField, impacts: list[Impact],
                  params: SimParams, seed: np.random.SeedSequence) -> list[ImuStream]:
    """The (left wheel, right wheel, seat) streams of one chair; `impacts` are this chair's seat impacts."""
    left_rng, right_rng, seat_rng = (np.random.default_rng(s) for s in seed.spawn(3))
    speed = motion.speed_mps[:, agent]
    left_id, right_id, seat_id = sensor_ids(build.agent_id)
    streams = []
    for side, sensor, rng in ((LEFT, left_id, left_rng), (RIGHT, right_id, right_rng)):
        gyro, accel = wheel_imu(motion, agent, build, side, params, float(rng.uniform(0.0, 2.0 * math.pi)))
        add_vibration(accel, speed, params, rng)
        streams.append(_finish(build.agent_id, sensor, motion, gyro, accel, params, rng))
    gyro, accel = seat_imu(motion, agent)
    add_impacts(accel, motion.time_s, impacts, params)
    add_vibration(accel, speed, params, seat_rng)
    seat = _finish(build.agent_id, seat_id, motion, gyro, accel, params, seat_rng)
    field_ut = field.field_ut(motion.x_m[:, agent], motion.y_m[:, agent])
    seat.mag_gauss = seat_magnetometer(field_ut, motion.heading_rad[:, agent], seat.imu.mounting,
                                       params.magnetic, seat_rng).astype(np.float32)
    streams.append(seat)
    return streams


def _finish(agent: str, sensor: str, motion: Motion, gyro: np.ndarray, accel: np.ndarray, params: SimParams,
            rng: np.random.Generator) -> ImuStream:
    """Apply one sensor's errors and clock to its error-free signals (draw order: mounting, errors,
    noise, clock, jitter)."""
    mounting = small_rotation(rng, params.sensors.misalignment_deg)
    imu = Imu.draw(imu_triads(params.sensors), rng, mounting)
    reported = imu.measure({"gyro": gyro, "accel": accel}, rng)
    clocks = params.clock
    clock = DeviceClock.draw(rng, start_unix_s=clocks.start_unix_s, offset_ms=clocks.offset_ms,
                             drift_ppm=clocks.drift_ppm, jitter_ms=clocks.jitter_ms)
    stamps = clock.stamp_ns(motion.time_s, rng, period_s=1.0 / params.sensors.rate_hz)
    warmup = np.zeros(3)
    if params.sensors.gyro_warmup_dps > 0:  # drawn last, so the other draws do not depend on it
        warmup = rng.normal(0.0, params.sensors.gyro_warmup_dps, 3)
        rise = 1.0 - np.exp(-motion.time_s / params.sensors.gyro_warmup_s)
        reported["gyro"] = digitise(reported["gyro"] + np.outer(rise, warmup), imu.triads["gyro"])
    return ImuStream(agent, sensor, clock, imu, stamps, reported["gyro"].astype(np.float32),
                     reported["accel"].astype(np.float32), None, warmup)


def imu_triads(sensors: SensorParams) -> dict[str, Triad]:
    """The chair IMU's gyroscope, then accelerometer (the order their errors are drawn and sensed in)."""
    return {"gyro": gyro_triad(sensors), "accel": accel_triad(sensors)}
