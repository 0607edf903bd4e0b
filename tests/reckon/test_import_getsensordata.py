"""GetSensorData logs (reckon/importers/getsensordata*.py) into session logs, and `reckon eval` on one.

Every log here is crafted in tmp_path (no real log is in ../shared/data): a phone walking at
1.8 steps/s, its sensor clock 4999.996 s ahead of the app's, with every record type, bad lines,
an unknown type, iBeacon and Eddystone sightings and POSI points on two floors."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from protocol import keys, messages
from protocol.errors import InputError
from protocol.session_log import LogMessages, read_session
from reckon.cli import main
from reckon.importers.geo import east_north_m
from reckon.importers.geomagnetic import venue_field
from reckon.importers.getsensordata import creation_time_ns
from reckon.importers.getsensordata_session import COURT_MARGIN_M, import_getsensordata
from reckon.importers.ilc_session import START_HEADING_SD_RAD

G = 9.80665
UUID = "e2c56db5-dffb-48d2-b060-d0f5a71096e0"
SENSOR_AHEAD_S = 5000.0  # the sensor clock at app time 0 (the app logs each event 4 ms after it)
LATENCY_S = 0.004
HEADER = ["% LogFile created by the 'GetSensorData' App for Android.",
          "% Date of creation: Fri Jul 27 11:28:34 GMT+02:00 2018",
          "% Manufacturer:            \tLGE", "% Model:                   \tNexus 5X"]
BEACONS = f"id,lat,lon,floor\nibeacon:{UUID.upper()}:01:2,40.0005,-3.0005,0\neddystone:00112233445566778899:0123456789ab,40.001,-2.999,1\n"
# The WGS 84 radii of curvature at 40 N: meridian M and prime vertical N (metres).
E2 = 0.00669437999014
M_40 = 6378137.0 * (1 - E2) / (1 - E2 * math.sin(math.radians(40.0)) ** 2) ** 1.5
N_40 = 6378137.0 / math.sqrt(1 - E2 * math.sin(math.radians(40.0)) ** 2)


def accel_ms2(t: float) -> tuple[float, float, float]:
    """The crafted phone's acceleration: gravity on +z with a 1.8 Hz step bounce."""
    bounce = math.sin(2 * math.pi * 1.8 * t)
    return 0.1, 0.3 * bounce, G + 2.0 * bounce


def motion(duration_s: float) -> list[str]:
    """ACCE and GYRO at 100 Hz (GYRO 5 ms later), MAGN at 50 Hz, PRES and AHRS at 5 Hz."""
    lines = []
    for k in range(round(duration_s * 100)):
        t = 0.01 * k
        sensor = f"{SENSOR_AHEAD_S + t:.3f}"
        x, y, z = accel_ms2(t)
        lines.append(f"ACCE;{t + LATENCY_S:.3f};{sensor};{x:.5f};{y:.5f};{z:.5f};3")
        lines.append(f"GYRO;{t + 0.005 + LATENCY_S:.3f};{SENSOR_AHEAD_S + t + 0.005:.3f};0.00000;0.00000;0.10000;3")
        if k % 2 == 0:
            lines.append(f"MAGN;{t + LATENCY_S:.3f};{sensor};20.00000;0.00000;-40.00000;3")
        if k % 20 == 0:
            lines.append(f"PRES;{t + LATENCY_S:.3f};{sensor};{1013.25 - 0.001 * k:.4f};3")
            lines.append(f"AHRS;{t + LATENCY_S:.3f};{sensor};1.0;2.0;3.0;0.1;0.2;0.3;3")
    return lines


