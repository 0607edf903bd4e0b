"""Assemble a simulated room session into a session log (MCAP) and return a summary.

Streams, each in non-decreasing log time, merged into one file in log-time order:
- ImuBatch per waist sensor, `sensors.batch_samples` samples each, device-clock stamps; lost
  batches are skipped (their sequence numbers stay unused); log time = true time of the batch's
  last sample + latency, kept in order as an in-order BLE link delivers them;
- TruthPose per wearer at TRUTH_HZ: the pelvis centre and the facing heading, in true time;
- with `camera=True`: the simulated tracker's CameraFrame and TruthTrackLabel (sim_devices.camera,
  ROOM preset unless `tracker` is given) over the wearers' heads and the extra people's paths.
Determinism: every random draw comes from fixed children of `numpy.random.SeedSequence(seed)`
(motion, devices, link, camera, extra people), so the camera never changes the motion or the
IMU, and no wall-clock time enters the file (`link.start_unix_s` is the epoch).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from protocol import keys, messages
from protocol.errors import ConfigError
from protocol.messages import imu_batch
from protocol.session import Agent, AgentKind, Mount, Sensor, Session, Venue
from sim_devices.camera import ROOM, CameraRecording, PersonPath, TrackerParams, camera_items, extra_people, \
    simulate_tracks
from sim_devices.common import Item, write_merged
from sim_devices.room.calibration import SpeedAccelFit, Track, fit
from sim_devices.room.imu import WaistImu, waist_imu
from sim_devices.room.params import RoomParams, check, extra_count
from sim_devices.room.person import MAX_HEIGHT_M, MIN_HEIGHT_M, bounce_m, draw_walk_ratio, step_frequency_hz
from sim_devices.room.walk import Motion, simulate_walk

VENUE = "room"
PRESET = "room"  # the camera preset of the paper's room
CAMERA_ID = "cam1"
TRUTH_HZ = 50.0
MAX_PEOPLE = 99  # ids p01..p99
MAX_DURATION_S = 4 * 3600.0
PAPER_DURATION_S = 297.0  # the paper's recording (Table 2)
MOTION_SHARE, CAMERA_SHARE = 0.4, 0.1  # progress bar: motion, camera, then sensors and writing


@dataclass(frozen=True)
class RoomSummary:
    """What a room simulation produced (counts over the whole session)."""

    output: str
    seed: int
    people: int
    extra_people: int
    duration_s: float
    room_m: tuple[float, float]
    imu_samples: int  # generated, all sensors
    imu_samples_written: int
    imu_batches_written: int
    lost_batches: int
    truth_poses: int
    file_bytes: int
    activity_share: dict[str, float]
    speed_accel: SpeedAccelFit | None  # the paper's relation on this session (None if too short)
    camera: dict[str, int] | None  # the tracker's counters; None without a camera

    def __str__(self) -> str:
        lines = [f"{self.output}: {self.people} people with waist sensors + {self.extra_people} without, "
                 f"{self.duration_s:.1f} s, seed {self.seed}, room {self.room_m[0]:.1f} m x {self.room_m[1]:.1f} m",
                 f"  IMU: {self.imu_samples_written} of {self.imu_samples} samples in {self.imu_batches_written} "
                 f"batches ({self.lost_batches} batches lost); truth poses: {self.truth_poses}; "
                 f"file {self.file_bytes / 1e6:.2f} MB",
                 "  time: " + ", ".join(f"{name} {100 * share:.0f} %" for name, share in self.activity_share.items()
                                        if share > 0)]
        if self.speed_accel is not None:
            lines.append(f"  speed vs vertical acceleration (paper r = 0.91): {self.speed_accel}")
        if self.camera is not None:
            lines.append("  camera: " + ", ".join(f"{name} {count}" for name, count in self.camera.items()))
        return "\n".join(lines)


def simulate_room(output: Path, seed: int = 1, people: int = 3, duration_s: float = PAPER_DURATION_S,
                  params: RoomParams | None = None, camera: bool = True,
                  progress: Callable[[float], None] | None = None, *,
                  tracker: TrackerParams | None = None, world: int = 0) -> RoomSummary:
    """Simulate people with waist sensors in the paper's room (grown for more people) and write the
    session log to `output`; `camera` adds the simulated tracker's frames (preset ROOM, or `tracker`).
    `world` only labels the session (source "world", when not 0): a room world's figures are already in
    `params` and `tracker` (sim_devices.room.worlds.room_world).

    ConfigError for a bad people count, duration or seed, inconsistent params, or an unwritable output.
    `progress`, if given, is called with the completed share in [0, 1].
    """
    params = params or RoomParams()
    check(params)
    _check(people, duration_s, seed)
    report = progress or (lambda share: None)
    motion_seed, device_seed, link_seed, camera_seed, extra_seed = np.random.SeedSequence(seed).spawn(5)
    motion = simulate_walk(people, duration_s, params, motion_seed)
    report(MOTION_SHARE)
    device_seeds = device_seed.spawn(people)
    imus = [waist_imu(p.person_id, motion.bodies[i], motion.time_s, params.sensors, params.link,
                      np.random.default_rng(device_seeds[i])) for i, p in enumerate(motion.persons)]
    extras: list[PersonPath] = []
    recording = None
    tracker = tracker or ROOM
    if camera:
        extras = _extras(people, motion, params, tracker, np.random.default_rng(extra_seed))
        recording = simulate_tracks(_wearer_paths(motion, params) + extras, motion.room_m, tracker,
                                    np.random.default_rng(camera_seed), CAMERA_ID)
    report(MOTION_SHARE + CAMERA_SHARE)
    session = _describe(motion, imus, extras, params, tracker if camera else None, seed, duration_s, world)
    counts = {"imu_samples_written": 0, "imu_batches_written": 0, "lost_batches": 0}
    link_rng = np.random.default_rng(link_seed)
    sources: list[Iterator[Item]] = [_imu_items(imu, motion, params, link_rng, counts) for imu in imus]
    sources.append(_truth_items(motion, params))
    if recording is not None:
        sources.append(camera_items(recording, VENUE))
    total = len(motion.time_s) * people / params.sensors.batch_samples + 1.0
    done = MOTION_SHARE + CAMERA_SHARE
    write_merged(output, session, sources, lambda written: report(done + (1.0 - done) * min(written / total, 0.99)))
    report(1.0)
    return _summary(output, seed, motion, imus, extras, counts, recording, params, duration_s)


def _check(people: int, duration_s: float, seed: int) -> None:
    if isinstance(people, bool) or not isinstance(people, int) or not 1 <= people <= MAX_PEOPLE:
        raise ConfigError(f"people: {people!r} is not an integer in [1, {MAX_PEOPLE}]")
    number = isinstance(duration_s, (int, float)) and not isinstance(duration_s, bool)
    if not number or not math.isfinite(duration_s) or not 0 < duration_s <= MAX_DURATION_S:
        raise ConfigError(f"duration: {duration_s!r} s is outside (0, {MAX_DURATION_S:.0f}] s")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"seed: {seed!r} is not a non-negative integer")


def _true_ns(true_s: np.ndarray, params: RoomParams) -> np.ndarray:
    return params.link.start_unix_s * 1_000_000_000 + np.round(np.asarray(true_s) * 1e9).astype(np.int64)


def _truth_steps(motion: Motion, params: RoomParams) -> np.ndarray:
    return np.arange(0, len(motion.time_s), max(1, int(round(params.sensors.rate_hz / TRUTH_HZ))))


def _wearer_paths(motion: Motion, params: RoomParams) -> list[PersonPath]:
    """What the camera sees of each wearer: the head top (leaning forward of the pelvis when rising),
    whose height moves with the pelvis: down by about 0.35 m when seated, and the gait's bob."""
    steps = _truth_steps(motion, params)
    stamps = _true_ns(motion.time_s[steps], params)
    return [PersonPath(person.person_id, stamps, body.head_xy_m[steps, 0].copy(), body.head_xy_m[steps, 1].copy(),
                       height_m=person.height_m,
                       head_m=person.height_m + body.pelvis_m[steps, 2] - person.sensor_height_m)
            for person, body in zip(motion.persons, motion.bodies)]


