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
from sim_devices.pedestrian.params import PedestrianParams, check
from sim_devices.pedestrian.sensors import MagneticField, error_record
from sim_devices.pedestrian.simulate import MOUNTS, WalkerRun, simulate_walker, truth_rows
from sim_devices.pedestrian.venues import PRESETS, Layout, layout

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

    def __str__(self) -> str:
        walks = ", ".join(f"{agent} {metres:.0f} m" for agent, metres in self.distance_m.items())
        return (f"{self.output}: {self.people} walkers ({self.mount}) on preset {self.preset}, seed {self.seed}, "
                f"{self.duration_s:.1f} s\n  walked: {walks}\n  IMU: {self.imu_samples} samples in "
                f"{self.imu_batches} batches; truth poses: {self.truth_poses}; stand scans: {self.stand_scans}; "
                f"junction passages: {self.junctions}; file {self.file_bytes / 1e6:.2f} MB")


def stand_key(seed: int) -> bytes:
    """The venue's stand key for a simulated session: SHA-256 of a label and the seed (not secret)."""
    return hashlib.sha256(KEY_LABEL + str(seed).encode("ascii")).digest()


def simulate_pedestrian(output: Path, seed: int = 1, people: int = 3, preset: str = "paper", mount: str = "hand",
                        params: PedestrianParams | None = None, duration_s: float | None = None,
                        progress: Callable[[float], None] | None = None) -> PedestrianSummary:
    """Walk `people` through the preset's building and write the session log to `output`.
    `duration_s` cuts every walk short (tests); None walks the whole route. ConfigError for a bad
    argument, inconsistent params or an unwritable output. `progress` gets the share done in [0, 1]."""
    params = params or PedestrianParams()
    check(params)
    _check(seed, people, preset, mount, duration_s)
    report = progress or (lambda share: None)
    venue_seed, walker_seed = np.random.SeedSequence(seed).spawn(2)
    plan = layout(preset, people, params.stand.offset_m)
    field = MagneticField.draw(params.magnetic, np.random.default_rng(venue_seed))
    epoch_ns = params.clock.start_unix_s * 1_000_000_000
    runs = []
    for index in range(people):
        runs.append(simulate_walker(plan, index, MOUNTS[mount], params, walker_seed, field, epoch_ns, duration_s))
        report(SIM_SHARE * (index + 1) / people)
    key = stand_key(seed)
    session = _describe(plan, runs, params, field, seed, mount, key, duration_s)
    counts = {"batches": 0, "scans": 0}
    sources: list[Iterator[Item]] = []
    for run in runs:
        sources += [_imu_items(plan.venue_name, run, index, params, counts) for index in range(len(run.phones))]
        sources.append(_truth_items(plan.venue_name, run))
        sources.append(_scan_items(plan, run, key, counts))
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
        sum(len(session.source["junctions"][r.person.person_id]) for r in runs), Path(output).stat().st_size)


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
              mount: str, key: bytes, duration_s: float | None) -> Session:
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
                  # what the venue file knows (as the ILC import's WMM figures): Earth's field undisturbed
                  magnetic_north_deg=params.magnetic.north_deg - params.magnetic.declination_deg,
                  magnetic_field_ut=params.magnetic.field_ut, magnetic_dip_deg=params.magnetic.inclination_deg)
    source: dict[str, Any] = {
        "generator": "sim_devices.pedestrian", "seed": seed, "preset": plan.preset, "mount": mount,
        "people": len(runs), "duration_s": duration_s, "truth_hz": TRUTH_HZ, "stand_key_hex": key.hex(),
        "params": dataclasses.asdict(params), "junctions": junctions,
        "turns": sorted(({"agent_id": agent, **passage} for agent, passages in junctions.items() for passage in passages
                         if abs(passage["turn_deg"]) >= TURN_MIN_DEG), key=lambda turn: (turn["time_ns"], turn["agent_id"])),
        "magnetic": {"floor_factor": field.floor_factor, "earth_ut": field.earth_ut.tolist()},
        "truth": {"people": people, "phones": phones}}
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


def _truth_items(venue: str, run: WalkerRun) -> Iterator[Item]:
    stamps, x, y, heading = truth_rows(run, TRUTH_HZ)
    agent_id = run.person.person_id
    topic = keys.truth(venue, agent_id)
    for row in range(len(stamps)):
        stamp = int(stamps[row])
        yield stamp, 2, topic, messages.new("TruthPose", timestamp_ns=stamp, agent_id=agent_id, x_m=float(x[row]),
                                            y_m=float(y[row]), heading_rad=float(heading[row]))


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

