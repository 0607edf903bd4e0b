"""The barometric floor counter (edge/pedestrian/floors.py) on synthetic pressure series: flights of
stairs up and down, weather drift, noise, a half landing, a storey height learned from two stands,
bad readings; and the pedestrian edge stamping each pose with its floor."""

from __future__ import annotations

import math

import numpy as np
import pytest

from edge.pedestrian import floors
from edge.pedestrian.floors import FloorSettings, FloorState, at_fix, height_m, step

RATE_HZ = 10.0
GROUND_HPA = 1008.0


def pressure_at(height: np.ndarray, drift_hpa: np.ndarray | float = 0.0) -> np.ndarray:
    """The hypsometric pressure (the counter's own scale height) at `height` above ground."""
    return (GROUND_HPA + drift_hpa) * np.exp(-np.asarray(height) / floors.SCALE_HEIGHT_M)


def profile(segments: list[tuple[float, float]], start_m: float = 0.0) -> np.ndarray:
    """Heights at RATE_HZ from (duration s, height at its end m) segments, linear within each, from `start_m`."""
    out, level = [], start_m
    for duration, end in segments:
        n = int(round(duration * RATE_HZ))
        out.append(np.linspace(level, end, n, endpoint=False) if n else np.array([]))
        level = end
    return np.concatenate(out)


def run(pressures: np.ndarray, settings: FloorSettings = FloorSettings(), start_floor: int = 0,
        fixes: dict[int, int] | None = None) -> tuple[FloorState, list[int]]:
    """Feed the series (a fix at start, and at the sample indices in `fixes`); the floor after each sample."""
    state, seen = FloorState(), []
    for i, value in enumerate(pressures):
        time_ns = int(i * 1e9 / RATE_HZ)
        state = step(state, time_ns, float(value), settings)
        if i == 0:
            state = at_fix(state, time_ns, start_floor, settings)
        if fixes and i in fixes:
            state = at_fix(state, time_ns, fixes[i], settings)
        seen.append(state.floor)
    return state, seen


def test_height_follows_the_hypsometric_relation():
    assert height_m(GROUND_HPA, GROUND_HPA) == 0.0
    # near sea level about 0.12 hPa per metre
    assert height_m(GROUND_HPA - 0.12, GROUND_HPA) == pytest.approx(1.0, abs=0.05)


def test_up_two_floors_and_down_one_with_noise_and_weather():
    rng = np.random.default_rng(1)
    heights = profile([(30, 0), (14, 4), (3, 4), (14, 8), (30, 8), (14, 4), (30, 4)])
    times = np.arange(len(heights)) / RATE_HZ
    drift = 0.5 * times / 3600.0  # a strong weather trend: 0.5 hPa/h
    noisy = pressure_at(heights, drift) + rng.normal(0.0, 0.015, len(heights))
    state, seen = run(noisy, start_floor=2)
    assert state.floor == 3
    assert state.changes == 3
    assert state.unresolved == 0
    assert max(f for f in seen if f is not None) == 4  # reached floor 4 in between


def test_a_level_walk_under_weather_and_noise_counts_nothing():
    rng = np.random.default_rng(2)
    n = int(1800 * RATE_HZ)  # half an hour
    times = np.arange(n) / RATE_HZ
    drift = 1.0 * times / 3600.0 + 0.05 * (times > 600)  # 1 hPa/h and a ventilation jump
    state, _ = run(pressure_at(np.zeros(n), drift) + rng.normal(0.0, 0.02, n), start_floor=1)
    assert (state.floor, state.changes) == (1, 0)


def test_a_half_landing_keeps_the_reference():
    # up half a floor to a landing, a pause there longer than settle_s, on up the second flight
    heights = profile([(10, 0), (7, 2), (6, 2), (7, 4), (20, 4)])
    state, seen = run(pressure_at(heights))
    assert state.floor == 1 and state.changes == 1
    assert set(f for f in seen) == {0, 1}


def test_a_storey_height_learned_from_two_stands():
    # a 3 m storey building: three floors up counts 9 m, which 4 m storeys would call 2
    settings = FloorSettings(floor_height_m=4.0)
    first = profile([(10, 0), (10, 3), (20, 3)])
    state, _ = run(pressure_at(first), settings, start_floor=0, fixes={len(first) - 1: 1})
    assert state.storey_m == pytest.approx(3.0, abs=0.1)
    heights = profile([(10, 3), (30, 12), (20, 12)], start_m=3.0)
    for i, value in enumerate(pressure_at(heights)):
        state = step(state, int((len(first) + i) * 1e9 / RATE_HZ), float(value), settings)
    assert state.floor == 4

    untaught, _ = run(pressure_at(np.concatenate([first, heights])), settings)
    assert untaught.floor != 4  # the same climb without the lesson: wrong floor (9 m / 4 m)


