"""`reckon edge`: one chair's edge process. Sensor messages in, dead-reckoned poses out, over Zenoh.

Source -> (raw messages published as they come: nothing received is lost) -> ChairEdge
(edge/chair/edge.py: merger and filter) -> EstimatedPose at `pose_rate_hz` on
`reckon/<venue>/<agent>/pose/edge`, an ImpactEvent at once on `.../event/impact`. The hub's
Correction messages for this agent (`.../correction`) are taken between batches and applied to
the filter. Sources: `mcap://FILE`, a session log replayed at `speed` x real time (the
simulator's sessions, or a recording); one serial device per sensor, an x-IMU3
(`SENSOR=serial://PORT?baud=N`) or an ATR-Promotions TSND121/151, which the edge sets up, starts
and stops (`SENSOR=serial://PORT?protocol=tsnd&rate_hz=1000`, docs/tsnd.md); or BLE through
bleak (`SENSOR=ble://ADDRESS`, a Thingy:52-style IMU, and `RECEIVER=ble://scan` for the venue's iBeacon/Eddystone beacons), with `--venue VENUE.toml`. Each raw batch carries the venue
clock at its arrival (`received_ns`: the log time in a replay), from which the hub estimates
the device's clock offset.
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

from edge.chair.edge import ChairEdge
from edge.pedestrian.edge import PedestrianEdge
from edge.swim.edge import SwimEdge
from protocol import bus as wire
from protocol import keys, messages
from protocol.errors import ConfigError
from protocol.session import AgentKind, Session, load_toml
from protocol.session_log import LogMessages, read_description
from reckon.transport.bus import Alive, Publisher, Subscription, flush, open_session, wait_for_peers
from reckon.transport.spool import DEFAULT_LIMIT_BYTES, SpooledPublisher, edge_publisher

log = logging.getLogger(__name__)
FLUSH_TIMEOUT_S = 10.0
STATUS_PERIOD_S = 1.0  # DeviceStatus per sensor about this often (and at once when its flags change)
STATUS_WARN_EVERY_S = 10.0  # a sensor's new faults are logged at most this often


@dataclass
class EdgeSummary:
    agent_id: str
    messages_in: int = 0
    samples: int = 0
    poses: int = 0
    impacts: int = 0
    corrections: int = 0
    extrapolated: int = 0
    wheel_overrun: int = 0
    final_pose: tuple[float, float, float] | None = None
    swimmer: bool = False
    lengths: int = 0  # swimmers: SwimLength messages out
    pedestrian: bool = False  # a phone: `poses` are its steps
    spooled: int = 0  # messages left in the spool at the end (replayed on the next start)
    spool_refused: int = 0  # messages lost because the spool was full

    def __str__(self) -> str:
        if self.swimmer:
            return f"edge {self.agent_id}: {self.messages_in} messages in, {self.samples} samples, {self.lengths} lengths out"
        pose = "none" if self.final_pose is None else "x %.2f m, y %.2f m, heading %.1f deg" % (
            self.final_pose[0], self.final_pose[1], math.degrees(self.final_pose[2]))
        if self.pedestrian:
            return (f"edge {self.agent_id}: {self.messages_in} messages in, {self.samples} samples, "
                    f"{self.poses} steps out; last pose {pose}")
        return (f"edge {self.agent_id}: {self.messages_in} messages in, {self.samples} samples, "
                f"{self.poses} poses and {self.impacts} impacts out, {self.corrections} corrections applied "
                f"({self.extrapolated} samples with a wheel extrapolated, {self.wheel_overrun} behind the wheel "
                f"history); last pose {pose}")


def mcap_source(path: Path, agent_ids: str | set[str] | None, speed: float, stop: threading.Event,
                start_at: float | None = None) -> Iterator[Any]:
    """Agents' IMU batches, beacon sightings and stand scans from a session log, paced by log time (speed 0: at once).

    `agent_ids`: one agent, a set, or None for all. Each ImuBatch gets `received_ns` = its log time.
    `start_at`: wall-clock time (time.time()) of the log's first message, so that several edges
    replaying one log stay in step; default: now.
    """
    wanted = {agent_ids} if isinstance(agent_ids, str) else agent_ids

    def accept(topic: str, name: str) -> bool:
        if name not in ("ImuBatch", "BeaconSighting", "StandScan"):
            return False
        return wanted is None or keys.parse(topic)[1] in wanted

    first_log = first_wall = None
    for log_time, _, message in LogMessages(path, accept):
        if speed > 0:
            if first_log is None:
                first_log = log_time
                first_wall = time.monotonic() + (0.0 if start_at is None else start_at - time.time())
            wait = (log_time - first_log) * 1e-9 / speed - (time.monotonic() - first_wall)
            if wait > 0 and stop.wait(wait):
                return
        if stop.is_set():
            return
        if messages.type_name(message) == "ImuBatch" and not message.received_ns:
            message.received_ns = log_time
        yield message


def run_edge(config: zenoh.Config, session: Session, agent_id: str, source: Iterable[Any], stop: threading.Event,
             pose_rate_hz: float = 50.0, wait_for: int = 0, wait_timeout_s: float = 60.0,
             progress: Callable[[EdgeSummary], None] | None = None, spool: Path | None = None,
             spool_limit_bytes: int = DEFAULT_LIMIT_BYTES, spool_wait_s: float = 5.0) -> EdgeSummary:
    """Run one agent's edge (a chair, a swimmer or a pedestrian's phone) until the source ends or
    `stop` is set. `spool`: a folder where messages wait while no hub is up (reckon/transport/spool.py), and
    at the end up to `spool_wait_s` for a hub to replay them to (else they stay for the next start)."""
    agent = session.agent(agent_id)
    edge: ChairEdge | SwimEdge | PedestrianEdge
    if agent.kind is AgentKind.SWIMMER:
        edge = SwimEdge(agent, session.venue.court_length_m)
    elif agent.kind is AgentKind.PEDESTRIAN:
        edge = PedestrianEdge(agent, session.venue)
    else:
        edge = ChairEdge(agent, pose_rate_hz)
    venue = session.venue.name
    summary = EdgeSummary(agent_id, swimmer=isinstance(edge, SwimEdge), pedestrian=isinstance(edge, PedestrianEdge))
    with open_session(config) as bus, edge_publisher(bus, session.venue.name, spool, spool_limit_bytes) as publisher, \
            Subscription(bus, keys.correction(venue, agent_id), capacity=256) as corrections, \
            Alive(bus, venue, wire.Role.EDGE, agent_id), \
            StatusReporter(bus, venue, agent, source, publisher) as status:
        if wait_for:
            wait_for_peers(bus, [wire.alive_selector(venue, wire.Role.HUB), wire.alive_selector(venue, wire.Role.RECORDER)],
                           wait_for, wait_timeout_s)

        def publish(outputs: list[Any]) -> None:
            for out in outputs:
                name = messages.type_name(out)
                if name == "ImpactEvent":
                    publisher.publish(keys.impact(venue, agent_id), out)
                elif name == "SwimLength":
                    publisher.publish(keys.length(venue, agent_id), out)
                    summary.lengths += 1
                    log.info("%s length %d: %.2f m swum in %.1f s, %d strokes", out.sensor_id, out.index,
                             out.swum_distance_m, out.duration_s, out.stroke_count)
                else:
                    publisher.publish(keys.pose(venue, agent_id, "edge"), out)

        for message in source:
            summary.messages_in += 1
            if isinstance(edge, ChairEdge):
                _take_corrections(corrections, edge)
            if message.DESCRIPTOR.name == "ImuBatch":
                # duplicates out, late batches re-ordered, clock jumps re-anchored (edge/health.py)
                for batch in status.push(message):
                    publisher.publish(keys.imu(venue, agent_id, batch.sensor_id), batch)  # before the estimator
                    publish(edge.push(batch))
            elif message.DESCRIPTOR.name == "StandScan":
                publisher.publish(keys.scan(venue, agent_id), message)  # refused ones too, with their reason
                if isinstance(edge, PedestrianEdge):
                    edge.scan(message)
            else:
                publisher.publish(keys.beacon(venue, agent_id, message.sensor_id), message)
            if progress and summary.messages_in % 1000 == 0:
                progress(_summarise(summary, edge))
        for batch in status.flush():
            publisher.publish(keys.imu(venue, agent_id, batch.sensor_id), batch)
            publish(edge.push(batch))
        publish(edge.flush())
        status.report()  # the last word on every sensor, before the flush below
        if isinstance(publisher, SpooledPublisher):
            publisher.finish(spool_wait_s)
            summary.spooled, summary.spool_refused = publisher.spooled, publisher.refused
        flush(bus, wire.alive_selector(venue), FLUSH_TIMEOUT_S)  # closing drops what is still queued
    return _summarise(summary, edge)


class StatusReporter:
    """The agent's sensors' health (edge/health.py) as DeviceStatus on `keys.status`: every
    STATUS_PERIOD_S from a thread of its own, so a silent device is reported too, and at once when
    a sensor's flags change. A source may tell more: `device_ranges` (sensor id -> full scales, for
    saturation) and `link(sensor_id) -> (connected, reconnects, battery_pct)`; `spooled` is the
    publisher's, when it spools. A status is a view of now: it goes straight to the bus, unspooled."""

    def __init__(self, bus: zenoh.Session, venue: str, agent: Any, source: Any, publisher: Any):
        from edge.health import DeviceHealth

        self.venue, self.agent_id = venue, agent.id
        self.health = DeviceHealth(agent.id, ranges=getattr(source, "device_ranges", None))
        self._link: Callable[[str], tuple[bool, int, float]] | None = getattr(source, "link", None)
        self._main_publisher = publisher
        self._publisher = Publisher(bus)
        self._lock = threading.Lock()
        self._sent: dict[str, list[str]] = {}
        self._warned: dict[str, int] = {}  # sensor -> edge time of its last warning
        self._stop = threading.Event()
        now = time.time_ns()
        for sensor in agent.sensors:
            self.health.expect(sensor.id, now)
        self._thread = threading.Thread(target=self._run, name=f"status {agent.id}", daemon=True)
        self._thread.start()

    def push(self, batch: Any) -> list[Any]:
        with self._lock:
            ready = self.health.push(batch, time.time_ns())
            self._report(batch.sensor_id, time.time_ns(), only_on_change=True)
        return ready

    def flush(self) -> list[Any]:
        with self._lock:
            return self.health.flush()

    def _run(self) -> None:
        while not self._stop.wait(STATUS_PERIOD_S):
            self.report()

    def report(self) -> None:
        """A DeviceStatus for every sensor now."""
        with self._lock:
            now = time.time_ns()
            for sensor_id in list(self.health.sensors):
                self._report(sensor_id, now, only_on_change=False)

    def _report(self, sensor_id: str, now_ns: int, only_on_change: bool) -> None:
        connected, reconnects, battery_pct = self._link(sensor_id) if self._link else (True, 0, -1.0)
        spooled = int(getattr(self._main_publisher, "spooled", 0) or 0)
        flags = self.health.flags(sensor_id, now_ns, connected) + (["spooling"] if spooled else [])
        if only_on_change and flags == self._sent.get(sensor_id):
            return
        new = [flag for flag in flags if flag not in self._sent.get(sensor_id, [])]
        self._sent[sensor_id] = flags
        status = self.health.status(sensor_id, now_ns, connected=connected, reconnects=reconnects,
                                    battery_pct=battery_pct, spooled=spooled)
        self._publisher.publish(keys.status(self.venue, self.agent_id, sensor_id), status)
        if new and now_ns - self._warned.get(sensor_id, 0) >= STATUS_WARN_EVERY_S * 1e9:
            self._warned[sensor_id] = now_ns
            log.warning("%s: %s (so far: %d gaps, %d duplicates, %d out of order, %d clock jumps, %d saturated "
                        "samples, %d reconnects)", sensor_id, ", ".join(flags), status.gaps, status.duplicates,
                        status.out_of_order, status.clock_jumps, status.saturated, status.reconnects)

    def __enter__(self) -> "StatusReporter":
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        self._publisher.close()


