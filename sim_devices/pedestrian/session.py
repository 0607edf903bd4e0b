"""A pedestrian session: every walker through the preset's building, written as one session log.

Agents `p01`..`pNN` (pedestrians, with `height_m`), each with a phone `<agent>-hand` (held flat in
front: forward axis +y, left -x, as the ILC import) and/or `<agent>-pocket` (nominal axes of the
first insertion; the truth of every insertion is in `source.truth.phones`). Walkers start one
after another (`people.start_interval_s`) at the start stand.

Streams, each in non-decreasing log time, merged in log-time order:
- ImuBatch per phone, `sensors.batch_samples` samples: accel g, gyro deg/s, mag gauss in the
  Android phone frame, stamps on the session clock (= truth clock) with jitter; `sequence` =
  batch index; log time = the batch's last stamp (a phone's own recording);
- TruthPose per walker at TRUTH_HZ ("waypoints"): the body centre on the path, heading = walking
  direction;
- StandScan per stand visit of each phone, halfway through its still time: the stand's real code
  text (protocol.stand_code.encode) under a key derived from the seed (`source.stand_key_hex`),
  checked and filled by protocol.stand_code.scan_message (accepted).
- Pressure per phone (barometer on: preset `floors`, or asked for) at `barometer.rate_hz`, stamped
  like the IMU samples (sim_devices/pedestrian/barometer.py);
- BeaconSighting per received advertisement (beacons on: preset `floors`, or asked for), beacon_id
  = the venue's beacon id, RSSI in whole dBm (sim_devices/pedestrian/radio.py).
TruthPose carries `floor` (the nearer floor; 0 on a one-floor preset, where it is not written).
`source.junctions[agent]`: every route node and map point passed, {time_ns, point_id,
heading_before_deg, heading_after_deg, turn_deg}; `source.turns`: the passages that turn (at
least TURN_MIN_DEG), every walker's in time order, each with its `agent_id` (what reckon eval
scores turns and the paper's snaps against). Determinism: fixed SeedSequence children; no wall clock.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from protocol import keys, messages, stand_code
from protocol.errors import ConfigError
from protocol.messages import imu_batch
from protocol.session import Agent, AgentKind, Mount, Sensor, Session, Venue
from sim_devices.common import Item, write_merged
from sim_devices.pedestrian.barometer import Atmosphere, PressureStream, barometer_stream
from sim_devices.pedestrian.params import PedestrianParams, check
from sim_devices.pedestrian.radio import RadioWorld, Sightings, scan, venue_beacons
from sim_devices.pedestrian.sensors import MagneticField, error_record
from sim_devices.pedestrian.simulate import MOUNTS, WalkerRun, simulate_walker, truth_floors, truth_rows
from sim_devices.pedestrian.venues import PRESETS, Layout, beacon_places, layout

TRUTH_HZ = 2.0
TURN_MIN_DEG = 10.0  # a junction passage with a smaller heading change is walking straight through
MAX_PEOPLE = 99
SIM_SHARE = 0.6
KEY_LABEL = b"reckon sim pedestrian stand key, seed "
# Nominal (forward, left) axes of a pocket phone for its first insertion (top down?, screen in?).
POCKET_AXES = {(False, False): ("+z", "+x"), (True, False): ("+z", "-x"), (False, True): ("-z", "-x"),
               (True, True): ("-z", "+x")}


@dataclass(frozen=True)
class PedestrianSummary:
    output: str
    seed: int
    preset: str
    mount: str
    people: int
    duration_s: float
    distance_m: dict[str, float]
    imu_samples: int
    imu_batches: int
    truth_poses: int
    stand_scans: int
    junctions: int
    file_bytes: int
    pressure_samples: int = 0
    beacons: int = 0  # in the venue, all floors
    beacon_sightings: int = 0
    floor_changes: int = 0  # in the truth, all walkers

    def __str__(self) -> str:
        walks = ", ".join(f"{agent} {metres:.0f} m" for agent, metres in self.distance_m.items())
        extra = ""
        if self.pressure_samples or self.beacons or self.floor_changes:
            extra = (f"\n  floor changes: {self.floor_changes}; pressure samples: {self.pressure_samples}; "
                     f"beacons: {self.beacons}, sightings: {self.beacon_sightings}")
        return (f"{self.output}: {self.people} walkers ({self.mount}) on preset {self.preset}, seed {self.seed}, "
                f"{self.duration_s:.1f} s\n  walked: {walks}\n  IMU: {self.imu_samples} samples in "
                f"{self.imu_batches} batches; truth poses: {self.truth_poses}; stand scans: {self.stand_scans}; "
                f"junction passages: {self.junctions}; file {self.file_bytes / 1e6:.2f} MB{extra}")


def stand_key(seed: int) -> bytes:
    """The venue's stand key for a simulated session: SHA-256 of a label and the seed (not secret)."""
    return hashlib.sha256(KEY_LABEL + str(seed).encode("ascii")).digest()