def test_bad_readings_are_refused_and_old_ones_ignored():
    state = step(FloorState(), 0, GROUND_HPA)
    with pytest.raises(ValueError, match="hPa"):
        step(state, 1, math.nan)
    with pytest.raises(ValueError, match="1200"):
        step(state, 1, 5000.0)
    assert step(state, 0, GROUND_HPA - 10.0) is state


@pytest.mark.parametrize("name", ["floor_height_m", "settle_s", "learn_within_s"])
def test_settings_are_checked(name):
    with pytest.raises(ValueError, match=name):
        FloorSettings(**{name: 0.0})


def test_state_does_not_grow():
    state, _ = run(pressure_at(profile([(60, 0), (14, 4), (60, 4)])))
    fields = {name: type(value) for name, value in vars(state).items()}
    longer, _ = run(pressure_at(profile([(600, 0), (14, 4), (600, 4), (14, 0), (600, 0)])))
    assert {name: type(value) for name, value in vars(longer).items()} == fields
    assert all(not isinstance(value, (list, dict, tuple, np.ndarray)) for value in vars(longer).values())


def test_a_climb_names_the_next_floor_before_it_settles_and_marks_the_stairs():
    settings = FloorSettings()
    heights = profile([(10, 0), (14, 4), (20, 4)])  # 0.29 m/s up a 4 m storey
    state = FloorState()
    named_at = stairs_from = stairs_to = None
    for i, value in enumerate(pressure_at(heights)):
        state = step(state, int(i * 1e9 / RATE_HZ), float(value), settings)
        if i == 0:
            state = at_fix(state, 0, 0, settings)
        if named_at is None and floors.current_floor(state, settings) == 1:
            named_at = i / RATE_HZ
        if floors.on_stairs(state, settings):
            stairs_from = stairs_from if stairs_from is not None else i / RATE_HZ
            stairs_to = i / RATE_HZ
    # 60 % of the storey is reached 18.4 s in; the smoothing adds about a second
    assert 18.4 <= named_at <= 20.5
    assert state.floor == 1 and state.changes == 1  # counted once settled, not twice
    assert stairs_from is not None and 12.0 <= stairs_from <= 15.0  # once 1 m up (start_m)
    assert 24.0 <= stairs_to <= 27.0  # the flight ended at 24 s


def test_the_pedestrian_edge_stamps_poses_with_the_floor_and_steps_a_stair_by_its_treads():
    from edge.pedestrian.edge import PedestrianEdge
    from protocol import messages
    from protocol.session import Agent, AgentKind, Mount, Sensor

    agent = Agent("p01", AgentKind.PEDESTRIAN, sensors=(Sensor("p01-hand", Mount.HAND),))
    edge = PedestrianEdge(agent)
    edge.scan(messages.new("StandScan", timestamp_ns=0, agent_id="p01", sensor_id="p01-hand", stand_id="s",
                           x_m=0.0, y_m=0.0, floor=2, heading_rad=0.0, accepted=True))
    heights = profile([(10, 0), (14, 4), (20, 4)])
    refused = messages.new("Pressure", timestamp_ns=1, agent_id="p01", sensor_id="p01-hand", pressure_hpa=math.nan)
    edge.pressure(refused)
    assert edge.counters.pressure_refused == 1 and "1 of 1 pressure readings refused" in edge.warnings()[0]
    assert edge.warnings() == []  # rate-limited: the next warning at 2
    stairs = []
    for i, value in enumerate(pressure_at(heights)):
        edge.pressure(messages.new("Pressure", timestamp_ns=int(i * 1e8) + 2, agent_id="p01", sensor_id="p01-hand",
                                   pressure_hpa=float(value)))
        stairs.append(edge.estimator.on_stairs)
    assert any(stairs) and not stairs[-1]
    assert floors.current_floor(edge.floors, edge.floor_settings) == 3
    other = messages.new("Pressure", timestamp_ns=int(1e12), agent_id="p01", sensor_id="p01-pocket",
                         pressure_hpa=900.0)
    edge.pressure(other)  # another phone's barometer is its own edge's
    assert edge.floors.floor == 3 and edge.counters.pressure_readings == len(heights) + 1
