"""`reckon import csv`: the documented example imports; every kind of bad input gives a clear error
or a counted skip naming file, line and value (reckon/importers/csv_folder.py, docs/csv-import.md)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from protocol import messages
from protocol.errors import ConfigError, InputError, ReckonError
from protocol.session_log import read_session
from reckon.importers import import_csv_folder
from reckon.importers.report import EXAMPLES_PER_FILE
from support.venue import agent_table, sensor_table, venue_toml, write_venue

EXAMPLE = Path(__file__).resolve().parents[2] / "docs/examples/csv-session"
G = 9.80665

SEAT = sensor_table("seat", "seat", rate_hz=100.0)
LEFT = sensor_table("left", "left_wheel", spin_axis="+z", rate_hz=100.0)


def session_toml(sensors: tuple[dict, ...] = (SEAT, LEFT), **chair: object) -> str:
    """A folder's session.toml: the gym with beacon b1 and chair c1 (`chair`: more keys of its table)."""
    return venue_toml("gym", agents=[agent_table("c1", sensors=list(sensors), **chair)],
                      beacons=[{"id": "b1", "x_m": 0.0, "y_m": 0.0}])


SESSION = session_toml()
HEADER = "time_s,accel_x_g,accel_y_g,accel_z_g,gyro_x_dps,gyro_y_dps,gyro_z_dps"


def sensor_rows(count: int = 30, start_s: float = 10.0) -> list[str]:
    """`count` rows at 100 Hz: accel (0, 0, 1) g, gyro z = row index deg/s."""
    return [f"{start_s + i / 100:.2f},0,0,1,0,0,{i}" for i in range(count)]


def make_folder(tmp_path: Path, files: dict[str, str | list[str] | None] | None = None,
                session: str = SESSION) -> Path:
    """A valid two-sensor folder, with `files` replacing (or, for None, removing) files by name."""
    folder = tmp_path / "session"
    folder.mkdir()
    contents: dict[str, str | list[str] | None] = {"session.toml": session, "seat.csv": [HEADER] + sensor_rows(),
                                                   "left.csv": [HEADER] + sensor_rows()}
    contents.update(files or {})
    for name, text in contents.items():
        if text is not None:
            (folder / name).write_text(text if isinstance(text, str) else "\n".join(text) + "\n", encoding="utf-8")
    return folder


def import_error(tmp_path: Path, error: type[Exception] = InputError, **make: object) -> str:
    folder = make_folder(tmp_path, **make)  # type: ignore[arg-type]
    output = tmp_path / "out.mcap"
    with pytest.raises(error) as caught:
        import_csv_folder(folder, output)
    assert not output.exists(), "a failed import must not leave an output file"
    return str(caught.value)


# ---------------------------------------------------------------------------------------------
# The documented example


def test_example_folder_imports_and_reads_back(tmp_path: Path) -> None:
    report = import_csv_folder(EXAMPLE, tmp_path / "example.mcap")
    data = read_session(tmp_path / "example.mcap")
    assert report.rows_skipped == 0 and report.warnings == []
    assert {sid: count.samples for sid, count in report.sensors.items()} == {
        "chair1-seat": 200, "chair1-left": 200, "chair1-right": 200}
    assert data.problems == []
    assert sorted(data.imu) == ["chair1-left", "chair1-right", "chair1-seat"]
    assert all(len(series.time_ns) == 200 and series.lost_batches == 0 for series in data.imu.values())
    seat, left, right = data.imu["chair1-seat"], data.imu["chair1-left"], data.imu["chair1-right"]
    assert seat.time_ns[0] == 1_718_000_000_000_000_000 and left.time_ns[0] == 1_718_000_000_003_000_000
    # first rows of the files, converted: m/s^2 -> g, rad/s -> deg/s, uT -> gauss (stored as float32)
    assert left.accel_g[0] == pytest.approx([0.0, -9.8066 / G, 0.0001 / G], rel=1e-6, abs=1e-7)
    assert left.gyro_dps[0] == pytest.approx(np.degrees([0.00064, -0.00166, 3.27716]), rel=1e-6)
    assert left.mag_gauss is None
    assert right.mag_gauss is not None and right.mag_gauss[0] == pytest.approx([0.215, 0.0, -0.412], rel=1e-6)
    assert seat.mag_gauss is not None and seat.mag_gauss[0] == pytest.approx([0.215, -0.003, -0.412], rel=1e-6)
    assert len(data.sightings["chair1"].time_ns) == 10 and data.sightings["chair1"].beacon_id[0] == "goal-west"
    truth = data.truth["chair1"]
    assert len(truth.time_ns) == 21 and truth.x_m[-1] == pytest.approx(3.5) and truth.heading_rad[0] == 0.0
    assert data.session.source["importer"] == "reckon import csv"