def _take_corrections(subscription: Subscription, edge: ChairEdge) -> None:
    """Hand every Correction that has arrived to the edge (never waits)."""
    while True:
        try:
            item = subscription.get(timeout=0)
        except queue.Empty:
            return
        if item is None:
            return
        try:
            message = item.decode()
        except Exception as error:  # a foreign sample on our key: counted by the log, never fatal
            log.warning("ignoring a sample on %s: %s", item.key, error)
            continue
        if messages.type_name(message) == "Correction":
            edge.correct(message)


def _summarise(summary: EdgeSummary, edge: ChairEdge | SwimEdge | PedestrianEdge) -> EdgeSummary:
    summary.samples = edge.samples
    if isinstance(edge, SwimEdge):
        return summary
    if isinstance(edge, PedestrianEdge):
        summary.poses = edge.counters.steps
        summary.final_pose = edge.last_pose
        return summary
    summary.poses, summary.impacts = edge.poses, edge.impacts
    summary.corrections = edge.corrections_applied
    summary.extrapolated = edge.merger.counters.extrapolated
    summary.wheel_overrun = edge.merger.counters.wheel_overrun
    if edge.state is not None:
        mean = edge.state.mean
        summary.final_pose = (float(mean[0]), float(mean[1]), float(mean[2]))
    return summary


