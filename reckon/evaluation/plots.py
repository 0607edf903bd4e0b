"""PNG plots of an evaluation: error over time, trajectories on the court, collision detection."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; no display on a Pi or in CI
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from reckon.evaluation.evaluate import EvalReport, ResultRow  # noqa: E402

# The paper's dead-reckoning curve (video heading, Fig. 7 and sec. 4.3): ~2.2 m after 2 min, 5.3 m max.
PAPER_DR_POINTS = ((120.0, 2.2), (317.0, 5.3))
PAPER_BEACON_MAX_M = 2.8


def write_plots(report: EvalReport, folder: Path, court_m: tuple[float, float]) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    return [_errors(report, folder / "error_over_time.png"),
            _trajectories(report, folder / "trajectories.png", court_m),
            _detection(report, folder / "collision_detection.png")]


def _errors(report: EvalReport, path: Path) -> Path:
    def panel(row: ResultRow) -> str:  # ours, with or without the magnetometer, beside the paper's sensors
        return "sensors" if row.track else row.heading

    headings = sorted({panel(row) for row in report.rows}, key=["true", "video", "sensors"].index)
    # each heading its own scale: the magnetometer's error is tens of times the others'
    fig, axes = plt.subplots(1, len(headings), figsize=(5.5 * len(headings), 4.2), squeeze=False)
    for ax, heading in zip(axes[0], headings):
        for row in report.rows:
            if panel(row) == heading:
                label = "+".join(row.corrections) or "none"
                if row.track:
                    label = f"reckon {row.track}{' gyro only' if row.heading == 'gyro' else ''}: {label}"
                ax.plot(report.frame_s, row.team_curve_m, lw=1.6 if row.track else 1.0,
                        ls="-" if row.track else "--", label=label)
        ax.plot(*zip(*PAPER_DR_POINTS), "k*", ms=11, label="paper DR (video heading)")
        ax.axhline(PAPER_BEACON_MAX_M, color="k", ls=":", lw=1, label="paper beacon max 2.8 m")
        ax.set_title(f"paper's method, heading: {heading}")
        ax.set_xlabel("time (s)")
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
        ax.set_ylabel("team-mean position error (m)")
    axes[0][0].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


TRAJECTORY_AGENTS = 3  # more chairs than this over a whole game is a tangle


def _trajectories(report: EvalReport, path: Path, court_m: tuple[float, float]) -> Path:
    rows = [r for r in report.rows if not r.corrections and r.heading in ("video", "sensors")]
    fig, axes = plt.subplots(1, len(rows), figsize=(7 * len(rows), 4.6), squeeze=False)
    colours = plt.cm.tab10(np.linspace(0, 1, 10))
    for ax, row in zip(axes[0], rows):
        ax.add_patch(plt.Rectangle((0, 0), *court_m, fill=False, lw=1.5))
        ax.axvline(court_m[0] / 2, color="grey", lw=0.8)
        for a, agent in enumerate(report.agent_ids[:TRAJECTORY_AGENTS]):
            c = colours[a % 10]
            ax.plot(report.truth_x_m[a], report.truth_y_m[a], color=c, lw=0.7, alpha=0.6)
            ax.plot(row.x_m[a], row.y_m[a], color=c, lw=0.9, ls="--", label=agent)
        ax.set_aspect("equal")
        ax.set_xlim(-6, court_m[0] + 6)
        ax.set_ylim(-6, court_m[1] + 6)
        ax.set_title(f"truth (solid) vs paper DR, heading {row.heading}, no corrections (dashed)", fontsize=9)
    axes[0][-1].legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _detection(report: EvalReport, path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(5, 3.6))
    g = [s.threshold_g for s in report.detection]
    ax.plot(g, [np.nan if s.precision is None else s.precision for s in report.detection], "o-", label="precision")
    ax.plot(g, [np.nan if s.recall is None else s.recall for s in report.detection], "s-", label="recall")
    ax.axvline(8, color="k", ls=":", lw=1)
    ax.set_xlabel("impact threshold Z (g)")
    ax.set_ylim(0, 1.05)
    ax.set_title("collision detection (paper's rule)")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
