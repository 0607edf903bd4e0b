"""`reckon bench load`: one real `reckon hub` with hundreds of simulated chairs at 50 Hz (docs/benchmarks.md).

Three processes on loopback Zenoh besides this one, which only starts them, samples /proc and
reads their results:
- the hub: `reckon hub --venue <500 chairs>`, as a venue runs it;
- a load generator (`python -m reckon.bench.load generate`): what the chairs' edges would send.
  EstimatedPose at `rate_hz` per chair, ImpactEvents in pairs when two chairs touch, BeaconSightings
  of its court's two goal beacons, DeviceStatus at 1 Hz. It takes the hub's corrections back as an
  edge would (acknowledges them in `correction_sequence` and moves its estimate by the Kalman
  shift), so the hub's pending shifts stay as short as in a real game;
- a watcher (`python -m reckon.bench.load watch`): every `pose/live` the hub publishes, stamped
  on arrival.

Latency: for each chair pose, its live pose's arrival at the watcher minus the instant the
generator put it (both wall clock on this machine), paired by agent and pose time (the hub copies
the time: without raw ImuBatch streams its clock offsets are 0).

The venue: 50 courts of 10 chairs (28 x 15 m, a FIBA court each, gaps of 4 m), one hub. Ten chairs
per court keeps each chair's neighbours, and so its contact and beacon rates, those of a real game;
one hub for all 500 is the hard case: one subscription, one collision-pairing watermark over
every chair. Motion is three sinusoids per axis and chair (0.02-0.10 Hz, up to ~5 m/s), computed
for all chairs at once each tick; a contact is two chairs of a court coming within 0.9 m.
Edges are not phase-aligned: chair i publishes in slot i % PHASES of each pose period.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from protocol import bus as wire
from protocol import keys, messages
from protocol.errors import ReckonError
from protocol.session import Agent, Beacon, Mount, Sensor, Session, Venue
from protocol.session_log import SessionWriter
from reckon.bench.pipeline import _Child, _percentiles, _system_busy_s, machine_info

VENUE = "load"
COURT_AGENTS = 10
COURTS_PER_ROW = 10
COURT_LENGTH_M, COURT_WIDTH_M, COURT_GAP_M = 28.0, 15.0, 4.0
BASKET_INSET_M = 1.575  # FIBA: backboard 1.2 m in, ring centre 0.375 m further
MAX_AGENTS = 2500  # 25 rows of courts: the venue file's 500 m limit
PHASES = 10  # publishing slots per pose period
CONTACT_M = 0.9  # two chair discs of 0.45 m touching (sim_devices/wheelchair)
POSE_VARIANCE_M2 = 0.25  # what the edges report: a few metres of drift are corrected every 10-30 s
HEADING_VARIANCE_RAD2 = 0.01
DRIFT_M_PER_TICK = 0.02  # random walk of each estimate: 0.14 m/sqrt(s) at 50 Hz
BEACON_HEARD_HZ = 7.0  # 10 Hz advertising x 0.7 scan efficiency (sim_devices/wheelchair/params.py)
PATH_LOSS_EXPONENT, RSSI_SD_DB, SENSITIVITY_DBM, TX_POWER_DBM = 2.2, 4.5, -95.0, -59.0
BEACON_HEIGHT_M, RECEIVER_HEIGHT_M = 2.9, 0.5
STARTUP_S = 8.0  # start_at: the hub, the generator and the watcher importing and connecting on 2 cores
WARMUP_S = 5.0  # left out of the steady-state window and of the percentiles
END_MARGIN_S = 1.0
DRAIN_TIMEOUT_S = 60.0
KEPT_UP_MS = 1000.0  # the generator never this far behind its schedule: the hub took the load as it came  # after the generator is done, for the hub to catch up
FIFO_CAPACITY = 65536  # the watcher's Zenoh FIFO: a few seconds of live poses
SUMMARY = re.compile(r"(\d+) messages in, (\d+) out, (\d+) corrections \((\d+) collision pairs\), "
                     r"(\d+) samples skipped, queue full (\d+) times")


@dataclass(frozen=True)
class LoadSpec:
    agents: int = 500
    rate_hz: float = 50.0
    duration_s: float = 60.0
    seed: int = 1
    start_at_ns: int = 0  # wall clock of the first pose period
    hub_endpoint: str = ""
    watcher_endpoint: str = ""

    def __post_init__(self) -> None:
        if not 2 <= self.agents <= MAX_AGENTS:
            raise ReckonError(f"bench load: --agents {self.agents} must be 2-{MAX_AGENTS} (courts of {COURT_AGENTS})")
        if not 1.0 <= self.rate_hz <= 200.0:
            raise ReckonError(f"bench load: --rate {self.rate_hz:g} Hz must be 1-200")
        if self.duration_s < 1.0:
            raise ReckonError(f"bench load: --duration {self.duration_s:g} s must be at least 1")

    @property
    def period_ns(self) -> int:
        return int(round(1e9 / self.rate_hz))

    @property
    def ticks(self) -> int:
        return int(self.duration_s * self.rate_hz)

    def agent_id(self, index: int) -> str:
        return f"c{index // COURT_AGENTS:02d}-{index % COURT_AGENTS}"

    def phase_ns(self) -> np.ndarray:
        return (np.arange(self.agents) % PHASES) * (self.period_ns // PHASES)


# ---------------------------------------------------------------------------------------------
# The venue and the chairs' motion


def court_origins(agents: int) -> np.ndarray:
    courts = -(-agents // COURT_AGENTS)
    index = np.arange(courts)
    return np.stack([(index % COURTS_PER_ROW) * (COURT_LENGTH_M + COURT_GAP_M),
                     (index // COURTS_PER_ROW) * (COURT_WIDTH_M + COURT_GAP_M)], axis=1)


def load_session(spec: LoadSpec) -> Session:
    origins = court_origins(spec.agents)
    beacons = tuple(Beacon(f"c{c:02d}-goal-{end}", float(x0 + inset), float(y0 + COURT_WIDTH_M / 2), 1.0,
                           TX_POWER_DBM, BEACON_HEIGHT_M)
                    for c, (x0, y0) in enumerate(origins)
                    for end, inset in (("a", BASKET_INSET_M), ("b", COURT_LENGTH_M - BASKET_INSET_M)))
    rows = -(-len(origins) // COURTS_PER_ROW)
    venue = Venue(VENUE, min(len(origins), COURTS_PER_ROW) * (COURT_LENGTH_M + COURT_GAP_M),
                  rows * (COURT_WIDTH_M + COURT_GAP_M), beacons)
    agents = []
    for i in range(spec.agents):
        agent_id = spec.agent_id(i)
        agents.append(Agent(agent_id, sensors=(
            Sensor(f"{agent_id}-l", Mount.LEFT_WHEEL, spin_axis="+z"), Sensor(f"{agent_id}-r", Mount.RIGHT_WHEEL,
                                                                               spin_axis="-z"),
            Sensor(f"{agent_id}-s", Mount.SEAT, forward_axis="+x", left_axis="+y"))))
    return Session(venue, tuple(agents), {"bench": "load", **asdict(spec)})


class Motion:
    """Every chair's true position at a time: its court's centre plus three sinusoids per axis."""

    def __init__(self, agents: int, rng: np.random.Generator):
        centre = court_origins(agents)[np.arange(agents) // COURT_AGENTS] + [COURT_LENGTH_M / 2, COURT_WIDTH_M / 2]
        self.centre = centre  # agents x 2
        reach = np.array([COURT_LENGTH_M / 2 - 1.0, COURT_WIDTH_M / 2 - 1.0])[None, :, None]
        self.amplitude = reach * rng.dirichlet(np.ones(3), size=(agents, 2))
        self.omega = 2 * np.pi * rng.uniform(0.02, 0.10, size=(agents, 2, 3))
        self.phase = rng.uniform(0, 2 * np.pi, size=(agents, 2, 3))

    def at(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(xy agents x 2 in m, heading rad) at `t_s`."""
        angle = self.omega * t_s + self.phase
        xy = self.centre + (self.amplitude * np.sin(angle)).sum(axis=2)
        velocity = (self.amplitude * self.omega * np.cos(angle)).sum(axis=2)
        return xy, np.arctan2(velocity[:, 1], velocity[:, 0])


