"""A swimmer's edge computation, without I/O: ImuBatch messages in, SwimLength messages out.

Per sensor: samples -> attitude and 100 Hz rows (edge/swim/bins.py) -> a buffer that holds the
current length -> wall events (edge/swim/walls.py) -> when a length has ended (its wall touch,
and the next push-off or rest that pins its velocity to zero), our estimate of it
(edge/swim/length.py) leaves as a SwimLength. Memory is bounded by the longest length
(`max_length_s`): a buffer that fills without a wall is dropped (counted) and the tracker waits
for the next push-off.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from edge.base import EdgeSummary
from edge.swim import walls
from edge.swim.bins import BIN_HZ, COLUMNS, BinSettings, BodyBinner
from edge.swim.length import RestGyro, YawDrift, lane_reading, reckon_length
from edge.swim.paper import LengthEstimate
from protocol import messages
from protocol.session import Agent, Mount, Route, Sensor

MAX_LENGTH_S = 300.0  # a 25 m length takes 15-60 s; a 50 m one up to 2 min
PRE_PUSH_S = 2.0  # rows kept before a push-off (its onset search looks back)
TURN_WAIT_S = 6.0  # after a heading reversal, the push-off comes within this, or the set has ended
# A length's velocity is taken zero at its touch (where the body's deceleration into the wall
# ends, edge/swim/walls.py) rather than at the next push-off: in the open turn between them (tuck,
# 50 deg of pitch, half a turn in 1.2-2 s) the attitude filter leaks 0.3-0.7 m/s into the velocity
# (simulated waist crawl diagonal sets against the exact motion), and removed as a line over the
# whole length that turn's leak bent the diagonal's speed profile (docs/swim-estimator.md, "What
# limits the diagonal"). Where the filter's leak over the length is far from a line (the head in
# backstroke and butterfly), the touch can leave the swimmer going backwards for a third of the
# length; a swimmer never does, so past BACKWARD_MAX the end that goes backwards least is taken.
BACKWARD_MAX = 0.2  # share of the travel: a crawler's touch leaves 0-0.01, a kickboard's to 0.11


@dataclass
class TrackerCounters:
    lengths: int = 0
    turns: int = 0
    stops: int = 0
    overlong: int = 0  # buffers dropped: no wall within max_length_s
    failed: int = 0  # lengths whose estimate could not be formed (too short, no displacement)


class SwimTracker:
    """One sensor: `push_samples(time_ns, accel_g, gyro_dps) -> [LengthEstimate]` (or `push_rows(rows)`), `flush()`."""

    def __init__(self, sensor: Sensor, pool_length_m: float, route: Route, max_length_s: float = MAX_LENGTH_S):
        self.binner = BodyBinner(BinSettings(sensor.rate_hz, sensor.forward_axis or "+x", sensor.left_axis or "+y"))
        self.pool_length_m, self.route = pool_length_m, route
        self.board = sensor.mount is Mount.KICKBOARD  # its touch: walls.touch_in
        self.capacity = walls.rows_for(max_length_s + PRE_PUSH_S + TURN_WAIT_S + 5.0)
        self.rows = np.zeros((self.capacity, len(COLUMNS)))
        self.n = 0
        self.scanned = 0  # rows already examined for events
        self.push: int | None = None  # row of the current length's push-off onset
        self.reversal: int | None = None  # row of a heading reversal waiting for its push-off
        # The heading's drift rate, carried from length to length, for every mounting. A kickboard's heading is
        # the board's, turned by hand at the wall, yet learning it helps with the velocity's zero at the touch
        # (simulated sets, seeds 1-6: diagonal -1.72 / 5.24 % RMS 3.04 against -2.00 / 8.96 % RMS 4.09 without,
        # straight +0.02 / 0.16 against +0.17 / 0.56): YawDrift's gate refuses the hand turns' readings. With
        # the zero at the next push-off it would not (diagonal -9.2 / 26.1 % against -8.3 / 27.5 without).
        self.drift = YawDrift()
        self.rest = RestGyro()  # the gyro's offset read at rest before a set, for its first length
        self.counters = TrackerCounters()

    def push_samples(self, time_ns: np.ndarray, accel_g: np.ndarray, gyro_dps: np.ndarray) -> list[LengthEstimate]:
        return self.push_rows(self.binner.push(time_ns, accel_g, gyro_dps))

    def flush(self) -> list[LengthEstimate]:
        """End of stream: a length in progress ends at its last rows if the swimmer had stopped."""
        out: list[LengthEstimate] = []
        if self.push is not None and self.reversal is not None:
            out += self._close(walls.touch_before_turn(self.rows, self.reversal, self.push, self.board), self.n - 1)
        return out

    def push_rows(self, new_rows: np.ndarray) -> list[LengthEstimate]:
        """Rows of edge/swim/bins.py already made (`reckon eval` bins a whole sensor once)."""
        out: list[LengthEstimate] = []
        for row in new_rows:
            if self.n == self.capacity:
                self._drop_overlong()
            self.rows[self.n] = row
            self.n += 1
        while self.scanned < self.n:
            out += self._examine(self.scanned)
            self.scanned += 1
        return out

    def _examine(self, i: int) -> list[LengthEstimate]:
        rows = self.rows
        if self.push is None:
            # Between sets only: within a length the glide or a pause can look still (and a turn's
            # rows are the previous length's).
            self.rest.add(rows[i:i + 1])
            found = walls.find_push(rows[:i + 1], max(0, i - walls.rows_for(1.0)), i)
            if found is not None:
                self._start(found[0])
            return []
        if self.reversal is None:
            glide = self.push + walls.rows_for(2.0)
            if walls.reversed_at(rows, i, glide):
                self.reversal = i
            elif i - walls.rows_for(walls.STILL_S) >= self.push + walls.rows_for(walls.GLIDE_MAX_S) \
                    and walls.still_until(rows, i):
                self.counters.stops += 1
                # The set has ended. Where is the velocity zero: at the touch, where the body stopped
                # at the wall, or once it is at rest? Coming upright at the wall (70 deg of pitch in
                # about a second) can tilt the attitude in between, and its leak, spread over the
                # length, took up to 20-86 % off a length whichever single row was chosen (seeds
                # 1-2). The touch, unless another leaves the swimmer going backwards less
                # (pick_zero_end).
                still_from = i - walls.rows_for(walls.STILL_S)
                touch = walls.touch_before_rest(rows, still_from, self.push, self.board)
                return self._close(touch, touch, other_stops=(still_from, i))
            return []
        found = walls.find_push(rows[:i + 1], max(self.reversal, i - walls.rows_for(1.0)), i)
        if found is not None:
            self.counters.turns += 1
            out = self._close(walls.touch_before_turn(rows, self.reversal, self.push, self.board), found[0])
            self._start(found[0])
            return out
        if i - self.reversal > walls.rows_for(TURN_WAIT_S):
            self.counters.stops += 1
            return self._close(walls.touch_before_turn(rows, self.reversal, self.push, self.board), i)
        return []

    def _start(self, push_row: int) -> None:
        """A length begins at `push_row`: keep only the rows from PRE_PUSH_S before it."""
        keep_from = max(0, push_row - walls.rows_for(PRE_PUSH_S))
        self._shift(keep_from)
        self.push = push_row - keep_from
        self.reversal = None

    def _close(self, touch: int, stop: int, other_stops: tuple[int, ...] = ()) -> list[LengthEstimate]:
        push = self.push
        self.push, self.reversal = None, None
        if push is None or not push < touch <= stop:
            self.counters.failed += 1
            return []
        rows = self.rows[:self.n]
        # The velocity's zero at the touch, else at `stop` (the next push-off) or a rest (BACKWARD_MAX).
        zeros = tuple(dict.fromkeys((touch, stop, *other_stops)))
        self.drift = self.drift.learn(lane_reading(rows, push, touch, touch, self.route,
                                                   rest_offset_dps=self.rest.take()))
        estimates = [reckon_length(rows, push, touch, zero_at, self.pool_length_m, self.route,
                                   drift_dps=self.drift.rate_dps) for zero_at in zeros if touch <= zero_at]
        estimate = pick_zero_end(estimates)
        if not np.isfinite(estimate.swum_distance_m):
            self.counters.failed += 1
            return []
        self.counters.lengths += 1
        return [estimate]

    def _shift(self, first: int) -> None:
        if first <= 0:
            return
        kept = self.n - first
        self.rows[:kept] = self.rows[first:self.n]
        self.n -= first
        self.scanned = max(0, self.scanned - first)
        if self.reversal is not None:
            self.reversal -= first

    def overlong_warning(self) -> str:
        """The line to log for each buffer dropped (counters.overlong): the caller logs it, this core has no I/O."""
        return f"no wall for {self.capacity / BIN_HZ:.0f} s: dropping the length in progress"

    def _drop_overlong(self) -> None:
        self.counters.overlong += 1
        self.push, self.reversal = None, None
        self._shift(self.n - walls.rows_for(PRE_PUSH_S))


def pick_zero_end(estimates: list[LengthEstimate]) -> LengthEstimate:
    """Of one length's estimates with different zero-velocity ends (the touch first), the first,
    unless its swimmer goes backwards for more than BACKWARD_MAX of the travel: then the one that
    goes backwards least (the first of equals)."""
    if estimates[0].backward_share <= BACKWARD_MAX:
        return estimates[0]
    return min(estimates, key=lambda estimate: estimate.backward_share)


@dataclass
class SwimEdge:
    """A swimmer's sensors: `push(batch) -> [SwimLength]`, `flush() -> [SwimLength]` (an edge.base.Edge)."""

    agent: Agent
    pool_length_m: float
    method: str = "reckon"
    trackers: dict[str, SwimTracker] = field(default_factory=dict)
    indices: dict[str, int] = field(default_factory=dict)
    samples: int = 0
    warned: dict[str, int] = field(default_factory=dict)  # per sensor, the dropped buffers already in warnings()

    def __post_init__(self) -> None:
        for sensor in self.agent.sensors:
            self.trackers[sensor.id] = SwimTracker(sensor, self.pool_length_m, self.agent.route)
            self.indices[sensor.id] = 0

    def push(self, batch: Any) -> list[Any]:
        tracker = self.trackers.get(batch.sensor_id)
        if tracker is None:
            return []
        times = batch.timestamp_ns + np.asarray(batch.sample_offset_ns, dtype=np.int64)
        accel = np.asarray(batch.accel_g, dtype=float).reshape(-1, 3)
        gyro = np.asarray(batch.gyro_dps, dtype=float).reshape(-1, 3)
        self.samples += len(times)
        return [self._message(batch.sensor_id, e) for e in tracker.push_samples(times, accel, gyro)]

    def flush(self) -> list[Any]:
        return [self._message(sensor_id, e) for sensor_id, tracker in self.trackers.items() for e in tracker.flush()]

    def warnings(self) -> list[str]:
        """A line for each length in progress dropped since the last call (no wall within its tracker's
        max_length_s), for the process to log."""
        out: list[str] = []
        for sensor_id, tracker in self.trackers.items():
            out += [tracker.overlong_warning()] * (tracker.counters.overlong - self.warned.get(sensor_id, 0))
            self.warned[sensor_id] = tracker.counters.overlong
        return out

    def correct(self, correction: Any) -> None:
        """The hub does not correct a swimmer's lengths."""

    def scan(self, scan: Any) -> None:
        """A pool has no stands to scan."""

    def pressure(self, reading: Any) -> None:
        """A pool has no floors to count."""

    def field_map(self, field_map: Any) -> None:
        """A swimmer's heading needs no map of the hall's field."""

    def summarise(self, summary: EdgeSummary) -> None:
        summary.swimmer = True
        summary.samples, summary.lengths = self.samples, sum(self.indices.values())

    def _message(self, sensor_id: str, estimate: LengthEstimate) -> Any:
        self.indices[sensor_id] += 1
        return length_message(self.agent.id, sensor_id, self.method, self.indices[sensor_id], estimate, True)


def length_message(agent_id: str, sensor_id: str, method: str, index: int, estimate: LengthEstimate,
                   walls_detected: bool) -> Any:
    swimming_s = max(estimate.duration_s, 1e-9)
    return messages.new(
        "SwimLength", timestamp_ns=estimate.end_ns, agent_id=agent_id, sensor_id=sensor_id, method=method,
        index=index, start_ns=estimate.start_ns, swum_distance_m=estimate.swum_distance_m,
        lane_distance_m=estimate.lane_distance_m, duration_s=estimate.duration_s,
        stroke_count=estimate.stroke_count, stroke_rate_per_min=60.0 * estimate.stroke_count / swimming_s,
        scale=estimate.scale, heading_error_deg=estimate.heading_error_deg,
        lateral_deviation_m=np.round(estimate.lateral_m, 3).tolist(), profile_step_m=estimate.profile_step_m,
        walls_detected=walls_detected)
