"""Pedestrian simulator (the indoor-navigation paper's walks): the session log, walls, the step model,
stand scans, accelerometer physics, the magnetic floor effect, determinism and `--set` validation.
Sessions are cut short (`duration_s`) to keep the suite fast."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import shapely

from hub.pedestrian.walkable import WalkableArea
from protocol import stand_code
from protocol.errors import ConfigError
from protocol.session import AgentKind, Mount, Stand
from protocol.session_log import read_session
from reckon.cli import build_parser
from sim_devices.pedestrian import MOUNTS, PedestrianParams, describe, error_free, params_with_overrides, \
    simulate_pedestrian, simulate_walker, stand_key
from sim_devices.pedestrian.calibration import _layout, fft_cadence
from sim_devices.pedestrian.path import smooth_path
from sim_devices.pedestrian.phone import flat_rotation
from sim_devices.pedestrian.sensors import MagneticField
from sim_devices.pedestrian.venues import PRESETS, layout, walkable_geometry

DOCS = Path(__file__).resolve().parents[2] / "docs" / "simulator-pedestrian.md"
RATE_HZ = PedestrianParams().sensors.rate_hz


def _walker(plan, index=0, mounts=(Mount.HAND,), params=None, seed=1, duration_s=None):
    params = params or PedestrianParams()
    venue_seed, walker_seed = np.random.SeedSequence(seed).spawn(2)
    field = MagneticField.draw(params.magnetic, np.random.default_rng(venue_seed))
    return simulate_walker(plan, index, mounts, params, walker_seed, field, 0, duration_s)


@pytest.fixture(scope="module")
def paper_log(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("pedestrian") / "paper.mcap"
    simulate_pedestrian(path, seed=2, people=2, preset="paper", mount="both", duration_s=30.0)
    return path


@pytest.fixture(scope="module")
def straight_walk():
    """One walker, 40 m straight from a stand, the hand phone (about 45 s)."""
    return _walker(_layout(((0.0, 0.0), (40.0, 0.0))), seed=3)


# -- the session log -----------------------------------------------------------------------------


def test_log_reads_back_like_an_ilc_import(paper_log: Path):
    data = read_session(paper_log)
    assert data.problems == []
    venue = data.session.venue
    assert [p.id for p in venue.map_points] == list("ABCDEFGHIJKL")
    assert venue.map_points[3].x_m == pytest.approx(32.175) and venue.map_points[4].y_m == pytest.approx(23.518)
    assert {s.id for s in venue.stands} == {"stand-I", "stand-C", "stand-A"}
    assert (venue.magnetic_north_deg, venue.magnetic_field_ut, venue.magnetic_dip_deg) == (97.5, 46.0, 49.0)
    assert [a.id for a in data.session.agents] == ["p01", "p02"]
    for agent in data.session.agents:
        assert agent.kind is AgentKind.PEDESTRIAN and agent.height_m in (1.69, 1.74)
        hand, pocket = agent.sensor(Mount.HAND), agent.sensor(Mount.POCKET)
        assert (hand.forward_axis, hand.left_axis, hand.rate_hz) == ("+y", "-x", RATE_HZ)
        assert pocket is not None
        for sensor in (hand, pocket):
            imu = data.imu[sensor.id]
            assert imu.mag_gauss is not None and len(imu.mag_gauss) == len(imu.time_ns) > 0.9 * 30 * RATE_HZ
            assert np.all(np.diff(imu.time_ns) > 0)
        truth = data.truth[agent.id]
        assert np.median(np.diff(truth.time_ns)) == 500_000_000  # 2 Hz waypoints
        assert np.all(np.isfinite(truth.heading_rad))
        assert [scan.stand_id for scan in data.scans[agent.id]] == ["stand-I", "stand-I"]  # hand, then pocket
        assert all(scan.accepted for scan in data.scans[agent.id])
    source = data.session.source
    assert source["preset"] == "paper" and source["stand_key_hex"] == stand_key(2).hex()
    passage = source["junctions"]["p01"][0]
    assert set(passage) == {"time_ns", "point_id", "heading_before_deg", "heading_after_deg", "turn_deg"}
    assert (passage["point_id"], passage["heading_before_deg"], passage["heading_after_deg"]) == ("J", 0.0, -90.0)
    turns = source["turns"]
    assert turns and all(abs(turn["turn_deg"]) >= 10 for turn in turns)
    assert [t["time_ns"] for t in turns] == sorted(t["time_ns"] for t in turns)
    assert {"agent_id": "p01", **passage} in turns


def test_the_paper_route_passes_every_point_with_its_turns():
    plan = layout("paper", 1)
    path = smooth_path(plan.routes[0], 0.6, passes=tuple((p.id, p.x_m, p.y_m) for p in plan.map_points))
    turns = [c for c in path.corners if abs(c.turn_rad) > 0.1]
    assert len(turns) == 15 and all(abs(abs(math.degrees(c.turn_rad)) - 90.0) < 1e-6 for c in turns)
    assert sum(c.turn_rad > 0 for c in turns) == 8  # 8 left, 7 right (the paper says 7 each)
    assert {c.node for c in path.corners} == set("ABCDEFGHJKL")  # I is the start and end
    assert plan.routes[0].length_m() == pytest.approx(279.95, abs=0.01)


def test_floorplan_log_has_the_plan_and_turns(tmp_path: Path):
    path = tmp_path / "floor.mcap"
    summary = simulate_pedestrian(path, seed=1, people=1, preset="floorplan", mount="pocket", duration_s=25.0)
    data = read_session(path)
    plan = data.session.venue.floor_plan
    assert len(plan[0]) == 4  # the outer ring and three holes: the room block's walls and two pillars
    assert summary.junctions == len(data.session.source["junctions"]["p01"]) >= 1
    assert data.session.agent("p01").sensor(Mount.POCKET) is not None


# -- walls ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("preset", PRESETS)
def test_paths_never_cross_walls(preset: str):
    plan = layout(preset, 3)
    area = walkable_geometry(plan)
    for route in plan.routes:
        path = smooth_path(route, PedestrianParams().gait.turn_radius_m)
        line = shapely.LineString(np.column_stack([path.x_m, path.y_m]))
        assert area.covers(line.buffer(0.2))  # a body-wide strip along the walked path
    if preset == "paper":  # the hub's own reading of the map: corridors between its points
        corridors = WalkableArea.from_venue(_venue(plan)).geometry
        assert corridors.covers(shapely.LineString(plan.routes[0].xy_m).buffer(0.2))


def _venue(plan):
    from protocol.session import Venue

    return Venue(plan.venue_name, map_points=plan.map_points, floor_plan=plan.floor_plan)


def test_a_wall_crossing_route_is_refused():
    from sim_devices.pedestrian.venues import Route, floor_geometry, route_problem

    through_block = Route(("a", "b"), ((5.2, 10.0), (34.8, 10.0)))  # straight across the room block
    assert "crosses a wall" in route_problem(through_block, floor_geometry())


# -- the step model ------------------------------------------------------------------------------


def test_truth_follows_the_step_model(straight_walk):
    run, gait = straight_walk, PedestrianParams().gait
    timeline, person = run.timeline, run.person
    cruise = timeline.speed_share > 0.97
    steps = np.flatnonzero(np.diff(np.floor(timeline.phase)) > 0) + 1  # each step's start (mid-stance)
    steps = steps[cruise[steps]]
    lengths = np.diff(timeline.s_m[steps])[np.diff(steps) < 1.5 * RATE_HZ / person.cadence_hz]
    assert len(lengths) > 20
    assert np.mean(lengths) == pytest.approx(person.step_length_m, rel=0.03)
    assert 0.5 * gait.step_length_cv < np.std(lengths) / np.mean(lengths) < 2.5 * gait.step_length_cv
    durations = np.diff(timeline.time_s[steps])[np.diff(steps) < 1.5 * RATE_HZ / person.cadence_hz]
    assert 1.0 / np.mean(durations) == pytest.approx(person.cadence_hz, rel=0.03)
    assert person.height_m == 1.69 and gait.cadence_min_hz <= person.cadence_hz <= gait.cadence_max_hz
    expected = person.height_m * gait.step_height_ratio * (person.cadence_hz / gait.step_reference_hz) ** \
        gait.step_cadence_exponent * person.step_ratio_factor
    assert person.step_length_m == pytest.approx(expected)
    assert float(run.timeline.s_m[-1]) == pytest.approx(40.0, abs=0.01)


def test_walkers_slow_down_in_turns_and_the_gyro_sees_the_turn():
    params = error_free()
    params = dataclasses.replace(params, hand=dataclasses.replace(params.hand, grip_change_per_min=0.0))
    run = _walker(_layout(((0.0, 0.0), (20.0, 0.0), (20.0, 20.0))), params=params, seed=4)
    corner = run.path.corners[0]
    reached = np.maximum.accumulate(run.timeline.s_m)
    inside = (reached > corner.start_m) & (reached < corner.end_m)
    before = (reached > 8.0) & (reached < 12.0)
    ratio = np.mean(run.timeline.speed_mps[inside]) / np.mean(run.timeline.speed_mps[before])
    assert ratio == pytest.approx(PedestrianParams().gait.turn_speed_ratio, abs=0.08)
    picked_up = int(run.phones[0].motion.windows[0].done_s * RATE_HZ)
    turned_deg = np.sum(run.phones[0].gyro_dps[picked_up:, 2]) / RATE_HZ  # a nearly flat phone: z is up
    assert turned_deg == pytest.approx(90.0 * math.cos(math.radians(params.hand.pitch_mean_deg)), abs=3.0)


# -- stands --------------------------------------------------------------------------------------


def test_a_stand_scan_happens_at_the_stands_pose():
    plan = _layout(((0.0, 0.0), (10.0, 0.0)))
    tilted = Stand("start", 0.0, 0.0, heading_deg=30.0, tilt_deg=12.0)
    plan = dataclasses.replace(plan, stands=(tilted,), routes=(dataclasses.replace(
        plan.routes[0], xy_m=((0.0, 0.0), (10 * math.cos(math.radians(30)), 10 * math.sin(math.radians(30))))),))
    run = _walker(plan, params=error_free(), duration_s=12.0)
    window = run.phones[0].motion.windows[0]
    row = int(round(window.scan_s * RATE_HZ))
    motion = run.phones[0].motion
    assert motion.position_m[row, :2] == pytest.approx([0.0, 0.0], abs=1e-9)
    expected = flat_rotation(np.radians([30.0]), np.radians([12.0]), np.zeros(1))[0]
    assert motion.rotation[row] == pytest.approx(expected, abs=1e-9)  # error_free: no placement error
    accel = run.phones[0].accel_g[row]  # still on the plate: gravity alone, tilted 12 deg about phone x
    assert accel == pytest.approx([0.0, math.sin(math.radians(12.0)), math.cos(math.radians(12.0))], abs=0.002)
    assert np.abs(run.phones[0].gyro_dps[row]) .max() < 0.1
    key = stand_key(1)
    message = stand_code.scan_message(stand_code.encode(tilted, "calibration", key), 0, "p01", "p01-hand",
                                      "calibration", key, (tilted,))
    assert message.accepted and message.heading_rad == pytest.approx(math.radians(30.0))


def test_scans_in_the_log_carry_the_stand_fields(paper_log: Path):
    data = read_session(paper_log)
    stand = data.session.venue.stands[0]
    key = bytes.fromhex(data.session.source["stand_key_hex"])
    assert len(data.scans["p01"]) > 0  # the walk starts at a stand, so there is something to check
    for scan in data.scans["p01"]:
        assert stand_code.decode(scan.payload, data.session.venue.name, key, data.session.venue.stands) == stand
        assert (scan.x_m, scan.y_m, scan.heading_rad, scan.tilt_rad) == pytest.approx(
            (stand.x_m, stand.y_m, math.radians(stand.heading_deg), 0.0))
        truth = data.truth["p01"]
        nearest = int(np.argmin(np.abs(truth.time_ns - scan.timestamp_ns)))
        assert math.hypot(truth.x_m[nearest] - stand.x_m, truth.y_m[nearest] - stand.y_m) < 0.05


# -- accelerometer physics -----------------------------------------------------------------------


def test_gravity_and_step_frequency_in_the_accelerometer(straight_walk):
    run = straight_walk
    accel = run.phones[0].accel_g.astype(float)
    window = run.phones[0].motion.windows[0]
    still = slice(int(window.still_s * RATE_HZ) + 5, int(window.pick_s * RATE_HZ) - 5)
    assert np.mean(np.linalg.norm(accel[still], axis=1)) == pytest.approx(1.0, abs=0.05)
    walking = np.flatnonzero(run.timeline.speed_share > 0.97)
    magnitude = np.linalg.norm(accel[walking], axis=1)
    assert np.mean(magnitude) == pytest.approx(1.0, abs=0.05)
    assert 0.05 < np.std(magnitude) < 0.4  # the bounce: hand-held walking 0.1-0.3 g
    frequency = fft_cadence(accel[walking], RATE_HZ)
    assert np.median(frequency) == pytest.approx(run.person.cadence_hz, abs=0.2)  # 0.2 Hz FFT bins
    spectrum = np.abs(np.fft.rfft(magnitude - magnitude.mean()))
    peak = np.fft.rfftfreq(len(magnitude), 1 / RATE_HZ)[np.argmax(spectrum)]
    assert peak == pytest.approx(run.person.cadence_hz, abs=0.05)


def test_pocket_phone_swings_with_the_thigh():
    run = _walker(_layout(((0.0, 0.0), (30.0, 0.0))), mounts=MOUNTS["both"], seed=5)
    hand, pocket = run.phones
    walking = run.timeline.speed_share > 0.97
    assert np.std(pocket.gyro_dps[walking], axis=0).max() > 3 * np.std(hand.gyro_dps[walking], axis=0).max()
    assert pocket.motion.windows[0].place_s >= hand.motion.windows[0].done_s  # one phone on the stand at a time


def test_magnetic_field_halves_on_the_twelfth_floor():
    params = PedestrianParams()
    calm = dataclasses.replace(params.magnetic, anomaly_ut=0.0)
    ground = MagneticField.draw(dataclasses.replace(calm, floor=1), np.random.default_rng(0))
    twelfth = MagneticField.draw(dataclasses.replace(calm, floor=12), np.random.default_rng(0))
    assert np.linalg.norm(twelfth.earth_ut) / np.linalg.norm(ground.earth_ut) == pytest.approx(0.51, abs=0.02)
    assert math.degrees(math.atan2(-ground.earth_ut[2], np.hypot(*ground.earth_ut[:2]))) == pytest.approx(49.0)


# -- determinism, validation, CLI, docs ----------------------------------------------------------


def test_same_seed_same_bytes_other_seed_differs(tmp_path: Path):
    paths = [tmp_path / name for name in ("a.mcap", "b.mcap", "c.mcap")]
    for path, seed in zip(paths, (7, 7, 8)):
        simulate_pedestrian(path, seed=seed, people=2, preset="floorplan", mount="hand", duration_s=6.0)
    assert paths[0].read_bytes() == paths[1].read_bytes()
    assert paths[0].read_bytes() != paths[2].read_bytes()


@pytest.mark.parametrize("pair, words", [
    ({"gait.cadence_min_hz": "9"}, ("gait.cadence_min_hz", "[0.8, 3.0] Hz")),
    ({"sensors.rate_hz": "fast"}, ("sensors.rate_hz", "not a number")),
    ({"sensors.batch_samples": "2.5"}, ("sensors.batch_samples", "not an integer")),
    ({"gait.nope": "1"}, ("gait.nope", "unknown key 'nope'")),
    ({"walk.speed": "1"}, ("walk.speed", "unknown group 'walk'")),
    ({"gait.cadence_min_hz": "2.5"}, ("gait.cadence_min_hz", "gait.cadence_max_hz")),
    ({"magnetic.floor": "30"}, ("magnetic.floor", "magnetic.storeys = 20")),
])
def test_bad_set_values_are_refused_with_the_key_and_limit(pair, words):
    with pytest.raises(ConfigError) as caught:
        params_with_overrides(pair)
    assert all(word in str(caught.value) for word in words)


def test_bad_arguments_are_refused(tmp_path: Path):
    for arguments, word in (({"people": 0}, "people"), ({"preset": "mall"}, "preset"), ({"mount": "head"}, "mount"),
                            ({"seed": -1}, "seed"), ({"duration_s": 0.1}, "duration")):
        with pytest.raises(ConfigError, match=word):
            simulate_pedestrian(tmp_path / "x.mcap", **arguments)


def test_cli_registers_the_subcommand():
    args = build_parser().parse_args(["sim", "pedestrian", "--preset", "floorplan", "--mount", "both", "-o", "x.mcap",
                                      "--set", "sensors.rate_hz=100"])
    assert (args.preset, args.mount, args.people, args.set) == ("floorplan", "both", 3, ["sensors.rate_hz=100"])
    assert args.run.__name__ == "run_sim_pedestrian"


def test_every_figure_is_documented():
    text = DOCS.read_text(encoding="utf-8")
    missing = [key for key, _, _, source in describe() if f"`{key}`" not in text or not source]
    assert missing == []