def test_example_batches_hold_20_samples_with_counting_sequences(tmp_path: Path) -> None:
    import_csv_folder(EXAMPLE, tmp_path / "example.mcap")
    sequences: dict[str, list[int]] = {}
    log_times = []
    with open(tmp_path / "example.mcap", "rb") as file:
        for _, channel, message in make_reader(file).iter_messages(log_time_order=False):
            log_times.append(message.log_time)
            if "/imu/" in channel.topic:
                batch = messages.ImuBatch.FromString(message.data)
                assert len(batch.sample_offset_ns) == 20 and len(batch.gyro_dps) == 60
                sequences.setdefault(batch.sensor_id, []).append(batch.sequence)
    assert sequences == {sensor: list(range(10)) for sensor in ("chair1-seat", "chair1-left", "chair1-right")}
    assert log_times == sorted(log_times), "streams are merged in time order in the file"


# ---------------------------------------------------------------------------------------------
# Units and times


def test_mixed_unit_headers_convert(tmp_path: Path) -> None:
    header = ("time_ms,accel_x_mps2,accel_y_g,accel_z_mg,gyro_x_radps,gyro_y_dps,gyro_z_deg/s,"
              "mag_x_ut,mag_y_nt,mag_z_gauss")
    folder = make_folder(tmp_path, {"seat.csv": [header, "1500,9.80665,0.5,250,3.14159265358979,10,-20,50,30000,0.4",
                                                 "1510,0,0,1000,0,0,0,0,0,0"]})
    import_csv_folder(folder, tmp_path / "out.mcap")
    seat = read_session(tmp_path / "out.mcap").imu["seat"]
    assert seat.time_ns.tolist() == [1_500_000_000, 1_510_000_000]
    assert seat.accel_g[0] == pytest.approx([1.0, 0.5, 0.25], rel=1e-6)
    assert seat.gyro_dps[0] == pytest.approx([180.0, 10.0, -20.0], rel=1e-6)
    assert seat.mag_gauss is not None and seat.mag_gauss[0] == pytest.approx([0.5, 0.3, 0.4], rel=1e-6)


def test_header_names_ignore_case_and_spaces(tmp_path: Path) -> None:
    header = " Time_S , Accel_X_G,accel_y_g,accel_z_g,GYRO_X_DPS,gyro_y_dps,gyro_z_dps"
    import_csv_folder(make_folder(tmp_path, {"seat.csv": [header] + sensor_rows()}), tmp_path / "out.mcap")
    assert len(read_session(tmp_path / "out.mcap").imu["seat"].time_ns) == 30


def test_unix_times_are_exact_nanoseconds(tmp_path: Path) -> None:
    rows = [HEADER, "1718000000.123456789,0,0,1,0,0,0", "1718000000.133456790,0,0,1,0,0,0"]
    import_csv_folder(make_folder(tmp_path, {"seat.csv": rows}), tmp_path / "out.mcap")
    times = read_session(tmp_path / "out.mcap").imu["seat"].time_ns.tolist()
    assert times == [1_718_000_000_123_456_789, 1_718_000_000_133_456_790]


def test_magnetometer_columns_are_optional(tmp_path: Path) -> None:
    import_csv_folder(make_folder(tmp_path), tmp_path / "out.mcap")
    assert read_session(tmp_path / "out.mcap").imu["seat"].mag_gauss is None


