"""`reckon bench --compare` (reckon/bench/compare.py): ratios against a saved run, flagged by the
declared direction of each figure, missing figures shown as missing, bad baseline files refused."""

from __future__ import annotations

import json

import pytest

from protocol.errors import ConfigError
from reckon.bench.compare import FIGURES, WORSE_BY, compare, format_comparison, load_baseline


def run(factor: float, p99: float, rss_edge: float) -> dict:
    return {"pipeline_realtime_factor": factor, "latency_ms": {"p50": 2.0, "p99": p99},
            "rss_mb": {"edge": rss_edge, "hub": 160.0}, "edge_samples_per_s": 5e6}


def row(rows: list[dict], path: str) -> dict:
    return next(r for r in rows if r["figure"] == path)


def test_worse_is_judged_by_each_figures_direction():
    base = run(factor=4.0, p99=10.0, rss_edge=180.0)
    rows = compare(run(factor=2.9, p99=12.4, rss_edge=240.0), base)
    assert row(rows, "pipeline_realtime_factor")["ratio"] == pytest.approx(2.9 / 4.0)
    assert row(rows, "pipeline_realtime_factor")["worse"]  # slower by 27.5 %
    assert not row(rows, "latency_ms.p99")["worse"]  # 24 % longer: inside the margin
    assert row(rows, "rss_mb.edge")["worse"]  # a third heavier
    better = compare(run(factor=8.0, p99=1.0, rss_edge=90.0), base)
    assert not any(r["worse"] for r in better)


def test_figures_missing_from_either_run_are_not_guessed():
    rows = compare(run(4.0, 10.0, 180.0), {"pipeline_realtime_factor": 4.0, "latency_ms": {"p99": float("nan")}})
    assert row(rows, "latency_ms.p99")["ratio"] is None and row(rows, "rss_mb.hub")["base"] is None
    text = format_comparison(rows, "base.json")
    assert "(not in both runs)" in text and "no figure worse" in text
    assert len(rows) == len(FIGURES)


def test_the_table_names_what_got_worse():
    rows = compare(run(1.0, 100.0, 180.0), run(4.0, 10.0, 180.0))
    text = format_comparison(rows, "base.json")
    assert f"more than {WORSE_BY:.0%} worse" in text
    assert "2 figure(s) worse: pipeline, x real time, latency p99, ms" in text


def test_a_bad_baseline_file_is_refused_naming_it(tmp_path):
    with pytest.raises(ConfigError, match="missing.json: cannot read it"):
        load_baseline(tmp_path / "missing.json")
    broken = tmp_path / "broken.json"
    broken.write_text('{"pipeline_realtime_factor": ')
    with pytest.raises(ConfigError, match="broken.json: not JSON"):
        load_baseline(broken)
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"agents": 500}))
    with pytest.raises(ConfigError, match="not a `reckon bench --json` result"):
        load_baseline(other)
    good = tmp_path / "good.json"
    good.write_text(json.dumps(run(4.0, 10.0, 180.0)))
    assert load_baseline(good)["pipeline_realtime_factor"] == 4.0
