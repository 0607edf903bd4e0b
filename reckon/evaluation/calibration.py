"""`reckon calibrate`: the simulator against the paper's only real-world figure.

The paper's dead reckoning with video-derived heading: team-mean error about 2.2 m after 2 min,
5.3 m at most over the 317 s game (sec. 4.3, Fig. 7). For each seed this simulates the default
game, runs the paper's dead reckoning (no corrections) with the true, video-derived and
magnetometer headings, and reports the curves against that figure with a +-25 % band. The
`video ...` variants rerun the video heading with one assumption changed, to show which error
sources could close a gap; the simulator itself is never adjusted here.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from protocol.session_log import read_session
from reckon.evaluation.headings import HeadingSource, VideoModel, headings
from reckon.evaluation.inputs import build_inputs
from reckon.evaluation.metrics import ErrorSummary, error_summary
from reckon.evaluation.paper_run import run_paper

PAPER_AT_120S_M = 2.2
PAPER_MAX_M = 5.3
BAND = 0.25

# name -> (heading source, video model): the three headings, then video-heading what-ifs.
VARIANTS: dict[str, tuple[HeadingSource, VideoModel]] = {
    "true": (HeadingSource.TRUE, VideoModel()),
    "video": (HeadingSource.VIDEO, VideoModel()),
    "sensors": (HeadingSource.SENSORS, VideoModel()),
    "video, noise 0.3 m": (HeadingSource.VIDEO, VideoModel(position_noise_m=0.3)),
    "video, no smoothing": (HeadingSource.VIDEO, VideoModel(smoothing_frames=1)),
    "video, clocks 0.5 s apart": (HeadingSource.VIDEO, VideoModel(sync_offset_s=0.5)),
}


@dataclass
class CalibrationRow:
    seed: int
    variant: str
    summary: ErrorSummary
    curve_m: np.ndarray


@dataclass
class Calibration:
    frame_s: np.ndarray
    rows: list[CalibrationRow]


def calibrate_sessions(sessions: dict[int, Path], progress: Callable[[str], None] = lambda _: None) -> Calibration:
    rows, frame_s = [], None
    for seed, path in sessions.items():
        inputs = build_inputs(read_session(path))
        frames = inputs.frame_index
        seconds = (inputs.frame_ns - inputs.frame_ns[0]) * 1e-9
        frame_s = seconds if frame_s is None or len(seconds) < len(frame_s) else frame_s
        truth_x = np.array([a.truth_x_m[frames] for a in inputs.agents])
        truth_y = np.array([a.truth_y_m[frames] for a in inputs.agents])
        for name, (source, video) in VARIANTS.items():
            progress(f"seed {seed}: dead reckoning, heading {name}")
            heading = headings(inputs, source, np.random.default_rng([seed, 1]), video)
            estimate = run_paper(inputs, heading, frozenset(), None, {}, [], np.random.default_rng(0))
            error = np.hypot(estimate.x_m - truth_x, estimate.y_m - truth_y)
            rows.append(CalibrationRow(seed, name, error_summary(error, seconds), np.nanmean(error, axis=0)))
    return Calibration(frame_s, rows)


def verdict(value: float, paper: float) -> str:
    low, high = paper * (1 - BAND), paper * (1 + BAND)
    return "within" if low <= value <= high else ("below" if value < low else "above")


def to_table(calibration: Calibration) -> str:
    lines = [f"paper's dead reckoning with video heading: {PAPER_AT_120S_M} m at 120 s, {PAPER_MAX_M} m max; "
             f"band +-{BAND:.0%}: {PAPER_AT_120S_M * (1 - BAND):.2f}-{PAPER_AT_120S_M * (1 + BAND):.2f} m, "
             f"{PAPER_MAX_M * (1 - BAND):.2f}-{PAPER_MAX_M * (1 + BAND):.2f} m",
             f"{'heading':28} {'seed':>4} {'@120s':>6} {'max':>6} {'final':>6} {'mean':>6}"]
    for name in VARIANTS:
        rows = [r for r in calibration.rows if r.variant == name]
        for r in rows:
            s = r.summary
            lines.append(f"{name:28} {r.seed:4d} {s.team_mean_error_at_120s_m:6.2f} {s.max_team_mean_error_m:6.2f} "
                         f"{s.final_team_mean_error_m:6.2f} {s.mean_error_m:6.2f}")
        at120 = float(np.mean([r.summary.team_mean_error_at_120s_m for r in rows]))
        peak = float(np.mean([r.summary.max_team_mean_error_m for r in rows]))
        lines.append(f"{name:28} {'mean':>4} {at120:6.2f} {peak:6.2f}   -> @120s {verdict(at120, PAPER_AT_120S_M)}, "
                     f"max {verdict(peak, PAPER_MAX_M)} the paper's band")
    return "\n".join(lines)


def to_json(calibration: Calibration) -> dict:
    return {"paper": {"at_120s_m": PAPER_AT_120S_M, "max_m": PAPER_MAX_M, "band": BAND},
            "rows": [{"seed": r.seed, "heading": r.variant,
                      **{k: round(v, 4) for k, v in dataclasses.asdict(r.summary).items()}}
                     for r in calibration.rows]}


def write_plot(calibration: Calibration, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.8))
    colours = {"true": "tab:green", "video": "tab:blue", "sensors": "tab:red"}
    n = len(calibration.frame_s)
    for name, colour in colours.items():
        curves = np.array([r.curve_m[:n] for r in calibration.rows if r.variant == name])
        if len(curves) == 0:
            continue
        for curve in curves:
            ax.plot(calibration.frame_s, curve, color=colour, lw=0.6, alpha=0.45)
        ax.plot(calibration.frame_s, curves.mean(axis=0), color=colour, lw=2.2, label=f"heading {name} (mean of seeds)")
    for name, style in zip([v for v in VARIANTS if v.startswith("video,")], ("--", "-.", ":")):
        curves = np.array([r.curve_m[:n] for r in calibration.rows if r.variant == name])
        ax.plot(calibration.frame_s, curves.mean(axis=0), color="tab:blue", lw=1.4, ls=style, label=f"what if: {name}")
    for t, value in ((120.0, PAPER_AT_120S_M), (317.0, PAPER_MAX_M)):
        ax.errorbar([t], [value], yerr=[[value * BAND], [value * BAND]], fmt="k*", ms=12, capsize=5)
    ax.plot([], [], "k*", ms=10, label="paper, video heading (+-25 %)")
    top = max(PAPER_MAX_M * 1.5, float(np.nanmax([r.curve_m.max() for r in calibration.rows if r.variant != "sensors"])) * 1.2)
    ax.set_ylim(0, top)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("team-mean position error (m)")
    ax.set_title("paper's dead reckoning, no corrections: simulator vs paper (sensors curve clipped)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