def test_a_gap_longer_than_a_batch_can_span_starts_a_new_batch(tmp_path: Path) -> None:
    # sample offsets are uint32 ns (4.29 s); a logger pause of 10 s must not overflow them
    rows = [HEADER] + sensor_rows(5, start_s=10.0) + sensor_rows(5, start_s=20.0)
    report = import_csv_folder(make_folder(tmp_path, {"seat.csv": rows}), tmp_path / "out.mcap")
    seat = read_session(tmp_path / "out.mcap").imu["seat"]
    assert report.sensors["seat"].batches == 2
    assert seat.time_ns.tolist() == [round((10.0 + i / 100) * 1e9) for i in range(5)] + \
        [round((20.0 + i / 100) * 1e9) for i in range(5)]


@settings(max_examples=25, deadline=None)
@given(intervals_us=st.lists(st.integers(min_value=1, max_value=6_000_000), min_size=0, max_size=70),
       seed=st.integers(min_value=0, max_value=2**32 - 1))
def test_any_increasing_times_and_values_read_back(tmp_path_factory: pytest.TempPathFactory,
                                                    intervals_us: list[int], seed: int) -> None:
    tmp_path = tmp_path_factory.mktemp("prop")
    times_us = np.cumsum([1_000_000] + intervals_us)
    values = np.random.default_rng(seed).normal(0, 100, size=(len(times_us), 6)).round(3)
    rows = [HEADER] + [f"{t / 1e6:.6f}," + ",".join(f"{v:.3f}" for v in row) for t, row in zip(times_us, values)]
    import_csv_folder(make_folder(tmp_path, {"seat.csv": rows}), tmp_path / "out.mcap")
    seat = read_session(tmp_path / "out.mcap").imu["seat"]
    assert seat.time_ns.tolist() == (times_us * 1000).tolist()
    assert np.allclose(seat.accel_g, values[:, :3], rtol=1e-6, atol=1e-4)
    assert np.allclose(seat.gyro_dps, values[:, 3:], rtol=1e-6, atol=1e-4)


@settings(max_examples=60, deadline=None)
@given(body=st.binary(max_size=300) | st.text(alphabet="0123456789.,-e\n\"nax ", max_size=300).map(str.encode),
       with_header=st.booleans())
def test_any_bytes_give_an_import_or_a_reckon_error(tmp_path_factory: pytest.TempPathFactory, body: bytes,
                                                    with_header: bool) -> None:
    tmp_path = tmp_path_factory.mktemp("fuzz")
    folder = make_folder(tmp_path)
    (folder / "seat.csv").write_bytes((HEADER.encode() + b"\n" if with_header else b"") + body)
    try:
        import_csv_folder(folder, tmp_path / "out.mcap")
    except ReckonError as error:
        assert "seat.csv" in str(error)
        assert not (tmp_path / "out.mcap").exists()
    else:
        assert read_session(tmp_path / "out.mcap").imu["seat"].time_ns.size > 0


# ---------------------------------------------------------------------------------------------
# Column errors


def test_missing_column_names_file_column_and_what_was_found(tmp_path: Path) -> None:
    header = "time_s,accel_x_g,accel_y_g,accel_z_g,gyro_x_dps,gyro_y_dps"
    message = import_error(tmp_path, files={"left.csv": [header, "0,0,0,1,0,0"]})
    assert "left.csv" in message and "missing column gyro_z" in message
    assert "found columns: time_s, accel_x_g, accel_y_g, accel_z_g, gyro_x_dps, gyro_y_dps" in message


def test_missing_time_column(tmp_path: Path) -> None:
    message = import_error(tmp_path, files={"seat.csv": [HEADER.replace("time_s", "t"), "0,0,0,1,0,0,0"]})
    assert "seat.csv" in message and "missing column time_s" in message and "found columns: t," in message


def test_unknown_unit_names_the_column_and_the_accepted_units(tmp_path: Path) -> None:
    message = import_error(tmp_path, files={"seat.csv": [HEADER.replace("gyro_y_dps", "gyro_y_rpm"), "0,0,0,1,0,0,0"]})
    assert "seat.csv" in message and "'gyro_y_rpm'" in message and "'rpm'" in message and "radps" in message


