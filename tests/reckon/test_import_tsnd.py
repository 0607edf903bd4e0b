"""`reckon import tsnd`: a TSND log in CSV (tagged ags/geo rows in device units) -> session MCAP;
the documented example, units, the midnight wrap, magnetometer pairing, the session description
with and without a TOML, and bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from protocol.errors import ConfigError, InputError
from protocol.session import AgentKind, Mount
from protocol.session_log import read_session
from reckon.cli import main
from reckon.importers.tsnd_csv import import_tsnd_csv
from support.venue import agent_table, sensor_table, write_venue

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "tsnd"
DAY_MS = 86_400_000


def swimmers_venue(path: Path, first: str) -> Path:
    """A 50 m pool with two swimmers: `first` (head and 1000 Hz waist sensors), then "other" (a waist sensor)."""
    return write_venue(path, "pool", court_length_m=50.0, agents=[
        agent_table(first, "swimmer", sensors=[sensor_table(f"{first}-head", "head"),
                                               sensor_table(f"{first}-waist", "waist", rate_hz=1000.0)]),
        agent_table("other", "swimmer", sensors=[sensor_table("other-waist", "waist")])])


def write(tmp_path: Path, lines: list[str], name="swim.csv") -> Path:
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def ags(tick, acc=(0, 0, 10000), gyro=(0, 0, 0)):
    return "ags," + ",".join(str(v) for v in (tick, *acc, *gyro))


def test_documented_example_imports_as_the_docs_say(tmp_path, capsys):
    output = tmp_path / "example.mcap"
    assert main(["import", "tsnd", str(EXAMPLE / "swim.csv"), "--venue", str(EXAMPLE / "pool.toml"),
                 "-o", str(output)]) == 0
    assert capsys.readouterr().out.splitlines()[:2] == [
        f"imported 1 sensors into {output}",
        "  swimmer1/swimmer1-waist: 200 samples in 10 batches, 36000.000-36000.199 s, 1000.0 Hz"]
    data = read_session(output)
    assert data.session.venue.court_length_m == 25.0 and data.session.source["importer"] == "reckon import tsnd"
    series = data.imu["swimmer1-waist"]
    assert series.mag_gauss is not None and np.all(np.abs(series.mag_gauss[:, 0] - 0.285) < 0.01)
    assert series.accel_g[-1, 0] == pytest.approx(1.5, abs=0.01)  # the push-off, 0.1 mg -> g


def test_units_midnight_wrap_and_magnetometer_without_a_toml(tmp_path):
    lines = ["geo,86399998,285,-30,-412"]
    lines += [ags(DAY_MS - 2, (-160000, 1, 9999), (200000, -1, -150)), ags(DAY_MS - 1), ags(0), ags(1)]
    lines += ["geo,2,286,-31,-411", ags(2), "pres,2,101325,2500"]
    report = import_tsnd_csv(write(tmp_path, lines), tmp_path / "out.mcap", venue="club-pool", agent_id="ana")
    data = read_session(tmp_path / "out.mcap")
    agent = data.session.agent("ana")
    assert data.session.venue.name == "club-pool" and data.session.venue.court_length_m == 25.0
    assert agent.kind is AgentKind.SWIMMER and agent.sensors[0].mount is Mount.WAIST
    assert agent.sensors[0].id == "ana-waist" and agent.sensors[0].rate_hz == 1000.0
    series = data.imu["ana-waist"]
    assert (series.time_ns // 1_000_000).tolist() == [DAY_MS - 2, DAY_MS - 1, DAY_MS, DAY_MS + 1, DAY_MS + 2]
    assert series.accel_g[0].tolist() == pytest.approx([-16.0, 0.0001, 0.9999])
    assert series.gyro_dps[0].tolist() == pytest.approx([2000.0, -0.01, -1.5])
    assert series.mag_gauss[0].tolist() == pytest.approx([0.285, -0.030, -0.412])  # 0.1 uT -> gauss
    assert series.mag_gauss[-1].tolist() == pytest.approx([0.286, -0.031, -0.411])  # the nearest reading
    assert any("ignored 1 rows not tagged ags or geo (1 x 'pres'" in w for w in report.warnings)


def test_rows_that_cannot_be_read_are_skipped_and_counted(tmp_path):
    lines = [ags(10), "ags,11,1,2", "ags,x12,0,0,0,0,0,0", ags(13), ags(13), "geo,14,1,2", ags(15)]
    report = import_tsnd_csv(write(tmp_path, lines), tmp_path / "out.mcap")
    assert report.sensors["swimmer-waist"].samples == 3
    assert report.skipped == {f"{tmp_path / 'swim.csv'}: wrong number of fields": 2,
                              f"{tmp_path / 'swim.csv'}: not a number": 1,
                              f"{tmp_path / 'swim.csv'}: repeated sample": 1}
    assert read_session(tmp_path / "out.mcap").imu["swimmer-waist"].mag_gauss is None


def test_magnetometer_left_out_when_samples_have_no_reading_near(tmp_path):
    lines = ["geo,0,1,2,3"] + [ags(tick) for tick in (0, 400, 800, 1200)]
    report = import_tsnd_csv(write(tmp_path, lines), tmp_path / "out.mcap")
    assert read_session(tmp_path / "out.mcap").imu["swimmer-waist"].mag_gauss is None
    assert any("2 of 4 samples have no geo reading within 0.5 s" in w for w in report.warnings)


def test_toml_picks_the_agent_and_its_waist_sensor(tmp_path):
    toml = swimmers_venue(tmp_path / "pool.toml", first="ben")
    csv = write(tmp_path, [ags(tick) for tick in range(100)])
    assert main(["import", "tsnd", str(csv), "--venue", str(toml), "--agent", "ben", "-o",
                 str(tmp_path / "out.mcap")]) == 0
    data = read_session(tmp_path / "out.mcap")
    assert list(data.imu) == ["ben-waist"] and data.session.venue.court_length_m == 50.0
    with pytest.raises(ConfigError, match="2 swimmer agents; say which one the log belongs to"):
        import_tsnd_csv(csv, tmp_path / "x.mcap", venue_toml=toml)
    with pytest.raises(ConfigError, match="--agent 'carla': not in .*agents: ben, other"):
        import_tsnd_csv(csv, tmp_path / "x.mcap", venue_toml=toml, agent_id="carla")


@pytest.mark.parametrize("lines, message", [
    ([ags(100), ags(50)], r"swim.csv line 2: tick_ms 50 is not after the previous row's 100 \(line 1\)"),
    ([ags(50_000_000), ags(10_000_000)], "line 2: tick_ms 10000000 is not after"),  # back 11 h: no midnight
    (["pres,1,2,3"], r"swim.csv: no samples after the header"),
    ([], "empty file"),
])
def test_bad_files_name_file_line_and_values(tmp_path, lines, message):
    with pytest.raises(InputError, match=message):
        import_tsnd_csv(write(tmp_path, lines), tmp_path / "out.mcap")
    assert not (tmp_path / "out.mcap").exists()


def test_bad_agent_id_fails_like_a_toml(tmp_path):
    with pytest.raises(ConfigError, match="--agent: id 'no spaces/allowed' must be"):
        import_tsnd_csv(write(tmp_path, [ags(1), ags(2)]), tmp_path / "out.mcap", agent_id="no spaces/allowed")
