"""`reckon edge`: one chair's edge process. Sensor messages in, dead-reckoned poses out, over Zenoh.

Source -> (raw messages published as they come: nothing received is lost) -> ChairMerger ->
chair estimator -> EstimatedPose at `pose_rate_hz` on `reckon/<venue>/<agent>/pose/edge`, an
ImpactEvent at once on `.../event/impact`. Sources today: `mcap://FILE`, a session log replayed at
`speed` x real time (the simulator's sessions, or a recording); serial and BLE sources plug in
through the same iterator of protocol messages.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable
from urllib.parse import urlparse

import zenoh

from edge.chair_estimator import Flag, ChairSettings, start, step
from edge.chair_merger import ChairMerger
from protocol import bus as wire
from protocol import keys, messages
from protocol.errors import ConfigError
from protocol.session import Session
from protocol.session_log import iter_records, read_description
from reckon.bus import Alive, Publisher, flush, open_session, wait_for_peers

FLUSH_TIMEOUT_S = 10.0


@dataclass
class EdgeSummary:
    agent_id: str
    messages_in: int = 0
    samples: int = 0
    poses: int = 0
    impacts: int = 0
    extrapolated: int = 0
    final_pose: tuple[float, float, float] | None = None

    def __str__(self) -> str:
        pose = "none" if self.final_pose is None else "x %.2f m, y %.2f m, heading %.1f deg" % (
            self.final_pose[0], self.final_pose[1], math.degrees(self.final_pose[2]))
        return (f"edge {self.agent_id}: {self.messages_in} messages in, {self.samples} samples, "
                f"{self.poses} poses and {self.impacts} impacts out ({self.extrapolated} samples with a wheel "
                f"extrapolated); last pose {pose}")


def mcap_source(path: Path, agent_id: str, speed: float, stop: threading.Event) -> Iterator[Any]:
    """This agent's IMU batches and beacon sightings from a session log, paced by log time."""
    problems: list[str] = []
    schemas, channels = {}, {}
    first_log = first_wall = None
    for record in iter_records(path, problems):
        kind = type(record).__name__
        if kind == "Schema":
            schemas[record.id] = record.name.removeprefix(messages.PACKAGE + ".")
        elif kind == "Channel":
            channels[record.id] = (record.topic, schemas.get(record.schema_id))
        elif kind == "Message":
            topic, name = channels.get(record.channel_id, ("", None))
            if name not in ("ImuBatch", "BeaconSighting") or keys.parse(topic)[1] != agent_id:
                continue
            if speed > 0:
                first_log = record.log_time if first_log is None else first_log
                first_wall = time.monotonic() if first_wall is None else first_wall
                wait = (record.log_time - first_log) * 1e-9 / speed - (time.monotonic() - first_wall)
                if wait > 0 and stop.wait(wait):
                    return
            if stop.is_set():
                return
            yield messages.CLASSES[name].FromString(record.data)


def run_edge(config: zenoh.Config, session: Session, agent_id: str, source: Iterator[Any], stop: threading.Event,
             pose_rate_hz: float = 50.0, wait_for: int = 0, wait_timeout_s: float = 60.0,
             progress: Callable[[EdgeSummary], None] | None = None) -> EdgeSummary:
    """Run one chair's edge until the source ends or `stop` is set."""
    agent = session.agent(agent_id)
    venue = session.venue.name
    settings = ChairSettings(wheel_diameter_m=agent.wheel_diameter_m, camber_deg=agent.camber_deg)
    merger = ChairMerger(agent)
    summary = EdgeSummary(agent_id)
    period_ns = int(1e9 / pose_rate_hz)
    state, next_pose_ns = None, 0
    with open_session(config) as bus, Publisher(bus) as publisher, Alive(bus, venue, wire.Role.EDGE, agent_id):
        if wait_for:
            wait_for_peers(bus, [wire.alive_selector(venue, wire.Role.HUB), wire.alive_selector(venue, wire.Role.RECORDER)],
                           wait_for, wait_timeout_s)

        def estimate(samples: list) -> None:
            nonlocal state, next_pose_ns
            for sample in samples:
                summary.samples += 1
                if state is None:
                    state = start(settings, sample, agent.start_x_m, agent.start_y_m, agent.start_heading_rad)
                    continue
                state = step(settings, state, sample)
                if state.flags & Flag.IMPACT:
                    summary.impacts += 1
                    peak = math.sqrt(sum(a * a for a in sample.accel_g)) - 1.0
                    publisher.publish(keys.impact(venue, agent_id), messages.new(
                        "ImpactEvent", timestamp_ns=sample.time_ns, agent_id=agent_id, peak_g=peak))
                if sample.time_ns >= next_pose_ns:  # on a fixed schedule, so timestamp jitter costs no pose
                    next_pose_ns = max(next_pose_ns + period_ns, sample.time_ns - period_ns // 2)
                    summary.poses += 1
                    publisher.publish(keys.pose(venue, agent_id, "edge"), messages.new(
                        "EstimatedPose", timestamp_ns=sample.time_ns, agent_id=agent_id, x_m=float(state.mean[0]),
                        y_m=float(state.mean[1]), heading_rad=float(state.mean[2]),
                        covariance=state.cov[:3, :3].ravel().tolist(), method="reckon", track=messages.Track.LIVE))

        for message in source:
            summary.messages_in += 1
            if message.DESCRIPTOR.name == "ImuBatch":
                publisher.publish(keys.imu(venue, agent_id, message.sensor_id), message)  # raw first: nothing lost
                estimate(merger.push_batch(message))
            else:
                publisher.publish(keys.beacon(venue, agent_id, message.sensor_id), message)
            if progress and summary.messages_in % 1000 == 0:
                progress(summary)
        estimate(merger.flush())
        summary.extrapolated = merger.counters.extrapolated
        if state is not None:
            summary.final_pose = (float(state.mean[0]), float(state.mean[1]), float(state.mean[2]))
        flush(bus, wire.alive_selector(venue), FLUSH_TIMEOUT_S)  # closing drops what is still queued
    return summary


def open_source(url: str, agent_id: str, speed: float, stop: threading.Event) -> tuple[Session, Iterator[Any]]:
    """(session description, message iterator) for a source URL."""
    parsed = urlparse(url)
    if parsed.scheme != "mcap":
        raise ConfigError(f"--source {url!r}: scheme {parsed.scheme!r} is not supported yet (supported: mcap://FILE)")
    path = Path(parsed.netloc + parsed.path)
    session = read_description(path)
    try:
        session.agent(agent_id)
    except KeyError:
        raise ConfigError(f"--agent {agent_id!r}: not in {path} (agents: "
                          f"{', '.join(a.id for a in session.agents)})") from None
    return session, mcap_source(path, agent_id, speed, stop)