def test_a_column_given_twice_is_refused(tmp_path: Path) -> None:
    message = import_error(tmp_path, files={"seat.csv": [HEADER + ",accel_x_mps2", "0,0,0,1,0,0,0,0"]})
    assert "seat.csv" in message and "'accel_x_g'" in message and "'accel_x_mps2'" in message


def test_magnetometer_needs_all_three_axes(tmp_path: Path) -> None:
    message = import_error(tmp_path, files={"seat.csv": [HEADER + ",mag_x_ut,mag_y_ut", "0,0,0,1,0,0,0,1,2"]})
    assert "seat.csv" in message and "all three or none" in message and "mag_z" in message


def test_extra_columns_are_ignored_with_a_warning(tmp_path: Path) -> None:
    rows = [HEADER + ",temperature_c"] + [row + ",25.0" for row in sensor_rows()]
    report = import_csv_folder(make_folder(tmp_path, {"seat.csv": rows}), tmp_path / "out.mcap")
    assert any("seat.csv" in warning and "temperature_c" in warning for warning in report.warnings)


# ---------------------------------------------------------------------------------------------
# Stray rows: skipped, counted, first few listed


def test_row_with_wrong_field_count_is_skipped_with_file_line_and_value(tmp_path: Path) -> None:
    rows = [HEADER] + sensor_rows(3) + ["10.03,0,0"] + sensor_rows(3, start_s=10.04)
    report = import_csv_folder(make_folder(tmp_path, {"seat.csv": rows}), tmp_path / "out.mcap")
    assert report.skipped == {f"{tmp_path / 'session' / 'seat.csv'}: wrong number of fields": 1}
    assert report.skip_examples == [f"{tmp_path / 'session' / 'seat.csv'} line 5: 3 fields, expected 7: '10.03,0,0'"]
    assert report.sensors["seat"].samples == 6
    assert len(read_session(tmp_path / "out.mcap").imu["seat"].time_ns) == 6


def test_non_numeric_value_is_skipped_with_file_line_and_value(tmp_path: Path) -> None:
    rows = [HEADER] + sensor_rows(2) + ["10.02,0,0,1,abc,0,0"] + sensor_rows(2, start_s=10.03)
    report = import_csv_folder(make_folder(tmp_path, {"seat.csv": rows}), tmp_path / "out.mcap")
    assert report.rows_skipped == 1 and report.sensors["seat"].samples == 4
    (example,) = report.skip_examples
    assert "seat.csv line 4" in example and "gyro_x_dps" in example and "'abc'" in example
    summary = str(report)
    assert "skipped 1 rows" in summary and "seat.csv: not a number" in summary and "'abc'" in summary


def test_non_finite_value_and_bad_time_are_skipped(tmp_path: Path) -> None:
    rows = [HEADER, "10.00,0,0,1,0,0,0", "10.01,nan,0,1,0,0,0", "ten,0,0,1,0,0,0", "1e999999999,0,0,1,0,0,0",
            "10.02,0,0,1,0,0,0"]
    report = import_csv_folder(make_folder(tmp_path, {"seat.csv": rows}), tmp_path / "out.mcap")
    assert report.sensors["seat"].samples == 2 and report.rows_skipped == 3
    assert any("line 3" in e and "'nan' is not a finite number" in e for e in report.skip_examples)
    assert any("line 4" in e and "time_s" in e and "'ten'" in e for e in report.skip_examples)


def test_only_the_first_few_skipped_rows_are_listed_but_all_are_counted(tmp_path: Path) -> None:
    rows = [HEADER] + sensor_rows(2) + [f"10.{i + 2:02d},x,0,1,0,0,0" for i in range(EXAMPLES_PER_FILE + 3)]
    report = import_csv_folder(make_folder(tmp_path, {"seat.csv": rows}), tmp_path / "out.mcap")
    assert report.rows_skipped == EXAMPLES_PER_FILE + 3
    assert len(report.skip_examples) == EXAMPLES_PER_FILE


