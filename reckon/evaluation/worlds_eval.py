"""`reckon eval --worlds A-B`: the same game in many simulated worlds, every method scored in each.

Each world (sim_devices.wheelchair.worlds) is simulated with the same motion seed, evaluated by
`evaluate_data` (the paper's method and ours, every heading and correction set), and its log
deleted once scored, so a sweep keeps one log per worker on disk. Worlds run in worker processes,
one per core by default.

What the sweep reports:
- per method, heading, corrections and track: the median and p90 over worlds of the mean error;
- per correction source of ours (and of the paper's method): in how many worlds adding it lowered
  the mean error, raised it, raised it by more than HURT_TOLERANCE, and the median and worst change;
  the magnetometer aid compares our sensors heading with our gyro-only heading, without corrections;
- the median over worlds of our live pose's NEES per correction set;
- the contacts our hub took (collisions alone), summed over worlds: how many, how many were true.
"""

from __future__ import annotations

import math
import os
import tempfile
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

HURT_TOLERANCE = 0.05  # issue 21: a source may never raise the mean error by more than 5 %
Key = tuple[str, str, tuple[str, ...], str | None]  # method, heading, corrections, track
BOTH = ("beacon", "collision")
# (name, the row without it, the row with it)
SOURCES: tuple[tuple[str, Key, Key], ...] = (
    ("magnetometer aid", ("reckon", "gyro", (), "live"), ("reckon", "sensors", (), "live")),
    ("beacon", ("reckon", "sensors", (), "live"), ("reckon", "sensors", ("beacon",), "live")),
    ("collision", ("reckon", "sensors", (), "live"), ("reckon", "sensors", ("collision",), "live")),
    ("beacon after collision", ("reckon", "sensors", ("collision",), "live"), ("reckon", "sensors", BOTH, "live")),
    ("collision after beacon", ("reckon", "sensors", ("beacon",), "live"), ("reckon", "sensors", BOTH, "live")),
    ("camera", ("reckon", "sensors", (), "live"), ("reckon", "sensors", ("camera",), "live")),
    ("refining", ("reckon", "sensors", BOTH, "live"), ("reckon", "sensors", BOTH, "refined")),
    ("beacon", ("paper", "sensors", (), None), ("paper", "sensors", ("beacon",), None)),
    ("collision", ("paper", "sensors", (), None), ("paper", "sensors", ("collision",), None)),
)


@dataclass(frozen=True)
class WorldResult:
    world: int
    mean_error_m: dict[Key, float]
    nees: dict[Key, float]
    figures: dict[str, float]  # the world's drawn figures (dotted keys)
    contact_pairs: tuple[int, int, int] | None = None  # ours, collisions alone: (taken, true, true contacts)


def run_world(world: int, seed: int, players: int, duration_s: float, workdir: str) -> WorldResult:
    """Simulate world `world` into `workdir`, evaluate it, delete the log; the scores."""
    from protocol.session_log import read_session
    from reckon.evaluation.evaluate import evaluate_data
    from sim_devices.wheelchair import simulate
    from sim_devices.wheelchair.worlds import draw_world, world_params

    path = Path(workdir) / f"world{world}.mcap"
    try:
        simulate(players, duration_s, seed, path, world_params(world), world=world)
        report = evaluate_data(read_session(path), path)
    finally:
        path.unlink(missing_ok=True)
    errors, nees = {}, {}
    for row in report.rows:
        key = (row.method, row.heading, tuple(row.corrections), row.track)
        errors[key] = row.summary.mean_error_m
        if row.nees is not None:
            nees[key] = row.nees
    pairs = report.contact_pairs
    taken = None if pairs is None else (pairs.detected, pairs.matched, pairs.true_contacts)
    return WorldResult(world, errors, nees, draw_world(world), taken)


def evaluate_worlds(worlds: list[int], seed: int, players: int, duration_s: float, jobs: int | None = None,
                    progress: Callable[[str], None] = lambda _: None) -> list[WorldResult]:
    """Every world's scores, in world order; `jobs` worker processes (default: one per core, at most
    one per world; 1 runs in this process)."""
    return in_workers(run_world, worlds, (seed, players, duration_s), jobs, progress, _done)


def in_workers(run: Callable[..., Any], worlds: list[int], args: tuple, jobs: int | None,
               progress: Callable[[str], None], done: Callable[[Any, int, int], str]) -> list[Any]:
    """`run(world, *args, workdir)` for every world, in `jobs` worker processes (default: one per core,
    at most one per world; 1: in this process), each log in one scratch folder; the results in world
    order (each has `.world`), `done(result, count, total)` reported as each comes in."""
    jobs = max(1, min(jobs or os.cpu_count() or 1, len(worlds)))
    results: list[Any] = []
    with tempfile.TemporaryDirectory(prefix="reckon-worlds-") as workdir:
        if jobs == 1:
            for world in worlds:
                results.append(run(world, *args, workdir))
                progress(done(results[-1], len(results), len(worlds)))
        else:
            with ProcessPoolExecutor(max_workers=jobs) as pool:
                futures = [pool.submit(run, w, *args, workdir) for w in worlds]
                for future in as_completed(futures):
                    results.append(future.result())
                    progress(done(results[-1], len(results), len(worlds)))
    return sorted(results, key=lambda r: r.world)


def _done(result: WorldResult, count: int, total: int) -> str:
    ours = result.mean_error_m.get(("reckon", "sensors", ("beacon", "collision"), "live"), math.nan)
    return f"world {result.world} scored ({count}/{total}): ours live beacon+collision {ours:.2f} m"