def simulate_pedestrian(output: Path, seed: int = 1, people: int = 3, preset: str = "paper", mount: str = "hand",
                        params: PedestrianParams | None = None, duration_s: float | None = None,
                        progress: Callable[[float], None] | None = None, beacons: int | None = None,
                        barometer: bool | None = None) -> PedestrianSummary:
    """Walk `people` through the preset's building and write the session log to `output`.
    `duration_s` cuts every walk short (tests); None walks the whole route. `beacons`: BLE beacons
    per floor (None: DEFAULT_BEACONS on preset floors, none elsewhere); `barometer` (None: on for
    preset floors only). ConfigError for a bad argument, inconsistent params or an unwritable
    output. `progress` gets the share done in [0, 1]."""
    params = params or PedestrianParams()
    check(params)
    _check(seed, people, preset, mount, duration_s)
    report = progress or (lambda share: None)
    venue_seed, walker_seed, extra_seed = np.random.SeedSequence(seed).spawn(3)  # the first two as ever
    plan = layout(preset, people, params.stand.offset_m, params.floors.height_m)
    per_floor = _beacon_count(plan, beacons)
    barometer = preset == "floors" if barometer is None else bool(barometer)
    field = MagneticField.draw(params.magnetic, np.random.default_rng(venue_seed))
    epoch_ns = params.clock.start_unix_s * 1_000_000_000
    runs = []
    for index in range(people):
        runs.append(simulate_walker(plan, index, MOUNTS[mount], params, walker_seed, field, epoch_ns, duration_s))
        report(SIM_SHARE * (index + 1) / people)
    key = stand_key(seed)
    extras = _extras(plan, runs, params, per_floor, barometer, extra_seed, epoch_ns)
    session = _describe(plan, runs, params, field, seed, mount, key, duration_s, extras)
    counts = {"batches": 0, "scans": 0}
    sources: list[Iterator[Item]] = []
    for number, run in enumerate(runs):
        sources += [_imu_items(plan.venue_name, run, index, params, counts) for index in range(len(run.phones))]
        sources.append(_truth_items(plan, run))
        sources.append(_scan_items(plan, run, key, counts))
        sources += [_pressure_items(plan.venue_name, run, stream) for stream in extras.pressure[number]]
        sources += [_sighting_items(plan.venue_name, run, found, extras.world) for found in extras.sightings[number]]
    total = sum(len(p.time_ns) for r in runs for p in r.phones) / params.sensors.batch_samples + 1.0
    write_merged(output, session, sources,
                 lambda written: report(SIM_SHARE + (1 - SIM_SHARE) * min(written / total, 0.99)))
    report(1.0)
    end_s = max(run.start_ns + run.timeline.time_s[-1] * 1e9 for run in runs) - epoch_ns
    return PedestrianSummary(
        str(output), seed, preset, mount, people, float(end_s) * 1e-9,
        {run.person.person_id: float(run.timeline.s_m[-1]) for run in runs},
        sum(len(p.time_ns) for r in runs for p in r.phones), counts["batches"],
        sum(len(truth_rows(run, TRUTH_HZ)[0]) for run in runs), counts["scans"],
        sum(len(session.source["junctions"][r.person.person_id]) for r in runs), Path(output).stat().st_size,
        sum(len(stream.time_ns) for streams in extras.pressure for stream in streams),
        len(extras.world.beacons) if extras.world else 0,
        sum(len(found.walker_s) for walker in extras.sightings for found in walker),
        sum(int(np.count_nonzero(np.diff(truth_floors(run, TRUTH_HZ, plan.floor_height_m)))) for run in runs))


