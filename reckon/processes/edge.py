"""`reckon edge`: one agent's edge process. Sensor messages in, its edge's messages out, over Zenoh.

Source (edge/sources/: opened by URL scheme, edge/sources/registry.py) -> (raw messages published
as they come: nothing received is lost) -> the agent kind's Edge (edge/base.py: a chair's merger
and filter, a swimmer's lengths, a phone's steps) -> what it makes on the agent's keys: a chair's
EstimatedPose at `pose_rate_hz` on `reckon/<venue>/<agent>/pose/edge` and an ImpactEvent at once
on `.../event/impact`, a swimmer's SwimLength as each length ends, a phone's pose per step. The
hub's Correction messages for this agent (`.../correction`) are taken between batches and handed to
the edge, and so are its maps of the hall's magnetic field (`.../field_map`, for the edge's
FieldReading on `.../field`). Each raw batch carries the venue clock at its arrival (`received_ns`: the log time in a
replay), from which the hub estimates the device's clock offset.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any, Callable

from edge.base import Edge, EdgeSummary
from edge.sources.mcap import mcap_source
from edge.sources.registry import open_sources
from protocol import bus as wire
from protocol import keys, messages
from protocol.session import Agent, AgentKind, Session
from protocol.session_log import session_description
from reckon.processes.raw_feed import RawFeed
from reckon.transport.bus import (Alive, BusConfig, BusSession, Publisher, Subscription, flush, open_session,
                                  wait_for_peers)
from reckon.transport.spool import DEFAULT_LIMIT_BYTES, SpooledPublisher, edge_publisher

# The edge's entry points, with run_edge: what the CLI, the tests and the benches take from here.
__all__ = ["EdgeSummary", "StatusReporter", "mcap_source", "open_sources", "run_edge", "session_description"]

log = logging.getLogger(__name__)
FLUSH_TIMEOUT_S = 10.0
STATUS_PERIOD_S = 1.0  # DeviceStatus per sensor about this often (and at once when its flags change)
STATUS_WARN_EVERY_S = 10.0  # a sensor's new faults are logged at most this often


# Each agent kind's edge computation: (agent, session, pose_rate_hz) -> Edge. Each imports its own
# kind only: an edge process runs one agent, and a chair's needs neither scipy (swimmers) nor
# imufusion (phones); a chair's merger and filter come ahead-of-time compiled, without numba (reckon/kernels.py).
def _chair(agent: Agent, session: Session, pose_rate_hz: float) -> Edge:
    from edge.chair.edge import ChairEdge
    from reckon.kernels import chair_kernels
    return ChairEdge(agent, pose_rate_hz, kernels=chair_kernels()[0])


def _swimmer(agent: Agent, session: Session, pose_rate_hz: float) -> Edge:
    from edge.swim.edge import SwimEdge
    return SwimEdge(agent, session.venue.court_length_m)


def _pedestrian(agent: Agent, session: Session, pose_rate_hz: float) -> Edge:
    from edge.pedestrian.edge import PedestrianEdge
    return PedestrianEdge(agent, session.venue)


EDGES: dict[AgentKind, Callable[[Agent, Session, float], Edge]] = {
    AgentKind.WHEELCHAIR: _chair, AgentKind.SWIMMER: _swimmer, AgentKind.PEDESTRIAN: _pedestrian}


def run_edge(config: BusConfig, session: Session, agent_id: str, source: Iterable[Any], stop: threading.Event,
             pose_rate_hz: float = 50.0, wait_for: int = 0, wait_timeout_s: float = 60.0,
             progress: Callable[[EdgeSummary], None] | None = None, spool: Path | None = None,
             spool_limit_bytes: int = DEFAULT_LIMIT_BYTES, spool_wait_s: float = 5.0) -> EdgeSummary:
    """Run one agent's edge (a chair, a swimmer or a pedestrian's phone) until the source ends or
    `stop` is set. `spool`: a folder where messages wait while no hub is up (reckon/transport/spool.py), and
    at the end up to `spool_wait_s` for a hub to replay them to (else they stay for the next start)."""
    agent = session.agent(agent_id)
    edge = EDGES[agent.kind](agent, session, pose_rate_hz)
    venue = session.venue.name
    summary = EdgeSummary(agent_id)
    with open_session(config) as bus, edge_publisher(bus, session.venue.name, spool, spool_limit_bytes) as publisher, \
            Subscription(bus, [keys.correction(venue, agent_id), keys.field_map(venue, agent_id)],
                         capacity=256) as corrections, \
            Alive(bus, venue, wire.Role.EDGE, agent_id), \
            StatusReporter(bus, venue, agent, source, publisher) as status, \
            RawFeed(bus, publisher, venue, agent_id) as raw:
        if wait_for:
            wait_for_peers(bus, [wire.alive_selector(venue, wire.Role.HUB), wire.alive_selector(venue, wire.Role.RECORDER)],
                           wait_for, wait_timeout_s)

        def publish(outputs: list[Any]) -> None:
            for out in outputs:
                name = messages.type_name(out)
                if name == "ImpactEvent":
                    publisher.publish(keys.impact(venue, agent_id), out)
                elif name == "FieldReading":
                    publisher.publish(keys.field(venue, agent_id), out)
                elif name == "SwimLength":
                    publisher.publish(keys.length(venue, agent_id), out)
                    log.info("%s length %d: %.2f m swum in %.1f s, %d strokes", out.sensor_id, out.index,
                             out.swum_distance_m, out.duration_s, out.stroke_count)
                else:
                    publisher.publish(keys.pose(venue, agent_id, "edge"), out)
            for warning in edge.warnings():  # the core counts what it dropped; the process logs it
                log.warning("%s", warning)

        for message in source:
            summary.messages_in += 1
            _take_corrections(corrections, edge)
            if message.DESCRIPTOR.name == "ImuBatch":
                # duplicates out, late batches re-ordered, clock jumps re-anchored (edge/health.py)
                for batch in status.push(message):
                    raw.push(batch)  # before the estimator
                    publish(edge.push(batch))
            elif message.DESCRIPTOR.name == "StandScan":
                publisher.publish(keys.scan(venue, agent_id), message)  # refused ones too, with their reason
                edge.scan(message)
            elif message.DESCRIPTOR.name == "Pressure":
                publisher.publish(keys.pressure(venue, agent_id, message.sensor_id), message)
                edge.pressure(message)
            else:
                publisher.publish(keys.beacon(venue, agent_id, message.sensor_id), message)
            if progress and summary.messages_in % 1000 == 0:
                edge.summarise(summary)
                progress(summary)
        for batch in status.flush():
            raw.push(batch)
            publish(edge.push(batch))
        raw.flush()
        publish(edge.flush())
        status.report()  # the last word on every sensor, before the flush below
        if isinstance(publisher, SpooledPublisher):
            publisher.finish(spool_wait_s)
            summary.spooled, summary.spool_refused = publisher.spooled, publisher.refused
        flush(bus, wire.alive_selector(venue), FLUSH_TIMEOUT_S)  # closing drops what is still queued
    edge.summarise(summary)
    summary.raw_sent, summary.raw_unasked, summary.clock_samples = raw.sent, raw.unasked, raw.clock_samples
    return summary


class StatusReporter:
    """The agent's sensors' health (edge/health.py) as DeviceStatus on `keys.status`: every
    STATUS_PERIOD_S from a thread of its own, so a silent device is reported too, and at once when
    a sensor's flags change. A source may tell more: `device_ranges` (sensor id -> full scales, for
    saturation) and `link(sensor_id) -> (connected, reconnects, battery_pct)`; `spooled` is the
    publisher's, when it spools. A status is a view of now: it goes straight to the bus, unspooled."""

    def __init__(self, bus: BusSession, venue: str, agent: Any, source: Any, publisher: Any):
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
                        "samples, %d malformed batches, %d reconnects)", sensor_id, ", ".join(flags), status.gaps,
                        status.duplicates, status.out_of_order, status.clock_jumps, status.saturated,
                        status.malformed, status.reconnects)

    def __enter__(self) -> "StatusReporter":
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        self._publisher.close()


def _take_corrections(subscription: Subscription, edge: Edge) -> None:
    """Hand every Correction and FieldMap that has arrived to the edge (never waits)."""
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
        elif messages.type_name(message) == "FieldMap":
            edge.field_map(message)
