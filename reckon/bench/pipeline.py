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

Here the run as a whole and number 2; the parts: `edge_speed` (1), `play` (edge and hub processes
on loopback, the hub's recording read back), `latency` (3), `hub_cost` (the hub's Python per
message), `children` (the processes' RSS and CPU, also for `load` and `soak`), `report` (targets,
machine, the table).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Callable

from protocol.session_log import read_description
from reckon.bench.edge_speed import edge_throughput
from reckon.bench.hub_cost import hub_profile
from reckon.bench.latency import LATENCY_S, LATENCY_SPEED, latency_run
from reckon.bench.play import hub_timeline, play
from reckon.bench.report import TARGETS, format_table, machine_info
from sim_devices.wheelchair import simulate

__all__ = ["run_bench", "pipeline_run", "format_table"]  # format_table: the CLI takes both from here

UNPACED_SPEED = 1e9  # `reckon edge --speed`: unpaced after `--start-at` (speed 0 would ignore --start-at)


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
    startup_cpu_s = edge["startup"]["first_pose_cpu_s"]
    pipeline = pipeline_run(game, out / "pipeline", duration_s, startup_cpu_s)
    latency_game = out / "latency-game.mcap"
    latency_duration = min(latency_s, duration_s)
    latency_players = latency_players or players
    simulate(latency_players, latency_duration, seed, latency_game)
    progress(f"bench: latency, {latency_players} chairs for {latency_duration:g} s at {latency_speed:g} x real time")
    latency = latency_run(latency_game, out / "latency", latency_speed, startup_cpu_s)
    latency["game_s"] = latency_duration
    progress("bench: the hub's per-message cost, from its recording")
    hub_cost = hub_profile(out / "pipeline" / "hub.mcap", read_description(game), out / "pipeline" / "rewrite.mcap")
    hub_inputs = sum(pipeline["hub_inputs"].values())
    hub_cost["cpu_per_input_in_run"] = 1e6 * pipeline["cpu_s"]["hub"] / max(1, hub_inputs)
    hub_cost["zenoh_and_rest_per_input"] = hub_cost["cpu_per_input_in_run"] - hub_cost["python_per_input"]
    per_game_s = 1e3 / duration_s
    edge_parts = dict(edge["process_ms_per_game_s"])  # its start-up, kernels loaded, is before T
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


def pipeline_run(game: Path, folder: Path, game_s: float, startup_cpu_s: float = 0.0) -> dict[str, Any]:
    """The unpaced run. Its CPU time from `--start-at` on also gives the best factor this work
    allows on this machine's cores (all of them busy throughout); each edge loads its kernel before.
    `startup_cpu_s`: what one edge process spends starting (play's start allowance)."""
    run = play(game, folder, UNPACED_SPEED, startup_cpu_s=startup_cpu_s)
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
        "late_starts_s": run.late_starts, "start_allowance_s": run.start_allowance_s,
        "hub_inputs": timeline["inputs"], "hub_outputs": timeline["outputs"],
        "hub_wall_us_per_input": 1e6 * wall_s / max(1, sum(timeline["inputs"].values())),
        "cpu_s": {"hub": hub_cpu, "edges_total": sum(edge_cpu), "edge_max": max(edge_cpu),
                  "startup_before_start_at": sum(run.cpu_at_start.values()), "bench_process": run.own_cpu_s,
                  "other_processes": run.system_busy_s - hub_cpu - sum(edge_cpu) - run.own_cpu_s},
        "cpu_bound_factor": game_s * cores / (hub_cpu + sum(edge_cpu)),
        "rss_mb": {"hub": run.hub.max_rss_mb, "edge_max": max(edge_rss), "edge_mean": sum(edge_rss) / len(edge_rss)},
        "hub_summary": run.hub_summary,
    }