def test_an_exactly_repeated_sample_is_skipped_and_counted(tmp_path: Path) -> None:
    rows = [HEADER, "10.00,0,0,1,0,0,0", "10.01,0,0,1,0,0,5", "10.01,0,0,1,0,0,5", "10.02,0,0,1,0,0,0"]
    report = import_csv_folder(make_folder(tmp_path, {"seat.csv": rows}), tmp_path / "out.mcap")
    assert report.sensors["seat"].samples == 3
    assert report.skipped == {f"{tmp_path / 'session' / 'seat.csv'}: repeated sample": 1}
    assert "line 4" in report.skip_examples[0] and "line 3" in report.skip_examples[0]


def test_a_repeated_sample_may_carry_a_slightly_earlier_time(tmp_path: Path) -> None:
    # as the NGIMU logger writes them: same values, time 4 us before the original's
    rows = [HEADER, "10.000000,0,0,1,0,0,1", "10.010000,0,0,1,0,0,2", "10.009996,0,0,1,0,0,2", "10.020000,0,0,1,0,0,3"]
    report = import_csv_folder(make_folder(tmp_path, {"seat.csv": rows}), tmp_path / "out.mcap")
    assert report.sensors["seat"].samples == 3 and report.rows_skipped == 1


def test_a_file_with_every_row_bad_is_an_error(tmp_path: Path) -> None:
    message = import_error(tmp_path, files={"seat.csv": [HEADER, "a,b,c,d,e,f,g"]})
    assert "seat.csv" in message and "no samples" in message and "line 2" in message


# ---------------------------------------------------------------------------------------------
# Time order


def test_time_going_backwards_names_file_line_value_and_previous(tmp_path: Path) -> None:
    rows = [HEADER, "10.00,0,0,1,0,0,0", "10.01,0,0,1,0,0,0", "9.50,0,0,1,0,0,0"]
    message = import_error(tmp_path, files={"left.csv": rows})
    assert "left.csv line 4" in message and "9.50" in message and "10.01" in message and "(line 3)" in message


def test_a_repeated_time_with_other_values_is_refused(tmp_path: Path) -> None:
    rows = [HEADER, "10.00,0,0,1,0,0,0", "10.00,0,0,1,0,0,7"]
    message = import_error(tmp_path, files={"seat.csv": rows})
    assert "seat.csv line 3" in message and "not after" in message


def test_negative_time_is_refused(tmp_path: Path) -> None:
    message = import_error(tmp_path, files={"seat.csv": [HEADER, "-0.5,0,0,1,0,0,0"]})
    assert "seat.csv line 2" in message and "-0.5" in message


# ---------------------------------------------------------------------------------------------
# Files and sensors


def test_csv_with_no_sensor_in_the_toml(tmp_path: Path) -> None:
    message = import_error(tmp_path, files={"right.csv": [HEADER] + sensor_rows()})
    assert "right.csv" in message and "no sensor 'right'" in message and "seat, left" in message


def test_toml_sensor_with_no_csv(tmp_path: Path) -> None:
    message = import_error(tmp_path, files={"left.csv": None})
    assert "session.toml" in message and "sensor 'left'" in message and "left.csv" in message


def test_two_files_for_one_sensor(tmp_path: Path) -> None:
    probe = tmp_path / "case-probe"
    probe.mkdir()
    (probe / "a").touch()
    if (probe / "A").exists():
        pytest.skip("case-insensitive file system: LEFT.csv and left.csv are one file here")
    message = import_error(tmp_path, files={"LEFT.csv": [HEADER] + sensor_rows()})
    assert "LEFT.csv" in message and "left.csv" in message and "two files for one sensor" in message


def test_two_toml_sensors_with_one_id(tmp_path: Path) -> None:
    session = session_toml((SEAT, LEFT, sensor_table("left", "right_wheel", spin_axis="-z")))
    message = import_error(tmp_path, ConfigError, session=session)
    assert "session.toml" in message and "duplicate sensor id 'left'" in message


def test_unknown_toml_key_is_the_config_error_of_load_toml(tmp_path: Path) -> None:
    message = import_error(tmp_path, ConfigError, session=session_toml(wheel_size=0.6))
    assert "session.toml" in message and "wheel_size: unknown key" in message


def test_missing_session_toml(tmp_path: Path) -> None:
    message = import_error(tmp_path, files={"session.toml": None})
    assert "no session.toml" in message


