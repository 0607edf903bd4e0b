"""One chair's edge computation, without I/O: sensor messages in, pose and impact messages out.

ImuBatch messages of the chair's three sensors -> the merger (edge/chair/merger.py) -> the chair
filter (edge/chair/estimator.py), both run in their compiled batch forms (edge/chair/merge_kernel.py,
edge/chair/kernel.py), handed in as `kernels`: reckon/kernels.py loads them ahead-of-time compiled,
without numba; by default they are compiled just in time, which the tests use. A pose leaves on a
fixed schedule of the seat clock (`pose_rate_hz`), an ImpactEvent at once. Corrections from the hub (`correct`) are applied before the next sample,
to the state as it is then: a Correction measures where the chair was at its time, as an offset
from the pose the hub had for that time, and the few samples since then moved the chair the same
whatever its error. The hub's map of the hall's magnetic field (`field_map`, hub/chair/field_map.py)
is looked up where the chair is before each batch and handed to the filter's magnetometer aid; each
reading the aid offers the map goes out as a FieldReading. `reckon edge` wraps this in Zenoh;
`reckon eval` drives it in lockstep with the hub.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from edge.base import EdgeSummary
from edge.chair import layout
from edge.chair.estimator import axle_scale_measured, position_update, start
from edge.chair.merge_layout import PackedMerger
from edge.chair.state import GYRO_SCALE, ChairSettings, ChairState, Flag
from protocol import messages
from protocol.session import Agent

NO_GATE = math.inf  # the hub gated the correction already, against the same pose
MAX_MAP_CELLS = 65_536  # a 500 x 260 m hall in 2 m cells: a bigger map is refused, not held


class ChairEdge:
    """`push(batch) -> [EstimatedPose | ImpactEvent]`, `correct(correction)`, `flush()` (an edge.base.Edge)."""

    def __init__(self, agent: Agent, pose_rate_hz: float = 50.0, method: str = "reckon",
                 kernels: layout.ChairKernels | None = None):
        if not pose_rate_hz > 0:
            raise ValueError(f"pose_rate_hz {pose_rate_hz}: must be > 0")
        self.agent = agent
        self.settings = ChairSettings(wheel_diameter_m=agent.wheel_diameter_m, camber_deg=agent.camber_deg)
        self.method = method
        self.period_ns = int(1e9 / pose_rate_hz)
        self.packed_settings = layout.pack_settings(self.settings)
        if kernels is None:
            from edge.chair.kernel import just_in_time
            kernels = just_in_time()
        self.kernels = kernels
        self.merger = PackedMerger(agent, kernels.merge_batch)
        # a first call of each now (just in time: compiles), not on the first sample of a live stream
        kernels.merge_batch(*self.merger.arguments(None))
        kernels.merge_and_run(*self.merger.arguments(None), self.packed_settings, np.zeros(layout.STATE_SIZE), 0,
                              self.period_ns)
        kernels.run_poses(self.packed_settings, np.zeros(layout.STATE_SIZE), np.zeros(0, dtype=np.int64),
                          np.zeros((0, layout.SAMPLE_WIDTH)), 0, self.period_ns)
        self.vector: np.ndarray | None = None  # the filter state, packed (fixed size)
        self.next_pose_ns = 0
        self.corrections: deque[Any] = deque(maxlen=64)  # the hub sends a few per minute
        self.correction_sequence = 0
        self.samples = self.poses = self.impacts = self.corrections_applied = 0
        self.axle_check = Flag.NONE  # the seat gyro's one scale check against the axle IMUs, once made
        self.axle_pending = True  # ... not yet made (a bool: read per batch)
        self.map: tuple[float, float, float, np.ndarray, np.ndarray] | None = None  # origin, cell, offsets, variances
        self.field_count = 0  # the aid's readings published so far
        self.maps_taken = self.maps_refused = 0
        self.pending_warnings: list[str] = []
        self.pose_fields = messages.EstimatedPose(schema_version=messages.SCHEMA_VERSION, agent_id=agent.id,
                                                  method=method, track=messages.Track.LIVE)

    @property
    def state(self) -> ChairState | None:
        return None if self.vector is None else layout.unpack_state(self.vector)

    def push(self, batch: Any) -> list[Any]:
        return self._step(self.merger.arguments(batch))

    def flush(self) -> list[Any]:
        return self._step(self.merger.arguments(None, flush=True))

    def correct(self, correction: Any) -> None:
        """Queue a hub Correction; it is applied before the next sample (or with the next pose)."""
        self.corrections.append(correction)

    def field_map(self, field_map: Any) -> None:
        """The hub's map of the hall's field (hub/chair/field_map.py): used from the next batch on; an
        empty one (no cells) drops the map, and the aid falls back to its own model of the hall."""
        columns, rows, cell_m = field_map.columns, field_map.rows, field_map.cell_m
        if columns * rows == 0:
            self.map = None
            self.maps_taken += 1
            return
        cells = columns * rows
        if (cells > MAX_MAP_CELLS or len(field_map.offset_rad) != cells or len(field_map.variance_rad2) != cells
                or not cell_m > 0.0):
            self.maps_refused += 1
            if self.maps_refused in (1, 10, 100) or self.maps_refused % 1000 == 0:
                self.pending_warnings.append(
                    f"{self.agent.id}: field map refused ({self.maps_refused} so far): {columns} x {rows} cells of "
                    f"{cell_m} m with {len(field_map.offset_rad)} offsets and {len(field_map.variance_rad2)} variances "
                    f"(at most {MAX_MAP_CELLS} cells, one of each per cell)")
            return
        offsets = np.array(field_map.offset_rad[:], dtype=float).reshape(rows, columns)
        variances = np.array(field_map.variance_rad2[:], dtype=float).reshape(rows, columns)
        variances[~(np.isfinite(offsets) & np.isfinite(variances) & (variances > 0.0))] = 0.0  # not known there
        self.map = (field_map.origin_x_m, field_map.origin_y_m, cell_m, offsets, variances)
        self.maps_taken += 1

    def scan(self, scan: Any) -> None:
        """A chair has no stands to scan."""

    def pressure(self, reading: Any) -> None:
        """A chair has no floors to count."""

    def warnings(self) -> list[str]:
        out, self.pending_warnings = self.pending_warnings, []
        return out

    def summarise(self, summary: EdgeSummary) -> None:
        summary.samples, summary.poses, summary.impacts = self.samples, self.poses, self.impacts
        summary.corrections = self.corrections_applied
        summary.field_readings, summary.field_maps = self.field_count, self.maps_taken
        counters = self.merger.counters
        summary.extrapolated, summary.wheel_overrun, summary.bridged = (counters.extrapolated, counters.wheel_overrun,
                                                                        counters.bridged)
        left_ns, right_ns = self.merger.clock_offsets_ns
        summary.wheel_clocks_ms = (left_ns / 1e6, right_ns / 1e6)
        state = self.state
        if state is not None:
            mean = state.mean
            summary.final_pose = (float(mean[0]), float(mean[1]), float(mean[2]))
            check = ("checked against the axles" if self.axle_check & Flag.AXLE_SCALE_USED else
                     "the axles disagreed, not used" if self.axle_check & Flag.AXLE_SCALE_REJECTED else
                     "not yet checked against the axles")
            summary.seat_gyro_scale = (100.0 * float(mean[GYRO_SCALE]), check)

    def _apply_corrections(self) -> None:
        while self.corrections and self.vector is not None:
            correction = self.corrections.popleft()
            if correction.sequence <= self.correction_sequence:
                continue  # a duplicate (the hub resends after a restart)
            state = layout.unpack_state(self.vector)
            shift = np.array([correction.dx_m, correction.dy_m])
            covariance = np.array(correction.covariance, dtype=float).reshape(2, 2)
            state, _ = position_update(state, state.mean[:2] + shift, covariance, NO_GATE)
            self.vector = layout.pack_state(state)
            self.correction_sequence = correction.sequence
            self.corrections_applied += 1

    def _step(self, merge_arguments: tuple) -> list[Any]:
        """One batch merged and its samples through the filter, a pose at each pose time; until the
        filter has started (its first merged sample), the two steps apart."""
        vector = self.vector
        if vector is not None:  # per batch: each step here costs a share of the push path's ~18 us
            if self.corrections:
                self._apply_corrections()
                vector = self.vector
            if self.map is not None or vector[layout.MAP_VAR] != 0.0:
                self._look_up_map()
            merged, flags, self.next_pose_ns, posed, times, rows = self.kernels.merge_and_run(
                *merge_arguments, self.packed_settings, vector, self.next_pose_ns, self.period_ns)
            self.samples += merged
            out = self._publish(flags, posed, times, rows)
            return out + self._field_reading() if vector[layout.FIELD_COUNT] != self.field_count else out
        times, values = self.kernels.merge_batch(*merge_arguments)
        if not len(times):
            return []
        first = layout.unpack_sample(times[0], values[0])
        self.vector = layout.pack_state(start(self.settings, first, self.agent.start_x_m, self.agent.start_y_m,
                                              self.agent.start_heading_rad))
        self.samples += len(times)
        self._apply_corrections()
        flags, self.next_pose_ns, posed, times, rows = self.kernels.run_poses(
            self.packed_settings, self.vector, times[1:], values[1:], self.next_pose_ns, self.period_ns)
        return self._publish(flags, posed, times, rows)

    def _look_up_map(self) -> None:
        """The map's offset and variance where the chair is, into the filter's state: bilinear between
        the four nearest cell centres, over those known (none known: no map here)."""
        offset = variance = 0.0
        if self.map is not None:
            origin_x, origin_y, cell_m, offsets, variances = self.map
            rows, columns = offsets.shape
            u = (self.vector[layout.MEAN] - origin_x) / cell_m - 0.5
            v = (self.vector[layout.MEAN + 1] - origin_y) / cell_m - 0.5
            column, row = math.floor(u), math.floor(v)
            fu, fv = u - column, v - row
            total = 0.0
            for dr, wr in ((0, 1.0 - fv), (1, fv)):
                for dc, wc in ((0, 1.0 - fu), (1, fu)):
                    r, c = min(max(row + dr, 0), rows - 1), min(max(column + dc, 0), columns - 1)
                    weight = wr * wc
                    if variances[r, c] > 0.0 and weight > 0.0:
                        total += weight
                        offset += weight * offsets[r, c]
                        variance += weight * variances[r, c]
            if total > 0.0:
                offset, variance = offset / total, variance / total
        self.vector[layout.MAP_OFFSET], self.vector[layout.MAP_VAR] = offset, variance

    def _field_reading(self) -> list[Any]:
        """The aid's newest reading for the hub's map, made in this batch (readings come at most every
        `mag_period_s`: of two in one batch, the later goes)."""
        self.field_count = int(self.vector[layout.FIELD_COUNT])
        v = self.vector
        time_ns = (int(v[layout.FIELD_TIME_HIGH]) << 32) + int(v[layout.FIELD_TIME_LOW])
        return [messages.new("FieldReading", timestamp_ns=time_ns, agent_id=self.agent.id, x_m=float(v[layout.FIELD_X]), y_m=float(v[layout.FIELD_Y]),
                             offset_rad=float(v[layout.FIELD_OFFSET]), variance_rad2=float(v[layout.FIELD_VAR]))]

    def _publish(self, flags: int, posed: int, times: np.ndarray, rows: np.ndarray) -> list[Any]:
        """A kernel call's poses and impacts (times and rows as run_poses hands them; the state
        already advanced) out as messages."""
        out: list[Any] = []
        if self.axle_pending and self.vector[layout.AXLE_DONE]:  # made in this call: its flag is here
            self.axle_pending = False
            self._note_axle_check(Flag(int(flags)))
        if not len(times):  # nothing released (a batch whose samples wait for another sensor's)
            return out
        times, rows = times.tolist(), rows.tolist()
        impacts = [self._impact(time_ns, row) for time_ns, row in zip(times[posed:], rows[posed:])]
        hit = 0  # an impact goes out before the pose its run ended with, as it happened before it
        for time_ns, pose in zip(times[:posed], rows[:posed]):
            while hit < len(impacts) and impacts[hit].timestamp_ns <= time_ns:
                out.append(impacts[hit])
                hit += 1
            out.append(self._pose_message(time_ns, pose))
        out += impacts[hit:]
        self.poses += posed
        self.impacts += len(impacts)
        return out

    def _pose_message(self, time_ns: int, pose: list[float]) -> Any:
        """A pose row (x, y, heading, covariance 3 x 3) as the EstimatedPose it stands for: its fixed
        fields copied from one made once (a third cheaper than setting them by name each time)."""
        message = messages.EstimatedPose()
        message.CopyFrom(self.pose_fields)
        message.timestamp_ns, message.x_m, message.y_m, message.heading_rad = time_ns, pose[0], pose[1], pose[2]
        message.covariance.extend(pose[3:])
        message.correction_sequence = self.correction_sequence
        return message

    def _impact(self, time_ns: int, row: list[float]) -> Any:
        """An impact row (accel, gravity then) as its ImpactEvent: the push without gravity."""
        ax, ay, az, gx, gy = row[:5]
        return messages.new("ImpactEvent", timestamp_ns=time_ns, agent_id=self.agent.id, sensor_id=self.merger.seat_id,
                            peak_g=math.sqrt(ax * ax + ay * ay + az * az) - 1.0, forward_g=ax - gx, left_g=ay - gy)

    def _note_axle_check(self, flags: Flag) -> None:
        """Keep the scale check's outcome; a refused one is the venue file's problem, so say why."""
        self.axle_check = flags & (Flag.AXLE_SCALE_USED | Flag.AXLE_SCALE_REJECTED)
        if not self.axle_check & Flag.AXLE_SCALE_REJECTED:
            return
        state = layout.unpack_state(self.vector)
        axle, mean, cov = state.axle, state.mean, state.cov
        if axle.xy <= 0.0:
            found = "the axle IMUs turned against the seat's gyro"
        else:
            measured = axle_scale_measured(self.settings, axle)
            found = (f"the axle IMUs' turn put the seat gyro's scale at {100 * measured:+.1f} %, the filter had "
                     f"{100 * mean[GYRO_SCALE]:+.1f} +- {100 * math.sqrt(cov[GYRO_SCALE, GYRO_SCALE]):.1f} %, "
                     f"beyond the {self.settings.axle_scale_gate_chi2} chi-square gate")
        self.pending_warnings.append(
            f"{self.agent.id}: {found} after {math.degrees(axle.seen_rad):.0f} deg of yaw; not used: check the "
            f"chair's camber ({self.settings.camber_deg} deg) and the axle IMUs' mounting in the venue file")
