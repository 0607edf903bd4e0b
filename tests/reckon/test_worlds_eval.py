"""`reckon eval --worlds A-B`: one short game in a few worlds, every method scored in each, summarised."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from reckon.cli import main
from reckon.evaluation.worlds_eval import HURT_TOLERANCE, WorldResult, evaluate_worlds, summarise, to_table
from sim_devices.wheelchair.worlds import describe_worlds

DOCS = Path(__file__).resolve().parents[2] / "docs" / "simulator-worlds.md"


@pytest.fixture(scope="module")
def results() -> list[WorldResult]:
    return evaluate_worlds([3, 4], seed=2, players=3, duration_s=20.0, jobs=2)


def test_every_world_is_scored_for_every_method(results):
    assert [r.world for r in results] == [3, 4]
    for result in results:
        assert ("reckon", "gyro", (), "live") in result.mean_error_m
        assert ("paper", "sensors", ("beacon", "collision"), None) in result.mean_error_m
        assert all(0.0 <= value < 50.0 for value in result.mean_error_m.values())
        assert {key[3] for key in result.nees} == {"live", "refined"}  # ours only: the paper states none
        assert result.figures["chair.radius_m"] > 0  # the world's own figures, not the defaults
    assert results[0].figures != results[1].figures


def test_the_summary_counts_what_each_source_did(results):
    summary = summarise(results)
    for row in summary["methods"]:
        assert row["worlds"] == 2 and row["median_m"] <= row["p90_m"] <= row["worst_m"]
    sources = {(row["source"], row["method"]): row for row in summary["sources"]}
    assert {("magnetometer aid", "reckon"), ("beacon", "reckon"), ("collision", "reckon"),
            ("beacon", "paper")} <= set(sources)
    beacon = sources[("beacon", "reckon")]
    off = [r.mean_error_m[("reckon", "sensors", (), "live")] for r in results]
    on = [r.mean_error_m[("reckon", "sensors", ("beacon",), "live")] for r in results]
    changes = [(b - a) / a for a, b in zip(off, on)]
    assert beacon["helped"] == sum(c < 0 for c in changes) and beacon["hurt"] == sum(c > 0 for c in changes)
    assert beacon["hurt_over_tolerance"] == sum(c > HURT_TOLERANCE for c in changes)
    assert beacon["worst_change"] == pytest.approx(max(changes))
    pairs = summary["contact_pairs"]
    assert pairs["taken"] == sum(r.contact_pairs[0] for r in results) and 0 <= pairs["true"] <= pairs["taken"]
    assert pairs["worlds"] == 2 and pairs["true_contacts"] == sum(r.contact_pairs[2] for r in results)
    table = to_table(summary, "reckon eval --worlds 3-4")
    assert "magnetometer aid" in table and "world   4:" in table and "of them false" in table


def test_the_command_prints_json(capsys):
    assert main(["-q", "eval", "--worlds", "5", "--players", "2", "--duration", "10", "--jobs", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["worlds"] == [5] and out["command"].startswith("reckon eval --worlds 5")
    assert out["per_world"][0]["figures"]["court.beacon_height_m"] > 0
    assert out["per_world"][0]["mean_error_m"]["reckon live sensors beacon+collision"] > 0


@pytest.mark.parametrize("argv, message", [
    (["eval", "--worlds", "4-2"], "0 <= A <= B"),
    (["eval", "game.mcap", "--worlds", "1-2"], "not both"),
    (["eval"], "give a session log"),
])
def test_bad_world_arguments_are_one_line(argv, message, capsys):
    assert main(argv) != 0
    assert message in capsys.readouterr().err


def test_docs_list_every_world_range():
    text = DOCS.read_text(encoding="utf-8")
    for row in describe_worlds():
        assert "| " + " | ".join(row) + " |" in text, row[0]
