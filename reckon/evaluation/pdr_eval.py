"""`reckon eval` on pedestrian sessions (phones): the paper's method and ours, with and without
map matching, scored at the truth waypoints.

Each session is pushed in log order through the live code: the edge (edge/pdr_edge.py, with our
dead reckoning or the paper's) and the hub's map matcher (hub/pedestrian_hub.py). One pass gives
both rows of a method: the edge's poses (no map matching) and the hub's (map matching).
- paper: edge/pdr_paper.py (5 s FFT cadence, height model, Euler attitude) and the paper's turn
  snap to corridor points (hub/map_snap_paper.py), which needs the venue's `map_points`; on a
  floor plan alone it has nothing to snap to and its map-matched row is left out (noted);
- reckon: edge/pdr.py and the particle filter over the walkable area (hub/map_particles.py).

Scoring: every truth pose after the agent's first accepted stand scan is a waypoint; the estimate
there is interpolated between the track's poses (the stand pose starts each track). Over the
waypoints of every session given: median, p75 and p90 of the position error in metres. Where the
session says where the true turns were (`source.turns`, the simulator), the heading error
TURN_SETTLE_S after each turn, and for the paper's snap whether it snapped to the right point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from edge.pdr_edge import PedestrianEdge
from hub.map_snap_paper import PaperSnapMatcher
from hub.pedestrian_hub import PedestrianHub
from protocol import messages
from protocol.errors import InputError
from protocol.session import AgentKind, Mount, Session
from protocol.session_log import LogMessages, SessionData

TURN_SETTLE_S = 2.0  # heading scored this long after a true turn: the turn has ended, the snap is done
SNAP_MATCH_S = 3.0  # a snap counts for a true junction passage within this much time of it
INPUT_TYPES = ("ImuBatch", "StandScan")


def is_pedestrian_session(data: SessionData) -> bool:
    """Every agent a pedestrian carrying a phone (hand or pocket); the identity paper's walkers
    wear a waist IMU and are scored by the identity evaluation instead."""
    agents = data.session.agents
    return bool(agents) and all(a.kind is AgentKind.PEDESTRIAN and any(s.mount in (Mount.HAND, Mount.POCKET)
                                                                         for s in a.sensors) for a in agents)


@dataclass
class Track:
    """One agent's output poses in time order (time ns, x m, y m, heading rad)."""

    rows: list[tuple[int, float, float, float]] = field(default_factory=list)

    def add(self, time_ns: int, x_m: float, y_m: float, heading_rad: float) -> None:
        if self.rows and time_ns <= self.rows[-1][0]:
            self.rows[-1] = (time_ns, x_m, y_m, heading_rad)  # a reset at a step's time replaces it
        else:
            self.rows.append((time_ns, x_m, y_m, heading_rad))

    def at(self, time_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rows = np.array(self.rows, dtype=float).reshape(-1, 4)
        if not len(rows):
            nan = np.full(len(time_ns), math.nan)
            return nan, nan, nan
        x = np.interp(time_ns, rows[:, 0], rows[:, 1])
        y = np.interp(time_ns, rows[:, 0], rows[:, 2])
        nearest = np.clip(np.searchsorted(rows[:, 0], time_ns, side="right") - 1, 0, len(rows) - 1)
        return x, y, rows[nearest, 3]


@dataclass
class MethodRun:
    """One method over one session: the edge's and the hub's tracks per agent, snap records."""

    method: str
    edge: dict[str, Track] = field(default_factory=dict)
    hub: dict[str, Track] | None = None  # None: no map matcher for this method on this venue
    snaps: list[tuple[str, Any]] = field(default_factory=list)  # (agent id, SnapRecord)


@dataclass
class WaypointErrors:
    method: str
    map_matching: bool
    matcher: str
    session: str
    errors_m: np.ndarray
    heading_errors_deg: np.ndarray
    snaps_correct: int | None = None
    snaps_total: int | None = None  # true junction passages
    snaps_wrong: int | None = None  # applied snaps at a point not being passed


@dataclass
class PedestrianReport:
    sessions: list[str]
    rows: list[WaypointErrors] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


def run_method(session: Session, inputs: list[Any], method: str) -> MethodRun:
    """Push the session's phone batches and stand scans through the edge and the hub."""
    run = MethodRun(method)
    if method == "paper":
        from edge.pdr_paper import PaperPdr

        edges = {a.id: PedestrianEdge(a, estimator=PaperPdr(height_m=a.height_m), method="paper")
                 for a in session.agents}
        points = session.venue.map_points
        factory = (lambda agent_id: PaperSnapMatcher(points)) if points else None  # noqa: E731
        hub = PedestrianHub(session, factory, method="paper") if factory else None
    else:
        edges = {a.id: PedestrianEdge(a, session.venue) for a in session.agents}
        hub = PedestrianHub(session)
        if not any(view.matcher for view in hub.agents.values()):
            hub = None
    run.edge = {agent_id: Track() for agent_id in edges}
    run.hub = {agent_id: Track() for agent_id in edges} if hub is not None else None
    for message in inputs:
        edge = edges.get(message.agent_id)
        if edge is None:
            continue
        if messages.type_name(message) == "StandScan":
            edge.scan(message)
            if message.accepted:
                run.edge[message.agent_id].add(message.timestamp_ns, message.x_m, message.y_m, message.heading_rad)
            continue
        for pose in edge.push(message):
            run.edge[pose.agent_id].add(pose.timestamp_ns, pose.x_m, pose.y_m, pose.heading_rad)
            if hub is None or run.hub is None:
                continue
            for out in hub.on_message(pose):
                run.hub[out.agent_id].add(out.timestamp_ns, out.x_m, out.y_m, out.heading_rad)
    if hub is not None:
        run.snaps = [(agent_id, snap) for agent_id, view in hub.agents.items() for snap in view.snaps]
    return run


def read_inputs(path: Path) -> list[Any]:
    return [message for _, _, message in LogMessages(path, lambda _topic, name: name in INPUT_TYPES)]


def evaluate_pedestrians(sessions: list[tuple[SessionData, Path]],
                         progress: Callable[[str], None] = lambda _: None) -> PedestrianReport:
    report = PedestrianReport([str(path) for _, path in sessions])
    no_points: list[str] = []
    for data, path in sessions:
        report.problems += data.problems
        missing = [a.id for a in data.session.agents if a.id not in data.truth]
        if missing:
            raise InputError(f"{path}: no truth poses for {', '.join(missing)}; `reckon eval` scores against truth")
        inputs = read_inputs(path)
        for method in ("paper", "reckon"):
            progress(f"{path.name}: {method}")
            run = run_method(data.session, inputs, method)
            report.rows.append(score(data, path, run, run.edge, False, "none"))
            if run.hub is not None:
                matcher = "turn snap" if method == "paper" else "particle filter"
                report.rows.append(score(data, path, run, run.hub, True, matcher))
            elif method == "paper":
                no_points.append(path.name)
    if no_points:
        report.problems.append(f"{len(no_points)} of {len(sessions)} sessions have no corridor map points: the "
                               f"paper's turn snap has nothing to snap to there ({', '.join(no_points[:3])}"
                               f"{', ...' if len(no_points) > 3 else ''})")
    return report


def score(data: SessionData, path: Path, run: MethodRun, tracks: dict[str, Track], map_matching: bool,
          matcher: str) -> WaypointErrors:
    errors, heading_errors = [], []
    turns = data.session.source.get("turns", []) if isinstance(data.session.source, dict) else []
    for agent_id, track in tracks.items():
        truth = data.truth[agent_id]
        scans = [s for s in data.scans.get(agent_id, []) if s.accepted]
        if not scans:
            continue
        after = truth.time_ns > scans[0].timestamp_ns
        x, y, _ = track.at(truth.time_ns[after])
        errors.append(np.hypot(x - truth.x_m[after], y - truth.y_m[after]))
        agent_turns = [t for t in turns if t.get("agent_id", agent_id) == agent_id]
        if agent_turns and np.all(np.isfinite(truth.heading_rad)):
            times = np.array([int(t["time_ns"]) for t in agent_turns]) + int(TURN_SETTLE_S * 1e9)
            times = times[(times > scans[0].timestamp_ns) & (times <= truth.time_ns[-1])]
            _, _, heading = track.at(times)
            true_heading = np.array([_heading_at(truth, t) for t in times])
            heading_errors.append(np.degrees(np.abs(np.remainder(heading - true_heading + math.pi, 2 * math.pi)
                                                    - math.pi)))
    row = WaypointErrors(run.method, map_matching, matcher, path.name,
                         np.concatenate(errors) if errors else np.array([]),
                         np.concatenate(heading_errors) if heading_errors else np.array([]))
    if map_matching and run.method == "paper" and turns:
        row.snaps_correct, row.snaps_total, row.snaps_wrong = _snap_score(turns, run.snaps)
    return row


def _heading_at(truth: Any, time_ns: int) -> float:
    index = int(np.clip(np.searchsorted(truth.time_ns, time_ns), 0, len(truth.time_ns) - 1))
    return float(truth.heading_rad[index])


def _snap_score(turns: list[dict], snaps: list[tuple[str, Any]]) -> tuple[int, int, int]:
    """(true passages with a correct applied snap, true passages, applied snaps at a wrong point)."""
    applied = [(agent_id, s) for agent_id, s in snaps if s.applied]
    correct, used = 0, set()
    for turn in turns:
        agent_id = turn.get("agent_id")
        for index, (snap_agent, snap) in enumerate(applied):
            if index in used or (agent_id is not None and snap_agent != agent_id):
                continue
            if snap.point_id == turn.get("point_id") and abs(snap.time_ns - int(turn["time_ns"])) <= SNAP_MATCH_S * 1e9:
                correct += 1
                used.add(index)
                break
    wrong = sum(1 for index in range(len(applied)) if index not in used)
    return correct, len(turns), wrong


def pooled(report: PedestrianReport) -> list[tuple[tuple[str, bool, str], np.ndarray, np.ndarray, list[WaypointErrors]]]:
    """Rows of every session pooled per (method, map matching, matcher), in first-seen order."""
    groups: dict[tuple[str, bool, str], list[WaypointErrors]] = {}
    for row in report.rows:
        groups.setdefault((row.method, row.map_matching, row.matcher), []).append(row)
    return [(key, np.concatenate([r.errors_m for r in rows]), np.concatenate([r.heading_errors_deg for r in rows]),
             rows) for key, rows in groups.items()]


def _percentiles(values: np.ndarray) -> dict[str, float | None]:
    if not len(values):
        return {"median": None, "p75": None, "p90": None}
    median, p75, p90 = np.percentile(values, [50, 75, 90])
    return {"median": round(float(median), 3), "p75": round(float(p75), 3), "p90": round(float(p90), 3)}


def _snaps(rows: list[WaypointErrors]) -> dict[str, int] | None:
    if any(r.snaps_total is None for r in rows):
        return None
    return {"correct": sum(r.snaps_correct or 0 for r in rows), "true_turns": sum(r.snaps_total or 0 for r in rows),
            "wrong": sum(r.snaps_wrong or 0 for r in rows)}


def to_json(report: PedestrianReport) -> dict[str, Any]:
    results = []
    for (method, map_matching, matcher), errors, headings, rows in pooled(report):
        results.append({"method": method, "map_matching": map_matching, "matcher": matcher,
                        "waypoints": int(len(errors)), "waypoint_error_m": _percentiles(errors),
                        "heading_error_after_turn_deg": _percentiles(headings) if len(headings) else None,
                        "turn_snaps": _snaps(rows),
                        "per_session_p75_m": {r.session: _percentiles(r.errors_m)["p75"] for r in rows}})
    return {"sessions": report.sessions, "results": results, "problems": report.problems}


def to_table(report: PedestrianReport) -> str:
    fmt = lambda v: "-" if v is None else f"{v:.2f}"  # noqa: E731
    lines = [f"{len(report.sessions)} pedestrian session(s): position error at the truth waypoints after the "
             "first stand (m)",
             f"{'method':8} {'map matching':16} {'waypoints':>9} {'median':>7} {'p75':>7} {'p90':>7} "
             f"{'heading after turns p90 deg':>28} {'turn snaps':>18}"]
    for (method, map_matching, matcher), errors, headings, rows in pooled(report):
        p = _percentiles(errors)
        h = _percentiles(headings)["p90"] if len(headings) else None
        snaps = _snaps(rows)
        snap_text = "-" if snaps is None else f"{snaps['correct']}/{snaps['true_turns']}, {snaps['wrong']} wrong"
        lines.append(f"{method:8} {(matcher if map_matching else 'none'):16} {len(errors):9d} {fmt(p['median']):>7} "
                     f"{fmt(p['p75']):>7} {fmt(p['p90']):>7} {fmt(h):>28} {snap_text:>18}")
    if len(report.sessions) > 1:
        lines += ["", "p75 per session (m): " + ", ".join(
            f"{key[0]}{'+' + key[2] if key[1] else ''}" for key, *_ in pooled(report))]
        by_session: dict[str, list[str]] = {}
        for _, _, _, rows in pooled(report):
            for r in rows:
                by_session.setdefault(r.session, []).append(fmt(_percentiles(r.errors_m)["p75"]))
        lines += [f"  {name}: {'  '.join(values)}" for name, values in by_session.items()]
    lines += [f"note: {problem}" for problem in report.problems]
    return "\n".join(lines)
