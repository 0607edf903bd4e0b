"""`reckon bench`: how fast the live path runs on this machine, measured in one run (docs/benchmarks.md).

1. `edge_samples_per_s`: the chair filter's compiled batch (`edge.chair.kernel.run_batch`) over
   one chair's merged samples, repeated to >= 10^6 samples, best of 3, one core. The whole edge
   computation (`ChairEdge.push`: merger, kernel calls per pose, messages) is in `details.edge`.
2. `pipeline_realtime_factor`: game seconds / wall seconds of `players` `reckon edge` processes
   and one `reckon hub` on loopback Zenoh, unpaced. The edges start together (`--start-at`, after
   every one is up), and the clock stops when the hub published the live pose of the last edge
   pose it was sent, read from the hub's own recording (`hub.mcap`: inputs are logged at their
   arrival, outputs when published).
3. `latency_ms`: a paced replay (real time by default) watched from this process: for each live
   pose of the hub, its arrival here minus the arrival here of the raw ImuBatch whose push made
   the edge emit the pose (the batch that completed the pose's inputs). So it is the processing
   path edge -> Zenoh -> hub -> Zenoh, not the sensors' batching or the wait for the next pose tick.
4. `rss_mb`: peak resident memory (VmHWM, read from /proc while they run) of the largest edge
   process and of the hub, in the unpaced pipeline run. MiB.

`details` holds what explains them: CPU seconds per process, the hub's Python cost per message
(its recorded inputs fed again to a ChairHub), the edge's per game second. docs/benchmarks.md.
"""

from __future__ import annotations

import bisect
import importlib.metadata
import math
import os
import platform
import queue
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
from mcap.records import Channel, Message, Schema

from edge.chair import kernel
from edge.chair.edge import ChairEdge
from edge.chair.estimator import start
from edge.chair.merger import ChairMerger
from hub.chair.hub import ChairHub
from protocol import bus as wire
from protocol import keys, messages
from protocol.errors import ReckonError
from protocol.session import Mount, Session
from protocol.session_log import LogMessages, SessionWriter, iter_records, read_description, read_session
from reckon.transport.bus import Received, Subscription, open_session, wait_for_peers, zenoh_config
from reckon.tools.demo import free_endpoint
from reckon.processes.edge import mcap_source
from reckon.evaluation.inputs import build_inputs
from reckon.evaluation.reckon_run import merged_samples
from sim_devices.wheelchair import simulate

TARGETS = {"edge_samples_per_s": 1_000_000, "pipeline_realtime_factor": 100.0, "latency_p99_ms": 5.0}
KERNEL_SAMPLES = 1_000_000  # run_batch is timed over at least this many samples
REPEATS = 3  # best of
UNPACED_SPEED = 1e9  # `reckon edge --speed`: unpaced after `--start-at` (speed 0 would ignore --start-at)
LATENCY_S = 20.0  # game seconds of the paced run
LATENCY_SPEED = 1.0  # its pace, times real time
WARMUP_S = 2.0  # each agent's first poses of the paced run, left out of the percentiles (first numba call)
START_S_PER_EDGE = 0.5  # start-up allowance per edge process on 2 cores (imports, numba cache, zenoh)
EXIT_TIMEOUT_S = 300.0
POLL_S = 0.05  # how often the processes' peak RSS is read, and what arrived here is taken, while they run
SUBSCRIPTION_CAPACITY = 16384  # samples between two takes: ~1,300 a second arrive with 10 chairs
HUB_INPUTS = ("imu", "beacon", "pose/edge", "event", "fix")


# ---------------------------------------------------------------------------------------------
# The whole run


