"""The `reckon` command end to end on short simulated sessions: outputs, plots, user errors."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest

from reckon.cli import main
from support.games import Game

GAME = Game(players=4, duration_s=40.0, seed=3)
RESULT_KEYS = {"method", "heading", "corrections", "mean_error_m", "max_team_mean_error_m",
               "worst_agent_mean_error_m", "final_team_mean_error_m"}


def test_sim_command_writes_the_simulators_game(games, tmp_path):
    """`reckon sim wheelchair` is `simulate` with the same settings: the same log, record for record
    (the other tests here take the game from `simulate`, shared with the suite)."""
    from mcap.reader import make_reader

    def records(path):
        with open(path, "rb") as stream:
            return [(channel.topic, message.log_time, message.data)
                    for _, channel, message in make_reader(stream).iter_messages(log_time_order=False)]

    path = tmp_path / "game.mcap"
    assert main(["-q", "sim", "wheelchair", "--players", "2", "--duration", "5", "--seed", "3", "-o", str(path)]) == 0
    written = records(path)
    assert len(written) > 500 and written == records(games.path(Game(players=2, duration_s=5.0, seed=3)))


def test_eval_json_has_every_heading_and_correction_set(game, capsys):
    assert main(["-q", "eval", str(game), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    rows = report["results"]
    paper = [r for r in rows if r["method"] == "paper"]
    ours = [r for r in rows if r["method"] == "reckon"]
    assert {r["heading"] for r in paper} == {"true", "video", "sensors"}
    assert {tuple(r["corrections"]) for r in paper} >= {(), ("beacon",), ("collision",), ("beacon", "collision"), ("video",)}
    assert {(r["heading"], tuple(r["corrections"]), r["track"]) for r in ours} == {
        ("sensors", c, t) for c in ((), ("beacon",), ("collision",), ("beacon", "collision"))
        for t in ("live", "refined")} | {("gyro", (), "live"), ("gyro", (), "refined")}
    assert all(0.0 < r["nees"] < 1e6 for r in ours)  # both tracks state a covariance
    assert not any("nees" in r for r in paper)
    assert len(paper) + len(ours) == len(rows)
    for row in rows:
        assert RESULT_KEYS <= set(row)
        assert 0.0 <= row["mean_error_m"] <= row["max_team_mean_error_m"] + 1e-9
    true_dr = next(r for r in rows if r["heading"] == "true" and not r["corrections"])
    assert true_dr["max_team_mean_error_m"] < 3.0  # 40 s of wheel odometry with true heading stays close
    assert [d["threshold_g"] for d in report["collision_detection"]] == [float(g) for g in range(4, 13)]
    for d in report["collision_detection"]:
        assert d["precision"] is None or 0.0 <= d["precision"] <= 1.0
    pairs = report["reckon_contact_pairs"]
    assert 0 <= pairs["matched"] <= pairs["taken"] and pairs["true_contacts"] == report["collision_detection"][0]["true_contacts"]


def test_eval_table_and_plots(game, tmp_path, capsys):
    assert main(["-q", "eval", str(game), "--plots", str(tmp_path / "plots")]) == 0
    out = capsys.readouterr().out
    assert "beacon_zone+collision" in out and "precision" in out
    for name in ("error_over_time.png", "trajectories.png", "collision_detection.png"):
        assert (tmp_path / "plots" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_calibrate_reports_against_the_paper(tmp_path, capsys):
    assert main(["-q", "calibrate", "--seeds", "2", "--players", "3", "--duration", "30", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "2.2 m at 120 s" in out and "video, clocks 0.5 s apart" in out
    assert (tmp_path / "calibration.png").exists()


@pytest.mark.parametrize("argv, message", [
    (["eval", "missing.mcap"], "missing.mcap: no such file"),
    (["sim", "wheelchair", "--duration", "5", "-o", "x.mcap", "--set", "sensors.gyro_bias=1"], "unknown key 'gyro_bias'"),
    (["sim", "wheelchair", "--duration", "5", "-o", "x.mcap", "--set", "nonsense"], "expected key=value"),
    (["import", "csv", "no-such-folder", "-o", "x.mcap"], "no-such-folder"),
])
def test_user_errors_are_one_line_not_a_traceback(argv, message, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["-q", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_console_script_runs(tmp_path):
    result = subprocess.run([sys.executable, "-m", "reckon.cli", "eval", str(tmp_path / "none.mcap")],
                            capture_output=True, text=True)
    assert result.returncode == 2
    assert result.stderr.startswith("reckon: error:")


def test_replay_into_record_over_zenoh(game, free_endpoint, tmp_path):
    """`reckon record` in its own process, `reckon replay` here: the log comes back whole."""
    from protocol.session_log import read_session

    endpoint = free_endpoint()
    output = tmp_path / "recorded.mcap"
    recorder = subprocess.Popen([sys.executable, "-m", "reckon.cli", "-q", "record", "--venue", "court",
                                 "-o", str(output), "--until-end", "--listen", endpoint],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert main(["-q", "replay", str(game), "--speed", "0", "--wait-for", "1", "--wait-timeout", "60",
                     "--connect", endpoint]) == 0
        out, err = recorder.communicate(timeout=60)
    finally:
        recorder.kill()
    assert recorder.returncode == 0, err
    assert "end of session seen" in out
    original, recorded = read_session(game), read_session(output)
    assert recorded.session == original.session
    for sensor, series in original.imu.items():
        assert (recorded.imu[sensor].time_ns == series.time_ns).all()
    assert len(recorded.contacts) == len(original.contacts)


def test_demo_runs_end_to_end_on_a_short_game(tmp_path, capsys):
    """The quickstart's main job, shortened: simulate, live through edges and the hub, then eval."""
    from reckon.cli import main as reckon_main

    assert reckon_main(["demo", "--players", "2", "--duration", "20", "--speed", "10", "--lag", "5",
                        "--out", str(tmp_path)]) == 0
    captured = capsys.readouterr()
    out = captured.out
    assert "live pipeline" in out and "mean error live" in out
    assert re.search(r"^chair01 +\d+\.\d+ +\d+\.\d+ ", captured.err, re.M)  # the court table took the hub's pose batches
    assert "paper" in out and "reckon" in out  # the offline comparison table
    assert (tmp_path / "hub.mcap").stat().st_size > 0 and any((tmp_path / "plots").iterdir())


def test_a_missing_extra_is_one_line_naming_it(tmp_path, monkeypatch, capsys):
    monkeypatch.delitem(sys.modules, "reckon.tools.foxglove", raising=False)
    monkeypatch.setitem(sys.modules, "foxglove", None)  # as if foxglove-sdk were not installed
    assert main(["-q", "export", "foxglove", str(tmp_path / "in.mcap"), "-o", str(tmp_path / "out.mcap")]) == 2
    err = capsys.readouterr().err
    assert err == "reckon export needs the [eval] extra: pip install 'reckon[eval]' (foxglove is not installed)\n"


def test_a_missing_module_of_our_own_is_a_traceback_not_an_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "reckon.tools.foxglove", None)  # a broken install, not a missing extra
    with pytest.raises(ModuleNotFoundError):
        main(["-q", "export", "foxglove", str(tmp_path / "in.mcap"), "-o", str(tmp_path / "out.mcap")])