def crafted_log(path: Path, duration_s: float = 10.0, posi: list[str] | None = None, extra: list[str] | None = None,
                drop: str = "") -> Path:
    """A log at `path`: HEADER, the motion, POSI points, every other record type, bad lines, and a
    last line cut short (without a line end, as the app never ends its last line). `drop`: a
    record type left out."""
    posi = posi if posi is not None else ["POSI;0.500;1;40.0;-3.0;0;0", "POSI;5.000;2;40.001;-3.0;0;0",
                                          "POSI;9.500;3;40.001;-2.999;1;0"]
    others = ["WIFI;1.000;5001.000;eduroam;00:11:22:33:44:55;2412;-60", "LIGH;1.000;5001.000;100.0;3",
              "GNSS;1.000;5001.000;40.0;-3.0;650.0;5.0;0.0;0.0;8;12", "BLUE;1.000;phone;00:11:22:33:44:66;0",
              f"BLE4;2.000;iBeacon;AA:BB:CC:DD:EE:FF;-70;-59;1;2;{UUID}",
              f"BLE4;2.100;iBeacon;AA:BB:CC:DD:EE:F0;-75;-59;9;9;{UUID.replace('-', '')}",
              "BLE4;2.200;Eddystone;AA:BB:CC:DD:EE:F1;-80;0123456789AB;3000;21.0;5;100",
              "BLE4;2.300;Eddystone;AA:BB:CC:DD:EE:F2;-81;ffffffffffff",
              "BLE4;2.400;Eddystone;AA:BB:CC:DD:EE:F2;-81;null;-1;-1.0;-1;-1",  # no instance: skipped
              "FOOB;1.000;2.000",  # unknown type
              "ACCE;3.000;abc;0.1;0.2;9.8;3",  # not a number
              "GYRO;3.000;5003.000;0.1",  # wrong field count
              "% a comment between records"]
    lines = HEADER + [line for line in motion(duration_s) + posi + others + (extra or []) if not line.startswith(drop or "~")]
    path.write_text("\n".join(lines) + "\nACCE;9.99;5009")  # the recording stopped mid-line
    return path


@pytest.fixture
def imported(tmp_path: Path):
    log = crafted_log(tmp_path / "log.txt")
    (tmp_path / "beacons.csv").write_text(BEACONS)
    result = import_getsensordata(log, tmp_path / "walk.mcap", beacons_csv=tmp_path / "beacons.csv")
    return result, read_session(tmp_path / "walk.mcap"), tmp_path


def test_the_tangent_plane_matches_a_hand_computation():
    east, north = east_north_m(np.array([40.001, 40.0]), np.array([-3.0, -2.999]), 40.0, -3.0)
    assert north[0] == pytest.approx(M_40 * math.radians(0.001), abs=0.005)  # 111.03 m
    assert north[0] == pytest.approx(111.2, abs=0.2)  # 0.001 deg of latitude, on a sphere 111.19 m
    assert east[0] == pytest.approx(0.0, abs=1e-6)
    assert east[1] == pytest.approx(N_40 * math.cos(math.radians(40.0)) * math.radians(0.001), abs=0.005)  # 85.39 m
    assert north[1] == pytest.approx(0.0, abs=0.001)  # the parallel curves away from the plane by 0.6 mm


def test_a_crafted_log_imports_every_stream(imported):
    result, data, _ = imported
    phone = data.imu["phone"]
    # 1000 ACCE lines: the first comes before any gyroscope sample, the last after the last
    # magnetometer one; both are dropped (and the ones with bad fields were never read).
    assert len(phone.time_ns) == 998 == result.report.sensors["phone"].samples
    # the time base: sensor times moved onto the app clock (the constant 4 ms latency kept)
    assert phone.time_ns[0] == round((0.01 + LATENCY_S) * 1e9) and phone.time_ns[1] - phone.time_ns[0] == 10_000_000
    t = 0.02  # the third ACCE line's sensor time, on the phone's clock
    assert phone.accel_g[1] == pytest.approx(np.array(accel_ms2(t)) / G, abs=1e-6)
    assert phone.gyro_dps[1] == pytest.approx([0.0, 0.0, math.degrees(0.1)], abs=1e-5)  # rad/s -> deg/s
    assert phone.mag_gauss is not None and phone.mag_gauss[1] == pytest.approx([0.2, 0.0, -0.4])  # uT -> gauss
    assert data.session.agent("walker").sensors[0].rate_hz == 100.0


