"""One agent's set: the swimmer, its timeline, each worn sensor's stream, and the truth.

Determinism: every draw comes from fixed children of `numpy.random.SeedSequence(seed)` (the path
and timeline: key (2,); the rest sway: (3,); the sensor at mount m: (4, index of m in Mount)), and
the swimmer's traits from `swimmer_seed` (default `seed`), so a sensor's stream does not depend on
which other mounts are simulated with it, and one swimmer's sets share the same body.

Clock: the device clock is taken as true time (stamps = session epoch + sample index / rate). A
TSND121 crystal off by 20-50 ppm drifts 4-9 ms over a 3-minute session, far inside the 0.2 s
turn-timing target, and the loggers are started together; docs/simulator-swim.md says more.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from protocol.errors import ConfigError
from protocol.session import Mount, Route
from sim_devices.common import small_rotation
from sim_devices.devices.clock import DeviceClock
from sim_devices.devices.imu import Imu
from sim_devices.swim.attitude import segment_angles
from sim_devices.swim.imu import SensorMotion, imu_triads, mount_group, mount_params, sensor_motion
from sim_devices.swim.params import STROKES, SwimParams, check
from sim_devices.swim.swimmer import Swimmer, draw_swimmer, swimmer_rngs
from sim_devices.swim.timeline import Timeline, build_timeline

TRUTH_HZ = 50.0
MAX_LENGTHS = 40
SENSOR_SUFFIX = {Mount.WAIST: "waist", Mount.BACK: "back", Mount.HEAD: "head", Mount.KICKBOARD: "board"}
SWIMMER_MOUNTS = (Mount.WAIST, Mount.BACK, Mount.HEAD, Mount.KICKBOARD)


@dataclass(frozen=True)
class SensorStream:
    """One sensor's samples over a whole set (device clock = true time), with every error applied."""

    sensor_id: str
    mount: Mount
    time_ns: np.ndarray  # int64
    accel_g: np.ndarray  # (n, 3) sensor frame
    gyro_dps: np.ndarray  # (n, 3) sensor frame


@dataclass(frozen=True)
class SetTruth:
    """One agent's set: per length (push-off start to wall touch) and the reference track at 50 Hz."""

    stroke: str
    route: Route
    pool_length_m: float
    push_ns: np.ndarray  # int64, per length (true time = device time)
    touch_ns: np.ndarray
    swum_m: np.ndarray  # body-centre path length, push-off to touch
    lane_m: np.ndarray  # its lane-parallel extent (= pool length)
    strokes: np.ndarray  # arm strokes; kicks (leg beats) for "kick"
    time_ns: np.ndarray  # reference track at 50 Hz
    x_m: np.ndarray
    y_m: np.ndarray
    heading_rad: np.ndarray  # heading of travel; the body's yaw while turning or resting, in [-pi, pi)


@dataclass(frozen=True)
class SetDetail:
    """Everything behind a set, for tests and calibration: swimmer, timeline, exact sensor motion."""

    swimmer: Swimmer
    timeline: Timeline
    motions: dict[Mount, SensorMotion]
    imus: dict[Mount, Imu]  # each sensor's drawn errors
    tilt_deg: dict[Mount, float]


def simulate_set(stroke: str, route: Route, mounts: Sequence[Mount], lengths: int, seed: int,
                 params: SwimParams | None = None, agent_id: str = "s1", *, swimmer_seed: int | None = None,
                 start_y_m: float | None = None) -> tuple[list[SensorStream], SetTruth]:
    """Simulate one agent's set of `lengths` lengths with sensors at `mounts` (no file written).

    `stroke`: one of STROKES; the kickboard mount only with "kick". `start_y_m`: the body centre's
    lane position at the first push-off (default: pool centre; diagonal: see timeline.default_start_y).
    ConfigError for a bad stroke, mount, length count or a start that leaves the pool.
    """
    streams, truth, _ = simulate_set_detail(stroke, route, mounts, lengths, seed, params, agent_id,
                                            swimmer_seed=swimmer_seed, start_y_m=start_y_m)
    return streams, truth


