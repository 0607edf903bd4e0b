"""`reckon eval` on a swimming session: the paper's method and ours, per mounting and route.

- paper: edge/swim/paper.py with the TRUE wall times (the paper cut its lengths by hand);
- reckon: the live edge's own output (edge/swim/edge.py: walls detected from the sensor, no truth);
- reckon, true walls: our length estimate given the true wall times, to tell the estimator's error
  from the wall detector's.
Distances are scored per length against the simulator's truth (TruthLength: the body centre's
path from push-off to touch), and so are our stroke counts (TruthLength's stroke_count). Wall
detection is scored on the touches: a detected touch within MATCH_S of a true one is a hit (one to
one, nearest first); timing error is |detected - true|. `turns` pools every sensor of the session
(all mountings and strokes); the issue's turn goal is stated for the paper's setting, the waist
sensor, so `turns_by_mounting` gives each mounting's own.
"""

from __future__ import annotations

import logging
import math
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from edge.mounting import seat_to_chair
from edge.swim.bins import BinSettings, BodyBinner, T
from edge.swim.edge import SwimTracker, pick_zero_end
from edge.swim.length import RestGyro, YawDrift, lane_reading, reckon_length
from edge.swim.paper import paper_length
from protocol.errors import InputError
from protocol.session import AgentKind, Route, route_end_heading_rad
from protocol.session_log import SessionData

log = logging.getLogger(__name__)
MATCH_S = 1.0
# The paper's reported estimates (4 subjects, one length each; methods.md section 2), metres.
PAPER_REPORTED_M = {
    ("kickboard", "straight"): (25.01, 25.03), ("kickboard", "diagonal"): (28.96, 31.98),
    ("back", "straight"): (25.16, 26.16), ("back", "diagonal"): (25.79, 36.69),
    ("head", "straight"): (25.15, 28.90), ("head", "diagonal"): (26.43, 33.49),
    ("waist", "straight"): (25.03, 25.23), ("waist", "diagonal"): (27.58, 30.25),
}
METHODS = ("paper", "reckon", "reckon, true walls")


@dataclass(frozen=True)
class LengthScore:
    method: str
    agent_id: str
    sensor_id: str
    mounting: str
    route: str
    stroke: str
    index: int
    truth_m: float
    estimate_m: float
    # Strokes per length (TruthLength: arm strokes, leg beats for a kick); None where the method
    # counts none (the paper's).
    truth_strokes: int | None = None
    strokes: int | None = None

    @property
    def error_pct(self) -> float:
        return 100.0 * (self.estimate_m - self.truth_m) / self.truth_m

    @property
    def stroke_error(self) -> int | None:
        return None if self.strokes is None or self.truth_strokes is None else self.strokes - self.truth_strokes


@dataclass
class TurnScore:
    true_walls: int = 0
    detected: int = 0
    matched: int = 0
    timing_errors_s: list[float] = field(default_factory=list)
    push_errors_s: list[float] = field(default_factory=list)

    @property
    def precision(self) -> float | None:
        return self.matched / self.detected if self.detected else None

    @property
    def recall(self) -> float | None:
        return self.matched / self.true_walls if self.true_walls else None

    @staticmethod
    def p90(values: list[float]) -> float | None:
        return float(np.percentile(values, 90)) if values else None


@dataclass
class SwimReport:
    session_path: Path
    pool_length_m: float
    lengths: list[LengthScore] = field(default_factory=list)
    turns: TurnScore = field(default_factory=TurnScore)
    turns_by_mounting: dict[str, TurnScore] = field(default_factory=lambda: defaultdict(TurnScore))
    missed: dict[str, int] = field(default_factory=lambda: defaultdict(int))  # mounting -> lengths not found
    problems: list[str] = field(default_factory=list)

    def groups(self) -> dict[tuple[str, str, str, str], list[LengthScore]]:
        """(method, mounting, route, stroke) -> scores, in METHODS order then by name."""
        out: dict[tuple[str, str, str, str], list[LengthScore]] = defaultdict(list)
        for score in self.lengths:
            out[(score.method, score.mounting, score.route, score.stroke)].append(score)
        return dict(sorted(out.items(), key=lambda kv: (METHODS.index(kv[0][0]), kv[0][3] != "crawl", kv[0][3],
                                                         kv[0][1], kv[0][2])))


def is_swim_session(data: SessionData) -> bool:
    return bool(data.session.agents) and all(a.kind is AgentKind.SWIMMER for a in data.session.agents)