def test_truth_is_in_metres_east_and_north_of_the_origin(imported):
    result, data, _ = imported
    truth = data.truth["walker"]
    assert truth.time_ns.tolist() == [500_000_000, 5_000_000_000, 9_500_000_000]
    assert all(math.isnan(h) for h in truth.heading_rad)
    dx, dy = truth.x_m - truth.x_m[0], truth.y_m - truth.y_m[0]
    assert dy[1] == pytest.approx(M_40 * math.radians(0.001), abs=0.01) and dx[1] == pytest.approx(0.0, abs=1e-6)
    assert dx[2] == pytest.approx(85.39, abs=0.02)  # 0.001 deg of longitude at 40.001 N
    # beacon 1 lies 0.0005 deg west of the origin: the frame's (0, 0) moves 5 m west of it, whole metres
    west_m = N_40 * math.cos(math.radians(40.0)) * math.radians(0.0005)
    assert truth.x_m[0] == math.ceil(west_m + COURT_MARGIN_M) and truth.y_m[0] == 0.0
    assert "40.0000000, -3.0000000 (the first POSI point), which lies at x 48, y 0 m" in data.session.source["frame"]
    assert data.session.source["truth_floors"] == ["0", "0", "1"]
    assert truth.floor.tolist() == [0, 0, 1]  # on the truth poses themselves, for the IPIN score
    venue = data.session.venue
    assert venue.court_length_m >= truth.x_m.max() + COURT_MARGIN_M and venue.court_width_m >= truth.y_m.max()
    field = venue_field(40.0, -3.0, creation_time_ns("Fri Jul 27 11:28:34 GMT+02:00 2018"))
    assert (venue.magnetic_north_deg, venue.magnetic_field_ut, venue.magnetic_dip_deg) == (
        field["magnetic_north_deg"], field["magnetic_field_ut"], field["magnetic_dip_deg"])
    assert "truth: 3 POSI points on floors 0, 1 (building 0)" in str(result)


def test_the_first_posi_point_stands_in_for_a_stand(imported):
    _, data, _ = imported
    scan = data.scans["walker"][0]
    truth = data.truth["walker"]
    assert len(data.scans["walker"]) == 1 and scan.accepted and scan.timestamp_ns == truth.time_ns[0]
    assert (scan.x_m, scan.y_m, scan.floor) == (truth.x_m[0], truth.y_m[0], 0)
    assert scan.heading_rad == pytest.approx(math.pi / 2, abs=1e-6)  # POSI 2 is due north
    assert scan.heading_sd_rad == pytest.approx(START_HEADING_SD_RAD)


def test_beacons_and_their_sightings(imported):
    result, data, _ = imported
    ibeacon, eddystone = data.session.venue.beacons
    assert (ibeacon.id, ibeacon.identity) == ("beacon-1", f"ibeacon:{UUID}:1:2")
    assert eddystone.identity == "eddystone:00112233445566778899:0123456789ab"
    truth = data.truth["walker"]
    west_m = N_40 * math.cos(math.radians(40.0)) * math.radians(0.0005)
    assert ibeacon.x_m - truth.x_m[0] == pytest.approx(-west_m, abs=0.01)
    assert ibeacon.y_m - truth.y_m[0] == pytest.approx(M_40 * math.radians(0.0005), abs=0.01)
    assert (eddystone.x_m, eddystone.y_m) == pytest.approx((truth.x_m[2], truth.y_m[2]), abs=1e-6)
    assert (ibeacon.floor, eddystone.floor) == (0, 1)
    sightings = data.sightings["walker"]
    # known beacons by their venue id (as the live edge writes them), the others by identity
    assert sightings.beacon_id.tolist() == ["beacon-1", f"ibeacon:{UUID}:9:9", "beacon-2", "eddystone:ffffffffffff"]
    assert sightings.rssi_dbm.tolist() == [-70.0, -75.0, -80.0, -81.0]
    assert sightings.time_ns.tolist() == [2_000_000_000, 2_100_000_000, 2_200_000_000, 2_300_000_000]
    assert result.unknown_sightings == {f"ibeacon:{UUID}:9:9": 1, "eddystone:ffffffffffff": 1}