def test_folder_that_does_not_exist(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="not a folder"):
        import_csv_folder(tmp_path / "nowhere", tmp_path / "out.mcap")


def test_empty_sensor_file(tmp_path: Path) -> None:
    message = import_error(tmp_path, files={"seat.csv": ""})
    assert "seat.csv" in message and "empty file" in message


def test_header_only_sensor_file(tmp_path: Path) -> None:
    message = import_error(tmp_path, files={"seat.csv": [HEADER]})
    assert "seat.csv" in message and "no samples" in message


def test_empty_beacons_file(tmp_path: Path) -> None:
    message = import_error(tmp_path, files={"beacons.csv": ""})
    assert "beacons.csv" in message and "empty file" in message


def test_file_that_is_not_text(tmp_path: Path) -> None:
    folder = make_folder(tmp_path)
    (folder / "seat.csv").write_bytes(HEADER.encode() + b"\n10.0,0,0,1,0,0,0\n\xff\xfe\x00binary\n")
    with pytest.raises(InputError, match="seat.csv: unreadable"):
        import_csv_folder(folder, tmp_path / "out.mcap")


def test_output_folder_must_exist(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="does not exist"):
        import_csv_folder(make_folder(tmp_path), tmp_path / "missing" / "out.mcap")


def test_rate_different_from_the_toml_is_warned(tmp_path: Path) -> None:
    rows = [HEADER] + [f"{10 + i / 50:.2f},0,0,1,0,0,0" for i in range(10)]  # 50 Hz, TOML says 100
    report = import_csv_folder(make_folder(tmp_path, {"seat.csv": rows}), tmp_path / "out.mcap")
    assert any("seat.csv" in w and "50.0 Hz" in w and "rate_hz = 100" in w for w in report.warnings)


# ---------------------------------------------------------------------------------------------
# beacons.csv and truth.csv


def test_beacon_rows_with_unknown_sensor_or_beacon_are_counted(tmp_path: Path) -> None:
    beacons = ["time_s,sensor_id,beacon_id,rssi_dbm", "10.05,seat,b1,-70", "10.02,left,b1,-72", "10.06,seat,b9,-71",
               "10.07,ghost,b1,-60", "10.08,seat,b1,strong"]
    report = import_csv_folder(make_folder(tmp_path, {"beacons.csv": beacons}), tmp_path / "out.mcap")
    assert report.sightings == 2 and report.rows_skipped == 3
    examples = "\n".join(report.skip_examples)
    assert "beacons.csv line 4: beacon_id 'b9'" in examples
    assert "beacons.csv line 5: sensor_id 'ghost'" in examples
    assert "beacons.csv line 6: column rssi_dbm: 'strong'" in examples
    sightings = read_session(tmp_path / "out.mcap").sightings["c1"]
    assert sightings.time_ns.tolist() == [10_020_000_000, 10_050_000_000]  # sorted: several receivers, one file
    assert sightings.rssi_dbm.tolist() == [-72.0, -70.0]


def test_beacons_file_missing_a_column(tmp_path: Path) -> None:
    message = import_error(tmp_path, files={"beacons.csv": ["time_s,sensor_id,rssi_dbm", "10,seat,-70"]})
    assert "beacons.csv" in message and "missing column beacon_id" in message
    assert "found columns: time_s, sensor_id, rssi_dbm" in message


def test_truth_reads_back(tmp_path: Path) -> None:
    truth = ["time_s,agent_id,x_m,y_m,heading_rad", "10.0,c1,1.0,2.0,0.5", "10.1,c1,1.1,2.0,0.6", "10.2,nobody,0,0,0"]
    report = import_csv_folder(make_folder(tmp_path, {"truth.csv": truth}), tmp_path / "out.mcap")
    assert report.truth_poses == 2 and "truth.csv line 4: agent_id 'nobody'" in report.skip_examples[0]
    poses = read_session(tmp_path / "out.mcap").truth["c1"]
    assert poses.x_m.tolist() == [1.0, 1.1] and poses.heading_rad.tolist() == [0.5, 0.6]


