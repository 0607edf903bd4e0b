"""`reckon demo`: a simulated game played live, device by device, through edges and the hub over Zenoh.

The session log stands in for the devices: one `reckon edge` process per chair replays that
chair's three IMUs and its beacon receiver from the log at `speed` x real time (all anchored to
one start time, as real devices share the venue's clock), and one `reckon hub` process corrects
them and records everything to `hub.mcap`. All on loopback: peer mode, explicit endpoints, no
router, no hardware. This process watches the bus like a court-side screen would (it may miss
poses, never slows anyone down) and prints a table: position, error against the simulator's
truth, corrections applied. At the end the hub's recorded live and refined tracks are scored.
"""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from protocol import bus as wire
from protocol import keys, messages
from protocol.errors import ReckonError
from protocol.session import Session
from protocol.session_log import LogMessages, read_description
from reckon.transport.bus import BusSession, DirectSubscription, free_endpoint, open_session, wait_for_peers, zenoh_config

START_DELAY_S = 3.0  # time for the edge processes to start (Python, numpy, zenoh) before the first sample
TABLE_EVERY_S = 2.0
BEHIND_WARN_S = 5.0
SCORE_HZ = 10.0


@dataclass
class Track:
    time_ns: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray

    def at(self, time_ns: np.ndarray | int) -> tuple[np.ndarray, np.ndarray]:
        return np.interp(time_ns, self.time_ns, self.x_m), np.interp(time_ns, self.time_ns, self.y_m)


@dataclass
class LiveResult:
    mean_error_m: dict[str, float]  # track -> team mean over agents and frames
    per_agent: dict[str, dict[str, float]] = field(default_factory=dict)  # track -> agent -> mean
    corrections: dict[str, dict[str, int]] = field(default_factory=dict)  # agent -> kind -> count
    wall_s: float = 0.0
    game_s: float = 0.0


def read_tracks(path: Path, wanted: Callable[[str, str], bool]) -> dict[str, dict[str, Track]]:
    """{stream: {agent: Track}} of the pose-like messages `wanted(topic, type)` accepts."""
    rows: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for _, topic, message in LogMessages(path, wanted):
        _, agent, stream, sub = keys.parse(topic)
        rows[f"{stream}/{sub}" if sub else stream][agent].append((message.timestamp_ns, message.x_m, message.y_m))
    tracks = {}
    for stream, by_agent in rows.items():
        tracks[stream] = {}
        for agent, values in by_agent.items():
            array = np.array(sorted(values))
            tracks[stream][agent] = Track(array[:, 0].astype(np.int64), array[:, 1], array[:, 2])
    return tracks


def score(truth: dict[str, Track], estimates: dict[str, Track]) -> tuple[float, dict[str, float]]:
    """Mean position error over agents at SCORE_HZ frames spanning the truth."""
    per_agent = {}
    for agent, reference in truth.items():
        estimate = estimates.get(agent)
        if estimate is None or len(estimate.time_ns) == 0:
            per_agent[agent] = math.nan
            continue
        frames = np.arange(reference.time_ns[0], reference.time_ns[-1], int(1e9 / SCORE_HZ))
        frames = frames[(frames >= estimate.time_ns[0]) & (frames <= estimate.time_ns[-1])]
        tx, ty = reference.at(frames)
        ex, ey = estimate.at(frames)
        per_agent[agent] = float(np.mean(np.hypot(ex - tx, ey - ty)))
    return float(np.nanmean(list(per_agent.values()))), per_agent


class CourtView:
    """Latest live pose and corrections per agent, from the bus; a ring buffer that drops when behind."""

    def __init__(self, bus: BusSession, venue: str):
        self.poses: dict[str, tuple[int, float, float]] = {}
        self.corrections: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
        # Only the latest pose is shown, so missing some costs nothing; every correction is counted. Every
        # agent's live poses: the hub's batches of them, a message per pass over its inputs, not per pose.
        self.poses_sub = DirectSubscription.ring(bus, keys.pose_batch(venue, "live"), 1024)
        self.corrections_sub = DirectSubscription.fifo(bus, keys.all_agents(venue, "correction"), 4096)

    def drain(self) -> None:
        for subscriber in (self.poses_sub, self.corrections_sub):
            while (sample := subscriber.try_get()) is not None:
                message = wire.decode(sample.encoding, sample.payload, sample.key)
                if messages.type_name(message) == "PoseBatch":
                    for pose in message.poses:
                        self.poses[pose.agent_id] = (pose.timestamp_ns, pose.x_m, pose.y_m)
                else:
                    self.corrections[message.agent_id][messages.CorrectionKind(message.kind).name.lower()] += 1

    def close(self) -> None:
        self.poses_sub.undeclare()
        self.corrections_sub.undeclare()