def test_pressure_messages(imported):
    _, _, folder = imported
    rows = [(topic, message) for _, topic, message in LogMessages(folder / "walk.mcap")
            if messages.type_name(message) == "Pressure"]
    assert len(rows) == 50 and {topic for topic, _ in rows} == {keys.pressure("log", "walker", "phone")}
    assert [m.pressure_hpa for _, m in rows[:2]] == [1013.25, 1013.23]
    assert rows[1][1].timestamp_ns == round((0.2 + LATENCY_S) * 1e9) and rows[0][1].sensor_id == "phone"


def test_the_report_counts_every_line(imported):
    result, _, _ = imported
    report = result.report
    assert dict(report.skipped) == {"log.txt: ACCE: no GYRO/MAGN samples around it": 2,
                                    "log.txt: ACCE: not a finite number": 1, "log.txt: ACCE: wrong field count": 1,
                                    "log.txt: BLE4 Eddystone: malformed instance": 1,
                                    "log.txt: GYRO: wrong field count": 1}
    assert report.sightings == 4 and report.truth_poses == 3 and not report.warnings
    text = str(result)
    last = len(HEADER) + len(motion(10.0)) + 3 + 13 + 1  # the 3 POSI and 13 other lines, then the cut one
    assert f"log.txt line {last}: ACCE has 2 fields after the type, expected 6: '9.99;5009'" in text
    assert "ACCE field 3 'abc' is not a finite number" in text and "instance 'null' is not 12 hex digits" in text
    assert "read, not used: AHRS 50, WIFI 1, LIGH 1, GNSS 1, BLUE 1" in text
    assert "unknown record types (counted, not read): FOOB 1" in text
    assert "pressure: 50 messages, 1012.27-1013.25 hPa" in text
    assert "stand scan at POSI 1: x 48.00, y 0.00 m, floor 0, heading 90.0 deg" in text


def test_an_origin_south_west_of_the_site_is_the_frames_corner(tmp_path: Path):
    posi = ["POSI;0.500;1;40.0;-3.0;2;0", "POSI;5.000;2;40.0;-2.999;2;0", "POSI;9.500;3;40.001;-2.999;3;0"]
    log = crafted_log(tmp_path / "log.txt", posi=posi)
    result = import_getsensordata(log, tmp_path / "walk.mcap", origin=(39.999, -3.001))
    data = read_session(tmp_path / "walk.mcap")
    truth = data.truth["walker"]
    assert (result.frame.x0_m, result.frame.y0_m) == (0.0, 0.0)
    east, north = east_north_m(40.0, -3.0, 39.999, -3.001)
    assert (truth.x_m[0], truth.y_m[0]) == pytest.approx((float(east), float(north)))
    assert truth.y_m[0] == pytest.approx(111.03, abs=0.02) and truth.x_m[0] == pytest.approx(85.39, abs=0.02)
    scan = data.scans["walker"][0]
    assert scan.floor == 2 and scan.heading_rad == pytest.approx(0.0, abs=1e-4)  # POSI 2 is due east
    assert "(--origin), which lies at x 0, y 0 m" in data.session.source["frame"]
    assert data.session.venue.beacons == ()


def test_the_cli_imports_and_prints_the_report(tmp_path: Path, capsys):
    log = crafted_log(tmp_path / "walk 1.txt")
    (tmp_path / "beacons.csv").write_text(BEACONS)
    out = tmp_path / "walk.mcap"
    assert main(["import", "getsensordata", str(log), "-o", str(out), "--beacons", str(tmp_path / "beacons.csv"),
                 "--origin", "40.0,-3.0"]) == 0
    printed = capsys.readouterr().out
    assert f"imported 1 sensors into {out}" in printed and "beacon sightings: 4; truth poses: 3" in printed
    assert "(--origin), which lies at x 48, y 0 m" in printed
    assert read_session(out).session.venue.name == "walk-1"
    assert main(["import", "getsensordata", str(log), "-o", str(out), "--origin", "north"]) == 2
    assert "--origin: 'north' is not LAT,LON" in capsys.readouterr().err