class SerialSources:
    """One reader thread per `SENSOR=serial://PORT?...` source, all feeding one blocking queue.

    Each URL's `protocol` picks the decoder and the commands (SerialSource.from_url: an x-IMU3
    streams on its own, a TSND is set up and started on open, stopped on close).
    Ports are opened here, at once, so a device that is missing fails before anything starts.
    A device that goes away (link lost, unplugged, a read error) keeps its last frames; its reader
    then tries to open the port again, first after `RETRY_S`, the wait doubling up to `MAX_RETRY_S`,
    and carries on when the device is back (a by-id path that points at the new port finds it),
    for up to `reconnect_s`; after that its stream ends. `link(sensor)` says whether a sensor is
    connected and how often it came back; `device_ranges` its full scales (for saturation).
    Iterating yields ImuBatch messages, each stamped with the host clock at its arrival, until
    every stream has ended or `stop` is set.
    """

    _DONE = object()
    RETRY_S = 0.1
    MAX_RETRY_S = 2.0

    def __init__(self, specs: list[tuple[str, str]], agent_id: str, stop: threading.Event, reconnect_s: float = 30.0):
        from edge.decoders import ImuBatcher
        from edge.health import DEVICE_RANGES
        from edge.sources.serial import SerialSource, parse_serial_protocol

        self.stop = stop
        self.reconnect_s = reconnect_s
        self.reconnects = 0
        self.queue: queue.Queue[Any] = queue.Queue(maxsize=1000)  # blocks the readers, never drops
        self.sources = [(url, SerialSource.from_url(url).open(), ImuBatcher(agent_id, sensor_id))
                        for sensor_id, url in specs]
        self.connected = {sensor_id: True for sensor_id, _ in specs}
        self.reconnects_by_sensor = {sensor_id: 0 for sensor_id, _ in specs}
        self.device_ranges = {sensor_id: DEVICE_RANGES[parse_serial_protocol(url)[0]] for sensor_id, url in specs}
        self.threads = [threading.Thread(target=self._read, args=triple, daemon=True) for triple in self.sources]
        for thread in self.threads:
            thread.start()

    def _put(self, batches: list[Any]) -> None:
        now = time.time_ns()
        for batch in batches:
            batch.received_ns = now
            self.queue.put(batch)

    def _read(self, url: str, source: Any, batcher: Any) -> None:
        from edge.sources.serial import DeviceDisconnected, DeviceUnavailable, SerialSource

        decoder = source.decoder  # kept across reconnects: its counters and device clock carry on
        try:
            while not self.stop.is_set():
                try:
                    while not self.stop.is_set():
                        self._put(batcher.feed(source.read_frames()))
                except DeviceDisconnected as gone:
                    self.connected[batcher.sensor_id] = False
                    self._put(batcher.feed(gone.frames))
                    source.close()
                    log.warning("%s; trying to reopen it for %.0f s", gone, self.reconnect_s)
                    source = None
                    deadline = time.monotonic() + self.reconnect_s
                    delay = self.RETRY_S
                    while source is None and time.monotonic() < deadline and not self.stop.wait(delay):
                        delay = min(2 * delay, self.MAX_RETRY_S)
                        try:
                            source = SerialSource.from_url(url, decoder=decoder).open()
                        except DeviceUnavailable:
                            continue
                    if source is None:
                        return
                    self.reconnects += 1
                    self.reconnects_by_sensor[batcher.sensor_id] += 1
                    self.connected[batcher.sensor_id] = True
                    log.warning("%s is back (reconnect %d)", url, self.reconnects)
        except Exception as error:  # handed to the consumer, raised there
            self.queue.put(error)
        finally:
            self.connected[batcher.sensor_id] = False
            self._put(batcher.flush())
            if source is not None:
                source.close()
            self.queue.put(self._DONE)

    def link(self, sensor_id: str) -> tuple[bool, int, float]:
        """(connected, reconnects, battery_pct): neither an x-IMU3 nor a TSND stream says its battery."""
        return self.connected.get(sensor_id, False), self.reconnects_by_sensor.get(sensor_id, 0), -1.0

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
                 venue_toml: Path | None = None, reconnect_s: float = 30.0, start_at: float | None = None, *,
                 ble_factories: dict[str, Any] | None = None) -> tuple[Session, Iterable[Any]]:
    """(session description, message stream) for `--source` URLs.

    `mcap://FILE`: this agent's sensors from a session log (one source; the description comes from
    the file). Live devices need `venue_toml` (a TOML session description, or a session log whose
    description to use), and are all serial or all BLE:
    - `SENSOR=serial://PORT?baud=N`: one x-IMU3 device per sensor;
    - `SENSOR=ble://AA:BB:CC:DD:EE:FF`: one Thingy:52 per sensor, and optionally one
      `RECEIVER=ble://scan`: BeaconSighting messages (sensor id RECEIVER) for the venue's beacons
      that have an `identity`.
    Serial and BLE IMUs are not mixed on one chair: x-IMU3 samples carry the device's clock, BLE
    notifications the host's, and the merger needs one clock. `ble_factories`: keyword arguments
    for BleSources (`client_factory`, `scanner_factory`: fakes in tests).
    """
    if len(urls) == 1 and urlparse(urls[0]).scheme == "mcap":
        parsed = urlparse(urls[0])
        path = Path(parsed.netloc + parsed.path)
        session = session_description(venue_toml) if venue_toml else read_description(path)
        _check_agent(session, agent_id, str(path))
        return session, mcap_source(path, agent_id, speed, stop, start_at)
    if any(urlparse(url.partition("=")[2]).scheme == "phone" for url in urls):  # SENSOR=phone://HOST:PORT
        from edge.sources.phone.server import open_phone_source

        return open_phone_source(urls, agent_id, stop, venue_toml)
    serial, ble, scans = _live_specs(urls)
    if serial and ble:
        raise ConfigError(f"--source {ble[0][2]!r}: serial and BLE IMUs cannot be mixed on one chair (x-IMU3 "
                          "samples carry the device's clock, BLE notifications the host's; make every IMU of the "
                          "chair one kind)")
    if serial and scans:
        raise ConfigError(f"--source {scans[0][2]!r}: ble://scan goes with BLE IMUs only; with serial sources it is "
                          "not supported yet")
    if venue_toml is None:
        kind = "serial" if serial else "BLE"
        raise ConfigError(f"--venue VENUE.toml is needed with {kind} sources (it says which sensor is where)")
    session = session_description(venue_toml)
    agent = _check_agent(session, agent_id, str(venue_toml))
    known = {s.id for s in agent.sensors}
    for sensor_id, _, _ in serial + ble:
        if sensor_id not in known:
            raise ConfigError(f"--source {sensor_id}=...: {agent_id} has no sensor {sensor_id!r} "
                              f"(sensors: {', '.join(sorted(known))})")
    if serial:
        return session, SerialSources([(sensor_id, device) for sensor_id, device, _ in serial], agent_id, stop,
                                      reconnect_s)
    from edge.sources.ble import BleSources

    beacons_by_identity = {b.identity: b.id for b in session.venue.beacons if b.identity}
    if scans and not beacons_by_identity:
        raise ConfigError(f"--source {scans[0][2]!r}: no beacon in {venue_toml} has an identity to listen for "
                          "(set identity = \"ibeacon:<uuid>:<major>:<minor>\" or \"eddystone:<namespace>:<instance>\" "
                          "in the beacon's [[venue.beacons]] table)")
    return session, BleSources([(sensor_id, device) for sensor_id, device, _ in ble + scans], agent_id,
                               beacons_by_identity, stop, **(ble_factories or {}))


