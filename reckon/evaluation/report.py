"""The evaluation as JSON (one object) and as a text table."""

from __future__ import annotations

import dataclasses
from typing import Any

from reckon.evaluation.evaluate import EvalReport


def _round(value: float | None) -> float | None:
    return None if value is None else round(value, 4)


def _share(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def to_json(report: EvalReport) -> dict[str, Any]:
    return {
        "session": str(report.session_path),
        "results": [
            {"method": row.method, "heading": row.heading, "corrections": list(row.corrections),
             **({"track": row.track} if row.track else {}),
             **{k: _round(v) for k, v in dataclasses.asdict(row.summary).items()},
             "corrections_applied": row.corrections_applied,
             **({"nees": _round(row.nees)} if row.nees is not None else {})}
            for row in report.rows
        ],
        "collision_detection": [
            {"threshold_g": s.threshold_g, "precision": _round(s.precision), "recall": _round(s.recall),
             "detected": s.detected, "true_contacts": s.true_contacts}
            for s in report.detection
        ],
        **({"reckon_contact_pairs": {"threshold_g": s.threshold_g, "precision": _round(s.precision),
                                     "recall": _round(s.recall), "taken": s.detected, "true_contacts": s.true_contacts,
                                     "matched": s.matched}} if (s := report.contact_pairs) else {}),
        "problems": report.problems,
    }


def to_table(report: EvalReport) -> str:
    lines = [f"session {report.session_path}: {len(report.agent_ids)} agents, "
             f"{report.frame_s[-1]:.0f} s, errors per 10 fps frame",
             f"{'method':15} {'heading':8} {'corrections':26} {'mean':>6} {'max team':>9} {'worst':>6} "
             f"{'final':>6} {'@120s':>6} {'fixes':>6} {'NEES':>5}"]
    for row in report.rows:
        s = row.summary
        method = f"{row.method} {row.track}" if row.track else row.method
        lines.append(f"{method:15} {row.heading:8} {'+'.join(row.corrections) or 'none':26} "
                     f"{s.mean_error_m:6.2f} {s.max_team_mean_error_m:9.2f} {s.worst_agent_mean_error_m:6.2f} "
                     f"{s.final_team_mean_error_m:6.2f} {s.team_mean_error_at_120s_m:6.2f} {row.corrections_applied:6d} "
                     f"{'' if row.nees is None else f'{row.nees:5.2f}'}".rstrip())
    lines.append("errors in metres: mean over agents and time; max over time of the team mean (the paper's "
                 "figure); worst agent's mean; team mean at the end and at 120 s; heading 'gyro': ours without the "
                 "seat magnetometer; NEES: ours live, median of the position error squared over the stated "
                 "covariance (1.39 if the covariance is honest)")
    lines.append("")
    lines.append("collision detection (pairs within 0.5 s; 3+ chairs at once skipped), against true contacts")
    lines.append(f"{'threshold g':>11} {'detected':>8} {'true':>5} {'precision':>9} {'recall':>6}")
    for s in report.detection:
        lines.append(f"{s.threshold_g:11.0f} {s.detected:8d} {s.true_contacts:5d} {_share(s.precision):>9} "
                     f"{_share(s.recall):>6}")
    if (s := report.contact_pairs) is not None:
        lines.append(f"ours: the hub's contacts (impacts from {s.threshold_g:.0f} g, paired by timing, distance and "
                     f"pushes; collisions alone): {s.detected} taken, {s.matched} true, "
                     f"precision {_share(s.precision)}, recall {_share(s.recall)}")
    for problem in report.problems:
        lines.append(f"note: {problem}")
    return "\n".join(lines)