def contacts(xy: np.ndarray, touching: np.ndarray) -> tuple[list[tuple[int, int]], np.ndarray]:
    """Pairs of chairs of one court that came within CONTACT_M since the last call, and who touches now."""
    padded = np.full((touching.shape[0] * COURT_AGENTS, 2), np.nan)
    padded[:len(xy)] = xy
    courts = padded.reshape(-1, COURT_AGENTS, 2)
    distance = np.linalg.norm(courts[:, :, None, :] - courts[:, None, :, :], axis=3)
    now = np.triu(distance < CONTACT_M, k=1)  # NaN (an empty seat of the last court) compares False
    court, a, b = np.nonzero(now & ~touching)
    return [(int(c * COURT_AGENTS + i), int(c * COURT_AGENTS + j)) for c, i, j in zip(court, a, b)], now


# ---------------------------------------------------------------------------------------------
# The generator process


def generate(spec: LoadSpec, out: Path) -> None:
    """Publish the chairs' streams from `spec.start_at_ns` for `spec.duration_s`; write what was put when."""
    import zenoh

    from reckon.transport.bus import Publisher, flush, open_session, wait_for_peers, zenoh_config

    session = load_session(spec)
    rng = np.random.default_rng(spec.seed)
    motion = Motion(spec.agents, rng)
    ids = [a.id for a in session.agents]
    index = {agent_id: i for i, agent_id in enumerate(ids)}
    seat = [f"{agent_id}-s" for agent_id in ids]
    beacon_xy = np.array([[b.x_m, b.y_m] for b in session.venue.beacons])
    beacon_ids = [b.id for b in session.venue.beacons]
    own_beacons = np.stack([2 * (np.arange(spec.agents) // COURT_AGENTS), 2 * (np.arange(spec.agents) // COURT_AGENTS) + 1], 1)
    poses = [messages.new("EstimatedPose", agent_id=a, method="reckon", track=messages.Track.LIVE,
                          covariance=[POSE_VARIANCE_M2, 0, 0, 0, POSE_VARIANCE_M2, 0, 0, 0, HEADING_VARIANCE_RAD2])
             for a in ids]
    pose_keys = [keys.pose(VENUE, a, "edge") for a in ids]
    pose_encoding = wire.encoding_for("EstimatedPose")
    period_ns, phase_ns, ticks = spec.period_ns, spec.phase_ns(), spec.ticks
    put_ns = np.zeros((ticks, spec.agents), dtype=np.int64)
    offset = np.zeros((spec.agents, 2))  # the corrections taken so far
    acknowledged = np.zeros(spec.agents, dtype=np.int64)
    drift = np.zeros((spec.agents, 2))
    touching = np.zeros((-(-spec.agents // COURT_AGENTS), COURT_AGENTS, COURT_AGENTS), dtype=bool)
    counts = {"poses": 0, "impacts": 0, "sightings": 0, "statuses": 0, "contacts": 0, "corrections_taken": 0}
    taken_by_kind: dict[str, int] = {}
    corrections: queue.SimpleQueue[bytes] = queue.SimpleQueue()  # unbounded: tens a second
    slots = [np.arange(s, spec.agents, PHASES) for s in range(PHASES)]
    config = zenoh_config(connect=[spec.hub_endpoint, spec.watcher_endpoint])
    with open_session(config) as bus, Publisher(bus) as publisher:
        subscriber = bus.declare_subscriber(keys.all_agents(VENUE, "correction"),
                                            lambda sample: corrections.put(sample.payload.to_bytes()))
        try:
            wait_for_peers(bus, [wire.alive_selector(VENUE, wire.Role.HUB),
                                 wire.alive_selector(VENUE, wire.Role.RECORDER)], 2, 120.0)
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
                rssi = _rssi(truth, beacon_xy[own_beacons], rng)
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
                            publisher.publish(keys.impact(VENUE, ids[i]), messages.new(
                                "ImpactEvent", timestamp_ns=impacted[i], agent_id=ids[i], sensor_id=seat[i],
                                peak_g=float(rng.uniform(7.0, 14.0))))
                            counts["impacts"] += 1
                        for end in np.flatnonzero(heard[i] & (rssi[i] >= SENSITIVITY_DBM)).tolist():
                            publisher.publish(keys.beacon(VENUE, ids[i], seat[i]), messages.new(
                                "BeaconSighting", timestamp_ns=pose.timestamp_ns, agent_id=ids[i], sensor_id=seat[i],
                                beacon_id=beacon_ids[own_beacons[i, end]], rssi_dbm=float(rssi[i, end])))
                            counts["sightings"] += 1
                        if status_tick:
                            publisher.publish(keys.status(VENUE, ids[i], seat[i]), messages.new(
                                "DeviceStatus", timestamp_ns=pose.timestamp_ns, agent_id=ids[i], sensor_id=seat[i],
                                connected=True, battery_pct=-1.0, last_sample_age_s=0.01,
                                samples=tick * 600 // int(spec.rate_hz)))
                            counts["statuses"] += 1
                counts["poses"] += spec.agents
            answered = flush(bus, wire.alive_selector(VENUE, wire.Role.HUB), 30.0)
            if not answered:
                raise ReckonError("bench load generator: the hub did not answer the flush barrier within 30 s")
        finally:
            subscriber.undeclare()
    counts["corrections_taken"] = sum(taken_by_kind.values())
    np.save(out / "put_ns.npy", put_ns)
    (out / "generator.json").write_text(json.dumps({
        **counts, "corrections_by_kind": taken_by_kind, "late_start_s": late_s, "max_behind_ms": behind_ns * 1e-6,
        "zenoh": zenoh.__version__ if hasattr(zenoh, "__version__") else None}))


def _rssi(truth: np.ndarray, beacons: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """RSSI (dBm) of each chair's two goal beacons: log-distance path loss plus shadowing and fading."""
    horizontal = np.linalg.norm(beacons - truth[:, None, :], axis=2)
    slant = np.sqrt(horizontal**2 + (BEACON_HEIGHT_M - RECEIVER_HEIGHT_M) ** 2)
    return np.round(TX_POWER_DBM - 10 * PATH_LOSS_EXPONENT * np.log10(slant) + rng.normal(0, RSSI_SD_DB, slant.shape))


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


# ---------------------------------------------------------------------------------------------
# The watcher process


def watch(spec: LoadSpec, out: Path) -> None:
    """Stamp the arrival of every live pose until all are in or SIGINT/SIGTERM; write them."""
    import zenoh

    from reckon.transport.bus import Alive, open_session, source_ns, zenoh_config

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    index = {spec.agent_id(i): i for i in range(spec.agents)}
    phase_ns, period_ns, ticks = spec.phase_ns(), spec.period_ns, spec.ticks
    received_ns = np.zeros((ticks, spec.agents), dtype=np.int64)
    published_ns = np.zeros((ticks, spec.agents), dtype=np.int64)  # the hub's Zenoh timestamp
    tally = {"live": 0, "duplicates": 0, "strays": 0}
    expected = ticks * spec.agents

    def drain(handler: Any) -> None:
        decode = messages.EstimatedPose.FromString
        for sample in handler:
            arrived = time.time_ns()
            pose = decode(sample.payload.to_bytes())
            i = index.get(pose.agent_id)
            tick = -1 if i is None else (pose.timestamp_ns - spec.start_at_ns - int(phase_ns[i])) // period_ns
            if not 0 <= tick < ticks:
                tally["strays"] += 1
                continue
            if received_ns[tick, i]:
                tally["duplicates"] += 1
                continue
            received_ns[tick, i] = arrived
            published_ns[tick, i] = source_ns(sample) or 0
            tally["live"] += 1
            if tally["live"] == expected:
                stop.set()

    with open_session(zenoh_config(listen=[spec.watcher_endpoint], connect=[spec.hub_endpoint])) as bus:
        subscriber = bus.declare_subscriber(keys.all_agents(VENUE, "pose/live"), zenoh.handlers.FifoChannel(FIFO_CAPACITY))
        thread = threading.Thread(target=drain, args=(subscriber.handler,), daemon=True)
        thread.start()
        with Alive(bus, VENUE, wire.Role.RECORDER, "bench-watcher"):
            while not stop.wait(0.2):
                pass
        subscriber.undeclare()
        thread.join(5.0)
    np.save(out / "received_ns.npy", received_ns)
    np.save(out / "hub_published_ns.npy", published_ns)
    (out / "watcher.json").write_text(json.dumps(tally))


# ---------------------------------------------------------------------------------------------
# The run: start the three processes, sample them, read their results


class _Helper(_Child):
    """A generator or watcher process of this module, watched like bench's `reckon` children."""

    def __init__(self, role: str, spec_path: Path, out: Path, log_path: Path):
        self.name, self.log_path = role, log_path
        with open(log_path, "wb") as log_file:
            self.process = subprocess.Popen([sys.executable, "-m", "reckon.bench.load", role, str(spec_path), str(out)],
                                            stdout=log_file, stderr=subprocess.STDOUT)
        self.exited = None
        self.peak_kb = 0


def vm_kb(pid: int, field: str) -> int:
    """One `Vm...` line of /proc/<pid>/status in kB (VmRSS now, VmHWM the peak); 0 once it has exited."""
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def thread_cpu_s(pid: int) -> dict[str, float]:
    """CPU seconds (utime + stime) of a process's threads by name, numbers dropped: Zenoh's runtime
    threads (`rx`, `tx`, `net`, `app`, `acc`) apart from Python's (`python`: the main thread and
    any Python thread, which all keep the process's name); {} once it has exited."""
    out: dict[str, float] = {}
    tick = os.sysconf("SC_CLK_TCK")
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return out
    for task in tasks:
        try:
            text = Path(f"/proc/{pid}/task/{task}/stat").read_text()
        except OSError:
            continue
        name = re.sub(r"-\d+$", "", text[text.index("(") + 1:text.rindex(")")])
        fields = text[text.rindex(")") + 2:].split()
        out[name] = out.get(name, 0.0) + (int(fields[11]) + int(fields[12])) / tick
    return out


def run_load(out: Path, agents: int = 500, rate_hz: float = 50.0, duration_s: float = 60.0, seed: int = 1,
             progress: Callable[[str], None] = print, record: bool = False) -> dict[str, Any]:
    """Run the hub under `agents` chairs' load for `duration_s`; the numbers (JSON-able).

    Keys: hub_cpu_cores, latency_ms {p50, p99, max}, rss_mb {hub, hub_peak}, dropped, skipped,
    corrections, machine, details. ReckonError when a process fails (logs in `out`/logs).
    """
    from reckon.tools.demo import free_endpoint

    out = Path(out)
    logs = out / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    for stale in ("generator.started", "put_ns.npy", "received_ns.npy", "generator.json", "watcher.json"):
        (out / stale).unlink(missing_ok=True)
    machine = machine_info()
    spec = LoadSpec(agents, rate_hz, duration_s, seed, int((time.time() + STARTUP_S) * 1e9), free_endpoint(),
                    free_endpoint())
    venue_file, spec_path = out / "venue.mcap", out / "spec.json"
    with SessionWriter(venue_file, load_session(spec)):
        pass
    spec_path.write_text(json.dumps(asdict(spec)))
    warmup_s, margin_s = min(WARMUP_S, duration_s / 4), min(END_MARGIN_S, duration_s / 10)
    progress(f"bench load: {agents} chairs at {rate_hz:g} Hz for {duration_s:g} s "
             f"({-(-agents // COURT_AGENTS)} courts), hub + generator + watcher on loopback Zenoh")
    hub = _Child("hub", ["hub", "--venue", str(venue_file), "--listen", spec.hub_endpoint, "--pose-rate", repr(rate_hz),
                         *(["-o", str(out / "hub.mcap")] if record else [])], logs / "hub.log")
    watcher = _Helper("watch", spec_path, out, logs / "watcher.log")
    generator = _Helper("generate", spec_path, out, logs / "generator.log")
    children = {"hub": hub, "generator": generator, "watcher": watcher}
    rss_mb: list[tuple[float, float]] = []  # (s since the first pose, the hub's VmRSS)
    try:
        started = out / "generator.started"
        while not started.exists():
            _check_running(children)
            time.sleep(0.05)
        first_ns = max(spec.start_at_ns, int(started.read_text()))
        window = (first_ns * 1e-9 + warmup_s, first_ns * 1e-9 + duration_s - margin_s)
        at_start: dict[str, float] = {}
        at_end: dict[str, float] = {}
        next_sample = time.time()
        while generator.poll() is None:
            now = time.time()
            if now >= next_sample:
                rss_mb.append((now - first_ns * 1e-9, vm_kb(hub.process.pid, "VmRSS") / 1024))
                next_sample += 1.0
            if not at_start and now >= window[0]:
                at_start = _cpu_now(children, now)
            if at_start and not at_end and now >= window[1]:
                at_end = _cpu_now(children, now)
            _check_running({"hub": hub, "watcher": watcher}, may_finish="watcher")  # done once it saw every pose
            time.sleep(0.02)
        if generator.exited.returncode != 0 or not at_end:
            raise ReckonError(f"bench load: the generator exited with {generator.exited.returncode} "
                              f"before the window's end; see {generator.log_path}")
        progress("bench load: generator done; waiting for the watcher to see every live pose")
        deadline = time.monotonic() + DRAIN_TIMEOUT_S
        while watcher.poll() is None and time.monotonic() < deadline:
            hub.poll()
            time.sleep(0.05)
    finally:
        for child in children.values():
            child.interrupt()
        for child in children.values():
            child.reap(DRAIN_TIMEOUT_S)
    for child in children.values():
        if child.exited.returncode != 0:
            raise ReckonError(f"bench load: {child.name} exited with {child.exited.returncode}; see {child.log_path}")
    result = _results(out, spec, hub, children, at_start, at_end, rss_mb, warmup_s, margin_s)
    machine["load_average_at_end"] = list(os.getloadavg())
    result["machine"] = machine
    return result


def _check_running(children: dict[str, _Child], may_finish: str = "") -> None:
    for name, child in children.items():
        exited = child.poll()
        if exited is not None and not (name == may_finish and exited.returncode == 0):
            raise ReckonError(f"bench load: {name} exited early with {exited.returncode}; see {child.log_path}")


def _cpu_now(children: dict[str, _Child], now: float) -> dict[str, Any]:
    return {"wall": now, "machine_busy": _system_busy_s(), "bench_process": time.process_time(),
            "hub_threads": thread_cpu_s(children["hub"].process.pid),
            **{name: child.cpu_s() for name, child in children.items()}}


def hub_summary(log_path: Path) -> dict[str, int]:
    """The counters of the hub's last summary line (reckon/processes/hub.py HubSummary)."""
    found = SUMMARY.findall(log_path.read_text(errors="replace"))
    if not found:
        raise ReckonError(f"bench load: no hub summary in {log_path}")
    names = ("inputs", "outputs", "corrections", "pairs", "skipped", "full_waits")
    return dict(zip(names, (int(v) for v in found[-1])))


def _results(out: Path, spec: LoadSpec, hub: _Child, children: dict[str, _Child], at_start: dict[str, float],
             at_end: dict[str, float], rss_mb: list[tuple[float, float]], warmup_s: float,
             margin_s: float) -> dict[str, Any]:
    from reckon.processes.hub import INPUTS

    generated = json.loads((out / "generator.json").read_text())
    watched = json.loads((out / "watcher.json").read_text())
    summary = hub_summary(hub.log_path)
    put, received, hub_put = (np.load(out / f"{name}.npy") for name in ("put_ns", "received_ns", "hub_published_ns"))
    sent, seen = put > 0, received > 0
    first, last = math.ceil(warmup_s * spec.rate_hz), spec.ticks - math.ceil(margin_s * spec.rate_hz)
    steady = np.zeros_like(sent)
    steady[first:last] = True
    both = sent & seen & steady
    stamped = both & (hub_put > 0)
    subscribed_status = any(stream.startswith("status") for stream in INPUTS)
    hub_expected = (generated["poses"] + generated["impacts"] + generated["sightings"]
                    + (generated["statuses"] if subscribed_status else 0))
    lost_live = int((sent & ~seen).sum())
    wall_s = at_end["wall"] - at_start["wall"]
    cores = {name: (at_end[name] - at_start[name]) / wall_s for name in ("hub", "generator", "watcher", "bench_process")}
    cores["other_processes"] = (at_end["machine_busy"] - at_start["machine_busy"]) / wall_s - sum(cores.values())
    steady_rss = [mb for t, mb in rss_mb if warmup_s <= t <= spec.duration_s - margin_s] or [mb for _, mb in rss_mb]
    # The inputs the hub took in the window: its live poses that reached the watcher in it, times
    # the hub's inputs per live pose (poses plus sightings and impacts).
    in_window = int(((received >= at_start["wall"] * 1e9) & (received < at_end["wall"] * 1e9)).sum())
    window_inputs = in_window * summary["inputs"] / max(1, watched["live"])
    threads = {name: (at_end["hub_threads"].get(name, 0.0) - used) / wall_s
               for name, used in at_start["hub_threads"].items()}
    hub_cpu_s = cores["hub"] * wall_s
    return {
        "agents": spec.agents, "rate_hz": spec.rate_hz, "duration_s": spec.duration_s,
        "hub_cpu_cores": cores["hub"],
        # CPU per input: robust where the share of the cores is not (the machine is shared)
        "hub_cpu_us_per_input": hub_cpu_s / window_inputs * 1e6 if window_inputs else None,
        # False: the hub's back-pressure held the generator back, so hub_cpu_cores is what the hub
        # manages on this machine (its ceiling), not what the load costs, and latency grows with the lag
        "kept_up": generated["max_behind_ms"] <= KEPT_UP_MS,
        "latency_ms": {key: value for key, value in _percentiles(((received - put)[both] * 1e-6).tolist()).items()
                       if key != "count"},
        "rss_mb": {"hub": steady_rss[-1], "hub_peak": hub.exited.max_rss_mb},
        "dropped": max(0, hub_expected - summary["inputs"]) + lost_live,
        "skipped": summary["skipped"],
        "corrections": {"total": summary["corrections"], "pairs": summary["pairs"],
                        "taken_by_kind": generated["corrections_by_kind"]},
        "details": {
            "targets": {"hub_cpu_cores": 1.0, "latency_p99_ms": 50.0},
            "window_s": wall_s, "cpu_cores": cores,
            "hub_threads_cpu_cores": {name: round(v, 4) for name, v in sorted(threads.items(), key=lambda kv: -kv[1])},
            "hub_inputs_in_window": round(window_inputs),
            "hub_cpu_us_per_input_whole_run": hub.exited.cpu_s / max(1, summary["inputs"]) * 1e6,
            "cpu_s_whole_run": {name: child.exited.cpu_s for name, child in children.items()},
            "generated": generated, "hub_expected_inputs": hub_expected, "hub": summary, "watched": watched,
            "lost_live_poses": lost_live, "poses_in_percentiles": int(both.sum()),
            "latency_parts_ms": {
                "generator_put_to_hub_publish": _percentiles(((hub_put - put)[stamped] * 1e-6).tolist()),
                "hub_publish_to_watcher": _percentiles(((received - hub_put)[stamped] * 1e-6).tolist())},
            "hub_rss_mb_steady": {"first": steady_rss[0], "last": steady_rss[-1], "max": max(steady_rss)},
            "hub_rss_mb_curve": [[round(t, 1), round(mb, 1)] for t, mb in rss_mb],
            "peak_rss_mb": {name: child.exited.max_rss_mb for name, child in children.items()},
            "statuses_reach_hub": subscribed_status, "warmup_s": warmup_s,
        },
    }


def format_load(result: dict[str, Any]) -> str:
    d, m = result["details"], result["machine"]
    cores, lat = d["cpu_cores"], result["latency_ms"]
    parts = d["latency_parts_ms"]

    def verdict(ok: bool) -> str:
        return "met" if ok else "NOT met"

    lag_s = d["generated"]["max_behind_ms"] * 1e-3
    keeping = ("the hub kept up" if result["kept_up"] else
               f"the hub did NOT keep up: its back-pressure put the generator up to {lag_s:.0f} s behind, so the CPU "
               "share is the hub's ceiling here, not the load's cost")
    return "\n".join([
        f"reckon bench load: {result['agents']} chairs at {result['rate_hz']:g} Hz, {result['duration_s']:g} s; "
        f"{m['cpu']}, {m['cores']} cores, Python {m['python']}",
        f"hub CPU                 {result['hub_cpu_cores']:6.2f} cores    target <= 1     "
        f"{verdict(result['hub_cpu_cores'] <= 1.0 and result['kept_up'])}   (over {d['window_s']:.0f} s of steady state)",
        f"  {keeping}",
        f"  {result['hub_cpu_us_per_input'] or math.nan:.1f} µs of hub CPU per input in the window "
        f"({d['hub_inputs_in_window'] / d['window_s']:,.0f} inputs/s; whole run "
        f"{d['hub_cpu_us_per_input_whole_run']:.1f} µs); threads "
        + ", ".join(f"{name} {v:.2f}" for name, v in d['hub_threads_cpu_cores'].items() if v >= 0.005) + " cores",
        f"  generator {cores['generator']:.2f}, watcher {cores['watcher']:.2f}, this process "
        f"{cores['bench_process']:.2f}, other processes {cores['other_processes']:.2f} cores (same 2 cores)",
        f"latency p50 / p99 / max {lat['p50']:6.1f} / {lat['p99']:.1f} / {lat['max']:.1f} ms   target p99 <= 50 ms  "
        f"{verdict(lat['p99'] <= 50.0)}",
        f"  generator put -> hub publish p99 {parts['generator_put_to_hub_publish']['p99']:.1f} ms, "
        f"hub -> watcher p99 {parts['hub_publish_to_watcher']['p99']:.1f} ms; {d['poses_in_percentiles']} poses",
        f"hub RSS                 {result['rss_mb']['hub']:6.0f} MiB (peak {result['rss_mb']['hub_peak']:.0f})",
        f"dropped {result['dropped']}, skipped {result['skipped']}, hub queue full {d['hub']['full_waits']} times; "
        f"{result['corrections']['total']} corrections ({result['corrections']['pairs']} collision pairs; taken "
        + ", ".join(f"{k} {v}" for k, v in sorted(result["corrections"]["taken_by_kind"].items())) + ")",
        f"sent: {d['generated']['poses']} poses, {d['generated']['impacts']} impacts, "
        f"{d['generated']['sightings']} sightings, {d['generated']['statuses']} statuses; generator at most "
        f"{d['generated']['max_behind_ms']:.1f} ms behind its schedule",
    ])


def main(argv: list[str]) -> int:
    """The generator and watcher processes: `python -m reckon.bench.load generate|watch SPEC.json OUT`."""
    parser = argparse.ArgumentParser(prog="python -m reckon.bench.load")
    parser.add_argument("role", choices=("generate", "watch"))
    parser.add_argument("spec", type=Path)
    parser.add_argument("out", type=Path)
    args = parser.parse_args(argv)
    spec = LoadSpec(**json.loads(args.spec.read_text()))
    (generate if args.role == "generate" else watch)(spec, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
