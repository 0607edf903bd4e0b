"""`latency_ms`: a paced replay watched from this process, each live pose paired with the raw batch behind it.

For each live pose of the hub: its arrival here minus the arrival here of the raw ImuBatch whose
push made the edge emit the pose (the batch that completed the pose's inputs). So it is the
processing path edge -> Zenoh -> hub -> Zenoh, not the sensors' batching or the wait for the next
pose tick.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from protocol import keys
from protocol.errors import ReckonError
from protocol.session import Mount, Session
from protocol.session_log import read_description
from reckon.bench.play import hub_timeline, play
from reckon.bench.report import percentiles
from reckon.transport.bus import Received

LATENCY_S = 20.0  # game seconds of the paced run
LATENCY_SPEED = 1.0  # its pace, times real time
WARMUP_S = 2.0  # each agent's first poses of the paced run, left out of the percentiles (first numba call)


def latency_run(game: Path, folder: Path, speed: float, startup_cpu_s: float = 0.0) -> dict[str, Any]:
    """`startup_cpu_s`: what one edge process spends starting (play's start allowance)."""
    session = read_description(game)
    venue = session.venue.name
    selectors = tuple(keys.all_agents(venue, stream) for stream in ("imu/*", "pose/edge", "pose/live"))
    run = play(game, folder, speed, selectors, startup_cpu_s)
    result = latencies(run.received, session)
    hub_inputs = sum(hub_timeline(run.recording)["inputs"].values())
    hub_cpu = run.hub.cpu_s - run.cpu_at_start["hub"]
    # what one sample arriving on its own costs to take in through `Subscription`, here and in the hub
    result["receive_cpu_us"] = {"hub_per_input": 1e6 * hub_cpu / max(1, hub_inputs),
                                "bench_per_sample": 1e6 * run.own_cpu_s / max(1, len(run.received))}
    result.update(players=len(session.agents), speed=speed,
                  rss_mb={"hub": run.hub.max_rss_mb, "edge_max": max(e.max_rss_mb for e in run.edges.values())},
                  cpu_s={"hub": hub_cpu,
                         "edges_total": sum(e.cpu_s - run.cpu_at_start[a] for a, e in run.edges.items()),
                         "bench_process": run.own_cpu_s, "machine_busy": run.system_busy_s},
                  hub_summary=run.hub_summary, late_starts_s=run.late_starts,
                  start_allowance_s=run.start_allowance_s)
    return result


@dataclass
class _Agent:
    seat_id: str
    raw_source_ns: list[int] = field(default_factory=list)  # the edge's clock at each raw publish, ascending
    raw_arrival_ns: list[int] = field(default_factory=list)  # this process's clock at its arrival
    seat_arrival_ns: dict[int, int] = field(default_factory=dict)  # seat sample time -> its batch's arrival
    edge_poses: list[tuple[Received, Any]] = field(default_factory=list)
    live_poses: list[tuple[Received, Any]] = field(default_factory=list)


def latencies(received: list[Received], session: Session, warmup_s: float = WARMUP_S) -> dict[str, Any]:
    """Pair each live pose with its edge pose (per agent, in order; the hub copies the heading) and
    that pose with the raw batch after whose push the edge emitted it; latencies in ms."""
    agents = {a.id: _Agent(a.sensor(Mount.SEAT).id) for a in session.agents}
    for item in received:
        _, agent_id, stream, sub = keys.parse(item.key)
        view = agents.get(agent_id)
        if view is None or item.delete:
            continue
        message = item.decode()
        if stream == "imu":
            if item.source_ns is None:
                raise ReckonError("bench: raw batches carry no Zenoh timestamp (timestamping is off)")
            view.raw_source_ns.append(item.source_ns)
            view.raw_arrival_ns.append(item.received_ns)
            if message.sensor_id == view.seat_id:
                for offset in message.sample_offset_ns:
                    view.seat_arrival_ns[message.timestamp_ns + offset] = item.received_ns
        elif sub == "edge":
            view.edge_poses.append((item, message))
        elif sub == "live":
            view.live_poses.append((item, message))
    processing, from_seat, edge_part, hub_part, delivery, warmup = [], [], [], [], [], []
    unmatched = 0
    for view in agents.values():
        order = np.argsort(view.raw_source_ns, kind="stable")
        raw_source = [view.raw_source_ns[i] for i in order]
        raw_arrival = [view.raw_arrival_ns[i] for i in order]
        first_ns = view.edge_poses[0][1].timestamp_ns if view.edge_poses else 0
        for (edge_item, edge_pose), (live_item, live_pose) in zip(view.edge_poses, view.live_poses):
            if edge_pose.heading_rad != live_pose.heading_rad or edge_item.source_ns is None:
                unmatched += 1
                continue
            index = bisect.bisect_left(raw_source, edge_item.source_ns) - 1  # the last raw batch before the pose
            if index < 0:
                unmatched += 1
                continue
            total_ms = (live_item.received_ns - raw_arrival[index]) * 1e-6
            if edge_pose.timestamp_ns - first_ns < warmup_s * 1e9:
                warmup.append(total_ms)
                continue
            processing.append(total_ms)
            edge_part.append((edge_item.source_ns - raw_source[index]) * 1e-6)
            if live_item.source_ns is not None:
                hub_part.append((live_item.source_ns - edge_item.source_ns) * 1e-6)
                delivery.append((live_item.received_ns - live_item.source_ns) * 1e-6)
            seat_arrival = view.seat_arrival_ns.get(edge_pose.timestamp_ns)
            if seat_arrival is not None:
                from_seat.append((live_item.received_ns - seat_arrival) * 1e-6)
        unmatched += abs(len(view.edge_poses) - len(view.live_poses))
    return {
        "processing_ms": percentiles(processing),
        "from_seat_batch_ms": percentiles(from_seat),
        "parts_ms": {"edge": percentiles(edge_part), "edge_pose_to_live_publish": percentiles(hub_part),
                     "live_delivery": percentiles(delivery)},
        "warmup_excluded": percentiles(warmup), "warmup_s": warmup_s, "unmatched": unmatched,
        "edge_poses": sum(len(v.edge_poses) for v in agents.values()),
        "live_poses": sum(len(v.live_poses) for v in agents.values()),
    }
