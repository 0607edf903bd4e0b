"""Indoor Location Competition 2.0 walks (reckon/importers/ilc*.py) and `reckon eval` on them.

Real-data tests read the shared sample (../shared/data/pdr/ilc-site1-F1: 10 phone walks on a mall
floor, MIT) and skip cleanly when it is absent; the bad-input tests use crafted files."""

from __future__ import annotations

import gzip
import json
import math
from pathlib import Path

import pytest

from protocol.errors import InputError
from protocol.session_log import read_session
from reckon.cli import main
from reckon.importers.ilc import IlcTruncatedError, read_ilc
from reckon.importers.ilc_session import START_HEADING_SD_RAD, import_ilc

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data" / "pdr" / "ilc-site1-F1"
WALKS = sorted((SHARED / "path_data_files").glob("*.txt.gz")) if SHARED.is_dir() else []
needs_data = pytest.mark.skipif(not WALKS, reason=f"shared ILC sample not found at {SHARED}")

HEADER = "#\tstartTime:1574559652119\n#\tSiteID:s1\tFloorName:F1\n#\tBrand:OPPO\tModel:PBCM10\n"


def crafted(lines: list[str]) -> str:
    return HEADER + "".join(line + "\n" for line in lines)


def motion(time_ms: int) -> list[str]:
    return [f"{time_ms}\tTYPE_ACCELEROMETER\t0.1\t0.2\t9.8\t3", f"{time_ms}\tTYPE_GYROSCOPE\t0.0\t0.0\t0.01\t3",
            f"{time_ms}\tTYPE_MAGNETIC_FIELD\t10\t20\t-40\t3"]


def test_a_crafted_walk_parses_and_aligns(tmp_path: Path):
    lines = [line for t in range(1000, 1200, 20) for line in motion(t)]
    lines += ["1000\tTYPE_WAYPOINT\t10.5\t20.25", "1190\tTYPE_WAYPOINT\t12.0\t22.0", "1100\tTYPE_WIFI\tx\ty\t-50",
              "1205\tTYPE_ACCELEROMETER\t0.1\t0.2\t9.8"]  # an accelerometer row whose gyro partner is missing
    path = tmp_path / "walk.txt"
    path.write_text(crafted(lines))
    walk = read_ilc(path)
    assert len(walk.time_ns) == 10 and walk.time_ns[0] == 1000 * 1_000_000
    assert walk.mag_ut is not None and walk.mag_ut[0].tolist() == [10.0, 20.0, -40.0]
    assert walk.waypoint_xy.tolist() == [[10.5, 20.25], [12.0, 22.0]]
    assert walk.ignored_lines == {"TYPE_WIFI": 1} and walk.skipped_lines == 1 and walk.phone == "OPPO PBCM10"


def test_a_bad_line_names_the_file_line_and_value(tmp_path: Path):
    path = tmp_path / "walk.txt"
    path.write_text(crafted(motion(1000) + ["1020\tTYPE_GYROSCOPE\t0.0\tabc\t0.0"]))
    with pytest.raises(InputError, match=r"walk.txt:7: TYPE_GYROSCOPE value .abc."):
        read_ilc(path)


def test_a_truncated_gzip_keeps_what_came_before(tmp_path: Path):
    lines = [line for t in range(1000, 3000, 20) for line in motion(t)] + ["1000\tTYPE_WAYPOINT\t1\t2"]
    whole = gzip.compress(crafted(lines).encode())
    path = tmp_path / "walk.txt.gz"
    path.write_bytes(whole[: len(whole) * 2 // 3])
    with pytest.raises(IlcTruncatedError, match="truncated or corrupt") as caught:
        read_ilc(path)
    assert 0 < len(caught.value.partial.time_ns) < 100


def test_one_waypoint_is_not_enough(tmp_path: Path):
    path = tmp_path / "walk.txt"
    path.write_text(crafted(motion(1000) + motion(1020) + ["1000\tTYPE_WAYPOINT\t1\t2"]))
    with pytest.raises(InputError, match="1 waypoints; a walk needs at least 2"):
        import_ilc(path, tmp_path / "walk.mcap")


@needs_data
def test_a_real_walk_imports_with_its_floor_plan_and_field(tmp_path: Path):
    result = import_ilc(WALKS[0], tmp_path / "walk.mcap")
    data = read_session(tmp_path / "walk.mcap")
    venue = data.session.venue
    assert result.floor_plan and len(venue.floor_plan) >= 1
    # WMM at Hangzhou (30.29 N, 120.08 E), November 2019: declination 5.6 deg W, dip 46 deg, 48.8 uT
    assert venue.magnetic_north_deg == pytest.approx(95.6, abs=0.3)
    assert venue.magnetic_dip_deg == pytest.approx(46.0, abs=0.5)
    assert venue.magnetic_field_ut == pytest.approx(48.8, abs=0.5)
    truth = data.truth["walker"]
    assert len(truth.time_ns) == result.waypoints >= 10 and all(math.isnan(h) for h in truth.heading_rad)
    scan = data.scans["walker"][0]
    assert scan.accepted and (scan.x_m, scan.y_m) == (truth.x_m[0], truth.y_m[0])
    assert scan.heading_sd_rad == pytest.approx(START_HEADING_SD_RAD)
    assert len(data.imu["walker/phone"].time_ns if "walker/phone" in data.imu else
               next(iter(data.imu.values())).time_ns) == result.samples


@needs_data
def test_eval_on_real_walks_prints_both_methods(tmp_path: Path, capsys):
    out = tmp_path / "walks"
    out.mkdir()
    assert main(["import", "ilc", str(WALKS[0]), str(WALKS[1]), "-o", str(out)]) == 0
    capsys.readouterr()
    logs = sorted(str(p) for p in out.glob("*.mcap"))
    assert main(["eval", *logs, "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    rows = {(r["method"], r["map_matching"]): r for r in report["results"]}
    assert set(rows) == {("paper", False), ("reckon", False), ("reckon", True)}  # no corridor points: no paper snap
    for row in rows.values():
        errors = row["waypoint_error_m"]
        assert row["waypoints"] >= 20 and 0.0 <= errors["median"] <= errors["p75"] <= errors["p90"]
        assert errors["p90"] < 60.0  # a sanity bound: the walks are 60-100 m long
    assert any("turn snap has nothing to snap to" in note for note in report["problems"])
    assert [w["outside"] for w in report["walkable_truth"]] == [0, 0]  # every waypoint walkable for the hub
    assert main(["eval", *logs]) == 0
    table = capsys.readouterr().out
    assert "particle filter" in table and "p75 per session" in table