def run_bench(out: Path, players: int = 10, duration_s: float = 60.0, seed: int = 1,
              progress: Callable[[str], None] = print, *, latency_players: int | None = None,
              latency_s: float = LATENCY_S, latency_speed: float = LATENCY_SPEED) -> dict[str, Any]:
    """Simulate a game into `out`, measure the four numbers, return them (JSON-able).

    Keys: edge_samples_per_s, pipeline_realtime_factor, latency_ms {p50, p99}, rss_mb {edge, hub},
    machine, details. The paced latency run replays its own game: `latency_players` chairs (default
    `players`) for min(latency_s, duration_s) s at `latency_speed` x real time.
    ReckonError if a process fails (its log is in `out`/<run>/logs).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    machine = machine_info()
    game = out / "game.mcap"
    progress(f"bench: simulating {players} chairs for {duration_s:g} s (seed {seed}) -> {game}")
    simulate(players, duration_s, seed, game)
    progress("bench: edge estimator (kernel and ChairEdge, one core)")
    edge = edge_throughput(game)
    progress(f"bench: pipeline, {players} edges + hub over Zenoh, unpaced")
    pipeline = pipeline_run(game, out / "pipeline", duration_s, edge["startup_cpu_s"]["first_call_s"])
    latency_game = out / "latency-game.mcap"
    latency_duration = min(latency_s, duration_s)
    latency_players = latency_players or players
    simulate(latency_players, latency_duration, seed, latency_game)
    progress(f"bench: latency, {latency_players} chairs for {latency_duration:g} s at {latency_speed:g} x real time")
    latency = latency_run(latency_game, out / "latency", latency_speed)
    latency["game_s"] = latency_duration
    progress("bench: the hub's per-message cost, from its recording")
    hub_cost = hub_profile(out / "pipeline" / "hub.mcap", read_description(game), out / "pipeline" / "rewrite.mcap")
    hub_inputs = sum(pipeline["hub_inputs"].values())
    hub_cost["cpu_per_input_in_run"] = 1e6 * pipeline["cpu_s"]["hub"] / max(1, hub_inputs)
    hub_cost["zenoh_and_rest_per_input"] = hub_cost["cpu_per_input_in_run"] - hub_cost["python_per_input"]
    per_game_s = 1e3 / duration_s
    edge_parts = dict(edge["process_ms_per_game_s"],
                      first_kernel_call=edge["startup_cpu_s"]["first_call_s"] * per_game_s)
    edge_in_run = pipeline["cpu_s"]["edges_total"] / players * per_game_s
    edge_cost = {"cpu_in_run": edge_in_run, **edge_parts, "zenoh_and_rest": edge_in_run - sum(edge_parts.values())}
    machine["load_average_at_end"] = list(os.getloadavg())
    return {
        "edge_samples_per_s": edge["kernel_samples_per_s"],
        "pipeline_realtime_factor": pipeline["realtime_factor"],
        "latency_ms": {"p50": latency["processing_ms"]["p50"], "p99": latency["processing_ms"]["p99"]},
        "rss_mb": {"edge": pipeline["rss_mb"]["edge_max"], "hub": pipeline["rss_mb"]["hub"]},
        "machine": machine,
        "details": {"players": players, "duration_s": duration_s, "seed": seed, "targets": TARGETS, "edge": edge,
                    "pipeline": pipeline, "latency": latency, "hub_cost_us": hub_cost,
                    "edge_process_cpu_ms_per_game_s": edge_cost},
    }


def format_table(result: dict[str, Any]) -> str:
    """The four numbers against their targets, with the details that explain them."""
    d, m = result["details"], result["machine"]
    edge, pipe, lat, hub = d["edge"], d["pipeline"], d["latency"], d["hub_cost_us"]
    factor, p99 = result["pipeline_realtime_factor"], result["latency_ms"]["p99"]

    def verdict(ok: bool) -> str:
        return "met" if ok else "NOT met"

    return "\n".join([
        f"reckon bench: {d['players']} chairs, {d['duration_s']:g} s game, seed {d['seed']}; {m['cpu']} "
        f"(family/model {m['cpu_family_model']}), {m['cores']} cores, Python {m['python']}",
        f"edge estimator (run_batch)     {result['edge_samples_per_s'] / 1e6:8.2f} M samples/s   target >= 1 M    "
        f"{verdict(result['edge_samples_per_s'] >= TARGETS['edge_samples_per_s'])}",
        f"  whole ChairEdge.push path    {edge['chair_edge']['chair_samples_per_s'] / 1e3:8.1f} k chair samples/s "
        f"({edge['chair_edge']['us_per_chair_sample']:.1f} us each, "
        f"merger {edge['merger']['us_per_chair_sample']:.1f} us)",
        f"pipeline (edges + hub, Zenoh)  {factor:8.1f} x real time     target >= 100 x  {verdict(factor >= 100)}",
        f"  CPU in the run: hub {pipe['cpu_s']['hub']:.1f} s, edges {pipe['cpu_s']['edges_total']:.1f} s; "
        "all cores busy "
        f"would give {pipe['cpu_bound_factor']:.1f} x; hub {hub['cpu_per_input_in_run']:.0f} us CPU per input "
        f"({hub['python_per_input']:.0f} us of it Python: decode, ChairHub, encode, record)",
        f"latency p50 / p99              {result['latency_ms']['p50']:5.2f} / {p99:.2f} ms    target p99 <= 5 ms "
        f"{verdict(p99 <= TARGETS['latency_p99_ms'])}",
        f"  from the seat sample's batch {lat['from_seat_batch_ms']['p50']:5.2f} / "
        f"{lat['from_seat_batch_ms']['p99']:.2f} ms "
        f"(includes the merger waiting for both wheels' batches); {lat['processing_ms']['count']} poses",
        f"peak RSS edge / hub            {result['rss_mb']['edge']:5.0f} / {result['rss_mb']['hub']:.0f} MiB",
    ])


def machine_info() -> dict[str, Any]:
    cpu = {}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            name, _, value = line.partition(":")
            if name.strip() in ("model name", "cpu family", "model", "cpu MHz") and name.strip() not in cpu:
                cpu[name.strip()] = value.strip()
    except OSError:
        pass
    versions = {}
    for package in ("numpy", "numba", "eclipse-zenoh", "protobuf", "mcap"):
        try:
            versions[package] = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            versions[package] = None
    return {"cpu": cpu.get("model name", platform.processor()),
            "cpu_family_model": f"{cpu.get('cpu family')}/{cpu.get('model')}", "cpu_mhz": cpu.get("cpu MHz"),
            "cores": len(os.sched_getaffinity(0)), "python": platform.python_version(),
            "platform": platform.platform(), "packages": versions, "load_average_at_start": list(os.getloadavg())}


# ---------------------------------------------------------------------------------------------
# 1. The edge estimator in one process


def _best_of(run: Callable[[], Any], repeats: int = REPEATS) -> float:
    best = math.inf
    for _ in range(repeats):
        began = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - began)
    return best


def edge_throughput(game: Path) -> dict[str, Any]:
    """The first chair of `game`: kernel samples/s, and the whole ChairEdge path with its parts."""
    agent_inputs = build_inputs(read_session(game)).agents[0]
    agent = agent_inputs.agent
    samples = merged_samples(agent_inputs)
    edge = ChairEdge(agent)
    state = kernel.pack_state(start(edge.settings, samples[0], agent.start_x_m, agent.start_y_m,
                                    agent.start_heading_rad))
    times, values = kernel.pack_samples(samples[1:])
    kernel.run_batch(edge.packed_settings, state, times[:2], values[:2])  # compiles, or loads the cache
    repeats = -(-KERNEL_SAMPLES // len(times))

    def kernel_loop() -> None:
        for _ in range(repeats):
            kernel.run_batch(edge.packed_settings, state, times, values)

    kernel_s = _best_of(kernel_loop)
    # as ChairEdge calls it: one call per pose (200 Hz seat, 50 Hz poses: 4 samples a call)
    seat_hz = (len(times) - 1) / max((times[-1] - times[0]) * 1e-9, 1e-9)
    per_pose = max(1, round(seat_hz * edge.period_ns * 1e-9))
    slices = [(times[i:i + per_pose], values[i:i + per_pose]) for i in range(0, len(times), per_pose)]

    def sliced_loop() -> None:
        vector = state
        for slice_times, slice_values in slices:
            vector, _ = kernel.run_batch(edge.packed_settings, vector, slice_times, slice_values)

    sliced_s = _best_of(sliced_loop)
    batches = [message for _, topic, message in LogMessages(
        game, lambda topic, name: name == "ImuBatch" and keys.parse(topic)[1] == agent.id)]
    raw_samples = sum(len(batch.sample_offset_ns) for batch in batches)

    def merger_loop() -> None:
        merger = ChairMerger(agent)
        for batch in batches:
            merger.push_batch(batch)
        merger.flush()

    def edge_loop() -> None:
        chair = ChairEdge(agent)
        for batch in batches:
            chair.push(batch)
        chair.flush()

    def source_loop() -> None:
        for _ in mcap_source(game, agent.id, 0.0, threading.Event()):
            pass

    merger_s = _best_of(merger_loop)
    edge_s = _best_of(edge_loop)
    source_s = _best_of(source_loop, 1)
    chair = ChairEdge(agent)
    produced = [out for batch in batches for out in chair.push(batch)] + chair.flush()
    outputs = len(produced)
    merged = chair.samples
    began = time.perf_counter()
    for message in [*batches, *produced]:  # what the edge publishes: every raw batch, every output
        wire.encode(message)
    encode_s = time.perf_counter() - began
    game_s = (times[-1] - times[0]) * 1e-9
    return {
        "agent": agent.id, "kernel_samples": repeats * len(times),
        "kernel_samples_per_s": repeats * len(times) / kernel_s,
        "kernel_per_pose_call": {"samples_per_call": per_pose, "samples_per_s": len(times) / sliced_s,
                                 "us_per_call": 1e6 * sliced_s / len(slices)},
        "chair_edge": {"batches": len(batches), "raw_samples": raw_samples, "chair_samples": merged, "outputs": outputs,
                       "chair_samples_per_s": merged / edge_s, "raw_samples_per_s": raw_samples / edge_s,
                       "us_per_chair_sample": 1e6 * edge_s / merged},
        "merger": {"chair_samples_per_s": merged / merger_s, "us_per_chair_sample": 1e6 * merger_s / merged,
                   "share_of_chair_edge": merger_s / edge_s},
        # an edge process's work per game second, besides Zenoh's own cost (ms of one core)
        "process_ms_per_game_s": {"replay_source": 1e3 * source_s / game_s, "chair_edge": 1e3 * edge_s / game_s,
                                  "encode": 1e3 * encode_s / game_s},
        "startup_cpu_s": startup_probe(),
    }


def startup_probe() -> dict[str, float]:
    """CPU seconds an edge process spends on its imports, and on its first kernel call (numba loads
    the compiled code from its cache then), measured in a fresh interpreter."""
    code = ("import time\n"
            "import numpy as np, zenoh, reckon.processes.edge\n"
            "from edge.chair import kernel as k\n"
            "from edge.chair.estimator import ChairSettings\n"
            "imported = time.process_time()\n"
            "k.run_batch(k.pack_settings(ChairSettings()), np.zeros(k.STATE_SIZE), np.zeros(0, np.int64),"
            " np.zeros((0, k.SAMPLE_WIDTH)))\n"
            "print(imported, time.process_time() - imported)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    if done.returncode != 0:
        raise ReckonError(f"bench: the start-up probe exited with {done.returncode}: {done.stderr.strip()[-300:]}")
    imports_s, first_call_s = (float(word) for word in done.stdout.split())
    return {"imports_s": imports_s, "first_call_s": first_call_s}


# ---------------------------------------------------------------------------------------------
# Edge and hub processes on loopback Zenoh


@dataclass
class Exited:
    returncode: int
    max_rss_mb: float  # VmHWM: the process's peak resident set, MiB
    cpu_s: float  # user + system, from wait4


class _Child:
    """A `reckon` subprocess whose peak RSS is read from /proc while it runs, reaped with wait4 (CPU time).

    Not wait4's ru_maxrss: Linux carries the parent's peak across fork and exec into it, so every
    child would report at least this (bigger) process's RSS.
    """

    def __init__(self, name: str, arguments: list[str], log_path: Path):
        self.name, self.log_path = name, log_path
        with open(log_path, "wb") as log_file:
            self.process = subprocess.Popen([sys.executable, "-m", "reckon.cli", "-q", *arguments],
                                            stdout=log_file, stderr=subprocess.STDOUT)
        self.exited: Exited | None = None
        self.peak_kb = 0

    def poll(self) -> Exited | None:
        """None while it runs (noting its peak RSS so far: the last note before it exits is the result)."""
        if self.exited is None:
            self.peak_kb = max(self.peak_kb, _vm_hwm_kb(self.process.pid))
            pid, status, usage = os.wait4(self.process.pid, os.WNOHANG)
            if pid:
                self.process.returncode = os.waitstatus_to_exitcode(status)
                self.exited = Exited(self.process.returncode, self.peak_kb / 1024.0, usage.ru_utime + usage.ru_stime)
        return self.exited

    def reap(self, timeout_s: float) -> Exited:
        """Wait for the exit, killing it after `timeout_s`."""
        deadline = time.monotonic() + timeout_s
        while (exited := self.poll()) is None:
            if time.monotonic() > deadline:
                self.process.kill()
                deadline = math.inf
            time.sleep(0.005)
        return exited

    def cpu_s(self) -> float:
        """CPU seconds (user + system) used so far, while it runs."""
        try:
            fields = Path(f"/proc/{self.process.pid}/stat").read_text().rpartition(")")[2].split()
        except OSError:
            return math.nan
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime: fields 14, 15

    def interrupt(self) -> None:
        if self.poll() is None:
            self.process.send_signal(signal.SIGINT)


def _vm_hwm_kb(pid: int) -> int:
    """Peak resident set of a running process (kB), 0 once it has exited."""
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


@dataclass
class Play:
    """What one run of the live pipeline left: times (ns, wall clock), processes, what this process saw."""

    start_at_ns: int
    edges_up_ns: int
    edges_done_ns: int
    hub: Exited
    edges: dict[str, Exited]
    recording: Path
    hub_summary: str
    cpu_at_start: dict[str, float]  # "hub" and agent ids: CPU seconds used before start_at (start-up)
    system_busy_s: float  # CPU seconds the whole machine was busy from start_at to the hub's exit
    own_cpu_s: float  # of which this process (watching)
    received: list[Received] = field(default_factory=list)


def play(game: Path, folder: Path, speed: float, selectors: tuple[str, ...] = ()) -> Play:
    """Run a hub and one `reckon edge` per agent of `game` at `speed`; collect `selectors` meanwhile.

    Peers do not relay for each other here (no gossip), so the edges connect to the hub and to
    this process; this process sends nothing. The edges wait for a common `--start-at`, later
    than their start-up, so all of them run from the same instant.
    """
    session = read_description(game)
    venue = session.venue.name
    logs = folder / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    hub_endpoint, bench_endpoint = free_endpoint(), free_endpoint()
    recording = folder / "hub.mcap"
    hub = _Child("hub", ["hub", "--venue", str(game), "--listen", hub_endpoint, "-o", str(recording)], logs / "hub.log")
    edges: dict[str, _Child] = {}
    received: list[Received] = []
    try:
        with open_session(zenoh_config(listen=[bench_endpoint], connect=[hub_endpoint])) as bus:
            wait_for_peers(bus, wire.alive_selector(venue, wire.Role.HUB), 1, 60.0)
            subscription = Subscription(bus, list(selectors), capacity=SUBSCRIPTION_CAPACITY) if selectors else None
            try:
                start_at = time.time() + 1.0 + START_S_PER_EDGE * len(session.agents)
                for agent in session.agents:
                    edges[agent.id] = _Child(f"edge {agent.id}", [
                        "edge", "--agent", agent.id, "--source", f"mcap://{game}", "--speed", repr(float(speed)),
                        "--start-at", f"{start_at:.6f}", "--connect", hub_endpoint, "--connect", bench_endpoint],
                        logs / f"edge-{agent.id}.log")
                wait_for_peers(bus, wire.alive_selector(venue, wire.Role.EDGE), len(edges), 60.0)
                edges_up_ns = time.time_ns()
                time.sleep(max(0.0, start_at - 0.05 - time.time()))  # everyone is idle, waiting for start_at
                cpu_at_start = {name: child.cpu_s() for name, child in [("hub", hub), *edges.items()]}
                busy_at_start, own_at_start = _system_busy_s(), time.process_time()
                while True:
                    hub.poll()  # notes its peak RSS so far
                    if all([edge.poll() is not None for edge in edges.values()]):  # a list: poll every one
                        break
                    _collect(subscription, received, POLL_S)
                edges_done_ns = time.time_ns()
                hub.interrupt()  # the edges' flush barrier answered: the hub holds all their samples
                while hub.poll() is None:
                    _collect(subscription, received, POLL_S)
                busy_s, own_s = _system_busy_s() - busy_at_start, time.process_time() - own_at_start
                while _collect(subscription, received, 0.2):
                    pass
            finally:
                if subscription is not None:
                    subscription.close()
    finally:
        children = [*edges.values(), hub]
        for child in children:
            child.interrupt()
        for child in children:
            child.reap(EXIT_TIMEOUT_S)
    for child in children:
        if child.exited is not None and child.exited.returncode != 0:
            raise ReckonError(f"bench: {child.name} exited with {child.exited.returncode}; see {child.log_path}")
    exited = {agent_id: edge.reap(0) for agent_id, edge in edges.items()}
    hub_exited = hub.reap(0)
    summary = (logs / "hub.log").read_text(errors="replace").strip().splitlines()
    return Play(int(start_at * 1e9), edges_up_ns, edges_done_ns, hub_exited, exited, recording,
                summary[-1] if summary else "", cpu_at_start, busy_s, own_s, received)


def _system_busy_s() -> float:
    """CPU seconds all cores have spent not idle since boot (/proc/stat), to notice foreign load."""
    try:
        fields = [int(word) for word in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    except (OSError, ValueError):
        return math.nan
    return (sum(fields[:8]) - fields[3] - fields[4]) / os.sysconf("SC_CLK_TCK")  # minus idle and iowait


def _collect(subscription: Subscription | None, into: list[Received], duration_s: float) -> int:
    """Sleep `duration_s`, then move what arrived meanwhile into `into`; how many came.

    The subscription's drain threads stamp each arrival as it happens; taking the samples in
    batches keeps this process from waking up for every one (it shares the cores it measures).
    """
    time.sleep(duration_s)
    count = 0
    while subscription is not None:
        try:
            item = subscription.get(timeout=0)
        except queue.Empty:
            break
        if item is None:
            break
        into.append(item)
        count += 1
    return count


# ---------------------------------------------------------------------------------------------
# 2. and 4. The unpaced pipeline


def pipeline_run(game: Path, folder: Path, game_s: float, first_call_cpu_s: float = 0.0) -> dict[str, Any]:
    """The unpaced run. Its CPU time from `--start-at` on also gives the best factor this work
    allows on this machine's cores (all of them busy throughout), and the same without each
    edge's first kernel call (`first_call_cpu_s`: numba loading its cache, on the first sample)."""
    run = play(game, folder, UNPACED_SPEED)
    timeline = hub_timeline(run.recording)
    end_ns = max(timeline["last_live_ns"], timeline["last_input_ns"])
    wall_s = (end_ns - run.start_at_ns) * 1e-9
    edge_rss = [e.max_rss_mb for e in run.edges.values()]
    edge_cpu = [e.cpu_s - run.cpu_at_start[agent_id] for agent_id, e in run.edges.items()]
    hub_cpu = run.hub.cpu_s - run.cpu_at_start["hub"]
    cores = len(os.sched_getaffinity(0))
    return {
        "realtime_factor": game_s / wall_s, "game_s": game_s, "wall_s": wall_s,
        "edges_wall_s": (run.edges_done_ns - run.start_at_ns) * 1e-9,
        "edges_late_s": max(0.0, (run.edges_up_ns - run.start_at_ns) * 1e-9),
        "hub_inputs": timeline["inputs"], "hub_outputs": timeline["outputs"],
        "hub_wall_us_per_input": 1e6 * wall_s / max(1, sum(timeline["inputs"].values())),
        "cpu_s": {"hub": hub_cpu, "edges_total": sum(edge_cpu), "edge_max": max(edge_cpu),
                  "startup_before_start_at": sum(run.cpu_at_start.values()), "bench_process": run.own_cpu_s,
                  "other_processes": run.system_busy_s - hub_cpu - sum(edge_cpu) - run.own_cpu_s},
        "cpu_bound_factor": game_s * cores / (hub_cpu + sum(edge_cpu)),
        "cpu_bound_factor_warm": game_s * cores / (hub_cpu + sum(edge_cpu) - len(edge_cpu) * first_call_cpu_s),
        "rss_mb": {"hub": run.hub.max_rss_mb, "edge_max": max(edge_rss), "edge_mean": sum(edge_rss) / len(edge_rss)},
        "hub_summary": run.hub_summary,
    }


