"""Assemble a simulated game into a session log (MCAP) and return a summary.

Streams, each in non-decreasing log time, merged into one file in log-time order:
- ImuBatch per sensor, `sensors.batch_samples` samples each, device-clock stamps; lost batches
  are skipped (their sequence numbers stay unused); log_time = true time of the batch's last
  sample + latency, kept in order as an in-order BLE link delivers them;
- BeaconSighting per heard advertisement (receiver = seat sensor, its clock), same latency model;
- TruthPose per agent at TRUTH_HZ and TruthContact per contact (one message, under the agent
  with the smaller id), in true time;
- with `camera`: CameraFrame and TruthTrackLabel per tracker frame (sim_devices.camera), log time
  = the frame's stamp in the tracker's clock.
Determinism: every random draw comes from `numpy.random.SeedSequence(seed)` children in a fixed
order, and no wall-clock time enters the file (`clock.start_unix_s` is the epoch).
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
from protocol.session import Agent, Beacon, Mount, Sensor, Session, Venue
from protocol.messages import imu_batch
from sim_devices.camera import COURT, SEATED_HEAD_HEIGHT_M, PersonPath, camera_items, extra_people, simulate_tracks
from sim_devices.common import Item, write_merged
from sim_devices.wheelchair.devices import ImuStream, build_chairs, chair_streams, sensor_ids
from sim_devices.wheelchair.impacts import Impact, contact_impacts, jolt_impacts
from sim_devices.wheelchair.kinematics import ChairBuild
from sim_devices.wheelchair.magnetic import CourtField
from sim_devices.wheelchair.motion import Motion, simulate_motion
from sim_devices.wheelchair.params import SimParams
from sim_devices.wheelchair.radio import BeaconSite, advertising_times, batch_losses, latencies_s, sightings

VENUE = "court"
TRUTH_HZ = 50.0
MAX_PLAYERS = 99  # ids chair01..chair99
MAX_DURATION_S = 4 * 3600.0
PROGRESS_STEP = 0.01  # report progress in steps of 1 %
MOTION_SHARE = 0.5  # share of the progress bar for the motion (the rest: sensors and writing)


@dataclass(frozen=True)
class SimSummary:
    """What a simulation produced (counts over the whole session)."""

    output: str
    players: int
    duration_s: float
    seed: int
    imu_samples: int  # generated, all sensors
    imu_samples_written: int
    imu_batches_written: int
    lost_batches: int
    truth_poses: int
    contacts: int
    frontal_contacts: int
    lateral_contacts: int
    contacts_per_player_per_min: float
    contact_impacts: int  # seat spikes from contacts (two per contact)
    jolts: int  # seat spikes not from contacts
    sightings: int
    max_speed_mps: float
    path_length_m: dict[str, float]
    skid_m: dict[str, float]  # displacement without wheel rotation (shoves, push-apart)
    camera: dict[str, int] | None = None  # the simulated tracker's counters (--camera), else None

    def __str__(self) -> str:
        paths = list(self.path_length_m.values())
        camera = [] if self.camera is None else [
            "  camera: " + ", ".join(f"{value} {name.replace('_', ' ')}" for name, value in self.camera.items())]
        return "\n".join([
            f"{self.output}: {self.players} chairs, {self.duration_s:.1f} s, seed {self.seed}",
            f"  IMU: {self.imu_samples_written} of {self.imu_samples} samples in {self.imu_batches_written} batches "
            f"({self.lost_batches} batches lost)",
            f"  contacts: {self.contacts} ({self.frontal_contacts} frontal, {self.lateral_contacts} lateral), "
            f"{self.contacts_per_player_per_min:.1f} per player per minute; seat spikes: {self.contact_impacts} "
            f"from contacts, {self.jolts} other",
            f"  beacon sightings: {self.sightings}; truth poses: {self.truth_poses}",
            f"  path per chair: {min(paths):.0f}-{max(paths):.0f} m; top speed {self.max_speed_mps:.2f} m/s; "
            f"moved without wheel rotation: up to {max(self.skid_m.values()):.2f} m", *camera])


def simulate(players: int, duration_s: float, seed: int, output: Path, params: SimParams | None = None,
             progress: Callable[[float], None] | None = None, camera: bool = False,
             world: int = 0) -> SimSummary:
    """Simulate a wheelchair-basketball game and write its session log to `output`.

    ConfigError for a bad player count, duration or seed, or an output that cannot be written.
    `progress`, if given, is called with the completed share in [0, 1]. `camera` adds a simulated
    court tracker's anonymous tracks and their truth labels (sim_devices.camera, COURT preset, two
    referees); its draws come from a seed of their own, so the other streams are the same either way.
    `world` only labels the session (source "world"): the world's figures are already in `params`
    (sim_devices.wheelchair.worlds.world_params).
    """
    params = params or SimParams()
    _check(players, duration_s, seed)
    report = _throttled(progress)
    root_seed = np.random.SeedSequence(seed)
    motion_seed, chair_seed, device_seed, radio_seed, impact_seed = root_seed.spawn(5)
    motion = simulate_motion(players, duration_s, params, np.random.default_rng(motion_seed),
                             lambda share: report(MOTION_SHARE * share))
    builds = build_chairs(players, params, np.random.default_rng(chair_seed))
    impacts = _impacts(motion, players, params, np.random.default_rng(impact_seed))
    field = CourtField(params.magnetic, np.random.default_rng(device_seed.spawn(1)[0]))
    agent_seeds = device_seed.spawn(players)
    radio_rng = np.random.default_rng(radio_seed)
    beacons = _beacon_sites(motion, params, radio_rng)
    streams = [s for i, b in enumerate(builds)
               for s in chair_streams(motion, i, b, field, impacts[i], params, agent_seeds[i])]
    session = _describe(builds, motion, streams, params, seed, duration_s, world)
    camera_sources, camera_about = ([], None) if not camera else \
        _camera_items(motion, builds, params, root_seed.spawn(1)[0])
    if camera_about is not None:
        session = dataclasses.replace(session, source={**session.source, "camera": camera_about})
    counts = {"imu_samples_written": 0, "imu_batches_written": 0, "lost_batches": 0, "sightings": 0}
    sources = [_imu_items(s, motion, params, radio_rng, counts) for s in streams]
    sources += [_sighting_items(motion, i, s, beacons, params, radio_rng, counts)
                for i, s in enumerate(streams[2::3])]
    sources += [_truth_items(motion, builds, params), _contact_items(motion, builds, params), *camera_sources]
    total = len(motion.time_s) * len(streams) / params.sensors.batch_samples + 1.0
    write_merged(output, session, sources,
           lambda written: report(MOTION_SHARE + (1.0 - MOTION_SHARE) * min(written / total, 0.99)))
    report(1.0)
    summary = _summary(output, players, duration_s, seed, motion, builds, streams, impacts, counts, params)
    return dataclasses.replace(summary, camera=camera_about["counters"]) if camera_about else summary


def _throttled(progress: Callable[[float], None] | None) -> Callable[[float], None]:
    """`progress` called only when the share has grown by PROGRESS_STEP (or reached 1)."""
    last = [-1.0]

    def report(share: float) -> None:
        if progress is not None and (share >= last[0] + PROGRESS_STEP or (share >= 1.0 > last[0])):
            last[0] = share
            progress(share)

    return report


def _check(players: int, duration_s: float, seed: int) -> None:
    if isinstance(players, bool) or not isinstance(players, int) or not 1 <= players <= MAX_PLAYERS:
        raise ConfigError(f"players: {players!r} is not an integer in [1, {MAX_PLAYERS}]")
    number = isinstance(duration_s, (int, float)) and not isinstance(duration_s, bool)
    if not number or not math.isfinite(duration_s) or not 0 < duration_s <= MAX_DURATION_S:
        raise ConfigError(f"duration: {duration_s!r} s is outside (0, {MAX_DURATION_S:.0f}] s")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"seed: {seed!r} is not a non-negative integer")


def _impacts(motion: Motion, players: int, params: SimParams, rng: np.random.Generator) -> list[list[Impact]]:
    """Seat impacts per agent: contact pulses, then each player's other jolts."""
    per_agent: list[list[Impact]] = [[] for _ in range(players)]
    for impact in contact_impacts(motion, params, rng):
        per_agent[impact.agent].append(impact)
    for agent in range(players):
        per_agent[agent] += jolt_impacts(motion, agent, params, rng)
    return per_agent