DEFAULT_BEACONS = 6  # per floor, preset floors


@dataclass(frozen=True)
class Extras:
    """The barometer and BLE part of a session (empty when off): per walker, per phone."""

    atmosphere: Atmosphere | None
    pressure: list[list[PressureStream]]
    world: RadioWorld | None
    sightings: list[list[Sightings]]


def _beacon_count(plan: Layout, beacons: int | None) -> int:
    places = beacon_places(plan)
    most = min(sum(1 for place in places if place[0] == floor) for floor in {place[0] for place in places})
    if beacons is None:
        return DEFAULT_BEACONS if plan.preset == "floors" else 0
    if isinstance(beacons, bool) or not isinstance(beacons, int) or not 0 <= beacons <= most:
        raise ConfigError(f"beacons: {beacons!r} per floor is outside [0, {most}] (the beacon places of preset "
                          f"{plan.preset})")
    return beacons


def _extras(plan: Layout, runs: list[WalkerRun], params: PedestrianParams, per_floor: int, barometer: bool,
            seed: np.random.SeedSequence, epoch_ns: int) -> Extras:
    """Pressure and sightings of every phone; draws from `seed` only (the other streams stay as they were)."""
    world_seed, phone_seed = seed.spawn(2)
    world_rng = np.random.default_rng(world_seed)
    phones = [phone for run in runs for phone in run.phones]
    phone_rngs = iter([np.random.default_rng(child) for child in phone_seed.spawn(len(phones))])
    end_s = max((run.start_ns - epoch_ns) * 1e-9 + float(run.timeline.time_s[-1]) for run in runs)
    atmosphere = Atmosphere.draw(params.barometer, end_s, world_rng) if barometer else None
    floors = max(1, len(plan.floor_plans))
    beacons = venue_beacons(beacon_places(plan), per_floor, params.ble.height_m) if per_floor else ()
    world = RadioWorld.draw(beacons, floors, params.ble, world_rng) if beacons else None
    pressure: list[list[PressureStream]] = []
    sightings: list[list[Sightings]] = []
    for run in runs:
        _, _, yaw = run.path.at(run.timeline.s_m)
        pressure.append([])
        sightings.append([])
        for phone in run.phones:
            rng = next(phone_rngs)
            if atmosphere is not None:
                pressure[-1].append(barometer_stream(phone.sensor_id, run.timeline.time_s, phone.motion.position_m,
                                                     run.start_ns, epoch_ns, atmosphere, params.barometer,
                                                     params.sensors.timestamp_jitter_ms, rng))
            if world is not None:
                sightings[-1].append(scan(phone.sensor_id, phone.mount, run.timeline.time_s, phone.motion.position_m,
                                          yaw, world, plan.floor_height_m, params.ble, rng))
    return Extras(atmosphere, pressure, world, sightings)


def _check(seed: int, people: int, preset: str, mount: str, duration_s: float | None) -> None:
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"seed: {seed!r} is not a non-negative integer")
    if isinstance(people, bool) or not isinstance(people, int) or not 1 <= people <= MAX_PEOPLE:
        raise ConfigError(f"people: {people!r} is not an integer in [1, {MAX_PEOPLE}]")
    if preset not in PRESETS:
        raise ConfigError(f"preset: {preset!r} is not one of {', '.join(PRESETS)}")
    if mount not in MOUNTS:
        raise ConfigError(f"mount: {mount!r} is not one of {', '.join(MOUNTS)}")
    if duration_s is not None and (not isinstance(duration_s, (int, float)) or not math.isfinite(duration_s)
                                   or not 1.0 <= duration_s <= 4 * 3600):
        raise ConfigError(f"duration: {duration_s!r} s is outside [1, 14400] s")