def evaluate_swim(data: SessionData, path: Path, progress: Callable[[str], None] = lambda _: None) -> SwimReport:
    pool = data.session.venue.court_length_m
    report = SwimReport(path, pool, problems=list(data.problems))
    strokes = data.session.source.get("strokes", {})
    for agent in data.session.agents:
        truth = data.lengths.get(agent.id, [])
        if not truth:
            raise InputError(f"{path}: no TruthLength for {agent.id}; `reckon eval` scores against truth")
        stroke = truth[0].stroke or str(strokes.get(agent.id, "?"))
        for sensor in agent.sensors:
            series = data.imu.get(sensor.id)
            if series is None or len(series.time_ns) < 10:
                report.problems.append(f"{sensor.id}: no samples")
                continue
            progress(f"{sensor.id}: {len(series.time_ns)} samples")
            common = dict(agent_id=agent.id, sensor_id=sensor.id, mounting=sensor.mount.value,
                          route=agent.route.value, stroke=stroke)
            forward, left = sensor.forward_axis or "+x", sensor.left_axis or "+y"
            accel = seat_to_chair(series.accel_g, forward, left)
            gyro = seat_to_chair(series.gyro_dps, forward, left)
            for k, length in enumerate(truth, start=1):
                a, b = np.searchsorted(series.time_ns, [length.start_ns, length.timestamp_ns])
                estimate = paper_length(series.time_ns[a:b + 1], accel[a:b + 1, 0], gyro[a:b + 1, 2], pool,
                                        math.degrees(route_end_heading_rad(agent.route)))
                report.lengths.append(LengthScore("paper", index=k, truth_m=length.swum_distance_m,
                                                  estimate_m=estimate.swum_distance_m, **common))
            rows = BodyBinner(BinSettings(sensor.rate_hz, forward, left)).push(series.time_ns, series.accel_g,
                                                                                 series.gyro_dps)
            _true_walls(report, rows, truth, pool, agent.route, common)
            tracker = SwimTracker(sensor, pool, agent.route)
            detected = tracker.push_rows(rows) + tracker.flush()
            for _ in range(tracker.counters.overlong):  # the tracker counts the lengths it dropped; said here
                log.warning("%s", tracker.overlong_warning())
            _score_detected(report, detected, truth, common)
    return report


def _true_walls(report: SwimReport, rows: np.ndarray, truth: list[Any], pool: float, route: Route,
                common: dict[str, Any]) -> None:
    times = rows[:, T]
    drift = YawDrift()  # every mounting learns its drift, as the live edge (edge/swim/edge.py)
    rest = RestGyro()  # as the live tracker: the rest before the set read for its first length's drift
    for k, length in enumerate(truth, start=1):
        push, touch = (int(i) for i in np.searchsorted(times, [length.start_ns, length.timestamp_ns]))
        if k == 1:
            rest.add(rows[:push])
        last = k == len(truth)
        following = length.timestamp_ns + 2_000_000_000 if last else truth[k].start_ns
        stop = min(int(np.searchsorted(times, following)), len(rows) - 1)
        touch = min(touch, stop)
        # As the live tracker: zero velocity at the touch, or at the next push-off (a set's last
        # length: 2 s into the rest) if the touch's leaves the swimmer going backwards.
        drift = drift.learn(lane_reading(rows, push, touch, touch, route, rest_offset_dps=rest.take()))
        estimate = pick_zero_end([reckon_length(rows, push, touch, zero_at, pool, route, drift_dps=drift.rate_dps)
                                  for zero_at in (touch, stop)])
        report.lengths.append(LengthScore("reckon, true walls", index=k, truth_m=length.swum_distance_m,
                                          estimate_m=estimate.swum_distance_m, truth_strokes=length.stroke_count,
                                          strokes=estimate.stroke_count, **common))


def _score_detected(report: SwimReport, detected: list[Any], truth: list[Any], common: dict[str, Any]) -> None:
    scores = (report.turns, report.turns_by_mounting[common["mounting"]])
    for turns in scores:
        turns.true_walls += len(truth)
        turns.detected += len(detected)
    pairs = sorted((abs(d.end_ns - t.timestamp_ns), i, j) for i, d in enumerate(detected) for j, t in enumerate(truth))
    used_d: set[int] = set()
    used_t: set[int] = set()
    for gap, i, j in pairs:
        if gap > MATCH_S * 1e9 or i in used_d or j in used_t:
            continue
        used_d.add(i)
        used_t.add(j)
        for turns in scores:
            turns.matched += 1
            turns.timing_errors_s.append(gap * 1e-9)
            turns.push_errors_s.append(abs(detected[i].start_ns - truth[j].start_ns) * 1e-9)
        report.lengths.append(LengthScore("reckon", index=j + 1, truth_m=truth[j].swum_distance_m,
                                          estimate_m=detected[i].swum_distance_m, truth_strokes=truth[j].stroke_count,
                                          strokes=detected[i].stroke_count, **common))
    report.missed[common["mounting"]] += len(truth) - len(used_t)


def _r(value: float | None, digits: int = 3) -> float | None:
    return None if value is None else round(value, digits)


