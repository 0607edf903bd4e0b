"""`edge_samples_per_s`: the chair filter in one process, and the whole edge computation with its parts.

The compiled batch (`edge.chair.kernel.run_batch`, loaded ahead-of-time compiled as the edge loads
it: reckon/kernels.py) over one chair's merged samples, repeated to >= 10^6 samples, best of 3, one core; `ChairEdge.push` (merger, kernel calls per pose, messages),
the replay source and the encoding beside it; and an edge process's start-up cost.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable

from edge.chair import layout
from edge.chair.edge import ChairEdge
from edge.chair.estimator import start
from edge.chair.merge_layout import PackedMerger
from protocol import bus as wire
from protocol import keys
from protocol.errors import ReckonError
from protocol.session_log import LogMessages, read_session
from reckon.evaluation.inputs import build_inputs
from reckon.evaluation.reckon_run import merged_samples
from reckon.kernels import chair_kernels
from reckon.processes.edge import mcap_source

KERNEL_SAMPLES = 1_000_000  # run_batch is timed over at least this many samples
REPEATS = 3  # best of


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
    kernels, loaded = chair_kernels()
    run_batch = kernels.run_batch
    edge = ChairEdge(agent, kernels=kernels)
    state = layout.pack_state(start(edge.settings, samples[0], agent.start_x_m, agent.start_y_m,
                                    agent.start_heading_rad))
    times, values = layout.pack_samples(samples[1:])
    repeats = -(-KERNEL_SAMPLES // len(times))

    def kernel_loop() -> None:
        for _ in range(repeats):
            run_batch(edge.packed_settings, state, times, values)

    kernel_s = _best_of(kernel_loop)
    # as ChairEdge calls it: one call per pose (200 Hz seat, 50 Hz poses: 4 samples a call)
    seat_hz = (len(times) - 1) / max((times[-1] - times[0]) * 1e-9, 1e-9)
    per_pose = max(1, round(seat_hz * edge.period_ns * 1e-9))
    slices = [(times[i:i + per_pose], values[i:i + per_pose]) for i in range(0, len(times), per_pose)]

    def sliced_loop() -> None:
        vector = state
        for slice_times, slice_values in slices:
            vector, _ = run_batch(edge.packed_settings, vector, slice_times, slice_values)

    sliced_s = _best_of(sliced_loop)
    batches = [message for _, topic, message in LogMessages(
        game, lambda topic, name: name == "ImuBatch" and keys.parse(topic)[1] == agent.id)]
    raw_samples = sum(len(batch.sample_offset_ns) for batch in batches)

    def merger_loop() -> None:  # the compiled merger, as ChairEdge runs it
        merger = PackedMerger(agent, kernels.merge_batch)
        for batch in batches:
            merger.push_batch(batch)
        merger.flush()

    def edge_loop() -> None:
        chair = ChairEdge(agent, kernels=kernels)
        for batch in batches:
            chair.push(batch)
        chair.flush()

    def source_loop() -> None:
        for _ in mcap_source(game, agent.id, 0.0, threading.Event()):
            pass

    merger_s = _best_of(merger_loop)
    edge_s = _best_of(edge_loop)
    source_s = _best_of(source_loop, 1)
    chair = ChairEdge(agent, kernels=kernels)
    produced = [out for batch in batches for out in chair.push(batch)] + chair.flush()
    outputs = len(produced)
    merged = chair.samples
    began = time.perf_counter()
    for message in [*batches, *produced]:  # what the edge publishes: every raw batch, every output
        wire.encode(message)
    encode_s = time.perf_counter() - began
    game_s = (times[-1] - times[0]) * 1e-9
    return {
        "agent": agent.id, "kernel_loaded": loaded, "kernel_samples": repeats * len(times),
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
        "startup": startup_probe(game, agent.id),
    }


# A fresh interpreter does what `reckon edge` does up to its first pose: imports, the session log
# opened as a source, a Zenoh session (dialling a closed port: it keeps retrying in the background,
# as an edge started before its hub does), the chair's edge with its kernel loaded, batches pushed
# until a pose comes out. It prints its CPU at each mark and its peak RSS (VmHWM: getrusage's maxrss
# would carry the parent's over exec); the wall time is the parent's.
_STARTUP = """
import json, re, sys, threading, time
from reckon.processes.edge import EDGES, open_sources
from reckon.transport.bus import open_session
from reckon.transport.config import zenoh_config
imported = time.process_time()
game, agent_id = sys.argv[1], sys.argv[2]
session, source = open_sources(["mcap://" + game], agent_id, 0.0, threading.Event())
with open_session(zenoh_config(connect=["tcp/127.0.0.1:9"])):
    agent = session.agent(agent_id)
    edge = EDGES[agent.kind](agent, session, 50.0)
    ready = time.process_time()
    for message in source:
        if message.DESCRIPTOR.name == "ImuBatch" and any(out.DESCRIPTOR.name == "EstimatedPose"
                                                         for out in edge.push(message)):
            break
    posed = time.process_time()
    print(json.dumps({"imports_s": imported, "edge_ready_s": ready - imported, "first_pose_cpu_s": posed,
                      "rss_mb": int(re.search(r"VmHWM:\\s+(\\d+)", open("/proc/self/status").read()).group(1)) / 1024,
                      "numba_loaded": "numba" in sys.modules}), flush=True)
"""


def startup_probe(game: Path, agent_id: str) -> dict[str, Any]:
    """An edge process's start-up to its first pose, measured in a fresh interpreter: CPU seconds of
    its imports and of making its edge (the kernel loaded), CPU and wall seconds to the first pose,
    peak RSS then, and whether numba was loaded."""
    chair_kernels()  # built before, not in the probe
    began = time.perf_counter()
    child = subprocess.Popen([sys.executable, "-c", _STARTUP, str(game), agent_id], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    line = child.stdout.readline() if child.stdout else ""
    wall_s = time.perf_counter() - began
    _, errors = child.communicate()
    if child.returncode != 0 or not line:
        raise ReckonError(f"bench: the start-up probe exited with {child.returncode}: {errors.strip()[-300:]}")
    return {**json.loads(line), "first_pose_wall_s": wall_s}
