"""One walker through a layout: person -> path -> timeline -> phone motion -> sensor streams.

`simulate_walker` returns everything about one walker (no file), for the session writer, the tests
and the calibration. Determinism: walker `index` draws from child `index` of its SeedSequence
(person, timeline, then one child per mount: motion, errors, noise), so a walker does not change
when more walkers are simulated and a phone's draws do not depend on the other mount's (its walk
does: with two phones every stand stop lasts twice as long).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from protocol.session import Mount
from sim_devices.devices.clock import jittered_stamps_ns
from sim_devices.devices.imu import Imu
from sim_devices.pedestrian.params import PedestrianParams
from sim_devices.pedestrian.path import Corner, SmoothPath, smooth_path
from sim_devices.pedestrian.person import Person, draw_person
from sim_devices.pedestrian.phone import PhoneMotion, StandWindow, exact_signals, phone_motion, stand_windows
from sim_devices.pedestrian.sensors import MagneticField, draw_phone
from sim_devices.pedestrian.timeline import Timeline, pause_stops, stand_stops, walk_timeline
from sim_devices.pedestrian.floors import height_floor
from sim_devices.pedestrian.venues import Layout

MOUNTS = {"hand": (Mount.HAND,), "pocket": (Mount.POCKET,), "both": (Mount.HAND, Mount.POCKET)}


@dataclass(frozen=True)
class PhoneStream:
    """One phone's report over the walk (stamps in ns of the session clock) and its truth."""

    sensor_id: str
    mount: Mount
    time_ns: np.ndarray  # (n,) int64, jittered
    accel_g: np.ndarray  # (n, 3) float32, phone frame
    gyro_dps: np.ndarray
    mag_gauss: np.ndarray
    motion: PhoneMotion
    imu: Imu  # the drawn misalignment and errors


@dataclass(frozen=True)
class WalkerRun:
    person: Person
    path: SmoothPath
    timeline: Timeline
    start_ns: int  # session-clock ns of the walker's time 0
    phones: tuple[PhoneStream, ...]

    def true_ns(self, walker_s: np.ndarray | float) -> np.ndarray:
        return self.start_ns + np.round(np.asarray(walker_s, dtype=np.float64) * 1e9).astype(np.int64)

    def corner_times_s(self) -> list[tuple[Corner, float]]:
        """Each corner and the time the walker passes its middle."""
        reached = np.maximum.accumulate(self.timeline.s_m)
        return [(corner, self.timeline.time_s[min(int(np.searchsorted(reached, corner.s_m)),
                                                  len(reached) - 1)].item()) for corner in self.path.corners]

    @property
    def stand_windows(self) -> tuple[StandWindow, ...]:
        return tuple(w for phone in self.phones for w in phone.motion.windows)


def sensor_id(agent_id: str, mount: Mount) -> str:
    return f"{agent_id}-{mount.value}"


def simulate_walker(layout: Layout, index: int, mounts: tuple[Mount, ...], params: PedestrianParams,
                    seed: np.random.SeedSequence, field: MagneticField, epoch_ns: int,
                    duration_s: float | None = None, person: Person | None = None) -> WalkerRun:
    """Walker `index` of `layout` carrying a phone at each of `mounts`; `seed` is the walkers' sequence.
    `duration_s` cuts the walk short (the same walk, recorded only so long); `person` replaces the
    drawn walker (repeated trials of one person)."""
    person_seed, timeline_seed, *phone_seeds = seed.spawn(index + 1)[index].spawn(2 + len(MOUNTS["both"]))
    drawn = draw_person(index, params.people, params.gait, np.random.default_rng(person_seed))
    person = person or drawn
    route = layout.routes[index]
    passes = tuple((p.id, p.x_m, p.y_m) for p in layout.map_points)
    path = smooth_path(route, params.gait.turn_radius_m, passes=passes)
    rng = np.random.default_rng(timeline_seed)
    stops = stand_stops(path, layout.stands, len(mounts), params.stand, layout.floor_height_m)
    stops += pause_stops(path, stops, params.gait, rng)
    rate = params.sensors.rate_hz
    floors = params.floors if path.height_knots is not None else None
    timeline = walk_timeline(path, person, stops, params.gait, rate, rng, floors).cut(duration_s)
    stands = {stand.id: stand for stand in layout.stands}
    windows = stand_windows(timeline, stands, len(mounts), params, rng)
    start_ns = epoch_ns + int(round(index * params.people.start_interval_s * 1e9))
    true_ns = start_ns + np.round(timeline.time_s * 1e9).astype(np.int64)
    phones = []
    for number, mount in enumerate(mounts):
        phone_rng = np.random.default_rng(phone_seeds[list(MOUNTS["both"]).index(mount)])
        motion = phone_motion(mount, path, timeline, person, windows[number], params, phone_rng)
        if path.height_knots is not None:  # the floor or stair under the walker carries the phone up
            motion.position_m[:, 2] += body_height_m(path, timeline, rate)
        accel, gyro = exact_signals(motion, rate)
        field_ut = np.einsum("nji,nj->ni", motion.rotation, field.at(motion.position_m))
        imu = draw_phone(params.sensors, phone_rng)
        reported = imu.measure({"accel": accel, "gyro": gyro, "mag": field_ut}, phone_rng)
        stamps = jittered_stamps_ns(true_ns, params.sensors.timestamp_jitter_ms, phone_rng)
        phones.append(PhoneStream(sensor_id(person.person_id, mount), mount, stamps,
                                  reported["accel"].astype(np.float32), reported["gyro"].astype(np.float32),
                                  (reported["mag"] / 100.0).astype(np.float32), motion, imu))  # 1 gauss = 100 uT
    return WalkerRun(person, path, timeline, start_ns, tuple(phones))


STAIR_SMOOTHING_S = 0.2  # SD of the smoothing of the body's rise where a flight starts or ends


def body_height_m(path: SmoothPath, timeline: Timeline, rate_hz: float) -> np.ndarray:
    """Height of the body's floor level above floor 0 per sample: the stair's profile smoothed over
    STAIR_SMOOTHING_S (the body does not change vertical speed in one sample where a flight begins)."""
    return gaussian_filter1d(path.height_at(timeline.s_m), STAIR_SMOOTHING_S * rate_hz, mode="nearest")


def truth_floors(run: WalkerRun, rate_hz: float, floor_height_m: float) -> np.ndarray:
    """The floor (int64) at each truth_rows time: the nearer floor to the walker's feet (on a stair,
    the floor being left until half-way; the half landing counts as the upper floor); zeros on one floor."""
    times = np.arange(0.0, float(run.timeline.time_s[-1]) + 1e-9, 1.0 / rate_hz)
    if run.path.height_knots is None or floor_height_m <= 0.0:
        return np.zeros(len(times), dtype=np.int64)
    height = run.path.height_at(np.interp(times, run.timeline.time_s, run.timeline.s_m))
    return height_floor(height, floor_height_m)


def truth_rows(run: WalkerRun, rate_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(session ns, x m, y m, heading rad in [-pi, pi)) of the walker at `rate_hz`: the body centre on
    the path and the walking direction (the path's tangent)."""
    times = np.arange(0.0, float(run.timeline.time_s[-1]) + 1e-9, 1.0 / rate_hz)
    s = np.interp(times, run.timeline.time_s, run.timeline.s_m)
    x, y, heading = run.path.at(s)
    return run.true_ns(times), x, y, np.remainder(heading + math.pi, 2 * math.pi) - math.pi