_LIVE_EXPECTED = ("expected mcap://FILE (alone), SENSOR=serial://PORT?baud=N, SENSOR=ble://AA:BB:CC:DD:EE:FF "
                  "or RECEIVER=ble://scan")


def _live_specs(urls: list[str]) -> tuple[list[tuple[str, str, str]], list[tuple[str, str, str]],
                                          list[tuple[str, str, str]]]:
    """(serial IMUs, BLE IMUs, BLE scans) as (sensor id, device URL, the --source URL); ConfigError
    naming the URL for anything malformed."""
    serial: list[tuple[str, str, str]] = []
    ble: list[tuple[str, str, str]] = []
    scans: list[tuple[str, str, str]] = []
    for url in urls:
        sensor_id, sep, device = url.partition("=")
        scheme = urlparse(device).scheme if sep else ""
        if scheme not in ("serial", "ble"):
            if not sep and urlparse(url).scheme in ("serial", "ble"):
                raise ConfigError(f"--source {url!r}: no sensor id in front; {_LIVE_EXPECTED}")
            raise ConfigError(f"--source {url!r}: {_LIVE_EXPECTED}")
        if scheme == "serial":
            serial.append((sensor_id, device, url))
            continue
        from edge.sources.ble import SCAN, parse_ble_url

        try:
            address = parse_ble_url(device)
        except ConfigError as error:
            raise ConfigError(f"--source {url!r}: {error}") from None
        if address == SCAN:
            keys.check_id(sensor_id, f"--source {url!r}: the receiver id")
            if scans:
                raise ConfigError(f"--source {url!r}: one ble://scan per edge (already given as {scans[0][2]!r})")
            scans.append((sensor_id, device, url))
        else:
            ble.append((sensor_id, device, url))
    given = [sensor_id for sensor_id, _, _ in serial + ble]
    twice = sorted({sensor_id for sensor_id in given if given.count(sensor_id) > 1})
    if twice:
        raise ConfigError(f"--source {twice[0]}=...: sensor {twice[0]!r} is given twice (one device per sensor)")
    return serial, ble, scans


def session_description(path: Path) -> Session:
    """A session description from a TOML file or from a session log's own record."""
    return read_description(path) if Path(path).suffix == ".mcap" else load_toml(path)


def _check_agent(session: Session, agent_id: str, where: str) -> Any:
    try:
        return session.agent(agent_id)
    except KeyError:
        raise ConfigError(f"--agent {agent_id!r}: not in {where} (agents: "
                          f"{', '.join(a.id for a in session.agents)})") from None
