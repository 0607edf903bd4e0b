"""`reckon eval --room-worlds A-B`: the camera-identity room in many simulated rooms, both methods scored in each.

Each room world (sim_devices.room.worlds) is simulated with the same motion seed and scored by the
identity evaluation (reckon/evaluation/identity_eval.py: ours live, refined and in hindsight, the
ceiling, the paper's method); its log is deleted once scored. Worlds run in worker processes, one per core by
default (reckon/evaluation/worlds_eval.py `in_workers`, as for chairs). The report: per method, the median, p10 and worst world's time correct, and in how many
worlds ours live is above the paper's method.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

ROWS = (("reckon", "live"), ("reckon", "refined"), ("hindsight", ""), ("ceiling", ""), ("paper", ""))


@dataclass(frozen=True)
class RoomWorldResult:
    world: int
    time_correct_pct: dict[str, float]  # "reckon live", "reckon refined", "hindsight", "ceiling", "paper"
    figures: dict[str, float]  # the world's drawn figures (dotted keys)


def _label(method: str, track: str) -> str:
    return f"{method} {track}".strip()


def run_room_world(world: int, seed: int, people: int, duration_s: float, workdir: str) -> RoomWorldResult:
    """Simulate room world `world` into `workdir`, score it, delete the log."""
    from protocol.session_log import read_session
    from reckon.evaluation.identity_eval import evaluate_identity
    from sim_devices.room import simulate_room
    from sim_devices.room.worlds import draw_room_world, room_world

    path = Path(workdir) / f"room{world}.mcap"
    params, tracker = room_world(world)
    try:
        simulate_room(path, seed=seed, people=people, duration_s=duration_s, params=params, tracker=tracker,
                      world=world)
        report = evaluate_identity(read_session(path), path)
    finally:
        path.unlink(missing_ok=True)
    scores: dict[str, float] = {}
    for row in report.rows:
        track = "" if row.method != "reckon" else ("refined" if row.note.startswith("refined") else "live")
        scores[_label(row.method, track)] = row.time_correct_pct
    return RoomWorldResult(world, scores, draw_room_world(world))


def evaluate_room_worlds(worlds: list[int], seed: int, people: int, duration_s: float, jobs: int | None = None,
                         progress: Callable[[str], None] = lambda _: None) -> list[RoomWorldResult]:
    """Every world's scores, in world order; `jobs` worker processes (default: one per core; 1: in this one)."""
    from reckon.evaluation.worlds_eval import in_workers

    return in_workers(run_room_world, worlds, (seed, people, duration_s), jobs, progress, _done)


def _done(result: RoomWorldResult, count: int, total: int) -> str:
    scores = result.time_correct_pct
    return (f"room world {result.world} scored ({count}/{total}): ours live {scores.get('reckon live', 0):.1f} %, "
            f"paper {scores.get('paper', 0):.1f} %")


def summarise(results: list[RoomWorldResult]) -> dict[str, Any]:
    """JSON-ready: per method the median, p10 and worst world; ours live against the paper; every world."""
    methods = []
    for method, track in ROWS:
        label = _label(method, track)
        values = np.array([r.time_correct_pct[label] for r in results if label in r.time_correct_pct])
        if len(values):
            methods.append({"method": method, "track": track or None, "worlds": len(values),
                            "median_pct": float(np.median(values)), "p10_pct": float(np.percentile(values, 10)),
                            "worst_pct": float(values.min())})
    pairs = [(r.time_correct_pct["reckon live"], r.time_correct_pct["paper"]) for r in results
             if "reckon live" in r.time_correct_pct and "paper" in r.time_correct_pct]
    return {"methods": methods,
            "ours_live_above_paper": {"worlds": len(pairs), "above": sum(a > b for a, b in pairs)},
            "worlds": [{"world": r.world, "time_correct_pct": {k: round(v, 2) for k, v in r.time_correct_pct.items()},
                        "figures": r.figures} for r in results]}


def to_table(summary: dict[str, Any], command: str) -> str:
    lines = [f"camera identity over room worlds ({command}): time correct %",
             f"{'method':9} {'track':8} {'worlds':>6} {'median':>7} {'p10':>6} {'worst':>6}"]
    for row in summary["methods"]:
        lines.append(f"{row['method']:9} {row['track'] or '-':8} {row['worlds']:6d} {row['median_pct']:7.1f} "
                     f"{row['p10_pct']:6.1f} {row['worst_pct']:6.1f}")
    above = summary["ours_live_above_paper"]
    lines.append(f"ours live above the paper's method in {above['above']} of {above['worlds']} worlds")
    lines.append("per world (ours live / refined / in hindsight, paper): " + ", ".join(
        f"{w['world']}: {w['time_correct_pct'].get('reckon live', float('nan')):.1f} / "
        f"{w['time_correct_pct'].get('reckon refined', float('nan')):.1f} / "
        f"{w['time_correct_pct'].get('hindsight', float('nan')):.1f}, {w['time_correct_pct'].get('paper', float('nan')):.1f}"
        for w in summary["worlds"]))
    return "\n".join(lines)