def test_truth_without_heading_is_nan_and_warned(tmp_path: Path) -> None:
    report = import_csv_folder(make_folder(tmp_path, {"truth.csv": ["time_s,agent_id,x_m,y_m", "10.0,c1,1.0,2.0"]}),
                               tmp_path / "out.mcap")
    assert any("heading_rad" in warning for warning in report.warnings)
    assert math.isnan(read_session(tmp_path / "out.mcap").truth["c1"].heading_rad[0])


def test_truth_time_going_backwards(tmp_path: Path) -> None:
    truth = ["time_s,agent_id,x_m,y_m,heading_rad", "10.0,c1,1.0,2.0,0", "9.0,c1,1.1,2.0,0"]
    message = import_error(tmp_path, files={"truth.csv": truth})
    assert "truth.csv line 3" in message and "9.0" in message and "10.0" in message


# ---------------------------------------------------------------------------------------------
# docs/csv-import.md stays true


def test_documented_output_of_the_example_is_what_the_import_prints(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    doc = (EXAMPLE.parents[1] / "csv-import.md").read_text(encoding="utf-8")
    assert "reckon import csv docs/examples/csv-session -o example.mcap" in doc
    monkeypatch.chdir(tmp_path)
    printed = str(import_csv_folder(EXAMPLE, Path("example.mcap")))
    assert f"```\n{printed}\n```" in doc


def test_every_accepted_unit_is_documented() -> None:
    from reckon.importers.tables import NS_PER_TIME_UNIT, TO_PROTOCOL_UNIT

    doc = (EXAMPLE.parents[1] / "csv-import.md").read_text(encoding="utf-8")
    units = list(NS_PER_TIME_UNIT) + [unit for table in TO_PROTOCOL_UNIT.values() for unit in table]
    assert [unit for unit in units if f"`{unit}`" not in doc] == []


def test_a_phone_walk_with_its_stand_imports_and_evaluates(tmp_path: Path, capsys) -> None:
    """Any phone app's export: the phone's CSV, when it lay on the stand, and the truth; `reckon
    eval` then scores it as a pedestrian walk (the walker steps along +x at 1.8 Hz, 0.7 m a step)."""
    from reckon.cli import main

    folder = tmp_path / "walk"
    folder.mkdir()
    write_venue(folder / "session.toml", "hall", stands=[{"id": "door", "x_m": 2.0, "y_m": 5.0, "heading_deg": 0.0}],
                agents=[agent_table("walker", "pedestrian", sensors=[sensor_table("phone", "hand", rate_hz=50.0)])])
    rows = ["time_s,accel_x_mps2,accel_y_mps2,accel_z_mps2,gyro_x_radps,gyro_y_radps,gyro_z_radps"]
    for i in range(50 * 20):
        t = i / 50.0
        bounce = 2.5 * math.sin(2 * math.pi * 1.8 * t) if t > 2.0 else 0.0
        rows.append(f"{100 + t:.3f},0,{0.3 * bounce / 2.5:.4f},{9.81 + bounce:.4f},0,0,0")
    (folder / "phone.csv").write_text("\n".join(rows) + "\n")
    (folder / "stands.csv").write_text("time_s,sensor_id,stand_id\n101.000,phone,door\n101.5,phone,nowhere\n")
    (folder / "truth.csv").write_text("time_s,agent_id,x_m,y_m\n" + "".join(
        f"{100 + t:.1f},walker,{2.0 + max(0.0, t - 2.0) * 1.26:.3f},5.0\n" for t in range(2, 21, 2)))
    report = import_csv_folder(folder, tmp_path / "walk.mcap")
    assert report.rows_skipped == 1  # the unknown stand, named
    data = read_session(tmp_path / "walk.mcap")
    scan = data.scans["walker"][0]
    assert (scan.accepted, scan.stand_id, scan.x_m, scan.y_m, scan.timestamp_ns) == (True, "door", 2.0, 5.0,
                                                                                     101_000_000_000)
    assert main(["eval", str(tmp_path / "walk.mcap"), "--json"]) == 0
    rows_out = {(r["method"], r["map_matching"]): r for r in json.loads(capsys.readouterr().out)["results"]}
    assert rows_out[("reckon", False)]["waypoints"] == 10
    assert rows_out[("reckon", False)]["waypoint_error_m"]["p90"] < 5.0