def summarise(results: list[WorldResult]) -> dict[str, Any]:
    """The sweep's summary (JSON-ready): methods, correction sources, NEES, and each world's headline."""
    keys = sorted({k for r in results for k in r.mean_error_m}, key=_order)
    methods = []
    for key in keys:
        values = np.array([r.mean_error_m[key] for r in results if key in r.mean_error_m])
        nees = [r.nees[key] for r in results if key in r.nees]
        methods.append({**_key_json(key), "worlds": len(values), "median_m": float(np.median(values)),
                        "p90_m": float(np.percentile(values, 90)), "worst_m": float(values.max()),
                        **({"median_nees": float(np.median(nees))} if nees else {})})
    sources = []
    for name, without, with_it in SOURCES:
        pairs = [(r.mean_error_m[without], r.mean_error_m[with_it]) for r in results
                 if without in r.mean_error_m and with_it in r.mean_error_m]
        if not pairs:
            continue
        change = np.array([(b - a) / a for a, b in pairs])
        sources.append({"source": name, "method": with_it[0], "worlds": len(change),
                        "helped": int((change < 0).sum()), "hurt": int((change > 0).sum()),
                        "hurt_over_tolerance": int((change > HURT_TOLERANCE).sum()),
                        "median_change": float(np.median(change)), "worst_change": float(change.max()),
                        "best_change": float(change.min())})
    counted = [r.contact_pairs for r in results if r.contact_pairs is not None]
    contact_pairs = ({"taken": sum(c[0] for c in counted), "true": sum(c[1] for c in counted),
                      "true_contacts": sum(c[2] for c in counted), "worlds": len(counted)} if counted else None)
    return {"worlds": [r.world for r in results], "methods": methods, "sources": sources,
            **({"contact_pairs": contact_pairs} if contact_pairs else {}),
            "per_world": [{"world": r.world, "mean_error_m": {_label(k): round(v, 4) for k, v in r.mean_error_m.items()},
                           "nees": {_label(k): round(v, 4) for k, v in r.nees.items()}, "figures": r.figures,
                           **({"contact_pairs": dict(zip(("taken", "true", "true_contacts"), r.contact_pairs))}
                              if r.contact_pairs else {})}
                          for r in results]}


HEADLINE: tuple[Key, ...] = (("reckon", "sensors", ("beacon", "collision"), "live"),
                             ("reckon", "sensors", (), "live"), ("reckon", "gyro", (), "live"),
                             ("paper", "sensors", ("beacon", "collision"), None))


def _order(key: Key) -> tuple[int, str, int, str, str]:
    method, heading, corrections, track = key
    return (0 if method == "reckon" else 1, heading, len(corrections), "+".join(corrections), track or "")


def _key_json(key: Key) -> dict[str, Any]:
    method, heading, corrections, track = key
    return {"method": method, "heading": heading, "corrections": list(corrections), **({"track": track} if track else {})}


def _label(key: Key) -> str:
    method, heading, corrections, track = key
    return " ".join(part for part in (method, track, heading, "+".join(corrections) or "none") if part)


def to_table(summary: dict[str, Any], command: str) -> str:
    worlds = summary["worlds"]
    lines = [f"{len(worlds)} worlds ({worlds[0]}-{worlds[-1]}): `{command}`",
             f"{'method':15} {'heading':8} {'corrections':26} {'median':>7} {'p90':>6} {'worst':>6} {'NEES':>5}"]
    for row in summary["methods"]:
        method = f"{row['method']} {row['track']}" if "track" in row else row["method"]
        nees = f"{row['median_nees']:5.2f}" if "median_nees" in row else ""
        lines.append(f"{method:15} {row['heading']:8} {'+'.join(row['corrections']) or 'none':26} "
                     f"{row['median_m']:7.2f} {row['p90_m']:6.2f} {row['worst_m']:6.2f} {nees}".rstrip())
    lines.append("mean error in metres over agents and time, then the median, p90 and worst over worlds; "
                 "NEES: median over worlds of ours live (1.39 if the covariance is honest)")
    lines += ["", f"{'correction source':24} {'method':7} {'helped':>7} {'hurt':>5} {'>5 %':>5} "
                  f"{'median':>7} {'worst':>7} {'best':>7}"]
    for row in summary["sources"]:
        lines.append(f"{row['source']:24} {row['method']:7} {row['helped']:4d}/{row['worlds']:<2d} {row['hurt']:5d} "
                     f"{row['hurt_over_tolerance']:5d} {100 * row['median_change']:+6.1f}% "
                     f"{100 * row['worst_change']:+6.1f}% {100 * row['best_change']:+6.1f}%")
    lines.append("change of the mean error when the source is added (negative: it helped); the magnetometer aid "
                 "is ours' sensors heading against ours without the magnetometer; refining: refined against live")
    if "contact_pairs" in summary:
        c = summary["contact_pairs"]
        lines.append(f"ours' contacts (collisions alone), over {c['worlds']} worlds: {c['taken']} taken, "
                     f"{c['taken'] - c['true']} of them false; {c['true_contacts']} true contacts")
    lines += ["", "per world, mean error (m): " + ", ".join(_label(k) for k in HEADLINE)]
    for row in summary["per_world"]:
        lines.append(f"  world {row['world']:3d}: " + "  ".join(
            f"{row['mean_error_m'].get(_label(k), math.nan):5.2f}" for k in HEADLINE))
    return "\n".join(lines)
