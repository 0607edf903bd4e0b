"""`reckon bench load`: one real `reckon hub` with hundreds of simulated chairs at 50 Hz (docs/benchmarks.md).

Three processes on loopback Zenoh besides this one, which only starts them, samples /proc and
reads their results:
- the hub: `reckon hub --venue <500 chairs>`, as a venue runs it (with `hubs` > 1, one per shard of
  the courts, each with its own venue: load_spec.py);
- a load generator (`python -m reckon.bench.load generate`): what the chairs' edges would send;
- a watcher (`python -m reckon.bench.load watch`): every live pose the hub publishes, taken as a
  consumer of every agent takes them (`reckon/<venue>/hub/poses/live`, batched), stamped on arrival.

The load, its venue and the chairs' motion: `load_spec`; the two helper processes: `load_traffic`;
the numbers and the table: `load_report`.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any, Callable

from protocol.errors import ReckonError
from protocol.session_log import SessionWriter
from reckon.bench.children import Child, cli_command, system_busy_s, thread_cpu_s, vm_kb
from reckon.bench.load_report import format_load, results
from reckon.bench.load_spec import LoadSpec, load_session
from reckon.bench.report import machine_info
from reckon.transport.bus import free_endpoint

__all__ = ["run_load", "main", "format_load"]  # format_load: the CLI takes both from here

STARTUP_S = 8.0  # start_at: the hub, the generator and the watcher importing and connecting on 2 cores
WARMUP_S = 5.0  # left out of the steady-state window and of the percentiles
END_MARGIN_S = 1.0
DRAIN_TIMEOUT_S = 60.0  # after the generator is done, for the hub to catch up


def run_load(out: Path, agents: int = 500, rate_hz: float = 50.0, duration_s: float = 60.0, seed: int = 1,
             progress: Callable[[str], None] = print, record: bool = False, hubs: int = 1) -> dict[str, Any]:
    """Run the hub (or `hubs` hubs, each for its block of courts) under `agents` chairs' load for
    `duration_s`; the numbers (JSON-able): the hubs' figures summed, each hub's in details.hubs.

    Keys: hub_cpu_cores, latency_ms {p50, p99, max}, rss_mb {hub, hub_peak}, dropped, skipped,
    corrections, machine, details. ReckonError when a process fails (logs in `out`/logs).
    """
    out = Path(out)
    logs = out / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    for stale in ("generator.started", "put_ns.npy", "received_ns.npy", "generator.json", "watcher.json"):
        (out / stale).unlink(missing_ok=True)
    machine = machine_info()
    spec = LoadSpec(agents, rate_hz, duration_s, seed, int((time.time() + STARTUP_S * hubs) * 1e9),
                    tuple(free_endpoint() for _ in range(hubs)), free_endpoint(), hubs)
    spec_path = out / "spec.json"
    names = ["hub"] if hubs == 1 else [f"hub{k + 1}" for k in range(hubs)]
    venue_files = [out / f"{name.replace('hub', 'venue')}.mcap" for name in names]
    for shard, venue_file in enumerate(venue_files):
        with SessionWriter(venue_file, load_session(spec, shard if hubs > 1 else None)):
            pass
    spec_path.write_text(json.dumps(asdict(spec)))
    warmup_s, margin_s = min(WARMUP_S, duration_s / 4), min(END_MARGIN_S, duration_s / 10)
    progress(f"bench load: {agents} chairs at {rate_hz:g} Hz for {duration_s:g} s "
             f"({spec.courts} courts), {hubs} hub{'s' if hubs > 1 else ''} + generator + watcher on loopback Zenoh")
    hub_children = [Child(name, cli_command(
        "hub", "--venue", str(venue_file), "--listen", endpoint, "--pose-rate", repr(rate_hz),
        *(["-o", str(out / f"{name}.mcap")] if record else [])), logs / f"{name}.log")
        for name, venue_file, endpoint in zip(names, venue_files, spec.hub_endpoints)]
    watcher = _helper("watch", spec_path, out, logs / "watcher.log")
    generator = _helper("generate", spec_path, out, logs / "generator.log")
    children = {**{hub.name: hub for hub in hub_children}, "generator": generator, "watcher": watcher}
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
            if now >= next_sample:  # the largest hub's
                rss_mb.append((now - first_ns * 1e-9, max(vm_kb(hub.process.pid, "VmRSS") for hub in hub_children) / 1024))
                next_sample += 1.0
            if not at_start and now >= window[0]:
                at_start = _cpu_now(children, now)
            if at_start and not at_end and now >= window[1]:
                at_end = _cpu_now(children, now)
            _check_running({**{hub.name: hub for hub in hub_children}, "watcher": watcher}, may_finish="watcher")
            time.sleep(0.02)
        if generator.exited.returncode != 0 or not at_end:
            raise ReckonError(f"bench load: the generator exited with {generator.exited.returncode} "
                              f"before the window's end; see {generator.log_path}")
        progress("bench load: generator done; waiting for the watcher to see every live pose")
        deadline = time.monotonic() + DRAIN_TIMEOUT_S
        while watcher.poll() is None and time.monotonic() < deadline:
            for hub in hub_children:
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
    result = results(out, spec, hub_children, children, at_start, at_end, rss_mb, warmup_s, margin_s)
    machine["load_average_at_end"] = list(os.getloadavg())
    result["machine"] = machine
    result["recorded"] = record  # the hub's own recording (-o) costs it CPU per input (docs/benchmarks.md)
    return result


def _check_running(children: dict[str, Child], may_finish: str = "") -> None:
    for name, child in children.items():
        exited = child.poll()
        if exited is not None and not (name == may_finish and exited.returncode == 0):
            raise ReckonError(f"bench load: {name} exited early with {exited.returncode}; see {child.log_path}")


def _cpu_now(children: dict[str, Child], now: float) -> dict[str, Any]:
    hubs = [name for name in children if name.startswith("hub")]
    return {"wall": now, "machine_busy": system_busy_s(), "bench_process": time.process_time(),
            "hub_threads": {f"{name}/{thread}" if len(hubs) > 1 else thread: cpu
                            for name in hubs for thread, cpu in thread_cpu_s(children[name].process.pid).items()},
            **{name: child.cpu_s() for name, child in children.items()}}


def _helper(role: str, spec_path: Path, out: Path, log_path: Path) -> Child:
    """A generator or watcher process of this module, watched like bench's `reckon` children."""
    return Child(role, [sys.executable, "-m", "reckon.bench.load", role, str(spec_path), str(out)], log_path)


def main(argv: list[str]) -> int:
    """The generator and watcher processes: `python -m reckon.bench.load generate|watch SPEC.json OUT`."""
    parser = argparse.ArgumentParser(prog="python -m reckon.bench.load")
    parser.add_argument("role", choices=("generate", "watch"))
    parser.add_argument("spec", type=Path)
    parser.add_argument("out", type=Path)
    args = parser.parse_args(argv)
    from reckon.bench.load_traffic import generate, watch  # only the helper processes need Zenoh's side of it

    found = json.loads(args.spec.read_text())
    spec = LoadSpec(**{**found, "hub_endpoints": tuple(found["hub_endpoints"])})
    (generate if args.role == "generate" else watch)(spec, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