def _extras(people: int, motion: Motion, params: RoomParams, tracker: TrackerParams,
            rng: np.random.Generator) -> list[PersonPath]:
    """People without sensors, walking like the tracker preset's bystanders at the wearers' room speeds,
    with statures drawn like the wearers', and heads that bob with their steps as the wearers' do (the
    camera sees every walker's gait, not only the wearers')."""
    count = extra_count(people, params.extra)
    if count == 0:
        return []
    walkers = dataclasses.replace(tracker.extras, speed_min_mps=params.people.forward_speed_min_mps,
                                  speed_max_mps=params.people.forward_speed_max_mps)
    start, end = (int(v) for v in _true_ns(motion.time_s[[0, -1]], params))
    paths = extra_people(count, motion.room_m, start, end, rng, walkers, prefix="extra")
    out = []
    for path in paths:
        female = rng.random() < params.people.female_share
        mean = params.people.female_height_m if female else params.people.male_height_m
        height = float(np.clip(rng.normal(mean, params.people.height_sd_m), MIN_HEIGHT_M, MAX_HEIGHT_M))
        out.append(dataclasses.replace(path, height_m=height))
    return [dataclasses.replace(path, head_m=path.height_m + _head_bob(path, params, rng)) for path in out]


def _head_bob(path: PersonPath, params: RoomParams, rng: np.random.Generator) -> np.ndarray:
    """A bystander's vertical head excursion (m) along its path: the wearers' gait model (sim_devices/room/gait.py:
    cadence from the walk ratio, the inverted pendulum's bounce for that step, the person's bounce factor,
    step time jitter) at the path's own speed; none while it stands."""
    gait = params.gait
    walk_ratio = draw_walk_ratio(path.height_m, params, rng)
    bounce_factor = float(math.exp(rng.normal(0.0, gait.bounce_person_sd)))
    start_phase = float(rng.uniform(0.0, 2.0 * math.pi))
    rate = 1e9 / float(np.median(np.diff(path.time_ns))) if len(path.time_ns) > 1 else 1.0
    speed = np.hypot(np.gradient(path.x_m, 1.0 / rate), np.gradient(path.y_m, 1.0 / rate)) if len(path.x_m) > 1 \
        else np.zeros(len(path.x_m))
    jitter = 1.0 + gait.step_time_cv * rng.normal(0.0, 1.0, len(speed))
    frequency = np.clip(step_frequency_hz(speed, walk_ratio, 1.0, params) * jitter, gait.min_step_frequency_hz,
                        gait.max_step_frequency_hz)
    phase = start_phase + 2.0 * math.pi * np.cumsum(frequency) / rate
    bounce = bounce_m(speed / frequency, params.people.leg_length_ratio * path.height_m, params) * bounce_factor
    return -0.5 * bounce * (np.cos(phase) + 0.25 * gait.second_harmonic * np.cos(2.0 * phase))