def _beacon_sites(motion: Motion, params: SimParams, rng: np.random.Generator) -> list[BeaconSite]:
    court = params.court
    duration = float(motion.time_s[-1]) + (motion.time_s[1] if len(motion.time_s) > 1 else 0.0)
    return [BeaconSite(beacon_id, x, court.width_m / 2.0, court.beacon_height_m, court.beacon_tx_power_dbm,
                       advertising_times(duration, params.radio, rng))
            for beacon_id, x in (("goal-a", court.basket_inset_m),
                                 ("goal-b", court.length_m - court.basket_inset_m))]


def _describe(builds: list[ChairBuild], motion: Motion, streams: list[ImuStream], params: SimParams, seed: int,
              duration_s: float, world: int) -> Session:
    court = params.court
    beacons = tuple(Beacon(beacon_id, x, court.width_m / 2.0, court.beacon_radius_m,
                           court.beacon_tx_power_dbm + court.listed_tx_error_db,
                           court.beacon_height_m + court.listed_height_error_m)
                    for beacon_id, x in (("goal-a", court.basket_inset_m),
                                         ("goal-b", court.length_m - court.basket_inset_m)))
    venue = Venue(VENUE, court.length_m, court.width_m, beacons)
    agents = []
    for index, build in enumerate(builds):
        left, right, seat = sensor_ids(build.agent_id)
        rate = params.sensors.rate_hz
        sensors = (Sensor(left, Mount.LEFT_WHEEL, rate, spin_axis="+z"),
                   Sensor(right, Mount.RIGHT_WHEEL, rate, spin_axis="-z"),
                   Sensor(seat, Mount.SEAT, rate, forward_axis="+x", left_axis="+y"))
        heading = math.remainder(float(motion.heading_rad[0, index]), 2.0 * math.pi)
        agents.append(Agent(build.agent_id, wheel_diameter_m=build.measured_diameter_m, camber_deg=build.camber_deg,
                            sensors=sensors, start_x_m=float(motion.x_m[0, index]),
                            start_y_m=float(motion.y_m[0, index]), start_heading_rad=heading))
    truth = {b.agent_id: {"team": int(motion.team[i]), "left_diameter_m": b.left_diameter_m,
                          "right_diameter_m": b.right_diameter_m, "top_speed_mps": float(motion.top_speed_mps[i])}
             for i, b in enumerate(builds)}
    devices = {s.sensor_id: {"clock_offset_s": s.clock.offset_s, "clock_drift": s.clock.drift,
                             "gyro_bias_dps": s.imu.errors["gyro"].bias.tolist(),
                             "gyro_warmup_dps": s.gyro_warmup_dps.tolist(),
                             "accel_bias_g": s.imu.errors["accel"].bias.tolist()} for s in streams}
    source = {"generator": "sim_devices.wheelchair", "seed": seed, "world": world, "players": len(builds),
              "duration_s": float(duration_s), "params": dataclasses.asdict(params),
              "truth": {"chairs": truth, "devices": devices}}
    return Session(venue, tuple(agents), source)