def simulate_set_detail(stroke: str, route: Route, mounts: Sequence[Mount], lengths: int, seed: int,
                        params: SwimParams | None = None, agent_id: str = "s1", *, swimmer_seed: int | None = None,
                        start_y_m: float | None = None) -> tuple[list[SensorStream], SetTruth, SetDetail]:
    """`simulate_set`, plus the detail behind it (exact motion, drawn errors)."""
    params = params or SwimParams()
    check(params)
    _check_args(stroke, route, mounts, lengths, seed)
    body_rng, stroke_rng = swimmer_rngs(stroke, seed if swimmer_seed is None else swimmer_seed)
    swimmer = draw_swimmer(stroke, params, body_rng, stroke_rng)
    timeline = build_timeline(route, lengths, swimmer, params, _rng(seed, 2), start_y_m)
    angles = segment_angles(timeline, swimmer, params, _rng(seed, 3))
    epoch_ns = params.link.start_unix_s * 1_000_000_000
    time_ns = DeviceClock(epoch_ns).stamp_ns(timeline.time_s)  # device clock = true time
    streams, motions, imus, tilts = [], {}, {}, {}
    for mount in mounts:
        rng = _rng(seed, 4, list(Mount).index(mount))
        mounting = small_rotation(rng, mount_params(params, mount).misalignment_deg)
        tilt = swimmer.tilt_deg[mount_group(mount)]
        motion = sensor_motion(timeline, angles, mount, tilt, mounting, params)
        imu = Imu.draw(imu_triads(params.sensors), rng)
        reported = imu.measure({"accel": motion.accel_g, "gyro": motion.gyro_dps}, rng)
        streams.append(SensorStream(f"{agent_id}-{SENSOR_SUFFIX[mount]}", mount, time_ns, reported["accel"],
                                    reported["gyro"]))
        motions[mount], imus[mount], tilts[mount] = motion, imu, tilt
    truth = _truth(stroke, route, timeline, params, epoch_ns)
    return streams, truth, SetDetail(swimmer, timeline, motions, imus, tilts)


def _rng(seed: int, *key: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))


def _check_args(stroke: str, route: Route, mounts: Sequence[Mount], lengths: int, seed: int) -> None:
    if stroke not in STROKES:
        raise ConfigError(f"stroke: {stroke!r} is not one of {', '.join(STROKES)}")
    if not isinstance(route, Route):
        raise ConfigError(f"route: {route!r} is not one of {', '.join(r.value for r in Route)}")
    if isinstance(lengths, bool) or not isinstance(lengths, int) or not 1 <= lengths <= MAX_LENGTHS:
        raise ConfigError(f"lengths: {lengths!r} is not an integer in [1, {MAX_LENGTHS}]")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"seed: {seed!r} is not a non-negative integer")
    for mount in mounts:
        if mount not in SWIMMER_MOUNTS:
            raise ConfigError(f"mounts: {mount!r} is not a swimmer mount ({', '.join(m.value for m in SWIMMER_MOUNTS)})")
        if mount is Mount.KICKBOARD and stroke != "kick":
            raise ConfigError(f"mounts: a kickboard sensor needs stroke 'kick', not {stroke!r}")
    if len(set(mounts)) != len(mounts):
        raise ConfigError(f"mounts: {[m.value for m in mounts]} has a mount twice")


def _truth(stroke: str, route: Route, timeline: Timeline, params: SwimParams, epoch_ns: int) -> SetTruth:
    every = max(1, int(round(params.sensors.rate_hz / TRUTH_HZ)))
    rows = np.arange(0, len(timeline.time_s), every)
    lengths = timeline.lengths
    lane = np.array([abs(float(length.x_m[-1] - length.x_m[0])) for length in lengths])
    return SetTruth(
        stroke=stroke, route=route, pool_length_m=params.pool.length_m,
        push_ns=epoch_ns + np.round(timeline.push_s * 1e9).astype(np.int64),
        touch_ns=epoch_ns + np.round(timeline.touch_s * 1e9).astype(np.int64),
        swum_m=np.array([length.path_m for length in lengths]), lane_m=lane,
        strokes=np.array([length.strokes for length in lengths], dtype=np.int64),
        time_ns=epoch_ns + np.round(timeline.time_s[rows] * 1e9).astype(np.int64),
        x_m=timeline.x_m[rows].copy(), y_m=timeline.y_m[rows].copy(),
        heading_rad=np.remainder(timeline.yaw_rad[rows] + np.pi, 2.0 * np.pi) - np.pi)
