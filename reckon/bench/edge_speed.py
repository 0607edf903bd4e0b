"""`edge_samples_per_s`: the chair filter in one process, and the whole edge computation with its parts.

The compiled batch (`edge.chair.kernel.run_batch`) over one chair's merged samples, repeated to
>= 10^6 samples, best of 3, one core; `ChairEdge.push` (merger, kernel calls per pose, messages),
the replay source and the encoding beside it; and an edge process's start-up cost.
"""

from __future__ import annotations

import math
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable

from edge.chair import kernel
from edge.chair.edge import ChairEdge
from edge.chair.estimator import start
from edge.chair.merger import ChairMerger
from protocol import bus as wire
from protocol import keys
from protocol.errors import ReckonError
from protocol.session_log import LogMessages, read_session
from reckon.evaluation.inputs import build_inputs
from reckon.evaluation.reckon_run import merged_samples
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
            "import numpy as np, reckon.processes.edge  # zenoh with it\n"
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
