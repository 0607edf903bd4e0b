"""A pedestrian's edge computation, without I/O: phone ImuBatch, StandScan and Pressure messages
in, per-step EstimatedPose messages out.

The phone's batches (protocol units: g, deg/s, gauss, the phone's own axes) become PhoneSample
rows (m/s^2, rad/s, uT) for the dead reckoning: ours (edge/pedestrian/estimator.py) or the paper's
(edge/pedestrian/paper.py), both `step(sample) -> [PdrStep]` with `reset_to_stand`. An accepted stand
scan resets it; a refused one is only counted (the raw scan is recorded by the caller either way).

Every pose says how many stand resets it includes in `correction_sequence`: the hub receives
poses and scans on different keys, so a pose can overtake its scan; the count on the pose itself
tells the hub that the dead reckoning restarted, whatever order the two arrive in.
Nothing is published before the first accepted scan: until then the phone has no position.
Every pose names its floor: the last stand's, plus the changes the phone's barometer counted since
(edge/pedestrian/floors.py); without a barometer, the last stand's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from edge.base import EdgeSummary
from edge.pedestrian import floors
from edge.pedestrian.estimator import PdrEstimator, PdrSettings, PdrStep, PhoneSample
from edge.pedestrian.magnetic import VenueField
from protocol import messages
from protocol.messages import STANDARD_GRAVITY_MS2, UT_PER_GAUSS
from protocol.session import Agent, Mount, Sensor, Venue

METHOD = "reckon"


class DeadReckoning(Protocol):
    def step(self, sample: PhoneSample) -> list[PdrStep]: ...

    def reset_to_stand(self, time_ns: int, x_m: float, y_m: float, heading_rad: float,
                       tilt_rad: float | None = 0.0, heading_sd_rad: float | None = None) -> None: ...


@dataclass
class PedestrianCounters:
    samples: int = 0
    steps: int = 0
    scans_accepted: int = 0
    scans_refused: int = 0
    other_sensor_batches: int = 0  # batches of a sensor that is not this agent's phone
    before_first_scan: int = 0  # steps taken before any stand: not published
    pressure_readings: int = 0
    pressure_refused: int = 0  # outside 100-1200 hPa or not a number (a decoding fault): skipped


class PedestrianEdge:
    """`push(ImuBatch) -> [EstimatedPose]`, `scan(StandScan)`, `flush()` (an edge.base.Edge)."""

    def __init__(self, agent: Agent, venue: Venue | None = None, estimator: DeadReckoning | None = None,
                 method: str = METHOD, sensor_id: str | None = None):
        """The agent's phone `sensor_id` (default its first sensor: one edge per device); our dead
        reckoning unless `estimator` is given; with the venue's Earth field stated
        (`venue.magnetic_*`), its magnetometer aid is on."""
        phone = next((s for s in agent.sensors if sensor_id is None or s.id == sensor_id), None)
        if phone is None:
            raise ValueError(f"agent {agent.id} has no sensor {sensor_id!r}")
        self.agent_id = agent.id
        self.sensor_id = phone.id
        self.estimator = estimator if estimator is not None else PdrEstimator(_settings_for(phone), venue_field(venue))
        self.method = method
        self.resets = 0
        self.last_pose: tuple[float, float, float] | None = None  # x m, y m, heading rad of the last step out
        self.counters = PedestrianCounters()
        self.floor_settings = floors.FloorSettings()
        self.floors = floors.FloorState()
        self._warned_pressure = 0  # refused readings already warned about

    @property
    def samples(self) -> int:
        return self.counters.samples

    def push(self, batch: Any) -> list[Any]:
        if batch.sensor_id != self.sensor_id:
            self.counters.other_sensor_batches += 1
            return []
        out: list[Any] = []
        for sample in phone_samples(batch):
            self.counters.samples += 1
            for step in self.estimator.step(sample):
                if not self.resets:
                    self.counters.before_first_scan += 1
                    continue
                self.counters.steps += 1
                out.append(self._pose(step))
        return out

    def scan(self, scan: Any) -> None:
        if scan.sensor_id and scan.sensor_id != self.sensor_id:  # the agent's other phone
            return
        if not scan.accepted:
            self.counters.scans_refused += 1
            return
        self.counters.scans_accepted += 1
        self.resets += 1
        self.floors = floors.at_fix(self.floors, scan.timestamp_ns, scan.floor, self.floor_settings)
        self.estimator.reset_to_stand(scan.timestamp_ns, scan.x_m, scan.y_m, scan.heading_rad, scan.tilt_rad,
                                      scan.heading_sd_rad or None)

    def field_map(self, field_map: Any) -> None:
        """The hub maps a chair hall's field; a phone's magnetometer has its own checks (edge/pedestrian/magnetic.py)."""

    def pressure(self, reading: Any) -> None:
        """One barometer reading of this phone (another phone's is its own edge's)."""
        if reading.sensor_id and reading.sensor_id != self.sensor_id:
            return
        self.counters.pressure_readings += 1
        try:
            self.floors = floors.step(self.floors, reading.timestamp_ns, reading.pressure_hpa, self.floor_settings)
        except ValueError:
            self.counters.pressure_refused += 1
            return
        if hasattr(self.estimator, "on_stairs"):  # ours; the paper's method knows no stairs
            self.estimator.on_stairs = floors.on_stairs(self.floors, self.floor_settings)

    def flush(self) -> list[Any]:
        return []

    def correct(self, correction: Any) -> None:
        """The hub does not correct a phone's dead reckoning: a stand scan resets it."""

    def warnings(self) -> list[str]:
        refused = self.counters.pressure_refused
        if refused and refused >= 2 * self._warned_pressure:  # 1, 2, 4, 8, ...: rate-limited
            self._warned_pressure = refused
            return [f"{self.sensor_id}: {refused} of {self.counters.pressure_readings} pressure readings refused "
                    f"(outside 100-1200 hPa or not a number); floors are counted from the others"]
        return []

    def summarise(self, summary: EdgeSummary) -> None:
        summary.pedestrian = True
        summary.samples, summary.poses, summary.final_pose = self.samples, self.counters.steps, self.last_pose

    def _pose(self, step: PdrStep) -> Any:
        self.last_pose = (step.x_m, step.y_m, step.heading_rad)
        return messages.new("EstimatedPose", timestamp_ns=step.time_ns, agent_id=self.agent_id, x_m=step.x_m,
                            y_m=step.y_m, heading_rad=step.heading_rad,
                            covariance=np.asarray(step.covariance, dtype=float).ravel().tolist(),
                            method=self.method, track=messages.Track.LIVE, correction_sequence=self.resets,
                            floor=floors.current_floor(self.floors, self.floor_settings) or 0)