def _describe(plan: Layout, runs: list[WalkerRun], params: PedestrianParams, field: MagneticField, seed: int,
              mount: str, key: bytes, duration_s: float | None, extras: Extras) -> Session:
    agents, junctions, people, phones = [], {}, {}, {}
    for run in runs:
        sensors = []
        for phone in run.phones:
            if phone.mount is Mount.HAND:
                forward, left = "+y", "-x"
            else:
                first = phone.motion.holds[0]
                forward, left = POCKET_AXES[(first["top_down"], first["screen_in"])]
            sensors.append(Sensor(phone.sensor_id, phone.mount, params.sensors.rate_hz, forward_axis=forward,
                                  left_axis=left))
            phones[phone.sensor_id] = {"errors": error_record(phone.imu), "holds": list(phone.motion.holds),
                                       "stand_windows": [{"stand_id": w.stand.id, "place_s": w.place_s,
                                                          "still_s": w.still_s, "pick_s": w.pick_s,
                                                          "done_s": w.done_s,
                                                          "placement_deg": math.degrees(w.placement_rad)}
                                                         for w in phone.motion.windows]}
        agent_id = run.person.person_id
        _, x, y, heading = truth_rows(run, TRUTH_HZ)
        agents.append(Agent(agent_id, kind=AgentKind.PEDESTRIAN, sensors=tuple(sensors), start_x_m=float(x[0]),
                            start_y_m=float(y[0]), start_heading_rad=float(heading[0]), height_m=run.person.height_m))
        junctions[agent_id] = _junctions(run)
        people[agent_id] = {**run.person.to_dict(), "route": list(plan.routes[runs.index(run)].nodes),
                            "start_ns": run.start_ns, "walked_m": float(run.timeline.s_m[-1]),
                            "stops": [dataclasses.asdict(stop) for stop in run.timeline.stops]}
    venue = Venue(plan.venue_name, court_length_m=max(1.0, plan.size_m[0]), court_width_m=max(1.0, plan.size_m[1]),
                  stands=plan.stands, map_points=plan.map_points, floor_plan=plan.floor_plan,
                  floor_plans=plan.floor_plans, beacons=extras.world.beacons if extras.world else (),
                  # what the venue file knows (as the ILC import's WMM figures): Earth's field undisturbed
                  magnetic_north_deg=params.magnetic.north_deg - params.magnetic.declination_deg,
                  magnetic_field_ut=params.magnetic.field_ut, magnetic_dip_deg=params.magnetic.inclination_deg)
    # the figures this session used (a one-floor session without barometer or beacons records what it always did)
    used = {"floors": bool(plan.floor_plans), "barometer": extras.atmosphere is not None,
            "ble": extras.world is not None}
    recorded = {group: values for group, values in dataclasses.asdict(params).items() if used.get(group, True)}
    source: dict[str, Any] = {
        "generator": "sim_devices.pedestrian", "seed": seed, "preset": plan.preset, "mount": mount,
        "people": len(runs), "duration_s": duration_s, "truth_hz": TRUTH_HZ, "stand_key_hex": key.hex(),
        "params": recorded, "junctions": junctions,
        "turns": sorted(({"agent_id": agent, **passage} for agent, passages in junctions.items() for passage in passages
                         if abs(passage["turn_deg"]) >= TURN_MIN_DEG), key=lambda turn: (turn["time_ns"], turn["agent_id"])),
        "magnetic": {"floor_factor": field.floor_factor, "earth_ut": field.earth_ut.tolist()},
        "truth": {"people": people, "phones": phones}}
    if extras.atmosphere is not None:
        source["barometer"] = {**extras.atmosphere.record(), "offset_hpa": {
            stream.sensor_id: stream.offset_hpa for streams in extras.pressure for stream in streams}}
    if extras.world is not None:
        source["ble"] = {**extras.world.record(), "phone_offset_db": {
            found.sensor_id: found.offset_db for walker in extras.sightings for found in walker}}
    if plan.floor_plans:
        source["floor_height_m"] = plan.floor_height_m
    return Session(venue, tuple(agents), source)


