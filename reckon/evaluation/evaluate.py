"""`reckon eval`: every heading x correction set of the paper's method, scored against truth."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from edge.chair.paper.impacts import PAPER_THRESHOLD_G
from hub.chair.hub import HubSettings
from hub.chair.paper import Collision, pair_impacts
from protocol.errors import InputError
from protocol.session_log import SessionData, read_session
from reckon.evaluation.headings import HeadingSource, headings
from reckon.evaluation.inputs import EvalInputs, agent_impacts, build_inputs
from reckon.evaluation.metrics import (DetectionScore, ErrorSummary, average_summaries, error_summary,
                                       score_collisions)
from reckon.evaluation.paper_run import VIDEO_RUNS, reception_from_sightings, reception_from_truth, run_paper
from reckon.evaluation.reckon_run import log_inputs, run_reckon, without_magnetometer

log = logging.getLogger(__name__)

CORRECTION_SETS: tuple[tuple[str, ...], ...] = (
    (), ("beacon",), ("beacon_zone",), ("collision",), ("collision_midpoint",),
    ("beacon", "collision"), ("beacon_zone", "collision"), ("video",),
)
RECKON_CORRECTION_SETS: tuple[tuple[str, ...], ...] = ((), ("beacon",), ("collision",), ("beacon", "collision"))
# with camera tracks in the session, also: ("camera",) and ("beacon", "collision", "camera")
GYRO_ONLY = "gyro"  # our heading without the seat magnetometer (the magnetometer aid's ablation)
DETECTION_THRESHOLDS_G = tuple(float(g) for g in range(4, 13))  # the paper's Fig. 5 range


@dataclass
class ResultRow:
    method: str
    heading: str
    corrections: tuple[str, ...]
    track: str | None  # ours: "live" or "refined"; the paper's method has one track
    summary: ErrorSummary
    corrections_applied: int
    team_curve_m: np.ndarray  # team-mean error per frame (first run for random fixes)
    x_m: np.ndarray  # (agents, frames) estimate of the first run
    y_m: np.ndarray
    nees: float | None = None  # ours, either track: median over frames of the position NEES (honest: 1.39)


@dataclass
class EvalReport:
    session_path: Path
    agent_ids: list[str]
    frame_s: np.ndarray
    truth_x_m: np.ndarray
    truth_y_m: np.ndarray
    court_m: tuple[float, float]
    rows: list[ResultRow] = field(default_factory=list)
    detection: list[DetectionScore] = field(default_factory=list)
    contact_pairs: DetectionScore | None = None  # ours: the contacts the hub took (collisions only), against the true ones
    problems: list[str] = field(default_factory=list)


def detect_collisions(inputs: EvalInputs, threshold_g: float) -> list[Collision]:
    return pair_impacts(agent_impacts(inputs, threshold_g))


def evaluate(path: Path, progress: Callable[[str], None] = lambda _: None) -> EvalReport:
    data = read_session(path)
    return evaluate_data(data, path, progress)


def position_nees(dx: np.ndarray, dy: np.ndarray, covariance: np.ndarray) -> float | None:
    """Median over agents and frames of e' P^-1 e, P the stated xx, xy, yy; None if no pose states one.

    For an honest Gaussian covariance e' P^-1 e is chi-square with 2 dof: mean 2, median 1.39; larger
    means the pose claims more certainty than it has."""
    xx, xy, yy = covariance[..., 0], covariance[..., 1], covariance[..., 2]
    det = xx * yy - xy * xy
    with np.errstate(invalid="ignore", divide="ignore"):
        value = (yy * dx * dx - 2.0 * xy * dx * dy + xx * dy * dy) / det
    value = value[np.isfinite(value) & (det > 0)]
    return float(np.median(value)) if len(value) else None


def evaluate_data(data: SessionData, path: Path, progress: Callable[[str], None] = lambda _: None) -> EvalReport:
    inputs = build_inputs(data)
    if any(a.truth_x_m is None for a in inputs.agents):
        missing = [a.agent.id for a in inputs.agents if a.truth_x_m is None]
        raise InputError(f"{path}: no truth poses for {', '.join(missing)}; `reckon eval` scores against truth")
    seed = int(data.session.source.get("seed", 0))
    frames = inputs.frame_index
    frame_s = (inputs.frame_ns - inputs.frame_ns[0]) * 1e-9
    truth_x = np.array([a.truth_x_m[frames] for a in inputs.agents])
    truth_y = np.array([a.truth_y_m[frames] for a in inputs.agents])
    venue = data.session.venue
    report = EvalReport(path, [a.agent.id for a in inputs.agents], frame_s, truth_x, truth_y,
                        (venue.court_length_m, venue.court_width_m), problems=list(data.problems))
    zones = {
        "beacon": np.array([reception_from_sightings(inputs.frame_ns, data.sightings.get(a.agent.id), venue) for a in inputs.agents]),
        "beacon_zone": np.array([reception_from_truth(tx, ty, venue) for tx, ty in zip(truth_x, truth_y)]),
    }
    progress("collision detection")
    detected_at = {g: detect_collisions(inputs, g) for g in DETECTION_THRESHOLDS_G}
    report.detection = [score_collisions(g, detected_at[g], data.contacts) for g in DETECTION_THRESHOLDS_G]
    collisions = detected_at[PAPER_THRESHOLD_G]
    sources = [HeadingSource.VIDEO]
    if all(a.truth_heading_rad is not None for a in inputs.agents):
        sources.insert(0, HeadingSource.TRUE)
    else:
        report.problems.append("truth has no headings: heading 'true' skipped")
    if all(a.seat_mag is not None for a in inputs.agents):
        sources.append(HeadingSource.SENSORS)
    else:
        report.problems.append("some seat sensors have no magnetometer: heading 'sensors' skipped")
    for source in sources:
        heading = headings(inputs, source, np.random.default_rng([seed, 1]))
        for corrections in CORRECTION_SETS:
            progress(f"paper, heading {source.value}, corrections {'+'.join(corrections) or 'none'}")
            runs = VIDEO_RUNS if "video" in corrections else 1
            summaries, first = [], None
            for run in range(runs):
                estimate = run_paper(inputs, heading, frozenset(corrections), venue, zones, collisions,
                                     np.random.default_rng([seed, 2, run]))
                error = np.hypot(estimate.x_m - truth_x, estimate.y_m - truth_y)
                summaries.append(error_summary(error, frame_s))
                if first is None:
                    first = (estimate, np.nanmean(error, axis=0))
            estimate, curve = first
            report.rows.append(ResultRow("paper", source.value, corrections, None, average_summaries(summaries),
                                         estimate.corrections_applied, curve, estimate.x_m, estimate.y_m))
    if all(a.seat_gyro_dps is not None for a in inputs.agents):
        progress("reckon: reading the log in arrival order")
        arrivals = log_inputs(path)
        camera_sets = (("camera",), ("beacon", "collision", "camera")) if data.cameras else ()
        runs = [(HeadingSource.SENSORS.value, arrivals, c) for c in RECKON_CORRECTION_SETS + camera_sets]
        if any(a.seat_mag is not None for a in inputs.agents):  # the magnetometer aid's ablation
            runs.append((GYRO_ONLY, without_magnetometer(arrivals), ()))
        for heading_name, messages_in, corrections in runs:
            progress(f"reckon, heading {heading_name}, corrections {'+'.join(corrections) or 'none'}")
            for track, estimate in zip(("live", "refined"),
                                       run_reckon(data.session, messages_in, inputs.frame_ns, frozenset(corrections))):
                dx, dy = estimate.x_m - truth_x, estimate.y_m - truth_y
                error = np.hypot(dx, dy)
                nees = None if estimate.covariance_m2 is None else position_nees(dx, dy, estimate.covariance_m2)
                report.rows.append(ResultRow("reckon", heading_name, corrections, track,
                                             error_summary(error, frame_s), estimate.corrections_applied,
                                             np.nanmean(error, axis=0), estimate.x_m, estimate.y_m, nees))
            if heading_name == HeadingSource.SENSORS.value and corrections == ("collision",):
                report.contact_pairs = score_collisions(HubSettings.impact_g, [Collision(t, a, b) for t, a, b in
                                                                               estimate.contacts], data.contacts)
    return report