def _stream(topic: str) -> str:
    _, _, stream, sub = keys.parse(topic)
    return f"{stream}/{sub}" if stream == "pose" else stream


def hub_timeline(recording: Path) -> dict[str, Any]:
    """Log times of the hub's recording: inputs carry their arrival, outputs their publication."""
    problems: list[str] = []
    streams: dict[int, str] = {}
    inputs: dict[str, int] = {}
    outputs: dict[str, int] = {}
    first_input = last_input = last_live = 0
    for record in iter_records(recording, problems):
        if isinstance(record, Channel):
            streams[record.id] = _stream(record.topic)
        elif isinstance(record, Message):
            stream = streams[record.channel_id]
            if stream in HUB_INPUTS:
                inputs[stream] = inputs.get(stream, 0) + 1
                first_input = record.log_time if not first_input else min(first_input, record.log_time)
                last_input = max(last_input, record.log_time)
            else:
                outputs[stream] = outputs.get(stream, 0) + 1
                if stream == "pose/live":
                    last_live = max(last_live, record.log_time)
    if problems or not last_live:
        raise ReckonError(f"bench: {recording} has no live pose{'; ' + problems[0] if problems else ''}")
    return {"first_input_ns": first_input, "last_input_ns": last_input, "last_live_ns": last_live,
            "inputs": inputs, "outputs": outputs}