def _describe(motion: Motion, imus: list[WaistImu], extras: list[PersonPath], params: RoomParams,
              tracker: TrackerParams | None, seed: int, duration_s: float, world: int = 0) -> Session:
    length, width = motion.room_m
    agents = []
    for person, body, imu in zip(motion.persons, motion.bodies, imus):
        sensor = Sensor(imu.sensor_id, Mount.WAIST, params.sensors.rate_hz, forward_axis="+x", left_axis="+y")
        heading = math.remainder(float(motion.plan.heading_rad[0, motion.persons.index(person)]), 2.0 * math.pi)
        agents.append(Agent(person.person_id, kind=AgentKind.PEDESTRIAN, sensors=(sensor,),
                            start_x_m=float(body.pelvis_m[0, 0]), start_y_m=float(body.pelvis_m[0, 1]),
                            start_heading_rad=heading))
    devices = {waist.sensor_id: {"clock_offset_s": waist.clock.offset_s, "clock_drift": waist.clock.drift,
                                 "belt_pitch_deg": waist.belt_pitch_deg,
                                 "accel_bias_g": waist.imu.errors["accel"].bias.tolist(),
                                 "gyro_bias_dps": waist.imu.errors["gyro"].bias.tolist()} for waist in imus}
    source: dict[str, Any] = {
        "generator": "sim_devices.room", "seed": seed, "people": len(motion.persons), "extra_people": len(extras),
        "duration_s": float(duration_s), "preset": PRESET if tracker is not None else None,
        "camera": tracker is not None, "room_m": [length, width], "params": dataclasses.asdict(params),
        "truth": {"people": {p.person_id: p.to_dict() for p in motion.persons}, "devices": devices,
                  "chairs": [dataclasses.asdict(c) for c in motion.plan.chairs], "away": _away_spans(motion),
                  "extras": {e.person_id: {"height_m": e.height_m} for e in extras}}}
    if tracker is not None:
        source["tracker"] = {"camera_id": CAMERA_ID, "params": dataclasses.asdict(tracker)}
    if world:
        source["world"] = world
    return Session(Venue(VENUE, length, width), tuple(agents), source)


