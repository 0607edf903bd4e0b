"""`reckon bench --compare BASE.json`: every figure of this run beside a saved run's, as a ratio.

A figure more than WORSE_BY worse than the baseline is flagged, so a regression is seen the day it
lands rather than found later by bisecting. Which way is better is declared per figure (speeds up,
times and memory down); figures missing from either run (an older baseline) are listed as such,
never guessed. Timings are machine-dependent: compare runs from the same machine, idle.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from protocol.errors import ConfigError

WORSE_BY = 0.25  # flagged when this much worse than the baseline

HIGHER = "higher"
LOWER = "lower"

# (dotted path in the bench's JSON, which way is better, what it is)
FIGURES: tuple[tuple[str, str, str], ...] = (
    ("edge_samples_per_s", HIGHER, "edge kernel, samples/s"),
    ("details.edge.chair_edge.chair_samples_per_s", HIGHER, "whole ChairEdge.push, chair samples/s"),
    ("details.edge.chair_edge.raw_samples_per_s", HIGHER, "whole ChairEdge.push, raw samples/s"),
    ("details.edge.merger.us_per_chair_sample", LOWER, "merger, us per chair sample"),
    ("details.edge.startup.imports_s", LOWER, "edge imports, CPU s"),
    ("details.edge.startup.first_pose_wall_s", LOWER, "edge start-up to first pose, wall s"),
    ("pipeline_realtime_factor", HIGHER, "pipeline, x real time"),
    ("details.pipeline.cpu_s.hub", LOWER, "pipeline, hub CPU s"),
    ("details.pipeline.cpu_s.edges_total", LOWER, "pipeline, edges' CPU s"),
    ("details.hub_cost_us.cpu_per_input_in_run", LOWER, "hub CPU per input in the run, us"),
    ("details.hub_cost_us.python_per_input", LOWER, "hub Python per input, us"),
    ("latency_ms.p50", LOWER, "latency p50, ms"),
    ("latency_ms.p99", LOWER, "latency p99, ms"),
    ("details.latency.parts_ms.edge.p99", LOWER, "latency p99, edge part, ms"),
    ("details.latency.parts_ms.edge_pose_to_live_publish.p99", LOWER, "latency p99, hub part, ms"),
    ("details.latency.parts_ms.live_delivery.p99", LOWER, "latency p99, delivery part, ms"),
    ("details.latency.receive_cpu_us.hub_per_input", LOWER, "hub CPU per input at real time, us"),
    ("rss_mb.edge", LOWER, "peak RSS edge, MiB"),
    ("rss_mb.hub", LOWER, "peak RSS hub, MiB"),
)


def load_baseline(path: Path | str) -> dict[str, Any]:
    """A saved `reckon bench --json` output; ConfigError naming the file and what is wrong."""
    try:
        result = json.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as error:
        raise ConfigError(f"--compare {path}: cannot read it ({error.strerror or error})") from None
    except json.JSONDecodeError as error:
        raise ConfigError(f"--compare {path}: not JSON ({error.msg} at line {error.lineno})") from None
    if not isinstance(result, dict) or "pipeline_realtime_factor" not in result:
        raise ConfigError(f"--compare {path}: not a `reckon bench --json` result (no pipeline_realtime_factor)")
    return result


def figure(result: dict[str, Any], path: str) -> float | None:
    value: Any = result
    for part in path.split("."):
        if not isinstance(value, dict) or part not in value:
            return None
        value = value[part]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return None
    return float(value)


def compare(result: dict[str, Any], baseline: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per figure: now, base, ratio (now / base) and whether it is more than WORSE_BY worse."""
    rows = []
    for path, better, label in FIGURES:
        now, base = figure(result, path), figure(baseline, path)
        row: dict[str, Any] = {"figure": path, "label": label, "better": better, "now": now, "base": base,
                               "ratio": None, "worse": False}
        if now is not None and base is not None and base != 0:
            ratio = now / base
            row["ratio"] = ratio
            row["worse"] = ratio < 1 - WORSE_BY if better == HIGHER else ratio > 1 + WORSE_BY
        rows.append(row)
    return rows


def format_comparison(rows: list[dict[str, Any]], baseline_path: str) -> str:
    def shown(value: float | None) -> str:
        return "-" if value is None else f"{value:.4g}"

    lines = [f"against {baseline_path} (flagged: more than {WORSE_BY:.0%} worse)",
             f"{'figure':54s} {'now':>10s} {'base':>10s} {'ratio':>7s}"]
    for row in rows:
        ratio = "-" if row["ratio"] is None else f"{row['ratio']:.2f}"
        flag = "  WORSE" if row["worse"] else ("  (not in both runs)" if row["ratio"] is None else "")
        name = f"{row['label']} ({row['better']} is better)"
        lines.append(f"{name:54s} {shown(row['now']):>10s} {shown(row['base']):>10s} {ratio:>7s}{flag}")
    worse = [row["label"] for row in rows if row["worse"]]
    lines.append(f"{len(worse)} figure(s) worse: {', '.join(worse)}" if worse else "no figure worse")
    return "\n".join(lines)