# ---------------------------------------------------------------------------------------------
# 3. Latency, in a paced run


def latency_run(game: Path, folder: Path, speed: float) -> dict[str, Any]:
    session = read_description(game)
    venue = session.venue.name
    selectors = tuple(keys.all_agents(venue, stream) for stream in ("imu/*", "pose/edge", "pose/live"))
    run = play(game, folder, speed, selectors)
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
                  hub_summary=run.hub_summary)
    return result


@dataclass
class _Agent:
    seat_id: str
    raw_source_ns: list[int] = field(default_factory=list)  # the edge's clock at each raw publish, ascending
    raw_arrival_ns: list[int] = field(default_factory=list)  # this process's clock at its arrival
    seat_arrival_ns: dict[int, int] = field(default_factory=dict)  # seat sample time -> its batch's arrival
    edge_poses: list[tuple[Received, Any]] = field(default_factory=list)
    live_poses: list[tuple[Received, Any]] = field(default_factory=list)


def _percentiles(values: list[float]) -> dict[str, float]:
    if not values:
        return {"p50": math.nan, "p99": math.nan, "max": math.nan, "count": 0}
    array = np.asarray(values)
    return {"p50": float(np.percentile(array, 50)), "p99": float(np.percentile(array, 99)),
            "max": float(array.max()), "count": len(values)}


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
        "processing_ms": _percentiles(processing),
        "from_seat_batch_ms": _percentiles(from_seat),
        "parts_ms": {"edge": _percentiles(edge_part), "edge_pose_to_live_publish": _percentiles(hub_part),
                     "live_delivery": _percentiles(delivery)},
        "warmup_excluded": _percentiles(warmup), "warmup_s": warmup_s, "unmatched": unmatched,
        "edge_poses": sum(len(v.edge_poses) for v in agents.values()),
        "live_poses": sum(len(v.live_poses) for v in agents.values()),
    }


