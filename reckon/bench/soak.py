"""`reckon bench soak`: an hour-long game through real edges and a real hub, replayed fast; is RSS flat?

The simulator writes `hours` of a `players`-chair game; one `reckon edge --speed 0` per chair
replays it as fast as it goes into one `reckon hub -o hub.mcap` (recording, as at a venue).
Every second this process reads VmRSS of each of them from /proc; at the end it reports per
process the first, last and largest VmRSS, the peak (VmHWM) and the slope, and draws the curves
(docs/img/soak-rss.png). The slope is fitted over the run after its first 10 % (start-up: imports,
numba's cache, Zenoh) against stream time, taking the replay's progress as even: MiB per hour of
stream. A leak of one small object per sample would show as tens of MiB an hour.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from protocol.errors import ReckonError
from protocol.session_log import read_description
from reckon.bench.children import Child, cli_command, vm_kb
from reckon.bench.play import hub_summary_line
from reckon.bench.report import machine_info
from reckon.transport.bus import free_endpoint
from sim_devices.wheelchair import simulate

PLAYERS = 2
SAMPLE_S = 1.0
SETTLE_SHARE = 0.1  # the first tenth of the run is start-up, left out of the slope
EXIT_TIMEOUT_S = 120.0
PLOT = Path(__file__).resolve().parents[2] / "docs" / "img" / "soak-rss.png"


def run_soak(out: Path, hours: float = 1.0, players: int = PLAYERS, seed: int = 1,
             progress: Callable[[str], None] = print, plot: Path | None = PLOT) -> dict[str, Any]:
    """Simulate, replay through edges and hub, sample RSS; the numbers (JSON-able) and the plot."""
    if not 0 < hours <= 24:
        raise ReckonError(f"bench soak: --hours {hours:g} must be in (0, 24]")
    out = Path(out)
    logs = out / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    machine = machine_info()
    game = out / "soak-game.mcap"
    duration_s = hours * 3600.0
    progress(f"bench soak: simulating {players} chairs for {duration_s:g} s (seed {seed}) -> {game}")
    began = time.monotonic()
    simulate(players, duration_s, seed, game)
    simulate_s = time.monotonic() - began
    session = read_description(game)
    endpoint = free_endpoint()
    hub = Child("hub", cli_command("hub", "--venue", str(game), "--listen", endpoint, "-o", str(out / "hub.mcap")),
                logs / "hub.log")
    edges = {agent.id: Child(f"edge {agent.id}", cli_command(
        "edge", "--agent", agent.id, "--source", f"mcap://{game}", "--speed", "0", "--wait-for", "1",
        "--connect", endpoint), logs / f"edge-{agent.id}.log") for agent in session.agents}
    children = {"hub": hub, **{f"edge {agent_id}": edge for agent_id, edge in edges.items()}}
    curves: dict[str, list[float]] = {name: [] for name in children}
    times: list[float] = []
    progress(f"bench soak: {players} edges at --speed 0 and a hub, VmRSS every {SAMPLE_S:g} s")
    started = time.monotonic()
    try:
        while any([edge.poll() is None for edge in edges.values()]):  # a list: poll (note the peak of) every one
            if hub.poll() is not None:
                raise ReckonError(f"bench soak: the hub exited early with {hub.exited.returncode}; see {hub.log_path}")
            times.append(time.monotonic() - started)
            for name, child in children.items():
                curves[name].append(vm_kb(child.process.pid, "VmRSS") / 1024 if child.exited is None else np.nan)
            time.sleep(SAMPLE_S)
        wall_s = time.monotonic() - started
    finally:
        for child in children.values():
            child.interrupt()
        for child in children.values():
            child.reap(EXIT_TIMEOUT_S)
    for child in children.values():
        if child.exited.returncode != 0:
            raise ReckonError(f"bench soak: {child.name} exited with {child.exited.returncode}; see {child.log_path}")
    processes = {name: _curve_summary(np.array(times), np.array(curves[name]), wall_s, hours, child.exited.max_rss_mb)
                 for name, child in children.items()}
    if plot is not None:
        _plot(plot, np.array(times), curves, wall_s, hours, players)
    machine["load_average_at_end"] = list(os.getloadavg())
    edge_names = [name for name in processes if name != "hub"]
    return {
        "hours": hours, "players": players,
        "rss_mb": {"hub": processes["hub"], "edge_max": max((processes[n] for n in edge_names),
                                                            key=lambda p: p["max"])},
        "slope_mb_per_hour": {name: p["slope_mb_per_hour"] for name, p in processes.items()},
        "machine": machine,
        "details": {"processes": processes, "wall_s": wall_s, "simulate_s": simulate_s, "samples": len(times),
                    "cpu_s": {name: child.exited.cpu_s for name, child in children.items()},
                    "hub_summary": hub_summary_line(hub.log_path.read_text(errors="replace")),
                    "plot": str(plot) if plot else None},
    }


def _curve_summary(times: np.ndarray, mb: np.ndarray, wall_s: float, hours: float, peak_mb: float) -> dict[str, Any]:
    alive = np.isfinite(mb) & (mb > 0)
    t, values = times[alive], mb[alive]
    if len(values) == 0:
        return {"first": np.nan, "last": np.nan, "max": np.nan, "peak_vmhwm": peak_mb, "slope_mb_per_hour": np.nan}
    settled = t >= SETTLE_SHARE * wall_s
    slope = np.nan
    if settled.sum() >= 3:
        per_wall_s = float(np.polyfit(t[settled], values[settled], 1)[0])
        slope = per_wall_s * wall_s / hours  # the replay's progress taken as even over the run
    return {"first": float(values[0]), "last": float(values[-1]), "max": float(values.max()),
            "settled_first": float(values[settled][0]) if settled.any() else float(values[0]),
            "peak_vmhwm": peak_mb, "slope_mb_per_hour": slope}


def _plot(path: Path, times: np.ndarray, curves: dict[str, list[float]], wall_s: float, hours: float,
          players: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    figure, axes = plt.subplots(figsize=(8, 4))
    stream_h = times / max(wall_s, 1e-9) * hours
    for name, values in curves.items():
        axes.plot(stream_h, values, label=name, linewidth=1.2 if name == "hub" else 0.8)
    axes.set_xlabel("stream replayed (hours, taking the replay's progress as even)")
    axes.set_ylabel("VmRSS (MiB)")
    axes.set_title(f"reckon bench soak: {hours:g} h of a {players}-chair game in {wall_s:.0f} s")
    axes.set_ylim(bottom=0)
    axes.grid(alpha=0.3)
    axes.legend(loc="lower right")
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def format_soak(result: dict[str, Any]) -> str:
    d = result["details"]
    lines = [f"reckon bench soak: {result['hours']:g} h of a {result['players']}-chair game, replayed in "
             f"{d['wall_s']:.0f} s ({d['samples']} samples); {result['machine']['cores']} cores",
             "process              first    last     max   VmHWM   slope (MiB per stream hour)"]
    for name, p in d["processes"].items():
        lines.append(f"{name:18s} {p['first']:7.0f} {p['last']:7.0f} {p['max']:7.0f} {p['peak_vmhwm']:7.0f}   "
                     f"{p['slope_mb_per_hour']:+.1f}")
    lines.append(d["hub_summary"])
    if d["plot"]:
        lines.append(f"curves: {d['plot']}")
    return "\n".join(lines)