AXES = {"+x": (1.0, 0.0, 0.0), "-x": (-1.0, 0.0, 0.0), "+y": (0.0, 1.0, 0.0), "-y": (0.0, -1.0, 0.0),
        "+z": (0.0, 0.0, 1.0), "-z": (0.0, 0.0, -1.0)}


def _settings_for(phone: Sensor) -> PdrSettings:
    """Our settings for a phone: its forward axis from the session (a phone's default is +y, the
    top of a phone held flat in front; in a pocket, the screen's normal, +z or -z). In a pocket the
    session's axis is only how the phone sat at first (its sign and its angle change each time it
    is put back), so the walking direction relative to it is read from the acceleration."""
    return PdrSettings(forward_axis=AXES[phone.forward_axis or "+y"],
                       direction_from_acceleration=phone.mount is Mount.POCKET)


def venue_field(venue: Venue | None) -> VenueField | None:
    """The venue's undisturbed field for the magnetometer aid, or None when the venue file does not
    state all three of magnetic_north_deg, magnetic_field_ut and magnetic_dip_deg."""
    if venue is None or None in (venue.magnetic_north_deg, venue.magnetic_field_ut, venue.magnetic_dip_deg):
        return None
    return VenueField(math.radians(venue.magnetic_north_deg), venue.magnetic_field_ut,
                      math.radians(venue.magnetic_dip_deg))


def phone_samples(batch: Any) -> list[PhoneSample]:
    """The batch's samples in PhoneSample units; a sample with a non-finite value is dropped
    (the raw batch is kept by the caller)."""
    count = len(batch.sample_offset_ns)
    accel = np.asarray(batch.accel_g, dtype=float).reshape(-1, 3) * STANDARD_GRAVITY_MS2
    gyro = np.radians(np.asarray(batch.gyro_dps, dtype=float).reshape(-1, 3))
    mag = (np.asarray(batch.mag_gauss, dtype=float).reshape(-1, 3) * UT_PER_GAUSS
           if len(batch.mag_gauss) == 3 * count else None)
    if len(accel) != count or len(gyro) != count:
        return []
    samples = []
    for i in range(count):
        row_mag = None if mag is None or not np.all(np.isfinite(mag[i])) else tuple(mag[i].tolist())
        if not (np.all(np.isfinite(accel[i])) and np.all(np.isfinite(gyro[i]))):
            continue
        samples.append(PhoneSample(batch.timestamp_ns + int(batch.sample_offset_ns[i]), tuple(accel[i].tolist()),
                                   tuple(gyro[i].tolist()), row_mag))
    return samples
