"""`reckon eval`'s identity table on a crafted session log (tests/support/identity_scenes.py)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from protocol.session_log import read_session
from reckon.evaluation.identity_eval import evaluate_identity, to_json, to_table
from support.identity_scenes import CROSSING, write_scene

TRACKS = [(1, "a", 0, 6), (2, "b", 0, 6), (3, "c", 0, 30), (4, "b", 6, 30), (5, "a", 6, 14), (6, "", 10, 14),
          (7, "a", 14.5, 30)]


def test_identity_table_scores_both_methods_from_a_session_log(tmp_path: Path):
    path = tmp_path / "crossing.mcap"
    write_scene(path, CROSSING, TRACKS, end_s=30)
    data = read_session(path)
    assert set(data.cameras) == {"cam1"} and data.cameras["cam1"].person_id is not None
    report = evaluate_identity(data, path)
    by_method = to_json(report)
    assert [row["method"] for row in by_method] == ["reckon", "reckon", "ceiling", "paper", "hindsight"]
    live, refined, ceiling, paper, hindsight = by_method
    for row in by_method:
        assert row["agents"] == 3
        assert 0.0 <= row["time_correct_pct"] <= 100.0 and 0.0 <= row["idf1"] <= 1.0
        assert (row["update_ms_p99"] is None) if row["method"] == "ceiling" else row["update_ms_p99"] > 0
        # every visible frame not correct has one cause
        assert sum(row["lost_pct"].values()) + row["time_correct_pct"] == pytest.approx(100.0, abs=0.05)
    # the live identity starts late (evidence first) and back-filling can only add correct time
    assert live["time_correct_pct"] < refined["time_correct_pct"]
    assert refined["time_correct_pct"] >= 95.0
    assert paper["note"].startswith("6 of 6 permutations")
    # ours in hindsight names every fragment for the whole of it (tests/hub/test_identity_hindsight.py)
    assert hindsight["time_correct_pct"] == pytest.approx(100.0)
    assert any("ours in hindsight: learnt without labels" in note for note in report.notes)
    # the ceiling waits the engine's median delay after each track starts showing a person: a at 0, 6 and
    # 14.5 s, b at 0 and 6 s, c at 0 s; visible: a 29.5 s (gone 14-14.5 s), b and c 30 s
    delay_s = float(re.search(r"for a person ([0-9.]+) s after", ceiling["note"]).group(1))
    assert 0.2 <= delay_s <= 1.0
    assert ceiling["time_correct_pct"] == pytest.approx(100.0 * (1 - 6 * delay_s / 89.5), abs=0.3)
    assert ceiling["lost_pct"]["no track: its track in its first 1.5 s"] == pytest.approx(100 - ceiling["time_correct_pct"])
    # six runs of a person on a track (1 a, 2 b, 3 c, 4 b, 5 a, 7 a) for 3 agents over 30 s: 4 per agent-minute;
    # the ceiling names each exactly its delay after it starts
    assert ceiling["naming"]["runs_per_agent_minute"] == pytest.approx(4.0, rel=0.02)
    assert ceiling["naming"]["first_frame_pct"] == 0 and ceiling["naming"]["p90_s"] == pytest.approx(delay_s, abs=0.06)
    assert live["naming"]["runs_per_agent_minute"] == ceiling["naming"]["runs_per_agent_minute"]
    assert 0 <= live["naming"]["p50_s"] <= live["naming"]["p90_s"] and "naming:" in to_table(report)
    assert "time correct" in to_table(report) and "lost: wrong track" in to_table(report)
