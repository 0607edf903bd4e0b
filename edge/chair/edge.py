"""One chair's edge computation, without I/O: sensor messages in, pose and impact messages out.

ImuBatch messages of the chair's three sensors -> ChairMerger -> the chair filter
(edge/chair/estimator.py, run by its compiled batch form edge/chair/kernel.py). A pose leaves on a fixed schedule of the seat clock (`pose_rate_hz`),
an ImpactEvent at once. Corrections from the hub (`correct`) are applied before the next sample,
to the state as it is then: a Correction measures where the chair was at its time, as an offset
from the pose the hub had for that time, and the few samples since then moved the chair the same
whatever its error. `reckon edge` wraps this in Zenoh; `reckon eval` drives it in lockstep with
the hub.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from edge.base import EdgeSummary
from edge.chair import kernel
from edge.chair.estimator import (GYRO_SCALE, N, ChairSettings, ChairState, Flag, axle_scale_measured, position_update,
                                  start)
from edge.chair.merger import ChairMerger
from protocol import messages
from protocol.session import Agent

NO_GATE = math.inf  # the hub gated the correction already, against the same pose


class ChairEdge:
    """`push(batch) -> [EstimatedPose | ImpactEvent]`, `correct(correction)`, `flush()` (an edge.base.Edge)."""

    def __init__(self, agent: Agent, pose_rate_hz: float = 50.0, method: str = "reckon"):
        if not pose_rate_hz > 0:
            raise ValueError(f"pose_rate_hz {pose_rate_hz}: must be > 0")
        self.agent = agent
        self.settings = ChairSettings(wheel_diameter_m=agent.wheel_diameter_m, camber_deg=agent.camber_deg)
        self.merger = ChairMerger(agent)
        self.method = method
        self.period_ns = int(1e9 / pose_rate_hz)
        self.packed_settings = kernel.pack_settings(self.settings)
        # load (or compile) the kernel now, not on the first sample of a live stream
        kernel.run_batch(self.packed_settings, np.zeros(kernel.STATE_SIZE), np.zeros(0, dtype=np.int64),
                         np.zeros((0, kernel.SAMPLE_WIDTH)))
        self.vector: np.ndarray | None = None  # the filter state, packed (fixed size)
        self.next_pose_ns = 0
        self.corrections: deque[Any] = deque(maxlen=64)  # the hub sends a few per minute
        self.correction_sequence = 0
        self.samples = self.poses = self.impacts = self.corrections_applied = 0
        self.axle_check = Flag.NONE  # the seat gyro's one scale check against the axle IMUs, once made
        self.pending_warnings: list[str] = []

    @property
    def state(self) -> ChairState | None:
        return None if self.vector is None else kernel.unpack_state(self.vector)

    def push(self, batch: Any) -> list[Any]:
        return self._estimate(self.merger.push_batch(batch))

    def flush(self) -> list[Any]:
        return self._estimate(self.merger.flush())

    def correct(self, correction: Any) -> None:
        """Queue a hub Correction; it is applied before the next sample (or with the next pose)."""
        self.corrections.append(correction)

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
        summary.extrapolated = self.merger.counters.extrapolated
        summary.wheel_overrun = self.merger.counters.wheel_overrun
        summary.bridged = self.merger.counters.bridged
        clocks = self.merger.clocks
        summary.wheel_clocks_ms = (clocks["left"].offset_ns / 1e6, clocks["right"].offset_ns / 1e6)
        state = self.state
        if state is not None:
            mean = state.mean
            summary.final_pose = (float(mean[0]), float(mean[1]), float(mean[2]))
            check = ("checked against the axles" if self.axle_check & Flag.AXLE_SCALE_USED else
                     "the axles disagreed, not used" if self.axle_check & Flag.AXLE_SCALE_REJECTED else
                     "not yet checked against the axles")
            summary.seat_gyro_scale = (100.0 * float(mean[GYRO_SCALE]), check)

    def pose(self, time_ns: int | None = None) -> Any:
        """The current pose as a message (None before the first sample)."""
        if self.vector is None:
            return None
        self._apply_corrections()
        v = self.vector
        mean = v[kernel.MEAN:kernel.MEAN + 3]
        cov = v[kernel.COV:kernel.COV + N * N].reshape(N, N)[:3, :3]
        return messages.new(
            "EstimatedPose", timestamp_ns=kernel.state_time_ns(v) if time_ns is None else time_ns,
            agent_id=self.agent.id, x_m=float(mean[0]), y_m=float(mean[1]), heading_rad=float(mean[2]),
            covariance=cov.ravel().tolist(), method=self.method, track=messages.Track.LIVE,
            correction_sequence=self.correction_sequence)

    def _apply_corrections(self) -> None:
        while self.corrections and self.vector is not None:
            correction = self.corrections.popleft()
            if correction.sequence <= self.correction_sequence:
                continue  # a duplicate (the hub resends after a restart)
            state = kernel.unpack_state(self.vector)
            shift = np.array([correction.dx_m, correction.dy_m])
            covariance = np.array(correction.covariance, dtype=float).reshape(2, 2)
            state, _ = position_update(state, state.mean[:2] + shift, covariance, NO_GATE)
            self.vector = kernel.pack_state(state)
            self.correction_sequence = correction.sequence
            self.corrections_applied += 1

    def _estimate(self, samples: list) -> list[Any]:
        out: list[Any] = []
        if not samples:
            return out
        if self.vector is None:
            first = samples[0]
            self.vector = kernel.pack_state(start(self.settings, first, self.agent.start_x_m, self.agent.start_y_m,
                                                  self.agent.start_heading_rad))
            self.samples += 1
            samples = samples[1:]
            if not samples:
                return out
        self._apply_corrections()
        times, values = kernel.pack_samples(samples)
        self.samples += len(samples)
        begin = 0
        for i, time_ns in enumerate(times.tolist()):  # run up to each pose, then publish it
            if time_ns < self.next_pose_ns and i < len(samples) - 1:
                continue
            self.vector, flags = kernel.run_batch(self.packed_settings, self.vector, times[begin:i + 1],
                                                  values[begin:i + 1])
            if not self.axle_check and self.vector[kernel.AXLE_DONE]:  # made in this call: its flag is here
                self._note_axle_check(Flag(int(np.bitwise_or.reduce(flags))))
            for j in np.flatnonzero(flags & Flag.IMPACT):
                self.impacts += 1
                accel = values[begin + j, 3:6]
                gravity = self.vector[kernel.GRAVITY:kernel.GRAVITY + 3]
                out.append(messages.new("ImpactEvent", timestamp_ns=int(times[begin + j]), agent_id=self.agent.id,
                                        sensor_id=self.merger.seat_id, peak_g=float(np.sqrt(accel @ accel) - 1.0),
                                        forward_g=float(accel[0] - gravity[0]), left_g=float(accel[1] - gravity[1])))
            begin = i + 1
            if time_ns >= self.next_pose_ns:  # a fixed schedule: timestamp jitter costs no pose
                self.next_pose_ns = max(self.next_pose_ns + self.period_ns, time_ns - self.period_ns // 2)
                self.poses += 1
                out.append(self.pose(time_ns))
        return out

    def _note_axle_check(self, flags: Flag) -> None:
        """Keep the scale check's outcome; a refused one is the venue file's problem, so say why."""
        self.axle_check = flags & (Flag.AXLE_SCALE_USED | Flag.AXLE_SCALE_REJECTED)
        if not self.axle_check & Flag.AXLE_SCALE_REJECTED:
            return
        state = kernel.unpack_state(self.vector)
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
