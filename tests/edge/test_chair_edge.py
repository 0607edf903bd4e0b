"""A chair's edge (edge/chair/edge.py) on hand-made batches: what its impact events say."""

from __future__ import annotations

import dataclasses
import threading

import numpy as np
import pytest

from edge.base import EdgeSummary
from edge.chair.edge import ChairEdge
from protocol import messages
from protocol.messages import imu_batch
from protocol.session import Agent, Mount, Sensor
from protocol.session_log import read_session
from edge.sources.mcap import mcap_source
from reckon.evaluation.reckon_run import log_inputs, without_magnetometer
from sim_devices.wheelchair import simulate
from sim_devices.wheelchair.worlds import world_params
from support.games import Game

# the seat is mounted backwards and upside down: chair (forward, left, up) = sensor (-x, +y, -z)
AGENT = Agent("chair01", sensors=(Sensor("left", Mount.LEFT_WHEEL, spin_axis="+z"),
                                  Sensor("right", Mount.RIGHT_WHEEL, spin_axis="-z"),
                                  Sensor("seat", Mount.SEAT, forward_axis="-x", left_axis="+y")))
DT = 5_000_000


def batches(seat_accel: np.ndarray, drop_seat: slice = slice(0, 0)):
    """20-sample batches of a parked chair, in time order; the seat's accelerometer as given (sensor frame)."""
    n = len(seat_accel)
    times = np.arange(n, dtype=np.int64) * DT + 1_000_000_000
    keep = np.ones(n, dtype=bool)
    keep[drop_seat] = False
    out = []
    for start in range(0, n, 20):
        rows = slice(start, start + 20)
        for sensor in ("left", "right"):
            out.append(imu_batch("chair01", sensor, start // 20, times[rows], np.zeros((20, 3)), np.zeros((20, 3)), None))
        seat_rows = np.arange(start, start + 20)[keep[rows]]
        if len(seat_rows):
            out.append(imu_batch("chair01", "seat", start // 20, times[seat_rows], seat_accel[seat_rows],
                                 np.zeros((len(seat_rows), 3)), None))
    return out


def run(stream):
    edge = ChairEdge(AGENT)
    out = []
    for batch in stream:
        out += edge.push(batch)
    return out + edge.flush(), edge


def test_an_impact_says_which_way_it_pushed_the_chair():
    accel = np.tile([0.0, 0.0, -1.0], (400, 1))  # parked, gravity's reaction up (= sensor -z)
    accel[200:202] = [7.0, 1.0, -1.0]  # the chair pushed backwards and a little to the left
    events = [m for m in run(batches(accel))[0] if messages.type_name(m) == "ImpactEvent"]
    assert len(events) == 1
    (event,) = events
    assert event.forward_g == pytest.approx(-7.0, abs=1e-3) and event.left_g == pytest.approx(1.0, abs=1e-3)
    assert event.peak_g == pytest.approx(np.sqrt(51.0) - 1.0, rel=1e-5)


def test_a_silent_seat_is_bridged_and_counted():
    accel = np.tile([0.0, 0.0, -1.0], (400, 1))
    out, edge = run(batches(accel, drop_seat=slice(100, 160)))  # 0.3 s of seat batches lost
    summary = EdgeSummary("chair01")
    edge.summarise(summary)
    assert summary.bridged == 29 and "29 bridging a silent seat" in str(summary)
    # a parked chair never turns, so nothing moves the wheels' clocks off the seat's
    assert summary.wheel_clocks_ms == (0.0, 0.0)
    assert "wheel clocks against the seat's: left +0.0 ms, right +0.0 ms" in str(summary)
    poses = [m for m in out if messages.type_name(m) == "EstimatedPose"]
    assert poses and all(np.isfinite([p.x_m, p.y_m, p.heading_rad]).all() for p in poses)


def chair_run(games, agent_changes: dict):
    """A simulated minute of one chair through its edge, the venue file's agent changed by `agent_changes`:
    (summary, warnings)."""
    path = games.path(Game(players=1, duration_s=60.0, seed=2))
    agent = dataclasses.replace(read_session(path).session.agent("chair01"), **agent_changes)
    edge, warnings = ChairEdge(agent), []
    for batch in mcap_source(path, "chair01", 0.0, threading.Event()):
        if messages.type_name(batch) == "ImuBatch":
            edge.push(batch)
            warnings += edge.warnings()
    edge.flush()
    summary = EdgeSummary("chair01")
    edge.summarise(summary)
    return summary, warnings + edge.warnings()


def test_the_seat_gyros_scale_is_checked_against_the_axles_once_they_turned(games):
    summary, warnings = chair_run(games, {})
    assert warnings == []
    scale, check = summary.seat_gyro_scale
    assert check == "checked against the axles" and abs(scale) < 5.0
    assert f"seat gyro scale correction {scale:+.2f} % (checked against the axles)" in str(summary)


def test_a_camber_the_venue_file_has_wrong_is_refused_and_named(games):
    """The axles read yaw x cos(camber): 40 deg where the chair has 17 makes their turn 20 % short."""
    summary, warnings = chair_run(games, {"camber_deg": 40.0})
    assert summary.seat_gyro_scale[1] == "the axles disagreed, not used"
    (warning,) = warnings
    assert warning.startswith("chair01: the axle IMUs' turn put the seat gyro's scale at +")
    assert "chi-square gate" in warning and "camber (40.0 deg)" in warning


def field_map(columns: int, rows: int, offset: float, variance: float, cells: int | None = None):
    cells = columns * rows if cells is None else cells
    return messages.new("FieldMap", timestamp_ns=0, agent_id="chair01", origin_x_m=-2.0, origin_y_m=-2.0, cell_m=2.0,
                        columns=columns, rows=rows, offset_rad=[offset] * cells, variance_rad2=[variance] * cells)


def test_the_hub_field_map_reaches_the_filter_and_readings_go_out(games):
    """The edge hands the filter the hub's map where the chair is, drops it when the hub withdraws it,
    refuses a malformed one by name, and offers its magnetometer readings to the map."""
    path = games.path(Game(players=1, duration_s=60.0, seed=2))
    agent = read_session(path).session.agent("chair01")
    edge, out, warnings = ChairEdge(agent), [], []
    stream = [b for b in mcap_source(path, "chair01", 0.0, threading.Event()) if messages.type_name(b) == "ImuBatch"]
    third = len(stream) // 3
    for k, batch in enumerate(stream):
        if k == third:
            edge.field_map(field_map(16, 10, 0.1, 4e-3))
            edge.field_map(field_map(16, 10, 0.5, 4e-3, cells=12))  # refused: the previous one holds
            warnings += edge.warnings()
        if k == third + 30:
            mag = edge.state.mag
            assert (mag.map_offset_rad, mag.map_var_rad2) == (pytest.approx(0.1), pytest.approx(4e-3))
            edge.field_map(field_map(0, 0, 0.0, 0.0))  # withdrawn
        if k == third + 60:
            assert edge.state.mag.map_var_rad2 == 0.0
        out += edge.push(batch)
    out += edge.flush()
    (warning,) = warnings
    assert warning.startswith("chair01: field map refused (1 so far): 16 x 10 cells of 2.0 m with 12 offsets")
    readings = [m for m in out if messages.type_name(m) == "FieldReading"]
    summary = EdgeSummary("chair01")
    edge.summarise(summary)
    assert summary.field_maps == 2 and summary.field_readings >= len(readings) > 20
    assert "field readings out and 2 field maps in" in str(summary)
    times = [r.timestamp_ns for r in readings]
    assert times == sorted(times) and all(abs(r.offset_rad) < 3.15 and r.variance_rad2 > 0.0 for r in readings)
    poses = [m for m in out if messages.type_name(m) == "EstimatedPose"]
    pose_times = np.array([p.timestamp_ns for p in poses])
    for r in readings:  # where the filter had the chair then
        p = poses[int(np.argmin(np.abs(pose_times - r.timestamp_ns)))]
        assert np.hypot(p.x_m - r.x_m, p.y_m - r.y_m) < 0.5


def test_in_a_hall_disturbed_smoothly_over_the_court_the_aid_is_no_worse_than_the_gyro(tmp_path):
    """Tune world 97's hall: 21 deg of disturbance correlated over 9 m, so smooth over the court that
    the field's strength spread reads only about 8 deg of it. Ten chairs for two minutes, each edge
    alone with and without its magnetometer: an aid that believed the spread pulled the headings
    (mean error 1.46 x the gyro's alone); the readings' own errors against the heading now say how
    far to trust them."""
    path = tmp_path / "world97.mcap"
    simulate(10, 120.0, 1, path, world_params(97), world=97)
    log = read_session(path)

    def mean_error(arrivals) -> float:
        """Every chair's edge over the log in one pass: the mean position error after each batch."""
        edges = {agent.id: ChairEdge(agent, 10.0) for agent in log.session.agents}
        errors = []
        for _, message in arrivals:
            if messages.type_name(message) != "ImuBatch":
                continue
            edge, truth = edges[message.agent_id], log.truth[message.agent_id]
            edge.push(message)
            if edge.vector is not None:
                state = edge.state
                errors.append(np.hypot(state.mean[0] - np.interp(state.time_ns, truth.time_ns, truth.x_m),
                                       state.mean[1] - np.interp(state.time_ns, truth.time_ns, truth.y_m)))
        return float(np.mean(errors))

    arrivals = log_inputs(path)
    assert mean_error(arrivals) < 1.1 * mean_error(without_magnetometer(arrivals))