def _imu_items(stream: ImuStream, motion: Motion, params: SimParams, rng: np.random.Generator,
               counts: dict[str, int]) -> Iterator[Item]:
    size = params.sensors.batch_samples
    batches = math.ceil(len(stream.stamps_ns) / size)
    lost = batch_losses(batches, params.radio, rng)
    last_sample = motion.time_s[np.minimum(np.arange(1, batches + 1) * size, len(motion.time_s)) - 1]
    log_ns = np.maximum.accumulate(_true_ns(last_sample + latencies_s(batches, params.radio, rng), params))
    counts["lost_batches"] += int(lost.sum())
    topic = keys.imu(VENUE, stream.agent_id, stream.sensor_id)
    return _imu_generator(stream, lost, log_ns, size, topic, counts)


def _imu_generator(stream: ImuStream, lost: np.ndarray, log_ns: np.ndarray, size: int, topic: str,
                   counts: dict[str, int]) -> Iterator[Item]:
    for batch in np.flatnonzero(~lost).tolist():
        rows = slice(batch * size, (batch + 1) * size)
        mag = None if stream.mag_gauss is None else stream.mag_gauss[rows]
        message = imu_batch(stream.agent_id, stream.sensor_id, batch, stream.stamps_ns[rows], stream.accel_g[rows],
                            stream.gyro_dps[rows], mag)
        counts["imu_samples_written"] += len(message.sample_offset_ns)
        counts["imu_batches_written"] += 1
        yield int(log_ns[batch]), 0, topic, message


def _sighting_items(motion: Motion, agent: int, seat: ImuStream, beacons: list[BeaconSite], params: SimParams,
                    rng: np.random.Generator, counts: dict[str, int]) -> Iterator[Item]:
    heard = [(t, b.beacon_id, r) for b in beacons for t, r in zip(*(a.tolist() for a in
                                                                    sightings(motion, agent, b, params.radio, rng)))]
    heard.sort(key=lambda row: (row[0], row[1]))
    times = np.array([row[0] for row in heard])
    stamps = seat.clock.stamp_ns(times)
    log_ns = np.maximum.accumulate(_true_ns(times + latencies_s(len(times), params.radio, rng), params)) \
        if len(times) else np.zeros(0, dtype=np.int64)
    counts["sightings"] += len(heard)
    topic = keys.beacon(VENUE, seat.agent_id, seat.sensor_id)
    return (((int(log_ns[n]), 1, topic,
              messages.new("BeaconSighting", timestamp_ns=int(stamps[n]), agent_id=seat.agent_id,
                           sensor_id=seat.sensor_id, beacon_id=beacon_id, rssi_dbm=rssi)))
            for n, (_, beacon_id, rssi) in enumerate(heard))


