"""The two helper processes of `reckon bench load`: the generator (the chairs' edges) and the watcher.

Started by `reckon.bench.load.run_load` as `python -m reckon.bench.load generate|watch SPEC.json OUT`;
each writes what it did into OUT for the run to read.

- generator: EstimatedPose at `rate_hz` per chair, ImpactEvents in pairs when two chairs touch,
  BeaconSightings of its court's two goal beacons, a ClockSample per device and DeviceStatus at 1 Hz. It takes the hub's
  corrections back as an edge would (acknowledges them in `correction_sequence` and moves its
  estimate by the Kalman shift), so the hub's pending shifts stay as short as in a real game;
- watcher: every live pose the hub publishes (its batches: `reckon/<venue>/hub/poses/live`), stamped on arrival.

With several hubs (`spec.hubs`), each chair's streams go under its court's venue (`spec.shard`),
and both processes talk to every hub.
"""

from __future__ import annotations

import json
import queue
from contextlib import ExitStack
import signal
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from protocol import bus as wire
from protocol import keys, messages
from protocol.errors import ReckonError
from reckon.bench.load_spec import (BEACON_HEARD_HZ, COURT_AGENTS, DRIFT_M_PER_TICK, HEADING_VARIANCE_RAD2, PHASES,
                                    POSE_VARIANCE_M2, SENSITIVITY_DBM, VENUE, LoadSpec, Motion, contacts, load_session)
from reckon.bench.load_spec import rssi as load_rssi
from reckon.transport.bus import (Alive, CallbackSubscription, DirectSubscription, Publisher, flush, open_session,
                                  wait_for_peers, zenoh_config, zenoh_version)

FIFO_CAPACITY = 65536  # the watcher's Zenoh FIFO: a few seconds of live poses


