"""What `reckon bench` reports against: the targets, the machine it ran on, percentiles, the table."""

from __future__ import annotations

import importlib.metadata
import math
import os
import platform
from pathlib import Path
from typing import Any

import numpy as np

TARGETS = {"edge_samples_per_s": 1_000_000, "pipeline_realtime_factor": 100.0, "latency_p99_ms": 5.0}


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


def percentiles(values: list[float]) -> dict[str, float]:
    if not values:
        return {"p50": math.nan, "p99": math.nan, "max": math.nan, "count": 0}
    array = np.asarray(values)
    return {"p50": float(np.percentile(array, 50)), "p99": float(np.percentile(array, 99)),
            "max": float(array.max()), "count": len(values)}