def to_json(report: SwimReport) -> dict[str, Any]:
    results = []
    for (method, mounting, route, stroke), scores in report.groups().items():
        errors = np.array([s.error_pct for s in scores])
        estimates = np.array([s.estimate_m for s in scores])
        results.append({
            "method": method, "mounting": mounting, "route": route, "stroke": stroke, "lengths": len(scores),
            "distance_error_pct": {"mean": _r(float(errors.mean())), "max_abs": _r(float(np.abs(errors).max()))},
            "distance_m": {"min": _r(float(estimates.min())), "max": _r(float(estimates.max()))},
            "true_distance_m": {"min": _r(min(s.truth_m for s in scores)), "max": _r(max(s.truth_m for s in scores))},
            **({"paper_reported_m": list(PAPER_REPORTED_M[(mounting, route)])}
               if method == "paper" and (mounting, route) in PAPER_REPORTED_M else {}),
            **({"stroke_count_error": strokes} if (strokes := _stroke_errors(scores)) else {}),
        })
    return {
        "session": str(report.session_path),
        "results": results,
        "turns": _turns_json(report.turns),
        "turns_by_mounting": {mounting: _turns_json(t) for mounting, t in sorted(report.turns_by_mounting.items())},
        "problems": report.problems,
    }


def _stroke_errors(scores: list[LengthScore]) -> dict[str, Any] | None:
    """Counted minus true strokes per length: mean, max |error| (strokes) and mean |error| in % of
    the true count; None when the method counts no strokes."""
    pairs = [(s.stroke_error, s.truth_strokes) for s in scores if s.stroke_error is not None]
    if not pairs:
        return None
    errors = np.array([e for e, _ in pairs], dtype=float)
    truth = np.array([max(t or 0, 1) for _, t in pairs], dtype=float)
    return {"mean": _r(float(errors.mean()), 2), "max_abs": int(np.abs(errors).max()),
            "mean_abs_pct": _r(float(np.mean(np.abs(errors) / truth) * 100.0), 1)}


def _turns_json(t: TurnScore) -> dict[str, Any]:
    return {"precision": _r(t.precision, 4), "recall": _r(t.recall, 4),
            "timing_error_s_p90": _r(t.p90(t.timing_errors_s)), "push_off_error_s_p90": _r(t.p90(t.push_errors_s)),
            "true_walls": t.true_walls, "detected": t.detected, "matched": t.matched,
            "missed": t.true_walls - t.matched, "false": t.detected - t.matched}


def to_table(report: SwimReport) -> str:
    lines = [f"session {report.session_path}: swum distance per length, pool {report.pool_length_m:g} m",
             f"{'method':19} {'stroke':12} {'mounting':9} {'route':8} {'n':>3} {'err mean %':>10} {'max |err| %':>11} "
             f"{'estimates m':>13} {'truth m':>13} {'paper reported':>15} {'strokes: err mean / max, |%|':>28}"]
    for (method, mounting, route, stroke), scores in report.groups().items():
        errors = np.array([s.error_pct for s in scores])
        est = [s.estimate_m for s in scores]
        tru = [s.truth_m for s in scores]
        reported = PAPER_REPORTED_M.get((mounting, route)) if method == "paper" and stroke in ("crawl", "kick") else None
        strokes = _stroke_errors(scores)
        lines.append(f"{method:19} {stroke:12} {mounting:9} {route:8} {len(scores):3d} {errors.mean():10.2f} "
                     f"{np.abs(errors).max():11.2f} {min(est):6.2f}-{max(est):6.2f} {min(tru):6.2f}-{max(tru):6.2f} "
                     + (f"{reported[0]:6.2f}-{reported[1]:6.2f}" if reported else f"{'-':>15}")
                     + (f" {strokes['mean']:+9.2f} / {strokes['max_abs']:3d}, {strokes['mean_abs_pct']:5.1f} %"
                        if strokes else f" {'-':>28}"))
    fmt = lambda v: "-" if v is None else f"{v:.3f}"  # noqa: E731

    def turn_line(name: str, t: TurnScore) -> str:
        return (f"{name}: {t.true_walls} true, {t.detected} detected, {t.matched} matched within {MATCH_S:g} s: "
                f"precision {fmt(t.precision)}, recall {fmt(t.recall)}, touch timing p90 "
                f"{fmt(t.p90(t.timing_errors_s))} s, push-off timing p90 {fmt(t.p90(t.push_errors_s))} s")

    lines += ["", turn_line("walls (touches) from the sensors, no truth given, every sensor pooled", report.turns)]
    lines += [turn_line(f"  {mounting}", t) for mounting, t in sorted(report.turns_by_mounting.items())]
    for problem in report.problems:
        lines.append(f"note: {problem}")
    return "\n".join(lines)