def table(session: Session, view: CourtView, truth: dict[str, Track], game_start_ns: int, duration_s: float,
          expected_s: float) -> str:
    newest = max((pose[0] for pose in view.poses.values()), default=game_start_ns)
    shown_s = (newest - game_start_ns) * 1e-9
    behind = ""
    if expected_s - shown_s > BEHIND_WARN_S and shown_s < duration_s - 1.0:
        behind = (f"  (behind the devices by {expected_s - shown_s:.0f} s: this machine cannot keep up with "
                  "this --speed, and the bus may drop links it holds blocked for 5 s)")
    lines = [f"game time {shown_s:6.1f} / {duration_s:.0f} s{behind}",
             f"{'agent':10} {'x m':>7} {'y m':>7} {'error m':>8}  corrections"]
    for agent in session.agents:
        pose = view.poses.get(agent.id)
        if pose is None:
            lines.append(f"{agent.id:10} {'-':>7} {'-':>7} {'-':>8}")
            continue
        error = "-"
        if agent.id in truth:
            tx, ty = truth[agent.id].at(pose[0])
            error = f"{math.hypot(pose[1] - tx, pose[2] - ty):.2f}"
        kinds = ", ".join(f"{kind} {count}" for kind, count in sorted(view.corrections[agent.id].items())) or "none"
        lines.append(f"{agent.id:10} {pose[1]:7.2f} {pose[2]:7.2f} {error:>8}  {kinds}")
    return "\n".join(lines)


def run_live(game: Path, out: Path, speed: float, lag_s: float, show: Callable[[str], None]) -> LiveResult:
    """Play `game` through one edge process per agent and a hub process; score the hub's recording."""
    session = read_description(game)
    venue = session.venue.name
    truth = read_tracks(game, lambda topic, name: name == "TruthPose").get("truth/pose", {})
    game_start = min((t.time_ns[0] for t in truth.values()), default=0)
    duration_s = max(((t.time_ns[-1] - t.time_ns[0]) * 1e-9 for t in truth.values()), default=0.0)
    endpoint = free_endpoint()
    recording = out / "hub.mcap"
    command = [sys.executable, "-m", "reckon.cli", "-q"]
    logs = out / "logs"
    logs.mkdir(parents=True, exist_ok=True)

    def spawn(name: str, arguments: list[str]) -> subprocess.Popen:
        with open(logs / f"{name}.log", "wb") as log_file:  # each process's summary and warnings
            return subprocess.Popen(command + arguments, stdout=log_file, stderr=subprocess.STDOUT)

    started = time.monotonic()
    hub = spawn("hub", ["hub", "--venue", str(game), "--listen", endpoint, "-o", str(recording), "--lag", str(lag_s)])
    edges: list[subprocess.Popen] = []
    try:
        with open_session(zenoh_config(connect=[endpoint])) as bus:
            wait_for_peers(bus, wire.alive_selector(venue, wire.Role.HUB), 1, 30.0)
            start_at = time.time() + START_DELAY_S
            for agent in session.agents:
                edges.append(spawn(f"edge-{agent.id}", [
                    "edge", "--agent", agent.id, "--source", f"mcap://{game}", "--speed", str(speed),
                    "--start-at", f"{start_at:.6f}", "--connect", endpoint]))
            view = CourtView(bus, venue)
            last = 0.0
            while any(edge.poll() is None for edge in edges):
                time.sleep(0.05)  # a screen refresh, not a wait for a condition
                view.drain()
                if time.monotonic() - last >= TABLE_EVERY_S:
                    last = time.monotonic()
                    show(table(session, view, truth, game_start, duration_s, (time.time() - start_at) * speed))
            view.drain()
            show(table(session, view, truth, game_start, duration_s, duration_s))
            view.close()
        failed = [agent.id for agent, edge in zip(session.agents, edges) if edge.returncode != 0]
        if failed:
            raise ReckonError(f"demo: the edge of {', '.join(failed)} failed; see {logs}/edge-<agent>.log")
    finally:
        for edge in edges:
            if edge.poll() is None:
                edge.send_signal(signal.SIGINT)
        hub.send_signal(signal.SIGINT)
        hub.wait(60)
    if hub.returncode != 0:
        raise ReckonError(f"demo: the hub exited with {hub.returncode}; see {logs / 'hub.log'}")
    wall_s = time.monotonic() - started
    tracks = read_tracks(recording, lambda topic, name: name == "EstimatedPose")
    result = LiveResult({}, wall_s=wall_s, game_s=duration_s)
    for _, _, correction in LogMessages(recording, lambda topic, name: name == "Correction"):
        kinds = result.corrections.setdefault(correction.agent_id, {})
        kind = messages.CorrectionKind(correction.kind).name.lower()
        kinds[kind] = kinds.get(kind, 0) + 1
    for track in ("live", "refined"):
        result.mean_error_m[track], result.per_agent[track] = score(truth, tracks.get(f"pose/{track}", {}))
    return result
