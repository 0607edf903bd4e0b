"""`reckon import tracks`: a tracks CSV round trip into a session log, into an existing log, and bad input."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from protocol.errors import ConfigError, InputError
from protocol.session_log import read_session
from reckon.cli import main
from reckon.importers.tracks_csv import import_tracks_csv
from sim_devices.camera import ROOM, camera_items, extra_people, simulate_tracks
from support.venue import agent_table, write_venue

START_NS = 1_718_000_000 * 1_000_000_000


@pytest.fixture(scope="module")
def recording():
    """A simulated ROOM tracker: 3 people for 20 s, frames stamped from unix 1718000000."""
    rng = np.random.default_rng(1)
    people = extra_people(3, (5.6, 3.0), START_NS, START_NS + 20 * 1_000_000_000, rng, ROOM.extras)
    return simulate_tracks(people, (5.6, 3.0), ROOM, rng)


def _seconds(ns: int) -> str:
    return f"{ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"


def _write_csv(path: Path, recording, time_column: bool = True) -> Path:
    header = "frame,id,x_m,y_m,height_m,conf" + (",time_s" if time_column else "")
    lines = [header]
    for frame in recording.frames:
        for tid, x, y, h in zip(frame.track_id.tolist(), frame.x_m.tolist(), frame.y_m.tolist(),
                                frame.height_m.tolist()):
            stamp = f",{_seconds(frame.time_ns)}" if time_column else ""
            lines.append(f"{frame.frame},{tid},{x!r},{y!r},{h!r},1{stamp}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


@pytest.fixture
def session_toml(tmp_path: Path) -> Path:
    return write_venue(tmp_path / "room.toml", "room", court_length_m=5.6, court_width_m=3.0,
                       agents=[agent_table("walker1", "pedestrian")])


def test_round_trip_with_a_time_column(recording, tmp_path: Path, session_toml: Path):
    csv = _write_csv(tmp_path / "tracks.csv", recording)
    report = import_tracks_csv(csv, tmp_path / "out.mcap", session_toml=session_toml, camera_id="stereo",
                               position_sd_m=0.05)
    seen = [f for f in recording.frames if len(f.track_id)]
    assert (report.frames, report.rows) == (len(seen), sum(len(f.track_id) for f in seen))
    assert report.warnings == [] and "imported" in str(report)
    data = read_session(tmp_path / "out.mcap")
    camera = data.cameras["stereo"]
    assert camera.person_id is None and camera.position_sd_m == pytest.approx(0.05)
    assert camera.frame_ns.tolist() == [f.time_ns for f in seen]  # exact nanoseconds through the decimal text
    assert camera.track_id.tolist() == np.concatenate([f.track_id for f in seen]).tolist()
    assert np.array_equal(camera.x_m, np.concatenate([f.x_m for f in seen]))
    assert np.allclose(camera.height_m, np.concatenate([f.height_m for f in seen]), atol=1e-6)  # float32 field
    assert data.session.venue.name == "room" and data.session.source["camera_import"]["file"] == "tracks.csv"


def test_fps_and_start_give_frame_times_and_cm_convert(tmp_path: Path, session_toml: Path):
    csv = tmp_path / "t.csv"
    csv.write_text("frame,track_id,x_cm,y_cm\n1,1,100,50\n1,2,300,250\n4,1,110,55\n", encoding="utf-8")
    report = import_tracks_csv(csv, tmp_path / "o.mcap", session_toml=session_toml, fps=20, start_s="1718000000.5")
    assert any("--position-sd not given" in w for w in report.warnings)
    camera = read_session(tmp_path / "o.mcap").cameras["cam1"]
    assert camera.frame_ns.tolist() == [1_718_000_000_500_000_000, 1_718_000_000_650_000_000]
    assert camera.x_m.tolist() == [1.0, 3.0, 1.1] and camera.y_m.tolist() == [0.5, 2.5, 0.55]
    assert camera.height_m is None and camera.position_sd_m == pytest.approx(0.1)


def test_into_an_existing_log_keeps_its_messages_and_adds_the_tracks(recording, tmp_path: Path, session_toml: Path):
    game = tmp_path / "game.mcap"
    assert main(["-q", "sim", "wheelchair", "--players", "2", "--duration", "5", "--seed", "1", "-o", str(game)]) == 0
    before = read_session(game)
    csv = _write_csv(tmp_path / "tracks.csv", recording, time_column=False)
    argv = ["-q", "import", "tracks", str(csv), "--into", str(game), "-o", str(game), "--fps", "20", "--start",
            _seconds(int(before.truth["chair01"].time_ns[0])), "--position-sd", "0.08"]
    assert main(argv) == 0
    after = read_session(game)
    assert set(after.imu) == set(before.imu) and after.session.agents == before.session.agents
    for sensor, series in before.imu.items():
        assert np.array_equal(after.imu[sensor].time_ns, series.time_ns)
    assert len(after.cameras["cam1"].frame_ns) == sum(1 for f in recording.frames if len(f.track_id))
    assert main(argv) == 2  # the same camera twice is refused, and the log is left as it was
    assert len(read_session(game).cameras["cam1"].frame_ns) == len(after.cameras["cam1"].frame_ns)


def test_simulated_items_and_imported_csv_read_back_alike(recording, tmp_path: Path, session_toml: Path):
    from protocol.session import load_toml
    from sim_devices.common import write_merged

    simulated = tmp_path / "sim.mcap"
    write_merged(simulated, load_toml(session_toml), [camera_items(recording, "room")], lambda _: None)
    imported = tmp_path / "imp.mcap"
    import_tracks_csv(_write_csv(tmp_path / "t.csv", recording), imported, session_toml=session_toml,
                      position_sd_m=recording.position_sd_m)
    first, second = read_session(simulated).cameras["cam1"], read_session(imported).cameras["cam1"]
    assert set(first.person_id) >= {"extra1", "extra2", "extra3"}
    assert len(first.frame_ns) == len(recording.frames)  # the simulator also logs frames that saw nobody
    assert len(second.frame_ns) == sum(1 for f in recording.frames if len(f.track_id))
    assert np.array_equal(first.time_ns, second.time_ns) and np.array_equal(first.track_id, second.track_id)
    assert np.array_equal(first.x_m, second.x_m) and first.position_sd_m == pytest.approx(second.position_sd_m)


@pytest.mark.parametrize("text, message", [
    ("frame,id,x_m,y_m\n1,1,1.0,2.0\n2,1,1.1,two\n", "t.csv:3: column y: 'two' is not a number"),
    ("frame,id,x_m\n1,1,1.0\n", "t.csv: missing column y_m; found columns: frame, id, x_m"),
    ("frame,id,x,y_m\n1,1,1.0,2.0\n", "column 'x' needs a unit: x_m, x_cm, x_mm"),
    ("frame,id,x_m,y_m\n2,1,1.0,2.0\n3,1,1.0,2.0\n1,1,1.0,2.0\n",
     "t.csv:4: frame 1 comes after frame 3 (line 3); rows must be in frame order"),
    ("", "t.csv: empty file"),
    ("frame,id,x_m,y_m\n", "t.csv: no rows after the header"),
    ("frame,id,x_m,y_m\n1,0,1.0,2.0\n", "t.csv:2: column id: 0 is outside 1 .. 4294967295"),
    ("frame,id,x_m,y_m\n1,1,1.0,2.0\n1,1,1.5,2.0\n", "t.csv:3: id 1 appears twice in frame 1"),
    ("frame,id,x_m,y_m\n1,1,1.0\n", "t.csv:2: 3 fields, expected 4"),
    ("frame,id,x_m,y_m,time_s\n1,1,1.0,2.0,5.0\n1,2,1.0,2.0,5.1\n", "frame 1: rows give different times"),
    ("frame,id,x_m,y_m,time_s\n1,1,1.0,2.0,5.0\n2,1,1.0,2.0,5.0\n", "frame 2: time 5000000000 ns is not after"),
    ("frame,id,x_m,y_m\n1,1,nan,2.0\n", "t.csv:2: column x: 'nan' is not a finite number"),
])
def test_bad_files_name_file_line_column_and_value(text, message, tmp_path: Path, session_toml: Path):
    csv = tmp_path / "t.csv"
    csv.write_text(text, encoding="utf-8")
    timing = {} if "time_s" in text else {"fps": 25.0, "start_s": "0"}
    with pytest.raises(InputError) as error:
        import_tracks_csv(csv, tmp_path / "o.mcap", session_toml=session_toml, **timing)
    assert message in str(error.value)
    assert not (tmp_path / "o.mcap").exists()


@pytest.mark.parametrize("options, message", [
    ({}, "give --session SESSION.toml or --into LOG.mcap"),
    ({"session": True, "fps": None}, "no time column: give --fps and --start"),
    ({"session": True, "fps": -1.0}, "--fps -1.0: expected a frame rate"),
    ({"session": True, "position_sd_m": 0.0}, "--position-sd 0.0"),
])
def test_bad_options_are_config_errors(options, message, tmp_path: Path, session_toml: Path):
    csv = tmp_path / "t.csv"
    csv.write_text("frame,id,x_m,y_m\n1,1,1.0,2.0\n", encoding="utf-8")
    kwargs = {"fps": 25.0, "start_s": "0", **options}
    kwargs["session_toml"] = session_toml if kwargs.pop("session", False) else None
    with pytest.raises(ConfigError, match=re.escape(message)):
        import_tracks_csv(csv, tmp_path / "o.mcap", **kwargs)


def test_cli_reports_a_bad_file_in_one_line(tmp_path: Path, session_toml: Path, capsys):
    csv = tmp_path / "t.csv"
    csv.write_text("frame,id,x_m,y_m\n1,1,1.0,oops\n", encoding="utf-8")
    argv = ["-q", "import", "tracks", str(csv), "--session", str(session_toml), "--fps", "25", "--start", "0",
            "-o", str(tmp_path / "o.mcap")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "t.csv:2: column y: 'oops' is not a number" in err and "Traceback" not in err
