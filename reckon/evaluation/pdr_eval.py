"""`reckon eval` on pedestrian sessions (phones): the paper's method and ours, with and without
map matching, scored at the truth waypoints.

Each session is pushed in log order through the live code: the edge (edge/pedestrian/edge.py, with our
dead reckoning or the paper's) and the hub's map matcher (hub/pedestrian/hub.py). One pass gives
both rows of a method: the edge's poses (no map matching) and the hub's (map matching).
- paper: edge/pedestrian/paper.py (5 s FFT cadence, height model, Euler attitude) and the paper's turn
  snap to corridor points (hub/pedestrian/paper.py), which needs the venue's `map_points`; on a
  floor plan alone it has nothing to snap to and its map-matched row is left out (noted);
- reckon: edge/pedestrian/estimator.py and the particle filter over the walkable area (hub/pedestrian/particles.py).

The hub's live poses that are the edge's own track because the map contradicted it (the map
guard, hub/pedestrian/guard.py: `map_fallback` on the pose) are counted per method; and every
truth position of a session with a map is checked against the walkable area the hub matches on
(hub/pedestrian/walkable.py): how many lie outside it and how far (a map problem, reported).

Scoring: every truth pose after the agent's first accepted stand scan is a waypoint; the estimate
there is interpolated between the track's poses (the stand pose starts each track). Over the
waypoints of every session given: median, p75 and p90 of the position error in metres. Where the
session says where the true turns were (`source.turns`, the simulator), the heading error
TURN_SETTLE_S after each turn, and for the paper's snap whether it snapped to the right point.
Where the truth names floors (a building of several), each pose's floor (the edge's, from the last
stand and the barometer: edge/pedestrian/floors.py) is scored too: the share of waypoints on the
right floor, and the IPIN competitions' score, p75 of the horizontal error plus FLOOR_PENALTY_M
for each floor wrong. Each track's covariance is scored too: the median over waypoints of the
position NEES e' P^-1 e with the covariance of the last pose at or before the waypoint (honest:
1.39, the median of a chi-square with 2 degrees of freedom).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from edge.pedestrian.edge import PedestrianEdge
from hub.pedestrian.matching import SnapStage
from hub.pedestrian.paper import PaperSnapMatcher
from hub.pedestrian.hub import PedestrianHub, our_matcher_factory
from hub.pedestrian.walkable import WalkableArea
from protocol import messages
from protocol.errors import InputError
from protocol.session import AgentKind, Mount, Session
from protocol.session_log import LogMessages, SessionData

TURN_SETTLE_S = 2.0  # heading scored this long after a true turn: the turn has ended, the snap is done
SNAP_MATCH_S = 3.0  # a snap counts for a true junction passage within this much time of it
INPUT_TYPES = ("ImuBatch", "StandScan", "Pressure", "BeaconSighting")
FLOOR_PENALTY_M = 15.0  # the IPIN competitions' score: p75 of (horizontal error + 15 m per floor wrong)


def is_pedestrian_session(data: SessionData) -> bool:
    """Every agent a pedestrian carrying a phone (hand or pocket); the identity paper's walkers
    wear a waist IMU and are scored by the identity evaluation instead."""
    agents = data.session.agents
    return bool(agents) and all(a.kind is AgentKind.PEDESTRIAN and any(s.mount in (Mount.HAND, Mount.POCKET)
                                                                         for s in a.sensors) for a in agents)


@dataclass
class Track:
    """One agent's output poses in time order (time ns, x m, y m, heading rad, floor) and each
    one's 2x2 position covariance (None: the pose gave none, a stand's)."""

    rows: list[tuple[int, float, float, float, int]] = field(default_factory=list)
    covariances: list[np.ndarray | None] = field(default_factory=list)

    def add(self, time_ns: int, x_m: float, y_m: float, heading_rad: float, floor: int = 0,
            covariance: Any = None) -> None:
        position = None if covariance is None or len(covariance) != 9 else \
            np.asarray(covariance, dtype=float).reshape(3, 3)[:2, :2]
        if self.rows and time_ns <= self.rows[-1][0]:
            self.rows[-1] = (time_ns, x_m, y_m, heading_rad, floor)  # a reset at a step's time replaces it
            self.covariances[-1] = position
        else:
            self.rows.append((time_ns, x_m, y_m, heading_rad, floor))
            self.covariances.append(position)

    def nees(self, time_ns: np.ndarray, dx_m: np.ndarray, dy_m: np.ndarray) -> np.ndarray:
        """e' P^-1 e of each error (estimate - truth) at these times, P the covariance of the last
        pose at or before it; NaN where that pose has none, inf where it is singular."""
        out = np.full(len(time_ns), math.nan)
        if not self.rows:
            return out
        times = np.array([row[0] for row in self.rows], dtype=np.int64)
        for i, index in enumerate(np.searchsorted(times, time_ns, side="right") - 1):
            covariance = self.covariances[index] if index >= 0 else None
            if covariance is not None:
                error = np.array([dx_m[i], dy_m[i]])
                try:
                    out[i] = float(error @ np.linalg.solve(covariance, error))
                except np.linalg.LinAlgError:  # a collapsed covariance claims no error at all
                    out[i] = math.inf
        return out

    def floor_at(self, time_ns: np.ndarray) -> np.ndarray:
        """The floor of the last pose at or before each time (the first pose's before it)."""
        if not self.rows:
            return np.zeros(len(time_ns), dtype=np.int64)
        times = np.array([row[0] for row in self.rows], dtype=np.int64)
        floors = np.array([row[4] for row in self.rows], dtype=np.int64)
        return floors[np.clip(np.searchsorted(times, time_ns, side="right") - 1, 0, len(floors) - 1)]

    def at(self, time_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rows = np.array([row[:4] for row in self.rows], dtype=float).reshape(-1, 4)
        if not len(rows):
            nan = np.full(len(time_ns), math.nan)
            return nan, nan, nan
        x = np.interp(time_ns, rows[:, 0], rows[:, 1])
        y = np.interp(time_ns, rows[:, 0], rows[:, 2])
        nearest = np.clip(np.searchsorted(rows[:, 0], time_ns, side="right") - 1, 0, len(rows) - 1)
        return x, y, rows[nearest, 3]


@dataclass
class BeaconFixCount:
    """Beacon passes judged by our hub's gate (hub/pedestrian/hub.py)."""

    taken: int = 0
    refused: int = 0
    elsewhere: int = 0  # another floor's beacon, or no pose near the pass

    def __add__(self, other: "BeaconFixCount") -> "BeaconFixCount":
        return BeaconFixCount(self.taken + other.taken, self.refused + other.refused, self.elsewhere + other.elsewhere)


@dataclass
class PhoneRun:
    """One phone (sensor) of one agent under one method: the edge's and the hub's tracks."""

    agent_id: str
    sensor_id: str
    mount: str
    edge: Track = field(default_factory=Track)
    hub: Track | None = None  # None: no map matcher for this method on this venue
    refined: Track | None = None  # the hub's pose/refined (a matcher with a lag), else None
    snaps: list[Any] = field(default_factory=list)  # the paper's SnapRecords
    live_poses: int = 0  # the hub's pose/live
    fallback_poses: int = 0  # ... of which the edge's own track (map_fallback)
    fixes: BeaconFixCount = field(default_factory=BeaconFixCount)


@dataclass
class WaypointErrors:
    method: str
    map_matching: bool
    matcher: str
    track: str  # live (the edge's, or the hub's pose/live) or refined (the hub's pose/refined)
    mount: str
    session: str
    errors_m: np.ndarray
    heading_errors_deg: np.ndarray
    nees: np.ndarray = field(default_factory=lambda: np.array([]))  # per waypoint (NaN: no covariance there)
    floor_errors: np.ndarray = field(default_factory=lambda: np.array([], dtype=np.int64))  # |floor - true| per waypoint
    floors_in_truth: bool = False  # the truth names floors (a building of several)
    snaps_correct: int | None = None
    snaps_total: int | None = None  # true turns
    snaps_wrong: int | None = None  # applied position snaps matching no true turn
    live_poses: int = 0  # the hub's track rows: its poses, and those on the edge's track (map_fallback)
    fallback_poses: int = 0


@dataclass(frozen=True)
class WalkableTruth:
    """One session's truth positions against the walkable area the hub matches on."""

    session: str
    positions: int
    outside_m: tuple[float, ...]  # the distance of each position outside, in time order


@dataclass
class PedestrianReport:
    sessions: list[str]
    rows: list[WaypointErrors] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    walkable: list[WalkableTruth] = field(default_factory=list)  # sessions with a map
    beacon_fixes: BeaconFixCount = field(default_factory=BeaconFixCount)


def phones(session: Session) -> list[tuple[Any, Any]]:
    """(agent, sensor) of every phone (hand or pocket) in the session."""
    return [(agent, sensor) for agent in session.agents for sensor in agent.sensors
            if sensor.mount in (Mount.HAND, Mount.POCKET)]


def run_method(session: Session, inputs: list[Any], method: str, area: WalkableArea | None = None,
               beacons: bool = False) -> list[PhoneRun]:
    """Push the session's phone batches and stand scans through one edge per phone and its hub
    (a hub per phone: the hub keys its matchers by agent, and one agent may carry two phones).
    `area`: the venue's walkable area when already built. `beacons`: our hub takes the phones'
    beacon sightings as fixes (the paper's method has none)."""
    if method == "paper":
        from edge.pedestrian.paper import PaperPdr

        points = session.venue.map_points
        def paper_matcher(agent_id: str, floor: int) -> PaperSnapMatcher | None:
            on_floor = tuple(p for p in points if p.floor == floor)
            return PaperSnapMatcher(on_floor) if on_floor else None

        factory = paper_matcher if points else None
    else:
        factory = our_matcher_factory(session.venue, area, beacons=beacons)
    runs: dict[str, tuple[PhoneRun, PedestrianEdge, PedestrianHub | None]] = {}
    for agent, sensor in phones(session):
        estimator = PaperPdr(height_m=agent.height_m) if method == "paper" else None
        edge = PedestrianEdge(agent, session.venue, estimator, method=method, sensor_id=sensor.id)
        hub = PedestrianHub(session, factory, method=method, beacons=beacons) if factory is not None else None
        runs[sensor.id] = (PhoneRun(agent.id, sensor.id, sensor.mount.value, hub=Track() if hub else None,
                                    refined=Track() if hub else None), edge, hub)
    for message in inputs:
        if message.sensor_id not in runs:
            continue
        run, edge, hub = runs[message.sensor_id]
        name = messages.type_name(message)
        if name == "StandScan":
            edge.scan(message)
            if message.accepted:
                run.edge.add(message.timestamp_ns, message.x_m, message.y_m, message.heading_rad, message.floor)
            continue
        if name == "Pressure":
            edge.pressure(message)
            continue
        if name == "BeaconSighting":
            if hub is not None:
                _take(run, hub.on_message(message))
            continue
        for pose in edge.push(message):
            run.edge.add(pose.timestamp_ns, pose.x_m, pose.y_m, pose.heading_rad, pose.floor, pose.covariance)
            if hub is not None:
                _take(run, hub.on_message(pose))
    for run, _, hub in runs.values():
        if hub is not None:
            _take(run, hub.flush())
            view = hub.agents[run.agent_id]
            run.snaps = list(view.snaps)
            run.fixes = BeaconFixCount(view.fixes_taken, view.fixes_refused, view.fixes_elsewhere)
            if run.refined is not None and not run.refined.rows:
                run.refined = None  # this matcher has no refined track
    return [run for run, _, _ in runs.values()]


def _take(run: PhoneRun, outputs: list[Any]) -> None:
    for out in outputs:
        track = run.refined if out.track == messages.Track.REFINED else run.hub
        if out.track != messages.Track.REFINED:
            run.live_poses += 1
            run.fallback_poses += bool(out.map_fallback)
        if track is not None:
            track.add(out.timestamp_ns, out.x_m, out.y_m, out.heading_rad, out.floor, out.covariance)


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
        venue = data.session.venue
        area = WalkableArea.from_venue(venue) if venue.floor_plan or venue.floor_plans or venue.map_points else None
        if area is not None:
            report.walkable.append(walkable_truth(data, path, area))
        heard = venue.beacons and any(messages.type_name(m) == "BeaconSighting" for m in inputs)
        for method, beacons in (("paper", False), ("reckon", False)) + ((("reckon", True),) if heard else ()):
            progress(f"{path.name}: {method}{' with beacons' if beacons else ''}")
            runs = run_method(data.session, inputs, method, area, beacons)
            report.beacon_fixes += sum((run.fixes for run in runs), start=BeaconFixCount()) if beacons else BeaconFixCount()
            for mount in sorted({run.mount for run in runs}):
                chosen = [run for run in runs if run.mount == mount]
                if not beacons:  # the edge's track is the same with or without them
                    report.rows.append(score(data, path, method, mount, chosen, "edge", "none"))
                matcher = ("turn snap" if method == "paper" else
                           ("particle filter" if area is not None else "") + (" + beacons" if beacons else ""))
                matcher = matcher.strip(" +") if matcher != " + beacons" else "beacons"
                for track in ("live", "refined"):
                    if all(getattr(run, "hub" if track == "live" else "refined") is not None for run in chosen):
                        report.rows.append(score(data, path, method, mount, chosen, track, matcher))
            if method == "paper" and not data.session.venue.map_points:
                no_points.append(path.name)
    if no_points:
        report.problems.append(f"{len(no_points)} of {len(sessions)} sessions have no corridor map points: the "
                               f"paper's turn snap has nothing to snap to there ({', '.join(no_points[:3])}"
                               f"{', ...' if len(no_points) > 3 else ''})")
    return report


def walkable_truth(data: SessionData, path: Path, area: WalkableArea) -> WalkableTruth:
    """Every truth position of the session against the walkable area of its floor (`area`: floor 0's)."""
    x_m = np.concatenate([truth.x_m for truth in data.truth.values()])
    y_m = np.concatenate([truth.y_m for truth in data.truth.values()])
    floors = np.concatenate([truth.floor if truth.floor is not None else np.zeros(len(truth.x_m), dtype=np.int64)
                             for truth in data.truth.values()])
    distances_m = np.zeros(len(x_m))
    for floor in np.unique(floors).tolist():
        on = floors == floor
        try:
            here = area if floor == 0 else WalkableArea.from_venue(data.session.venue, floor=int(floor))
        except ValueError:  # no map on that floor: nothing to check there
            continue
        distances_m[on] = here.outside_by_m(x_m[on], y_m[on])
    return WalkableTruth(path.name, len(x_m), tuple(float(d) for d in distances_m if d > 0.0))


def score(data: SessionData, path: Path, method: str, mount: str, runs: list[PhoneRun], track_name: str,
          matcher: str) -> WaypointErrors:
    """Waypoint errors (and heading after turns, snaps) of these phones' tracks: "edge" (no map
    matching), or the hub's "live" or "refined"."""
    map_matching = track_name != "edge"
    errors, heading_errors, floor_errors, nees = [], [], [], []
    turns = data.session.source.get("turns", []) if isinstance(data.session.source, dict) else []
    for run in runs:
        track = {"edge": run.edge, "live": run.hub, "refined": run.refined}[track_name] or run.edge
        truth = data.truth[run.agent_id]
        scans = [s for s in data.scans.get(run.agent_id, []) if s.accepted and s.sensor_id in ("", run.sensor_id)]
        if not scans:
            continue
        after = truth.time_ns > scans[0].timestamp_ns
        x, y, _ = track.at(truth.time_ns[after])
        errors.append(np.hypot(x - truth.x_m[after], y - truth.y_m[after]))
        nees.append(track.nees(truth.time_ns[after], x - truth.x_m[after], y - truth.y_m[after]))
        true_floor = truth.floor[after] if truth.floor is not None else np.zeros(int(after.sum()), dtype=np.int64)
        floor_errors.append(np.abs(track.floor_at(truth.time_ns[after]) - true_floor))
        agent_turns = [t for t in turns if t.get("agent_id", run.agent_id) == run.agent_id]
        if agent_turns and np.all(np.isfinite(truth.heading_rad)) and track_name != "refined":  # it keeps live's
            times = np.array([int(t["time_ns"]) for t in agent_turns]) + int(TURN_SETTLE_S * 1e9)
            times = times[(times > scans[0].timestamp_ns) & (times <= truth.time_ns[-1])]
            _, _, heading = track.at(times)
            true_heading = np.array([_heading_at(truth, t) for t in times])
            heading_errors.append(np.degrees(np.abs(np.remainder(heading - true_heading + math.pi, 2 * math.pi)
                                                    - math.pi)))
    row = WaypointErrors(method, map_matching, matcher, "live" if track_name == "edge" else track_name, mount,
                         path.name,
                         np.concatenate(errors) if errors else np.array([]),
                         np.concatenate(heading_errors) if heading_errors else np.array([]),
                         np.concatenate(nees) if nees else np.array([]),
                         np.concatenate(floor_errors) if floor_errors else np.array([], dtype=np.int64),
                         any(truth.floor is not None for truth in data.truth.values()))
    if track_name == "live" and method == "paper" and turns:
        row.snaps_correct, row.snaps_total, row.snaps_wrong = _snap_score(
            [t for t in turns if any(t.get("agent_id", r.agent_id) == r.agent_id for r in runs)],
            [(r.agent_id, snap) for r in runs for snap in r.snaps])
    if track_name == "live":
        row.live_poses = sum(r.live_poses for r in runs)
        row.fallback_poses = sum(r.fallback_poses for r in runs)
    return row


def _heading_at(truth: Any, time_ns: int) -> float:
    index = int(np.clip(np.searchsorted(truth.time_ns, time_ns), 0, len(truth.time_ns) - 1))
    return float(truth.heading_rad[index])


def _snap_score(turns: list[dict], snaps: list[tuple[str, Any]]) -> tuple[int, int, int]:
    """(true turns with a correct position snap, true turns, position snaps matching no true turn)."""
    # The position snap names the point; the heading snap that follows it is the same decision.
    applied = [(agent_id, s) for agent_id, s in snaps if s.applied and s.stage is SnapStage.POSITION]
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


def pooled(report: PedestrianReport) -> list[tuple[tuple[str, bool, str, str, str], np.ndarray, np.ndarray,
                                                  list[WaypointErrors]]]:
    """Rows of every session pooled per (method, map matching, matcher, track, mount), by mount."""
    groups: dict[tuple[str, bool, str, str, str], list[WaypointErrors]] = {}
    for row in sorted(report.rows, key=lambda r: r.mount):
        groups.setdefault((row.method, row.map_matching, row.matcher, row.track, row.mount), []).append(row)
    return [(key, np.concatenate([r.errors_m for r in rows]), np.concatenate([r.heading_errors_deg for r in rows]),
             rows) for key, rows in groups.items()]


def _percentiles(values: np.ndarray) -> dict[str, float | None]:
    if not len(values):
        return {"median": None, "p75": None, "p90": None}
    median, p75, p90 = np.percentile(values, [50, 75, 90])
    return {"median": round(float(median), 3), "p75": round(float(p75), 3), "p90": round(float(p90), 3)}


def floor_score(rows: list[WaypointErrors]) -> dict[str, Any]:
    """Waypoints on the right floor, and the IPIN score: p75 of error + FLOOR_PENALTY_M x floors wrong."""
    errors = np.concatenate([r.errors_m for r in rows])
    wrong = np.concatenate([r.floor_errors for r in rows])
    if not len(errors):
        return {"right_floor": None, "ipin_score_m": None}
    return {"right_floor": round(float(np.mean(wrong == 0)), 4),
            "ipin_score_m": round(float(np.percentile(errors + FLOOR_PENALTY_M * wrong, 75)), 3)}


def nees_median(rows: list[WaypointErrors]) -> float | None:
    """The median position NEES over these rows' waypoints that have a covariance (None: none has)."""
    values = np.concatenate([r.nees for r in rows]) if rows else np.array([])
    values = values[np.isfinite(values)]
    return round(float(np.median(values)), 3) if len(values) else None


def _snaps(rows: list[WaypointErrors]) -> dict[str, int] | None:
    if any(r.snaps_total is None for r in rows):
        return None
    return {"correct": sum(r.snaps_correct or 0 for r in rows), "true_turns": sum(r.snaps_total or 0 for r in rows),
            "wrong": sum(r.snaps_wrong or 0 for r in rows)}


def to_json(report: PedestrianReport) -> dict[str, Any]:
    results = []
    for (method, map_matching, matcher, track, mount), errors, headings, rows in pooled(report):
        results.append({"method": method, "map_matching": map_matching, "matcher": matcher, "track": track,
                        "mount": mount,
                        "waypoints": int(len(errors)), "waypoint_error_m": _percentiles(errors),
                        "nees_median": nees_median(rows),
                        "heading_error_after_turn_deg": _percentiles(headings) if len(headings) else None,
                        "turn_snaps": _snaps(rows),
                        "map_fallback": ({"poses": sum(r.fallback_poses for r in rows),
                                          "of_live_poses": sum(r.live_poses for r in rows)}
                                         if map_matching and track == "live" else None),
                        "floors": floor_score(rows),
                        "per_session_p75_m": {r.session: _percentiles(r.errors_m)["p75"] for r in rows}})
    return {"sessions": report.sessions, "results": results, "problems": report.problems,
            "beacon_fixes": dataclasses.asdict(report.beacon_fixes),
            "walkable_truth": [{"session": w.session, "positions": w.positions, "outside": len(w.outside_m),
                                "farthest_outside_m": round(max(w.outside_m), 3) if w.outside_m else None}
                               for w in report.walkable]}


def to_table(report: PedestrianReport) -> str:
    fmt = lambda v: "-" if v is None else f"{v:.2f}"  # noqa: E731
    lines = [f"{len(report.sessions)} pedestrian session(s): position error at the truth waypoints after the "
             "first stand (m)",
             f"{'method':8} {'phone':7} {'map matching':36} {'waypoints':>9} {'median':>7} {'p75':>7} {'p90':>7} "
             f"{'NEES':>6} {'heading after turns p90 deg':>28} {'turn snaps':>18}"]
    for (method, map_matching, matcher, track, mount), errors, headings, rows in pooled(report):
        p = _percentiles(errors)
        matcher = matcher + (", refined" if track == "refined" else "")
        h = _percentiles(headings)["p90"] if len(headings) else None
        snaps = _snaps(rows)
        snap_text = "-" if snaps is None else f"{snaps['correct']}/{snaps['true_turns']}, {snaps['wrong']} wrong"
        lines.append(f"{method:8} {mount:7} {(matcher if map_matching else 'none'):36} {len(errors):9d} {fmt(p['median']):>7} "
                     f"{fmt(p['p75']):>7} {fmt(p['p90']):>7} {fmt(nees_median(rows)):>6} {fmt(h):>28} {snap_text:>18}")
    if len(report.sessions) > 1:
        lines += ["", "p75 per session (m): " + ", ".join(
            f"{key[0]}{'+' + key[2] if key[1] else ''}{' refined' if key[3] == 'refined' else ''} ({key[4]})"
            for key, *_ in pooled(report))]
        by_session: dict[str, list[str]] = {}
        for _, _, _, rows in pooled(report):
            for r in rows:
                by_session.setdefault(r.session, []).append(fmt(_percentiles(r.errors_m)["p75"]))
        lines += [f"  {name}: {'  '.join(values)}" for name, values in by_session.items()]
    fallbacks = [(key, rows) for key, _, _, rows in pooled(report) if key[1] and key[3] == "live"
                 and any(r.fallback_poses for r in rows)]
    for (method, _, matcher, _, mount), rows in fallbacks:
        lines.append(f"map guard: {method}+{matcher} ({mount}): {sum(r.fallback_poses for r in rows)} of "
                     f"{sum(r.live_poses for r in rows)} live poses on the edge's track (the map contradicted it), "
                     f"in {sum(1 for r in rows if r.fallback_poses)} of {len(rows)} sessions")
    if any(r.floors_in_truth for r in report.rows):
        lines.append(f"floors (IPIN score: p75 of the error + {FLOOR_PENALTY_M:.0f} m per floor wrong): " + "; ".join(
            f"{key[0]}{'+' + key[2] if key[1] else ''}{' refined' if key[3] == 'refined' else ''} ({key[4]}) "
            f"{fmt(score['ipin_score_m'])} m, right floor {100 * (score['right_floor'] or 0):.1f} %"
            for key, _, _, rows in pooled(report) for score in [floor_score(rows)]))
    fixes = report.beacon_fixes
    if fixes.taken or fixes.refused or fixes.elsewhere:
        lines.append(f"beacon passes (ours): {fixes.taken} fixes taken, {fixes.refused} refused by the gate, "
                     f"{fixes.elsewhere} on another floor or off the track")
    if report.walkable:
        lines.append(walkable_line(report.walkable))
    lines += [f"note: {problem}" for problem in report.problems]
    return "\n".join(lines)


def walkable_line(checks: list[WalkableTruth]) -> str:
    """`truth positions walkable: 345 of 347; outside: a.mcap 2 (farthest 0.31 m)`."""
    total = sum(w.positions for w in checks)
    outside = [w for w in checks if w.outside_m]
    text = f"truth positions walkable for the hub: {total - sum(len(w.outside_m) for w in checks)} of {total}"
    if not outside:
        return text
    return text + "; outside: " + ", ".join(f"{w.session} {len(w.outside_m)} (farthest {max(w.outside_m):.2f} m)"
                                           for w in outside[:8]) + (", ..." if len(outside) > 8 else "")