# ---------------------------------------------------------------------------------------------
# What the hub pays per message, without Zenoh


def hub_profile(recording: Path, session: Session, scratch: Path) -> dict[str, Any]:
    """Feed the hub's recorded inputs, in order, to a fresh ChairHub: mean microseconds per step."""
    problems: list[str] = []
    names: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    inputs: list[tuple[str, str, bytes, int]] = []
    for record in iter_records(recording, problems):
        if isinstance(record, Schema):
            names[record.id] = record.name.removeprefix(messages.PACKAGE + ".")
        elif isinstance(record, Channel):
            channels[record.id] = (record.topic, names.get(record.schema_id, ""))
        elif isinstance(record, Message):
            topic, name = channels[record.channel_id]
            if _stream(topic) in HUB_INPUTS:
                inputs.append((topic, name, record.data, record.log_time))
    hub = ChairHub(session)
    decode: dict[str, list[int]] = {}
    compute: dict[str, list[int]] = {}
    encode_ns = write_ns = outputs = 0
    clock = time.perf_counter_ns
    with SessionWriter(scratch, session) as writer:
        for topic, name, payload, arrival_ns in inputs:
            began = clock()
            message = messages.CLASSES[name].FromString(payload)
            decoded = clock()
            results = hub.on_message(message, arrival_ns)
            computed = clock()
            writer.write(topic, message, decoded)
            for out in results:
                writer.write(hub.key_for(out), out, computed)
            written = clock()
            for out in results:
                wire.encode(out)
            encode_ns += clock() - written
            write_ns += written - computed
            outputs += len(results)
            decode.setdefault(name, [0, 0])[0] += decoded - began
            decode[name][1] += 1
            compute.setdefault(name, [0, 0])[0] += computed - decoded
            compute[name][1] += 1
    scratch.unlink(missing_ok=True)
    count = len(inputs)
    total_ns = sum(v[0] for v in decode.values()) + sum(v[0] for v in compute.values()) + encode_ns + write_ns
    return {
        "inputs": {name: n for name, (_, n) in compute.items()}, "outputs": outputs,
        "decode": {name: 1e-3 * ns / n for name, (ns, n) in decode.items()},
        "chair_hub": {name: 1e-3 * ns / n for name, (ns, n) in compute.items()},
        "encode_per_output": 1e-3 * encode_ns / max(1, outputs),
        "record_per_message": 1e-3 * write_ns / max(1, count + outputs),
        "python_per_input": 1e-3 * total_ns / max(1, count),
    }