def _junctions(run: WalkerRun) -> list[dict[str, Any]]:
    out = []
    for corner, time_s in run.corner_times_s():
        if time_s >= run.timeline.time_s[-1] or run.timeline.s_m[-1] < corner.s_m:
            continue  # not reached before the walk was cut short
        before, after = math.degrees(corner.heading_before_rad), math.degrees(corner.heading_after_rad)
        out.append({"time_ns": int(run.true_ns(time_s)), "point_id": corner.node,
                    "heading_before_deg": _wrap_deg(before), "heading_after_deg": _wrap_deg(after),
                    "turn_deg": math.degrees(corner.turn_rad)})
    return out


def _wrap_deg(angle: float) -> float:
    return (angle + 180.0) % 360.0 - 180.0


def _imu_items(venue: str, run: WalkerRun, index: int, params: PedestrianParams,
               counts: dict[str, int]) -> Iterator[Item]:
    phone, size = run.phones[index], params.sensors.batch_samples
    agent_id = run.person.person_id
    topic = keys.imu(venue, agent_id, phone.sensor_id)
    for sequence, start in enumerate(range(0, len(phone.time_ns), size)):
        rows = slice(start, start + size)
        message = imu_batch(agent_id, phone.sensor_id, sequence, phone.time_ns[rows], phone.accel_g[rows],
                            phone.gyro_dps[rows], phone.mag_gauss[rows])
        counts["batches"] += 1
        yield int(phone.time_ns[rows][-1]), 0, topic, message


def _truth_items(plan: Layout, run: WalkerRun) -> Iterator[Item]:
    stamps, x, y, heading = truth_rows(run, TRUTH_HZ)
    floors = truth_floors(run, TRUTH_HZ, plan.floor_height_m)
    agent_id = run.person.person_id
    topic = keys.truth(plan.venue_name, agent_id)
    for row in range(len(stamps)):
        stamp = int(stamps[row])
        yield stamp, 2, topic, messages.new("TruthPose", timestamp_ns=stamp, agent_id=agent_id, x_m=float(x[row]),
                                            y_m=float(y[row]), heading_rad=float(heading[row]),
                                            floor=int(floors[row]))


def _pressure_items(venue: str, run: WalkerRun, stream: PressureStream) -> Iterator[Item]:
    agent_id = run.person.person_id
    topic = keys.pressure(venue, agent_id, stream.sensor_id)
    for stamp, value in zip(stream.time_ns.tolist(), stream.pressure_hpa.tolist()):
        yield stamp, 3, topic, messages.new("Pressure", timestamp_ns=stamp, agent_id=agent_id,
                                            sensor_id=stream.sensor_id, pressure_hpa=value)


def _sighting_items(venue: str, run: WalkerRun, found: Sightings, world: RadioWorld | None) -> Iterator[Item]:
    if world is None:
        return
    agent_id = run.person.person_id
    topic = keys.beacon(venue, agent_id, found.sensor_id)
    stamps = run.true_ns(found.walker_s)
    for stamp, index, rssi in zip(stamps.tolist(), found.beacon_index.tolist(), found.rssi_dbm.tolist()):
        yield stamp, 4, topic, messages.new("BeaconSighting", timestamp_ns=stamp, agent_id=agent_id,
                                            sensor_id=found.sensor_id, beacon_id=world.beacons[index].id,
                                            rssi_dbm=rssi)


def _scan_items(plan: Layout, run: WalkerRun, key: bytes, counts: dict[str, int]) -> Iterator[Item]:
    agent_id = run.person.person_id
    topic = keys.scan(plan.venue_name, agent_id)
    visits = sorted((w.scan_s, phone.sensor_id, w.stand) for phone in run.phones for w in phone.motion.windows)
    for scan_s, sensor, stand in visits:
        if scan_s > run.timeline.time_s[-1]:
            continue
        stamp = int(run.true_ns(scan_s))
        text = stand_code.encode(stand, plan.venue_name, key)
        counts["scans"] += 1
        yield stamp, 1, topic, stand_code.scan_message(text, stamp, agent_id, sensor, plan.venue_name, key,
                                                       plan.stands)

