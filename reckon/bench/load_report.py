"""What `reckon bench load` reports: its numbers from the processes' files and the hub's log, and the table.

Latency: for each chair pose, its live pose's arrival at the watcher minus the instant the
generator put it (both wall clock on this machine), paired by agent and pose time (the hub copies
the time: without raw ImuBatch streams its clock offsets are 0).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from protocol.errors import ReckonError
from reckon.bench.children import Child
from reckon.bench.load_spec import LoadSpec
from reckon.bench.report import percentiles

KEPT_UP_MS = 1000.0  # the generator never this far behind its schedule: the hub took the load as it came
SUMMARY = re.compile(r"(\d+) messages in, (\d+) out, (\d+) corrections \((\d+) collision pairs\), "
                     r"(\d+) samples skipped, queue full (\d+) times")


def hub_summary(log_path: Path) -> dict[str, int]:
    """The counters of the hub's last summary line (reckon/processes/hub.py HubSummary)."""
    found = SUMMARY.findall(log_path.read_text(errors="replace"))
    if not found:
        raise ReckonError(f"bench load: no hub summary in {log_path}")
    names = ("inputs", "outputs", "corrections", "pairs", "skipped", "full_waits")
    return dict(zip(names, (int(v) for v in found[-1])))


def results(out: Path, spec: LoadSpec, hubs: list[Child], children: dict[str, Child], at_start: dict[str, Any],
             at_end: dict[str, Any], rss_mb: list[tuple[float, float]], warmup_s: float,
             margin_s: float) -> dict[str, Any]:
    """The run's numbers; with several hubs, their CPU and counters summed (each in details.hubs)."""
    from reckon.processes.hub import INPUTS

    generated = json.loads((out / "generator.json").read_text())
    watched = json.loads((out / "watcher.json").read_text())
    summaries = {hub.name: hub_summary(hub.log_path) for hub in hubs}
    summary = {name: sum(each[name] for each in summaries.values()) for name in next(iter(summaries.values()))}
    put, received, hub_put = (np.load(out / f"{name}.npy") for name in ("put_ns", "received_ns", "hub_published_ns"))
    sent, seen = put > 0, received > 0
    first, last = math.ceil(warmup_s * spec.rate_hz), spec.ticks - math.ceil(margin_s * spec.rate_hz)
    steady = np.zeros_like(sent)
    steady[first:last] = True
    both = sent & seen & steady
    stamped = both & (hub_put > 0)
    subscribed_status = any(stream.startswith("status") for stream in INPUTS)
    hub_expected = (generated["poses"] + generated["impacts"] + generated["sightings"] + generated["clocks"]
                    + (generated["statuses"] if subscribed_status else 0))
    lost_live = int((sent & ~seen).sum())
    wall_s = at_end["wall"] - at_start["wall"]
    hub_cores = {hub.name: (at_end[hub.name] - at_start[hub.name]) / wall_s for hub in hubs}
    cores = {"hub": sum(hub_cores.values()),
             **{name: (at_end[name] - at_start[name]) / wall_s for name in ("generator", "watcher", "bench_process")}}
    cores["other_processes"] = (at_end["machine_busy"] - at_start["machine_busy"]) / wall_s - sum(cores.values())
    steady_rss = [mb for t, mb in rss_mb if warmup_s <= t <= spec.duration_s - margin_s] or [mb for _, mb in rss_mb]
    # The inputs the hub took in the window: its live poses that reached the watcher in it, times
    # the hub's inputs per live pose (poses plus sightings, impacts and clock samples).
    in_window = int(((received >= at_start["wall"] * 1e9) & (received < at_end["wall"] * 1e9)).sum())
    window_inputs = in_window * summary["inputs"] / max(1, watched["live"])
    threads = {name: (at_end["hub_threads"].get(name, 0.0) - used) / wall_s
               for name, used in at_start["hub_threads"].items()}
    hub_cpu_s = cores["hub"] * wall_s
    return {
        "agents": spec.agents, "rate_hz": spec.rate_hz, "duration_s": spec.duration_s, "hubs": spec.hubs,
        "hub_cpu_cores": cores["hub"],
        # CPU per input: robust where the share of the cores is not (the machine is shared)
        "hub_cpu_us_per_input": hub_cpu_s / window_inputs * 1e6 if window_inputs else None,
        # False: the hub's back-pressure held the generator back, so hub_cpu_cores is what the hub
        # manages on this machine (its ceiling), not what the load costs, and latency grows with the lag
        "kept_up": generated["max_behind_ms"] <= KEPT_UP_MS,
        "latency_ms": {key: value for key, value in percentiles(((received - put)[both] * 1e-6).tolist()).items()
                       if key != "count"},
        "rss_mb": {"hub": steady_rss[-1], "hub_peak": max(hub.exited.max_rss_mb for hub in hubs)},
        "dropped": max(0, hub_expected - summary["inputs"]) + lost_live,
        "skipped": summary["skipped"],
        "corrections": {"total": summary["corrections"], "pairs": summary["pairs"],
                        "taken_by_kind": generated["corrections_by_kind"]},
        "details": {
            "targets": {"hub_cpu_cores": 1.0, "latency_p99_ms": 50.0},
            "window_s": wall_s, "cpu_cores": cores,
            "hub_threads_cpu_cores": {name: round(v, 4) for name, v in sorted(threads.items(), key=lambda kv: -kv[1])},
            "hub_inputs_in_window": round(window_inputs),
            "hub_cpu_us_per_input_whole_run": sum(hub.exited.cpu_s for hub in hubs) / max(1, summary["inputs"]) * 1e6,
            "hubs": {hub.name: {"cpu_cores": hub_cores[hub.name], **summaries[hub.name]} for hub in hubs},
            "cpu_s_whole_run": {name: child.exited.cpu_s for name, child in children.items()},
            "generated": generated, "hub_expected_inputs": hub_expected, "hub": summary, "watched": watched,
            "lost_live_poses": lost_live, "poses_in_percentiles": int(both.sum()),
            "latency_parts_ms": {
                "generator_put_to_hub_publish": percentiles(((hub_put - put)[stamped] * 1e-6).tolist()),
                "hub_publish_to_watcher": percentiles(((received - hub_put)[stamped] * 1e-6).tolist())},
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
    hubs = result.get("hubs", 1)
    each = ("" if hubs == 1 else "  " + ", ".join(f"{name} {h['cpu_cores']:.2f} cores ({h['inputs']} inputs)"
                                                  for name, h in d["hubs"].items()) + "\n")
    return "\n".join([
        f"reckon bench load: {result['agents']} chairs at {result['rate_hz']:g} Hz, {result['duration_s']:g} s"
        f"{'' if hubs == 1 else f', {hubs} hubs (courts sharded)'}"
        f"{', recording' if result.get('recorded') else ''}; {m['cpu']}, {m['cores']} cores, Python {m['python']}",
        f"hub CPU                 {result['hub_cpu_cores']:6.2f} cores    target <= {hubs}     "
        f"{verdict(result['hub_cpu_cores'] <= hubs and result['kept_up'])}   (over {d['window_s']:.0f} s of steady state)",
        f"{each}  {keeping}",
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
        f"{d['generated']['sightings']} sightings, {d['generated']['clocks']} clock samples, "
        f"{d['generated']['statuses']} statuses; generator at most "
        f"{d['generated']['max_behind_ms']:.1f} ms behind its schedule",
    ])
