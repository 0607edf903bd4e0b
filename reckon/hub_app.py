"""`reckon hub`: the venue's hub over Zenoh. Every agent's streams in; corrected poses and corrections out.

One subscription to the agents' input streams (a blocking queue: a slow hub slows the edges
down, it never loses a measurement) feeds `hub.venue_hub.VenueHub` (chairs' corrections, pedestrians' map matching, camera identities) on one
thread, in arrival order. Its
outputs go out at once: live poses on `reckon/<venue>/<agent>/pose/live`, refined ones on
`.../pose/refined`, corrections to the edges on `.../correction`. A swimmer's lengths
(`.../length`, from its edge) are recorded, logged as they come and totalled in the summary. With `output`, every input and
every output is written to a session log (MCAP) as it passes, with the hub's clock as log time.

The hub needs no edge to be up first and no edge needs the hub: an edge started earlier is picked
up with its next pose, one that goes quiet stops holding the collision pairing back after
`stale_s`, and one that comes back carries on (its pose says which corrections it holds).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import zenoh

from hub.chair_hub import HubSettings
from hub.venue_hub import VenueHub
from protocol import bus as wire
from protocol import keys
from protocol.errors import InputError
from protocol.session import Session
from protocol.session_log import SessionWriter
from reckon.bus import Alive, Publisher, Subscription, open_session

log = logging.getLogger(__name__)
POLL_S = 0.1
INPUTS = ("imu/*", "beacon/*", "pose/edge", "event/impact", "event/scan", "fix", "length", "tracks/*")  # tracks: camera frames
WARN_EVERY_S = 10.0


@dataclass
class HubSummary:
    venue: str
    inputs: int = 0
    outputs: int = 0
    corrections: dict[str, dict[str, int]] = field(default_factory=dict)  # agent -> kind -> count
    pairs: int = 0
    skipped: int = 0
    full_waits: int = 0
    swims: dict[str, SwimTotals] = field(default_factory=dict)  # sensor -> its lengths so far
    walkers: dict[str, str] = field(default_factory=dict)  # pedestrian -> its map-matched poses and the last one

    def __str__(self) -> str:
        total = sum(sum(kinds.values()) for kinds in self.corrections.values())
        text = (f"hub {self.venue}: {self.inputs} messages in, {self.outputs} out, {total} corrections "
                f"({self.pairs} collision pairs), {self.skipped} samples skipped, queue full {self.full_waits} times")
        for sensor_id, swim in sorted(self.swims.items()):
            text += f"\n  {sensor_id}: {swim}"
        for agent_id, line in sorted(self.walkers.items()):
            text += f"\n  {agent_id}: {line}"
        return text


@dataclass
class SwimTotals:
    """A swimmer's sensor as the hub shows it: lengths, total swum distance, the latest length."""

    lengths: int = 0
    swum_m: float = 0.0
    seconds: float = 0.0
    latest: str = ""

    def add(self, length: Any) -> str:
        self.lengths += 1
        self.swum_m += length.swum_distance_m
        self.seconds += length.duration_s
        deviation = max((abs(v) for v in length.lateral_deviation_m), default=0.0)
        self.latest = (f"length {length.index}: {length.swum_distance_m:.2f} m swum ({length.lane_distance_m:.2f} m "
                       f"along the lane) in {length.duration_s:.1f} s, {length.stroke_count} strokes "
                       f"({length.stroke_rate_per_min:.0f}/min), snaking up to {deviation:.2f} m")
        return self.latest

    def __str__(self) -> str:
        return f"{self.lengths} lengths, {self.swum_m:.1f} m in {self.seconds:.0f} s; last {self.latest or 'none'}"


def run_hub(config: zenoh.Config, session: Session, stop: threading.Event, settings: HubSettings = HubSettings(),
            output: Path | None = None, ready: threading.Event | None = None,
            on_output: Callable[[Any], None] | None = None) -> HubSummary:
    """Run until `stop`; then take what was already received, flush the refined track, return."""
    hub = VenueHub(session, settings)
    venue = session.venue.name
    summary = HubSummary(venue)
    skipped_since, last_warning = 0, 0.0
    with ExitStack() as stack:
        writer = stack.enter_context(SessionWriter(output, session)) if output else None
        bus = stack.enter_context(open_session(config))
        publisher = stack.enter_context(Publisher(bus))
        # Inputs only: were the hub subscribed to its own outputs, a full queue would block its
        # own publishing, which only it can drain.
        subscription = stack.enter_context(Subscription(bus, [keys.all_agents(venue, stream) for stream in INPUTS]))
        stack.enter_context(Alive(bus, venue, wire.Role.HUB))
        if ready is not None:
            ready.set()

        def emit(outputs: list[Any]) -> None:
            now = time.time_ns()
            for out in outputs:
                key = hub.key_for(out)
                publisher.publish(key, out)
                if writer:
                    writer.write(key, out, now)
                if on_output:
                    on_output(out)
            summary.outputs += len(outputs)

        stopping = False
        while True:
            if stop.is_set() and not stopping:
                stopping = True
                subscription.undeclare()  # what was received before still comes out of `get`
            try:
                item = subscription.get(timeout=POLL_S)
            except queue.Empty:
                continue
            if item is None:
                break
            if item.delete:
                continue
            try:
                message = item.decode()
                if writer:
                    writer.write(item.key, message, item.received_ns)
                summary.inputs += 1
                if message.DESCRIPTOR.name == "SwimLength":
                    line = summary.swims.setdefault(message.sensor_id, SwimTotals()).add(message)
                    log.info("%s %s", message.sensor_id, line)
                    if on_output:
                        on_output(message)
                    continue
                emit(hub.on_message(message, item.received_ns))
            except (InputError, ValueError) as error:
                summary.skipped += 1
                skipped_since += 1
                if time.monotonic() - last_warning >= WARN_EVERY_S:
                    log.warning("skipped %d samples; latest on %s: %s", skipped_since, item.key, error)
                    skipped_since, last_warning = 0, time.monotonic()
        emit(hub.flush())
        summary.full_waits = subscription.stats.full_waits
    summary.corrections = {view.agent_id: dict(view.applied) for view in hub.agents.values()}
    summary.pairs = hub.counters.pairs
    summary.walkers = {view.agent_id: view.describe() for view in hub.pedestrians.agents.values() if view.poses}
    return summary