@pytest.mark.parametrize("drop, posi, message", [
    ("GYRO", None, r"log.txt: 0 readable GYRO lines; the phone IMU needs ACCE and GYRO"),
    ("ACCE", None, r"log.txt: 0 readable ACCE lines"),
    ("", ["POSI;0.500;1;40.0;-3.0;0;0"], r"log.txt: 1 POSI points; a walk needs at least 2"),
])
def test_what_a_walk_cannot_do_without(tmp_path: Path, drop: str, posi: list[str] | None, message: str):
    log = crafted_log(tmp_path / "log.txt", posi=posi, drop=drop)
    with pytest.raises(InputError, match=message):
        import_getsensordata(log, tmp_path / "walk.mcap")
    assert not (tmp_path / "walk.mcap").exists()


@pytest.mark.parametrize("text, message", [
    ("name,lat,lon\n", r"beacons.csv:1: expected the header 'id,lat,lon,floor'"),
    ("id,lat,lon,floor\nibeacon:xyz:1:2,40.0,-3.0,0\n", r"beacons.csv:2: id: 'ibeacon:xyz:1:2' is not ibeacon:"),
    ("id,lat,lon,floor\neddystone:0123456789ab,91.0,-3.0,0\n", r"beacons.csv:2: \(91.0, -3.0\) is not a latitude"),
    ("id,lat,lon,floor\neddystone:0123456789ab,40.0,-3.0,first\n", r"beacons.csv:2: .* floor 'first' an integer"),
    ("id,lat,lon,floor\neddystone:0123456789ab,40,-3,0\neddystone:00112233445566778899:0123456789ab,40,-3,0\n",
     r"beacons.csv:3: beacon 0123456789ab is also on line 2"),
])
def test_a_bad_beacons_file_names_the_line(tmp_path: Path, text: str, message: str):
    log = crafted_log(tmp_path / "log.txt")
    (tmp_path / "beacons.csv").write_text(text)
    with pytest.raises(InputError, match=message):
        import_getsensordata(log, tmp_path / "walk.mcap", beacons_csv=tmp_path / "beacons.csv")


def test_a_pressure_message_round_trips():
    message = messages.new("Pressure", timestamp_ns=5, agent_id="walker", sensor_id="phone", pressure_hpa=1013.2456)
    decoded = messages.Pressure.FromString(message.SerializeToString())
    assert decoded == message and decoded.pressure_hpa == 1013.2456 and decoded.schema_version == messages.SCHEMA_VERSION
    assert keys.parse(keys.pressure("v", "walker", "phone")) == ("v", "walker", "pressure", "phone")


def test_eval_scores_an_imported_walk(tmp_path: Path, capsys):
    # 30 s northwards at about 1.2 m/s: a POSI point every 0.0001 deg of latitude (11.1 m)
    posi = [f"POSI;{1.0 + 9.0 * i:.3f};{i + 1};{40.0 + 0.0001 * i:.4f};-3.0;0;0" for i in range(4)]
    log = crafted_log(tmp_path / "log.txt", duration_s=30.0, posi=posi)
    assert main(["import", "getsensordata", str(log), "-o", str(tmp_path / "walk.mcap")]) == 0
    capsys.readouterr()
    assert main(["eval", str(tmp_path / "walk.mcap"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    rows = {(row["method"], row["map_matching"]): row for row in report["results"]}
    assert set(rows) == {("paper", False), ("reckon", False)}  # no floor plan, no map points
    for row in rows.values():
        errors = row["waypoint_error_m"]
        assert row["waypoints"] == 3 and 0.0 <= errors["median"] <= errors["p75"] <= errors["p90"] < 100.0
