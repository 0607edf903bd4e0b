"""What every agent kind's edge computation offers, so that `reckon edge` drives any of them the same way.

    edge = ChairEdge(agent)            # or SwimEdge(agent, pool_length_m), PedestrianEdge(agent, venue)
    for batch in batches:
        outputs = edge.push(batch)     # messages to publish: poses, impacts, lengths
    outputs = edge.flush()             # end of stream

The three edges (edge/chair/edge.py, edge/swim/edge.py, edge/pedestrian/edge.py) satisfy `Edge`;
an input an edge has no use for (a Correction for a swimmer, a StandScan or a Pressure for a chair) is taken and
ignored, so the caller never asks which kind it holds. Pure: no I/O, no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol


@dataclass
class EdgeSummary:
    """What one edge did, for the log line at its end. The process counts `messages_in` and the
    spool; the edge fills its own counts (`Edge.summarise`)."""

    agent_id: str
    messages_in: int = 0
    samples: int = 0
    poses: int = 0
    impacts: int = 0
    corrections: int = 0
    field_readings: int = 0  # chairs: magnetometer readings offered to the hub's field map
    field_maps: int = 0  # chairs: field maps taken from the hub
    extrapolated: int = 0
    wheel_overrun: int = 0
    bridged: int = 0  # chairs: samples where the seat was silent and the wheels alone told the turn
    wheel_clocks_ms: tuple[float, float] | None = None  # chairs: (left, right) wheel clock minus the seat's
    seat_gyro_scale: tuple[float, str] | None = None  # chairs: the seat gyro's scale error (%), how it was checked
    final_pose: tuple[float, float, float] | None = None
    swimmer: bool = False
    lengths: int = 0  # swimmers: SwimLength messages out
    pedestrian: bool = False  # a phone: `poses` are its steps
    spooled: int = 0  # messages left in the spool at the end (replayed on the next start)
    spool_refused: int = 0  # messages lost because the spool was full
    raw_sent: int = 0  # raw batches published (while someone subscribed: reckon/processes/raw_feed.py)
    raw_unasked: int = 0  # ... not published: nobody subscribed
    clock_samples: int = 0  # ClockSample messages out

    def __str__(self) -> str:
        if self.swimmer:
            return f"edge {self.agent_id}: {self.messages_in} messages in, {self.samples} samples, {self.lengths} lengths out"
        pose = "none" if self.final_pose is None else "x %.2f m, y %.2f m, heading %.1f deg" % (
            self.final_pose[0], self.final_pose[1], math.degrees(self.final_pose[2]))
        if self.pedestrian:
            return (f"edge {self.agent_id}: {self.messages_in} messages in, {self.samples} samples, "
                    f"{self.poses} steps out; last pose {pose}")
        return (f"edge {self.agent_id}: {self.messages_in} messages in, {self.samples} samples, "
                f"{self.poses} poses and {self.impacts} impacts out, {self.corrections} corrections applied, "
                f"{self.field_readings} field readings out and {self.field_maps} field maps in "
                f"({self.extrapolated} samples with a wheel extrapolated, {self.wheel_overrun} behind the wheel "
                f"history, {self.bridged} bridging a silent seat){self._calibration()}; {self._raw()}; last pose {pose}")

    def _raw(self) -> str:
        return (f"raw batches {self.raw_sent} published, {self.raw_unasked} not (nobody subscribed), "
                f"{self.clock_samples} clock samples")

    def _calibration(self) -> str:
        if self.wheel_clocks_ms is None:
            return ""
        left, right = self.wheel_clocks_ms
        text = f"; wheel clocks against the seat's: left {left:+.1f} ms, right {right:+.1f} ms"
        if self.seat_gyro_scale is not None:
            text += "; seat gyro scale correction %+.2f %% (%s)" % self.seat_gyro_scale
        return text


class Edge(Protocol):
    """One agent's edge computation: sensor messages in, messages to publish out."""

    @property
    def samples(self) -> int:
        """Samples taken in so far."""
        ...

    def push(self, batch: Any) -> list[Any]:
        """An ImuBatch -> the messages it completes (EstimatedPose, ImpactEvent, SwimLength), maybe none."""
        ...

    def flush(self) -> list[Any]:
        """End of stream: what is still held, as messages."""
        ...

    def correct(self, correction: Any) -> None:
        """A hub Correction for this agent (ignored by an edge the hub does not correct)."""
        ...

    def scan(self, scan: Any) -> None:
        """A StandScan of this agent, accepted or refused (ignored by an edge without stands)."""
        ...

    def pressure(self, reading: Any) -> None:
        """A Pressure reading of this agent's barometer (ignored by an edge without floors)."""
        ...

    def field_map(self, field_map: Any) -> None:
        """The hub's FieldMap of the hall's magnetic field for this agent (ignored by an edge without one)."""
        ...

    def warnings(self) -> list[str]:
        """Lines for the process to log, each once (this core has no logger)."""
        ...

    def summarise(self, summary: EdgeSummary) -> None:
        """Write this edge's counts (and last pose) into `summary`."""
        ...
