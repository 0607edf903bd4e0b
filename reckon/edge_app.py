"""`reckon edge`: one chair's edge process. Sensor messages in, dead-reckoned poses out, over Zenoh.

Source -> (raw messages published as they come: nothing received is lost) -> ChairMerger ->
chair estimator -> EstimatedPose at `pose_rate_hz` on `reckon/<venue>/<agent>/pose/edge`, an
ImpactEvent at once on `.../event/impact`. Sources: `mcap://FILE`, a session log replayed at
`speed` x real time (the simulator's sessions, or a recording), or one x-IMU3 serial device per
sensor (`SENSOR=serial://PORT?baud=N`, with `--venue VENUE.toml`); BLE will plug in the same way,
as an iterable of protocol messages.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections.abc import Iterable, Iterator
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
from protocol.session import Session, load_toml
from protocol.session_log import iter_records, read_description
from reckon.bus import Alive, Publisher, flush, open_session, wait_for_peers

log = logging.getLogger(__name__)
FLUSH_TIMEOUT_S = 10.0


@dataclass
class EdgeSummary:
    agent_id: str
    messages_in: int = 0
    samples: int = 0
    poses: int = 0
    impacts: int = 0
    extrapolated: int = 0
    wheel_overrun: int = 0
    final_pose: tuple[float, float, float] | None = None

    def __str__(self) -> str:
        pose = "none" if self.final_pose is None else "x %.2f m, y %.2f m, heading %.1f deg" % (
            self.final_pose[0], self.final_pose[1], math.degrees(self.final_pose[2]))
        return (f"edge {self.agent_id}: {self.messages_in} messages in, {self.samples} samples, "
                f"{self.poses} poses and {self.impacts} impacts out ({self.extrapolated} samples with a wheel "
                f"extrapolated, {self.wheel_overrun} behind the wheel history); last pose {pose}")


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


def run_edge(config: zenoh.Config, session: Session, agent_id: str, source: Iterable[Any], stop: threading.Event,
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
        summary.wheel_overrun = merger.counters.wheel_overrun
        if state is not None:
            summary.final_pose = (float(state.mean[0]), float(state.mean[1]), float(state.mean[2]))
        flush(bus, wire.alive_selector(venue), FLUSH_TIMEOUT_S)  # closing drops what is still queued
    return summary


class SerialSources:
    """One reader thread per `SENSOR=serial://PORT?baud=N` source, all feeding one blocking queue.

    Ports are opened here, at once, so a device that is missing fails before anything starts.
    Iterating yields ImuBatch messages until every device has gone away or `stop` is set; a
    device that disappears ends its own stream only (its last frames are kept).
    """

    _DONE = object()

    def __init__(self, specs: list[tuple[str, str]], agent_id: str, stop: threading.Event):
        from edge.decoders import ImuBatcher, Ximu3Decoder
        from edge.sources.serial_source import SerialSource

        self.stop = stop
        self.queue: queue.Queue[Any] = queue.Queue(maxsize=1000)  # blocks the readers, never drops
        self.sources = [(SerialSource(url, Ximu3Decoder()).open(), ImuBatcher(agent_id, sensor_id))
                        for sensor_id, url in specs]
        self.threads = [threading.Thread(target=self._read, args=pair, daemon=True) for pair in self.sources]
        for thread in self.threads:
            thread.start()

    def _read(self, source: Any, batcher: Any) -> None:
        from edge.sources.serial_source import DeviceDisconnected

        try:
            while not self.stop.is_set():
                for batch in batcher.feed(source.read_frames()):
                    self.queue.put(batch)
        except DeviceDisconnected as gone:
            for batch in batcher.feed(gone.frames):
                self.queue.put(batch)
            log.warning("%s", gone)
        except Exception as error:  # handed to the consumer, raised there
            self.queue.put(error)
        finally:
            for batch in batcher.flush():
                self.queue.put(batch)
            source.close()
            self.queue.put(self._DONE)

    def __iter__(self) -> Iterator[Any]:
        running = len(self.threads)
        while running:
            item = self.queue.get()
            if item is self._DONE:
                running -= 1
            elif isinstance(item, Exception):
                raise item
            else:
                yield item


def open_sources(urls: list[str], agent_id: str, speed: float, stop: threading.Event,
                 venue_toml: Path | None = None) -> tuple[Session, Iterable[Any]]:
    """(session description, message stream) for `--source` URLs.

    `mcap://FILE`: this agent's sensors from a session log (one source; the description comes from
    the file). `SENSOR=serial://PORT?baud=N`: one x-IMU3 device per sensor; needs `venue_toml`
    (a TOML session description, or a session log whose description to use).
    """
    if len(urls) == 1 and urlparse(urls[0]).scheme == "mcap":
        parsed = urlparse(urls[0])
        path = Path(parsed.netloc + parsed.path)
        session = _description(venue_toml) if venue_toml else read_description(path)
        _check_agent(session, agent_id, str(path))
        return session, mcap_source(path, agent_id, speed, stop)
    specs = []
    for url in urls:
        sensor_id, sep, device = url.partition("=")
        if not sep or urlparse(device).scheme != "serial":
            raise ConfigError(f"--source {url!r}: expected mcap://FILE (alone) or SENSOR=serial://PORT?baud=N")
        specs.append((sensor_id, device))
    if venue_toml is None:
        raise ConfigError("--venue VENUE.toml is needed with serial sources (it says which sensor is where)")
    session = _description(venue_toml)
    agent = _check_agent(session, agent_id, str(venue_toml))
    known = {s.id for s in agent.sensors}
    for sensor_id, _ in specs:
        if sensor_id not in known:
            raise ConfigError(f"--source {sensor_id}=...: {agent_id} has no sensor {sensor_id!r} "
                              f"(sensors: {', '.join(sorted(known))})")
    return session, SerialSources(specs, agent_id, stop)


def _description(path: Path) -> Session:
    """A session description from a TOML file or from a session log's own record."""
    return read_description(path) if Path(path).suffix == ".mcap" else load_toml(path)


def _check_agent(session: Session, agent_id: str, where: str) -> Any:
    try:
        return session.agent(agent_id)
    except KeyError:
        raise ConfigError(f"--agent {agent_id!r}: not in {where} (agents: "
                          f"{', '.join(a.id for a in session.agents)})") from None