def _truth_items(motion: Motion, builds: list[ChairBuild], params: SimParams) -> Iterator[Item]:
    every = max(1, int(round(params.sensors.rate_hz / TRUTH_HZ)))
    steps = np.arange(0, len(motion.time_s), every)
    stamps = _true_ns(motion.time_s[steps], params)
    heading = np.remainder(motion.heading_rad[steps] + math.pi, 2.0 * math.pi) - math.pi
    topics = [keys.truth(VENUE, b.agent_id) for b in builds]
    for row, step in enumerate(steps.tolist()):
        stamp = int(stamps[row])
        for agent, build in enumerate(builds):
            yield stamp, 2, topics[agent], messages.new(
                "TruthPose", timestamp_ns=stamp, agent_id=build.agent_id, x_m=float(motion.x_m[step, agent]),
                y_m=float(motion.y_m[step, agent]), heading_rad=float(heading[row, agent]))


def _contact_items(motion: Motion, builds: list[ChairBuild], params: SimParams) -> Iterator[Item]:
    for contact in sorted(motion.contacts, key=lambda c: (c.time_s, c.first, c.second)):
        stamp = int(_true_ns(np.array([contact.time_s]), params)[0])
        first, second = builds[contact.first].agent_id, builds[contact.second].agent_id
        yield stamp, 3, keys.contact(VENUE, first), messages.new(
            "TruthContact", timestamp_ns=stamp, agent_id=first, other_agent_id=second, kind=contact.kind,
            closing_speed_mps=contact.closing_mps)


def _camera_items(motion: Motion, builds: list[ChairBuild], params: SimParams,
                  seed: np.random.SeedSequence) -> tuple[list[Iterator[Item]], dict[str, Any]]:
    """The court tracker over every chair (truth at TRUTH_HZ, seated head height) and two referees."""
    rng = np.random.default_rng(seed)
    steps = np.arange(0, len(motion.time_s), max(1, int(round(params.sensors.rate_hz / TRUTH_HZ))))
    stamps = _true_ns(motion.time_s[steps], params)
    area = (params.court.length_m, params.court.width_m)
    people = [PersonPath(b.agent_id, stamps, motion.x_m[steps, i], motion.y_m[steps, i], SEATED_HEAD_HEIGHT_M)
              for i, b in enumerate(builds)]
    people += extra_people(COURT.extras.count, area, int(stamps[0]), int(stamps[-1]), rng, COURT.extras, "referee")
    recording = simulate_tracks(people, area, COURT, rng)
    about = {"camera_id": recording.camera_id, "preset": "court", "clock_offset_s": COURT.camera.clock_offset_ms / 1e3,
             "extra_people": [p.person_id for p in people[len(builds):]], "counters": recording.counters}
    return [camera_items(recording, VENUE)], about


def _true_ns(true_s: np.ndarray, params: SimParams) -> np.ndarray:
    return params.clock.start_unix_s * 1_000_000_000 + np.round(np.asarray(true_s) * 1e9).astype(np.int64)


def _summary(output: Path, players: int, duration_s: float, seed: int, motion: Motion, builds: list[ChairBuild],
             streams: list[ImuStream], impacts: list[list[Impact]], counts: dict[str, int],
             params: SimParams) -> SimSummary:
    steps = np.hypot(np.diff(motion.x_m, axis=0), np.diff(motion.y_m, axis=0))
    kinds = [c.kind for c in motion.contacts]
    flat = [i for agent in impacts for i in agent]
    skid = motion.skid_m if motion.skid_m is not None else np.zeros(players)
    return SimSummary(
        output=str(output), players=players, duration_s=float(duration_s), seed=seed,
        imu_samples=len(motion.time_s) * len(streams), imu_samples_written=counts["imu_samples_written"],
        imu_batches_written=counts["imu_batches_written"], lost_batches=counts["lost_batches"],
        truth_poses=len(range(0, len(motion.time_s), max(1, int(round(params.sensors.rate_hz / TRUTH_HZ))))) * players,
        contacts=len(kinds), frontal_contacts=kinds.count(messages.ContactKind.FRONTAL),
        lateral_contacts=kinds.count(messages.ContactKind.LATERAL),
        contacts_per_player_per_min=2.0 * len(kinds) / players / (duration_s / 60.0),
        contact_impacts=sum(i.contact for i in flat), jolts=sum(not i.contact for i in flat),
        sightings=counts["sightings"], max_speed_mps=float(np.abs(motion.speed_mps).max()),
        path_length_m={b.agent_id: float(steps[:, i].sum()) for i, b in enumerate(builds)},
        skid_m={b.agent_id: float(skid[i]) for i, b in enumerate(builds)})