def generate(spec: LoadSpec, out: Path) -> None:
    """Publish the chairs' streams from `spec.start_at_ns` for `spec.duration_s`; write what was put when."""
    session = load_session(spec)
    rng = np.random.default_rng(spec.seed)
    motion = Motion(spec.agents, rng)
    ids = [a.id for a in session.agents]
    index = {agent_id: i for i, agent_id in enumerate(ids)}
    seat = [f"{agent_id}-s" for agent_id in ids]
    sensors = [[sensor.id for sensor in agent.sensors] for agent in session.agents]
    beacon_xy = np.array([[b.x_m, b.y_m] for b in session.venue.beacons])
    beacon_ids = [b.id for b in session.venue.beacons]
    own_beacons = np.stack([2 * (np.arange(spec.agents) // COURT_AGENTS), 2 * (np.arange(spec.agents) // COURT_AGENTS) + 1], 1)
    poses = [messages.new("EstimatedPose", agent_id=a, method="reckon", track=messages.Track.LIVE,
                          covariance=[POSE_VARIANCE_M2, 0, 0, 0, POSE_VARIANCE_M2, 0, 0, 0, HEADING_VARIANCE_RAD2])
             for a in ids]
    venues = [spec.venue(spec.shard(i)) for i in range(spec.agents)]
    pose_keys = [keys.pose(venues[i], a, "edge") for i, a in enumerate(ids)]
    pose_encoding = wire.encoding_for("EstimatedPose")
    period_ns, phase_ns, ticks = spec.period_ns, spec.phase_ns(), spec.ticks
    put_ns = np.zeros((ticks, spec.agents), dtype=np.int64)
    offset = np.zeros((spec.agents, 2))  # the corrections taken so far
    acknowledged = np.zeros(spec.agents, dtype=np.int64)
    drift = np.zeros((spec.agents, 2))
    touching = np.zeros((-(-spec.agents // COURT_AGENTS), COURT_AGENTS, COURT_AGENTS), dtype=bool)
    counts = {"poses": 0, "impacts": 0, "sightings": 0, "clocks": 0, "statuses": 0, "contacts": 0, "corrections_taken": 0}
    taken_by_kind: dict[str, int] = {}
    corrections: queue.SimpleQueue[bytes] = queue.SimpleQueue()  # unbounded: tens a second
    slots = [np.arange(s, spec.agents, PHASES) for s in range(PHASES)]
    config = zenoh_config(connect=[*spec.hub_endpoints, spec.watcher_endpoint])
    with open_session(config) as bus, Publisher(bus) as publisher, ExitStack() as subscriptions:
        for venue in spec.venues():
            subscriptions.enter_context(CallbackSubscription(bus, keys.all_agents(venue, "correction"),
                                                             lambda item: corrections.put(item.payload)))
        # every hub, and the watcher as a recorder of each venue, up before the first pose
        wait_for_peers(bus, [wire.alive_selector(venue, role) for venue in spec.venues()
                             for role in (wire.Role.HUB, wire.Role.RECORDER)], 2 * spec.hubs, 120.0)
        started_ns = time.time_ns()
        (out / "generator.started").write_text(str(started_ns))
        late_s = max(0.0, (started_ns - spec.start_at_ns) * 1e-9)
        start_ns = max(spec.start_at_ns, started_ns)
        behind_ns = 0
        for tick in range(ticks):
            t_ns = spec.start_at_ns + tick * period_ns  # device time of the tick (venue clock)
            truth, heading = motion.at(tick * period_ns * 1e-9)
            drift += rng.normal(0.0, DRIFT_M_PER_TICK, drift.shape)
            pairs, touching = contacts(truth, touching)
            counts["contacts"] += len(pairs)
            impacted = {i: t_ns for pair in pairs for i in pair}
            while not corrections.empty():
                _take(messages.Correction.FromString(corrections.get()), index, offset, acknowledged, taken_by_kind)
            estimate = truth + drift + offset
            heard = rng.random((spec.agents, 2)) < BEACON_HEARD_HZ / spec.rate_hz
            rssi = load_rssi(truth, beacon_xy[own_beacons], rng)
            status_tick = tick % max(1, int(spec.rate_hz)) == 0
            for slot, members in enumerate(slots):
                due_ns = start_ns + tick * period_ns + slot * (period_ns // PHASES)
                wait_s = (due_ns - time.time_ns()) * 1e-9
                if wait_s > 0:
                    time.sleep(wait_s)
                else:
                    behind_ns = max(behind_ns, -int(wait_s * 1e9))
                for i in members.tolist():
                    pose = poses[i]
                    pose.timestamp_ns = t_ns + int(phase_ns[i])
                    pose.x_m, pose.y_m = float(estimate[i, 0]), float(estimate[i, 1])
                    pose.heading_rad = float(heading[i])
                    pose.correction_sequence = int(acknowledged[i])
                    put_ns[tick, i] = time.time_ns()
                    publisher.publish_bytes(pose_keys[i], pose.SerializeToString(), pose_encoding)
                    if i in impacted:
                        publisher.publish(keys.impact(venues[i], ids[i]), messages.new(
                            "ImpactEvent", timestamp_ns=impacted[i], agent_id=ids[i], sensor_id=seat[i],
                            peak_g=float(rng.uniform(7.0, 14.0))))
                        counts["impacts"] += 1
                    for end in np.flatnonzero(heard[i] & (rssi[i] >= SENSITIVITY_DBM)).tolist():
                        publisher.publish(keys.beacon(venues[i], ids[i], seat[i]), messages.new(
                            "BeaconSighting", timestamp_ns=pose.timestamp_ns, agent_id=ids[i], sensor_id=seat[i],
                            beacon_id=beacon_ids[own_beacons[i, end]], rssi_dbm=float(rssi[i, end])))
                        counts["sightings"] += 1
                    if status_tick:
                        for sensor in sensors[i]:  # each device's clock once a second, as an edge's RawFeed sends it
                            publisher.publish(keys.clock(venues[i], ids[i], sensor), messages.new(
                                "ClockSample", timestamp_ns=pose.timestamp_ns, agent_id=ids[i], sensor_id=sensor,
                                received_ns=pose.timestamp_ns))
                            counts["clocks"] += 1
                        publisher.publish(keys.status(venues[i], ids[i], seat[i]), messages.new(
                            "DeviceStatus", timestamp_ns=pose.timestamp_ns, agent_id=ids[i], sensor_id=seat[i],
                            connected=True, battery_pct=-1.0, last_sample_age_s=0.01,
                            samples=tick * 600 // int(spec.rate_hz)))
                        counts["statuses"] += 1
            counts["poses"] += spec.agents
        for venue in spec.venues():
            if not flush(bus, wire.alive_selector(venue, wire.Role.HUB), 30.0):
                raise ReckonError(f"bench load generator: the hub of {venue} did not answer the flush barrier "
                                  "within 30 s")
    counts["corrections_taken"] = sum(taken_by_kind.values())
    np.save(out / "put_ns.npy", put_ns)
    (out / "generator.json").write_text(json.dumps({
        **counts, "corrections_by_kind": taken_by_kind, "late_start_s": late_s, "max_behind_ms": behind_ns * 1e-6,
        "zenoh": zenoh_version()}))


def _take(correction: Any, index: dict[str, int], offset: np.ndarray, acknowledged: np.ndarray,
          taken: dict[str, int]) -> None:
    """What an edge does with a correction: a Kalman update of its position, then acknowledge it."""
    i = index.get(correction.agent_id)
    if i is None or correction.sequence <= acknowledged[i]:
        return
    prior = np.eye(2) * POSE_VARIANCE_M2
    gain = prior @ np.linalg.inv(prior + np.array(correction.covariance).reshape(2, 2))
    offset[i] += gain @ np.array([correction.dx_m, correction.dy_m])
    acknowledged[i] = correction.sequence
    kind = messages.CorrectionKind(correction.kind).name.lower()
    taken[kind] = taken.get(kind, 0) + 1


def watch(spec: LoadSpec, out: Path) -> None:
    """Stamp the arrival of every live pose until all are in or SIGINT/SIGTERM; write them."""
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    index = {spec.agent_id(i): i for i in range(spec.agents)}
    phase_ns, period_ns, ticks = spec.phase_ns(), spec.period_ns, spec.ticks
    received_ns = np.zeros((ticks, spec.agents), dtype=np.int64)
    published_ns = np.zeros((ticks, spec.agents), dtype=np.int64)  # the hub's Zenoh timestamp
    tally = {"live": 0, "duplicates": 0, "strays": 0}
    expected = ticks * spec.agents

    def drain(subscription: DirectSubscription) -> None:
        decode = messages.PoseBatch.FromString
        for item in subscription:  # ends once undeclared and empty
            arrived = item.received_ns  # as it left Zenoh's FIFO
            for pose in decode(item.payload).poses:
                i = index.get(pose.agent_id)
                tick = -1 if i is None else (pose.timestamp_ns - spec.start_at_ns - int(phase_ns[i])) // period_ns
                if not 0 <= tick < ticks:
                    tally["strays"] += 1
                    continue
                if received_ns[tick, i]:
                    tally["duplicates"] += 1
                    continue
                received_ns[tick, i] = arrived
                published_ns[tick, i] = item.source_ns or 0
                tally["live"] += 1
            if tally["live"] == expected:
                stop.set()

    with open_session(zenoh_config(listen=[spec.watcher_endpoint], connect=list(spec.hub_endpoints))) as bus:
        # A FIFO, not a ring: a live pose missed here would count as lost; a full FIFO holds the hub back.
        # Every venue's live poses as the hub batches them for a consumer of all agents (the demo's court
        # table's way): `reckon/<venue>/hub/poses/live` whatever the venue.
        subscription = DirectSubscription.fifo(bus, keys.pose_batch(VENUE if spec.hubs == 1 else "*", "live"),
                                               FIFO_CAPACITY)
        thread = threading.Thread(target=drain, args=(subscription,), daemon=True)
        thread.start()
        with ExitStack() as alive:
            for venue in spec.venues():
                alive.enter_context(Alive(bus, venue, wire.Role.RECORDER, "bench-watcher"))
            while not stop.wait(0.2):
                pass
        subscription.undeclare()
        thread.join(5.0)
    np.save(out / "received_ns.npy", received_ns)
    np.save(out / "hub_published_ns.npy", published_ns)
    (out / "watcher.json").write_text(json.dumps(tally))
