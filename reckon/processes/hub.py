"""`reckon hub`: the venue's hub over Zenoh. Every agent's streams in; corrected poses and corrections out.

One subscription to the agents' input streams (`reckon.transport.bus.PolledSubscription`: taken in
batches on the hub's thread; a slow hub's full FIFOs slow the edges down, it never loses a
measurement) feeds `hub.venue.VenueHub` (chairs' corrections, pedestrians' map matching, camera
identities) on one thread, in arrival order. Its outputs go out at once: live poses on
`reckon/<venue>/<agent>/pose/live`, refined ones on `.../pose/refined`, corrections to the edges on
`.../correction`. A pose track goes out only while someone subscribes to it (recorded either way);
each track's poses of one pass over the inputs go out together on `reckon/<venue>/hub/poses/<track>`
while someone subscribes to that (`PoseBatches`); the refined track, when nobody takes it and
nothing records it, is not even made into messages (`ChairHub.refined_wanted`). A swimmer's lengths
(`.../length`, from its edge) are recorded, logged as they come and totalled in the summary. With
`output`, every input and every output is written to a session log (MCAP) as it passes, with the
hub's clock as log time.

The hub needs no edge to be up first and no edge needs the hub: an edge started earlier is picked
up with its next pose, one that goes quiet stops holding the collision pairing back after
`stale_s`, and one that comes back carries on (its pose says which corrections it holds).

Repeats (an edge's spool replays what the hub may have had) are dropped before anything else
(hub/dedup.py). With `state`, the hub checkpoints itself every `snapshot_every_s`, and a hub
started with an existing state file restores it, re-applies the inputs its recording holds after
the checkpoint, records to the next free name (hub.1.mcap) and goes on (reckon/processes/checkpoint.py,
docs/faults.md).
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

from reckon.processes import checkpoint as hub_state
from hub.chair.hub import HubSettings
from hub.dedup import Deduplicator, Verdict
from hub.venue import VenueHub
from protocol import bus as wire
from protocol import keys, messages
from protocol.errors import ConfigError, InputError
from protocol.session import Session
from protocol.session_log import LogMessages, SessionWriter
from reckon.transport.bus import Alive, BusConfig, BusSession, PolledSubscription, Publisher, open_session
from reckon.transport.matching import Listened

log = logging.getLogger(__name__)
POLL_S = 0.1
BATCH = 256  # samples taken from the FIFOs at a time
FIFO_CAPACITY = 1024  # per input selector: what the hub holds before Zenoh pushes back on the edges
# Raw IMU (`imu/*`) is not among them: the clocks come from `clock/*`, and the edges publish raw batches
# only while someone subscribes (reckon/processes/raw_feed.py). The hub subscribes once a camera is on:
# the identity engine reads the IMU.
INPUTS = ("clock/*", "beacon/*", "pose/edge", "event/impact", "event/scan", "fix", "length", "field", "tracks/*")  # tracks: camera frames
RAW_IMU = "imu/*"
CLOCK_CHECK_S = 1.0  # how often the hub looks for agents sending poses but no clock samples
CLOCKLESS_POSES = 100  # ... with this many poses (2 s at 50 Hz: an edge's first ClockSample goes with its first batch)
SWIM_LENGTH = messages.CLASSES["SwimLength"]
LIVE, REFINED = "/pose/live", "/pose/refined"  # the ends of the two pose tracks' keys (protocol.keys.pose)
WARN_EVERY_S = 10.0
SNAPSHOT_EVERY_S = 2.0  # a restarted hub re-applies at most this much of its recording
FLUSH_EVERY_S = 0.5  # with a state file, the recording reaches the disk this often: a kill loses at most this much of it


@dataclass
class HubSummary:
    venue: str
    inputs: int = 0
    outputs: int = 0
    corrections: dict[str, dict[str, int]] = field(default_factory=dict)  # agent -> kind -> count
    pairs: int = 0
    skipped: int = 0
    full_waits: int = 0
    unheard: int = 0  # poses of a track nobody subscribed to: recorded, not published
    duplicates: int = 0  # inputs dropped as exact repeats (hub/dedup.py)
    stale: int = 0  # inputs dropped as older than their stream's newest
    reapplied: int = 0  # inputs re-applied from the recording after a restart
    swims: dict[str, SwimTotals] = field(default_factory=dict)  # sensor -> its lengths so far
    walkers: dict[str, str] = field(default_factory=dict)  # pedestrian -> its map-matched poses and the last one
    beacons: dict[str, str] = field(default_factory=dict)  # a chair venue's beacon -> what its passes showed
    field_map: str = ""  # a chair venue's map of the hall's magnetic field, once an edge sent readings

    def __str__(self) -> str:
        total = sum(sum(kinds.values()) for kinds in self.corrections.values())
        text = (f"hub {self.venue}: {self.inputs} messages in, {self.outputs} out, {total} corrections "
                f"({self.pairs} collision pairs), {self.skipped} samples skipped, queue full {self.full_waits} times, "
                f"{self.duplicates} duplicates and {self.stale} stale inputs dropped")
        if self.reapplied:
            text += f", {self.reapplied} inputs re-applied after a restart"
        if self.unheard:
            text += f", {self.unheard} poses of a track nobody subscribed to (not published)"
        for sensor_id, swim in sorted(self.swims.items()):
            text += f"\n  {sensor_id}: {swim}"
        for agent_id, line in sorted(self.walkers.items()):
            text += f"\n  {agent_id}: {line}"
        for beacon_id, line in sorted(self.beacons.items()):
            text += f"\n  beacon {beacon_id}: {line}"
        if self.field_map:
            text += f"\n  {self.field_map}"
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


def run_hub(config: BusConfig, session: Session, stop: threading.Event, settings: HubSettings = HubSettings(),
            output: Path | None = None, ready: threading.Event | None = None,
            on_output: Callable[[Any], None] | None = None, on_input: Callable[[Any], None] | None = None,
            on_bus: Callable[[BusSession], Any] | None = None, state: Path | None = None,
            snapshot_every_s: float = SNAPSHOT_EVERY_S) -> HubSummary:
    """Run until `stop`; then take what was already received, flush the refined track, return.

    on_input / on_output: called with every decoded input / output message on the hub's thread (the
    court view's hand-over: they must not block). on_bus: called with the hub's Zenoh session once
    open; the context manager it returns is entered and closed with the hub (the view's own
    subscriptions). state: the checkpoint file (needs `output`); restored from when it exists.
    """
    if state is not None and output is None:
        raise ConfigError(f"hub state {state}: needs a recording (-o FILE.mcap) to re-apply inputs from")
    hub, dedup = VenueHub(session, settings), Deduplicator()
    venue = session.venue.name
    summary = HubSummary(venue)
    skipped_since, last_warning = 0, 0.0
    restored = hub_state.read(state) if state is not None else None
    if restored is not None:
        output = hub_state.next_recording(output)  # the recording restored from stays as it is
    recorded, unsent, next_snapshot = 0, [], time.monotonic() + snapshot_every_s
    next_flush = time.monotonic() + FLUSH_EVERY_S
    with ExitStack() as stack:
        writer = stack.enter_context(SessionWriter(output, session)) if output else None
        if restored is not None:
            hub, dedup, recorded, unsent = _catch_up(restored, state, writer, summary)
        bus = stack.enter_context(open_session(config))
        publisher = stack.enter_context(Publisher(bus))
        # Inputs only: were the hub subscribed to its own outputs, a full queue would block its
        # own publishing, which only it can drain.
        # Taken in batches on this thread (no drain threads: see PolledSubscription), each batch in the
        # order its samples were published, whatever their streams: as they arrived, not stream by stream.
        subscription = stack.enter_context(PolledSubscription(bus, [keys.all_agents(venue, stream) for stream in INPUTS],
                                                              fifo_capacity=FIFO_CAPACITY, by_source_time=True))
        asked_raw = False

        def ask_raw(why: str, level: int = logging.INFO) -> None:
            """Subscribe to every agent's raw IMU, once: one FIFO more, however many agents (a FIFO per
            agent made each sweep of the subscription as long as the venue)."""
            nonlocal asked_raw
            if not asked_raw:
                subscription.add(keys.all_agents(venue, RAW_IMU))
                asked_raw = True
                log.log(level, "subscribed to the edges' raw IMU: %s", why)

        def ask_raw_clocks() -> None:
            """Chairs whose poses come without any ClockSample (edges older than the hub, a replayed
            recording from before them): the raw IMU for their clock offsets, as before ClockSample."""
            late = [] if asked_raw else hub.chairs.without_clocks(CLOCKLESS_POSES)
            if late:
                ask_raw(f"{len(late)} chairs ({', '.join(late[:5])}{', ...' if len(late) > 5 else ''}) sent "
                        f"{CLOCKLESS_POSES} poses or more and no clock samples (edges older than this hub, or a "
                        "replayed recording from before them): their clock offsets come from it", logging.WARNING)

        if hub.identity is not None:  # a hub restored with its identity engine
            ask_raw("a camera is on (the identity engine reads the IMU)")
        next_clock_check = time.monotonic() + CLOCK_CHECK_S
        stack.enter_context(Alive(bus, venue, wire.Role.HUB))
        if on_bus:
            stack.enter_context(on_bus(bus))
        if ready is not None:
            ready.set()

        # A pose track goes on the bus only while someone subscribes to it (the court view, a recorder):
        # at 500 chairs the refined track nobody reads was half the hub's puts. Recorded either way.
        live_heard = stack.enter_context(Listened(bus, keys.all_agents(venue, "pose/live")))
        refined_heard = stack.enter_context(Listened(bus, keys.all_agents(venue, "pose/refined")))

        batches = stack.enter_context(PoseBatches(bus, publisher, venue))
        keeps_refined = writer is not None or on_output is not None  # these take every refined pose

        def want_refined() -> None:
            hub.chairs.refined_wanted = keeps_refined or refined_heard.matching or batches.heard(REFINED)

        def emit(outputs: list[Any]) -> None:
            now = time.time_ns() if writer else 0
            for out in outputs:
                key = hub.key_for(out)
                track = LIVE if key.endswith(LIVE) else REFINED if key.endswith(REFINED) else None
                if track is None or (live_heard if track == LIVE else refined_heard).matching:
                    publisher.publish(key, out)
                elif not batches.heard(track):
                    summary.unheard += 1
                if track is not None:
                    batches.hold(track, out)
                if writer:
                    writer.write(key, out, now)
                if on_output:
                    on_output(out)
            summary.outputs += len(outputs)

        emit(unsent)  # made again from the recording, never sent by the hub before (edges drop repeats)
        batches.send()
        stopping = False
        while True:
            if stop.is_set() and not stopping:
                stopping = True
                subscription.undeclare()  # what was received before still comes out of `take`
            try:
                batch = subscription.take(BATCH, timeout=POLL_S)
            except queue.Empty:
                continue
            if batch is None:
                break
            want_refined()
            if time.monotonic() >= next_clock_check:
                ask_raw_clocks()
                next_clock_check = time.monotonic() + CLOCK_CHECK_S
            for item in batch:
                if item.delete:
                    continue
                try:
                    message = item.decode()
                    if dedup.check(item.key, message) is not Verdict.NEW:
                        continue
                    if writer:
                        writer.write(item.key, message, item.received_ns)
                        recorded += 1
                    if on_input:
                        on_input(message)
                    summary.inputs += 1
                    if type(message) is SWIM_LENGTH:
                        line = summary.swims.setdefault(message.sensor_id, SwimTotals()).add(message)
                        log.info("%s %s", message.sensor_id, line)
                        if on_output:
                            on_output(message)
                        continue
                    emit(hub.on_message(message, item.received_ns))
                    if not asked_raw and hub.identity is not None:
                        ask_raw("a camera is on (the identity engine reads the IMU)")
                except (InputError, ValueError) as error:
                    summary.skipped += 1
                    skipped_since += 1
                    if time.monotonic() - last_warning >= WARN_EVERY_S:
                        log.warning("skipped %d samples; latest on %s: %s", skipped_since, item.key, error)
                        skipped_since, last_warning = 0, time.monotonic()
                if state is not None and time.monotonic() >= next_snapshot:
                    _checkpoint(state, writer, output, hub_state.HubState(hub, dedup, output.name, recorded))
                    next_snapshot, next_flush = time.monotonic() + snapshot_every_s, time.monotonic() + FLUSH_EVERY_S
                elif state is not None and time.monotonic() >= next_flush:
                    writer.flush()
                    next_flush = time.monotonic() + FLUSH_EVERY_S
            batches.send()
        if state is not None:  # before the final flush: a hub restarted from it carries on the session
            _checkpoint(state, writer, output, hub_state.HubState(hub, dedup, output.name, recorded))
        want_refined()
        for part in hub.chairs.flush_by_agent():  # one agent's refined track at a time, not the venue's at once
            emit(part)
            batches.send()
        emit(hub.flush())  # the rest (pedestrians); the chairs' smoothers are empty now
        batches.send()
        summary.full_waits = subscription.stats.full_waits
    summary.corrections = {view.agent_id: dict(view.applied) for view in hub.agents.values()}
    summary.pairs = hub.counters.pairs
    summary.unheard += hub.chairs.counters.refined_unbuilt
    summary.duplicates, summary.stale = dedup.counters.duplicates, dedup.counters.stale
    summary.walkers = {view.agent_id: view.describe() for view in hub.pedestrians.agents.values() if view.poses}
    levels = hub.chairs.beacon_levels
    summary.beacons = {beacon_id: levels.describe(beacon_id) for beacon_id in levels.beacons
                       if levels.levels[beacon_id].close_fixes + levels.levels[beacon_id].far_fixes}
    if hub.chairs.field.readers:
        summary.field_map = hub.chairs.field.describe()
    return summary


class PoseBatches:
    """Each pose track's poses of one pass over the inputs, sent as one PoseBatch on
    `reckon/<venue>/hub/poses/<track>` while someone subscribes to that key (a consumer of every
    agent: the demo's court table, the load bench's watcher). At 500 chairs a put per pose cost the
    hub 5-6 us of CPU; a pose held here costs 0.4 us. At most MAX_POSES to a message (a refined
    track's flush is one agent's whole game)."""

    MAX_POSES = 1024

    def __init__(self, bus: BusSession, publisher: Publisher, venue: str):
        self._publisher = publisher
        self._keys = {LIVE: keys.pose_batch(venue, "live"), REFINED: keys.pose_batch(venue, "refined")}
        self._listened = {track: Listened(bus, key) for track, key in self._keys.items()}
        self._held: dict[str, list[Any]] = {LIVE: [], REFINED: []}

    def heard(self, track: str) -> bool:
        return self._listened[track].matching

    def hold(self, track: str, pose: Any) -> None:
        if self._listened[track].matching:
            held = self._held[track]
            held.append(pose)
            if len(held) >= self.MAX_POSES:
                self._send(track, held)

    def send(self) -> None:
        for track, held in self._held.items():
            if held:
                self._send(track, held)

    def _send(self, track: str, held: list[Any]) -> None:
        self._publisher.publish(self._keys[track], messages.new("PoseBatch", timestamp_ns=time.time_ns(), poses=held))
        held.clear()

    def close(self) -> None:
        for listened in self._listened.values():
            listened.close()

    def __enter__(self) -> "PoseBatches":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _checkpoint(path: Path, writer: SessionWriter, output: Path, state: hub_state.HubState) -> None:
    """Flush the recording (the snapshot's inputs must be on disk), then replace the snapshot."""
    if output.parent.resolve() != path.parent.resolve():
        state.recording = str(output.resolve())
    writer.flush()
    hub_state.write_atomic(path, hub_state.dumps(state))


def _catch_up(restored: hub_state.HubState, path: Path, writer: SessionWriter,
              summary: HubSummary) -> tuple[VenueHub, Deduplicator, int, list[Any]]:
    """Re-apply the old recording after the snapshot into `restored`, recording those inputs again."""
    started = time.monotonic()
    old = path.parent / restored.recording  # an absolute name stays absolute
    log_messages = LogMessages(old)
    if not old.exists():  # the snapshot alone still holds the session up to it
        log.warning("restoring the hub: its recording %s is gone; carrying on from the snapshot alone", old)
    result = hub_state.catch_up(restored, log_messages if old.exists() else [],
                                lambda log_time, topic, message: writer.write(topic, message, log_time))
    for problem in log_messages.problems + result.problems:
        log.warning("restoring the hub: %s", problem)
    summary.reapplied = result.reapplied
    log.warning("hub restored from %s and %s: %d inputs re-applied (%d repeats dropped) in %.3f s; %d corrections "
                "to send again", path, old, result.reapplied, result.repeats, time.monotonic() - started,
                len(result.unsent))
    return restored.hub, restored.dedup, result.reapplied, result.unsent