def _away_spans(motion: Motion) -> dict[str, list[float]]:
    """Each leaver's [start, end] s of waiting outside the sensing area (the walks out and back not included)."""
    from sim_devices.room.activities import Activity

    spans = {}
    for index, person in enumerate(motion.persons):
        away = np.flatnonzero(motion.plan.activity[:, index] == Activity.AWAY)
        if away.size:
            spans[person.person_id] = [float(motion.time_s[away[0]]), float(motion.time_s[away[-1]])]
    return spans


def _imu_items(imu: WaistImu, motion: Motion, params: RoomParams, rng: np.random.Generator,
               counts: dict[str, int]) -> Iterator[Item]:
    size, link = params.sensors.batch_samples, params.link
    batches = math.ceil(len(imu.stamps_ns) / size)
    last = motion.time_s[np.minimum(np.arange(1, batches + 1) * size, len(motion.time_s)) - 1]
    extra_s = rng.exponential(link.latency_jitter_ms * 1e-3, batches) if link.latency_jitter_ms > 0 \
        else np.zeros(batches)
    log_ns = np.maximum.accumulate(_true_ns(last + link.latency_ms * 1e-3 + extra_s, params))
    lost = rng.random(batches) < link.batch_loss_rate
    counts["lost_batches"] += int(lost.sum())
    topic = keys.imu(VENUE, imu.agent_id, imu.sensor_id)
    return _imu_generator(imu, lost, log_ns, size, topic, counts)


def _imu_generator(imu: WaistImu, lost: np.ndarray, log_ns: np.ndarray, size: int, topic: str,
                   counts: dict[str, int]) -> Iterator[Item]:
    for batch in np.flatnonzero(~lost).tolist():
        rows = slice(batch * size, (batch + 1) * size)
        message = imu_batch(imu.agent_id, imu.sensor_id, batch, imu.stamps_ns[rows], imu.accel_g[rows],
                            imu.gyro_dps[rows], None)
        counts["imu_samples_written"] += len(message.sample_offset_ns)
        counts["imu_batches_written"] += 1
        yield int(log_ns[batch]), 0, topic, message


def _truth_items(motion: Motion, params: RoomParams) -> Iterator[Item]:
    steps = _truth_steps(motion, params)
    stamps = _true_ns(motion.time_s[steps], params)
    heading = np.remainder(motion.plan.heading_rad[steps] + math.pi, 2.0 * math.pi) - math.pi
    topics = [keys.truth(VENUE, p.person_id) for p in motion.persons]
    for row, step in enumerate(steps.tolist()):
        stamp = int(stamps[row])
        for index, person in enumerate(motion.persons):
            pelvis = motion.bodies[index].pelvis_m
            yield stamp, 2, topics[index], messages.new(
                "TruthPose", timestamp_ns=stamp, agent_id=person.person_id, x_m=float(pelvis[step, 0]),
                y_m=float(pelvis[step, 1]), heading_rad=float(heading[row, index]))


def _summary(output: Path, seed: int, motion: Motion, imus: list[WaistImu], extras: list[PersonPath],
             counts: dict[str, int], recording: CameraRecording | None, params: RoomParams,
             duration_s: float) -> RoomSummary:
    steps = _truth_steps(motion, params)
    stamps = _true_ns(motion.time_s[steps], params)
    tracks = [Track(imu.stamps_ns, imu.accel_g, stamps, body.pelvis_m[steps, 0], body.pelvis_m[steps, 1])
              for imu, body in zip(imus, motion.bodies)]
    try:
        relation: SpeedAccelFit | None = fit(tracks)
    except ValueError:
        relation = None
    return RoomSummary(
        output=str(output), seed=seed, people=len(motion.persons), extra_people=len(extras),
        duration_s=float(duration_s), room_m=motion.room_m, imu_samples=sum(len(i.stamps_ns) for i in imus),
        imu_samples_written=counts["imu_samples_written"], imu_batches_written=counts["imu_batches_written"],
        lost_batches=counts["lost_batches"], truth_poses=len(steps) * len(motion.persons),
        file_bytes=Path(output).stat().st_size, activity_share=motion.activity_share(), speed_accel=relation,
        camera=None if recording is None else dict(recording.counters))
