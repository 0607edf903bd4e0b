"""The indoor-navigation paper's dead reckoning (edge/pedestrian/paper.py) on synthetic phone data."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from edge.pedestrian.estimator import PhoneSample
from edge.pedestrian.paper import PaperPdr, PaperPdrSettings, speed_eq1_m_s, speed_eq2_m_s
from protocol.errors import ConfigError

G = 9.80665
TICK_NS = 20_000_000  # 50 Hz, the paper's rate
START_NS = 1_700_000_000 * 1_000_000_000  # unix ns
RESOLUTION_HZ = 1.0 / 5.0  # a 5 s window


def walk_samples(cadence_hz: float, seconds: float, start_ns: int = START_NS, seed: int = 3) -> Iterator[PhoneSample]:
    """A phone held flat at 50 Hz from start_ns (exclusive): the vertical bounce at the cadence, a
    lateral sway at half of it, a little noise; no rotation."""
    rng = np.random.default_rng(seed)
    for i in range(1, round(seconds * 50) + 1):
        t = i * TICK_NS * 1e-9
        bounce = 1.5 * math.sin(2 * math.pi * cadence_hz * t)
        sway = 0.4 * math.sin(math.pi * cadence_hz * t)
        noise = rng.normal(0.0, 0.05, 3)
        yield PhoneSample(start_ns + i * TICK_NS, (sway + noise[0], 0.2 + noise[1], G + bounce + noise[2]),
                          (0.0, 0.0, 0.0))


def flat_walk(cadence_hz: float, seconds: float, start_ns: int = START_NS) -> list[PhoneSample]:
    return list(walk_samples(cadence_hz, seconds, start_ns))


def run(pdr: PaperPdr, samples: list[PhoneSample]) -> list:
    return [out for sample in samples for out in pdr.step(sample)]


def test_the_equations_worked_by_hand():
    # eq. 2: 0.37 * 1.74 m * 1.8 Hz = 1.15884 m/s, plus (0.001 * 1.8)^2 = 3.24e-6
    assert speed_eq2_m_s(1.8, 1.74) == pytest.approx(1.1588432, abs=1e-7)
    # eq. 1 via [4]: 1.8 Hz = 108 steps/min; (108 / 18.59)^(1 / 0.42) = 66.0 m/min = 1.10 m/s
    assert speed_eq1_m_s(1.8) == pytest.approx(66.0 / 60.0, rel=2e-3)
    assert 18.59 * (speed_eq1_m_s(1.8) * 60.0) ** 0.42 == pytest.approx(108.0)  # round trip
    assert 1.8 / 18.59 ** (1 / 0.42) < 0.002  # the printed form of eq. 1: not a walking speed


def test_the_unit_reading_of_eq_2_matches_tables_1_and_2():
    # The same 86 m walk under eq. 1 (table 1 means) and eq. 2 (table 2 means): the ratio is
    # V2(f) / V1(f) at each person's cadence. With f in Hz the cadences are near fig. 3's 1.8 Hz.
    cadences = np.linspace(1.0, 3.0, 20001)
    for height_m, table_1, table_2, expected_hz in ((1.69, 76.30, 81.70, 1.74), (1.74, 81.03, 86.63, 1.78),
                                                    (1.79, 97.29, 86.78, 2.07)):
        ratio = np.array([speed_eq2_m_s(f, height_m) / speed_eq1_m_s(f) for f in cadences])
        solved = cadences[int(np.argmin(abs(ratio - table_2 / table_1)))]
        assert solved == pytest.approx(expected_hz, abs=0.01)


@pytest.mark.parametrize("signal", ["magnitude", "vertical"])
@pytest.mark.parametrize("cadence_hz", [1.8, 2.05])
def test_a_walk_at_a_known_cadence_gives_eq_2s_speed(cadence_hz, signal):
    height_m = 1.74
    pdr = PaperPdr(PaperPdrSettings(cadence_signal=signal), height_m=height_m)
    heading = math.radians(30.0)
    pdr.reset_to_stand(START_NS, 10.0, 5.0, heading)
    outputs = run(pdr, flat_walk(cadence_hz, 20.0))
    state = pdr.snapshot()
    assert abs(state.cadence_hz - cadence_hz) <= RESOLUTION_HZ / 2 + 1e-9
    assert state.speed_m_s == pytest.approx(speed_eq2_m_s(state.cadence_hz, height_m))
    assert state.speed_m_s == pytest.approx(speed_eq2_m_s(cadence_hz, height_m), rel=0.1 / cadence_hz)
    # one output every 0.5 s; the paper's constant start speed (eq. 2 at 1.8 Hz) until the window
    # is full (250 ticks: 5 s), then the window's speed (hop 0.5 s, the first 4.98 s after the stand)
    assert len(outputs) == 40 and [o.count for o in outputs] == list(range(1, 41))
    assert np.diff([o.time_ns for o in outputs]) == pytest.approx(500_000_000)
    start = speed_eq2_m_s(1.8, height_m)
    expected_m = start * 4.98 + state.speed_m_s * (20.0 - 4.98)
    travelled = sum(o.step_length_m for o in outputs)
    assert travelled == pytest.approx(expected_m, abs=0.05)
    assert math.hypot(state.x_m - 10.0, state.y_m - 5.0) == pytest.approx(travelled)
    assert math.atan2(state.y_m - 5.0, state.x_m - 10.0) == pytest.approx(heading, abs=1e-3)
    assert outputs[-1].covariance.shape == (3, 3)
    assert outputs[-1].covariance[0, 0] > outputs[0].covariance[0, 0]  # grows with distance


def test_eq_1_is_selectable():
    pdr = PaperPdr(PaperPdrSettings(speed_model="eq1"), height_m=1.74)
    pdr.reset_to_stand(START_NS, 0.0, 0.0, 0.0)
    run(pdr, flat_walk(1.8, 8.0))
    assert pdr.snapshot().speed_m_s == pytest.approx(speed_eq1_m_s(1.8))


def _rotation(axis: int, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m = np.eye(3)
    m[i, i] = m[j, j] = c
    m[i, j], m[j, i] = -s, s
    return m


def _smooth(t: float, start: float, end: float) -> float:
    """0 before start, 1 after end, a raised cosine between (rates zero at both ends)."""
    u = min(max((t - start) / (end - start), 0.0), 1.0)
    return 0.5 - 0.5 * math.cos(math.pi * u)


def test_a_turn_with_the_phone_pitched_and_rolled():
    # The phone in Android axes, the venue x, y, up: forward (+y) heading h, the top raised by
    # pitch p, then rolled by r about its forward axis: C = Rz(h - 90 deg) Rx(p) Ry(r).
    # Rates from C^T dC/dt (not from eq. 5), accelerometer C^T (0, 0, g). The stand sets pitch 20
    # deg; the hand then rolls 15 deg (2-3 s) and turns left 90 deg (5-7 s).
    pitch, roll_end, turn = math.radians(20.0), math.radians(15.0), math.radians(90.0)

    def attitude(t: float) -> np.ndarray:
        heading = turn * _smooth(t, 5.0, 7.0)
        roll = roll_end * _smooth(t, 2.0, 3.0)
        return _rotation(2, heading - math.pi / 2) @ _rotation(0, pitch) @ _rotation(1, roll)

    pdr = PaperPdr()
    raw = PaperPdr(PaperPdrSettings(use_attitude=False))
    for estimator in (pdr, raw):
        estimator.reset_to_stand(START_NS, 0.0, 0.0, 0.0, tilt_rad=pitch)
    h = 1e-6
    for i in range(1, 9 * 50 + 1):
        t = i * TICK_NS * 1e-9
        c = attitude(t)
        skew = c.T @ (attitude(t + h) - attitude(t - h)) / (2 * h)
        gyro = (skew[2, 1], skew[0, 2], skew[1, 0])
        accel = tuple(c.T @ np.array([0.0, 0.0, G]))
        sample = PhoneSample(START_NS + i * TICK_NS, accel, gyro)
        pdr.step(sample)
        raw.step(sample)
    state = pdr.snapshot()
    assert math.degrees(state.heading_rad) == pytest.approx(90.0, abs=0.5)
    assert math.degrees(state.pitch_rad) == pytest.approx(20.0, abs=0.5)
    assert math.degrees(state.roll_rad) == pytest.approx(15.0, abs=0.5)
    # eq. 4, the raw z gyro: the turn seen through the tilt, 90 cos(15) cos(20) = 81.7 deg (short)
    short = 90.0 * math.cos(roll_end) * math.cos(pitch)
    assert math.degrees(state.raw_heading_rad) == pytest.approx(short, abs=0.5)
    assert math.degrees(raw.snapshot().heading_rad) == pytest.approx(short, abs=0.5)
    assert state.near_gimbal_lock == 0


def test_a_stand_sets_the_pose_and_nothing_comes_out_before_it():
    pdr = PaperPdr(height_m=1.8)
    assert run(pdr, flat_walk(1.8, 3.0)) == []
    assert not pdr.snapshot().stood
    reset_ns = START_NS + 3 * 1_000_000_000
    pdr.reset_to_stand(reset_ns, 12.5, -4.0, math.radians(120.0), tilt_rad=math.radians(10.0))
    state = pdr.snapshot()
    assert (state.stood, state.x_m, state.y_m) == (True, 12.5, -4.0)
    assert math.degrees(state.heading_rad) == pytest.approx(120.0)
    assert math.degrees(state.pitch_rad) == pytest.approx(10.0) and state.roll_rad == 0.0
    assert state.window_fill == 0 and math.isnan(state.cadence_hz)  # the window restarts
    assert state.covariance[2, 2] == pytest.approx(0.037 ** 2)
    outputs = run(pdr, flat_walk(1.8, 1.0, start_ns=reset_ns))
    assert len(outputs) == 2 and outputs[0].time_ns == reset_ns + 500_000_000
    first = outputs[0]
    assert first.step_length_m == pytest.approx(0.5 * speed_eq2_m_s(1.8, 1.8))
    assert first.x_m == pytest.approx(12.5 + first.step_length_m * math.cos(math.radians(120.0)), abs=1e-3)
    assert first.y_m == pytest.approx(-4.0 + first.step_length_m * math.sin(math.radians(120.0)), abs=1e-3)


def _structure(pdr: PaperPdr) -> dict[str, object]:
    return {name: (type(value).__name__, value.shape if isinstance(value, np.ndarray) else None)
            for name, value in vars(pdr).items()}


def test_memory_is_constant():
    pdr = PaperPdr()
    pdr.reset_to_stand(START_NS, 0.0, 0.0, 0.0)
    samples = walk_samples(1.9, 2000.0)
    for _ in range(10):
        pdr.step(next(samples))
    before = _structure(pdr)
    before_bytes = sum(v.nbytes for v in vars(pdr).values() if isinstance(v, np.ndarray))
    for _ in range(100_000 - 10):
        pdr.step(next(samples))
    assert _structure(pdr) == before
    assert sum(v.nbytes for v in vars(pdr).values() if isinstance(v, np.ndarray)) == before_bytes
    assert pdr.snapshot().outputs == 4000  # 2000 s at one output per 0.5 s, the last at 2000.0 s


def test_bad_samples_are_counted_not_raised():
    pdr = PaperPdr()
    pdr.reset_to_stand(START_NS, 0.0, 0.0, 0.0)
    walk = flat_walk(1.8, 10.0)
    run(pdr, walk[:300])
    assert pdr.snapshot().window_fill == 250
    before = pdr.snapshot()
    assert pdr.step(walk[299]) == [] and pdr.step(walk[100]) == []  # the same time, then an earlier one
    nan = PhoneSample(walk[300].time_ns, (math.nan, 0.0, G), (0.0, 0.0, 0.0))
    assert pdr.step(nan) == []
    after = pdr.snapshot()
    assert (after.backwards, after.nonfinite, after.gaps) == (2, 1, 0)
    assert (after.time_ns, after.x_m, after.window_fill) == (before.time_ns, before.x_m, before.window_fill)
    run(pdr, walk[350:])  # a 1 s gap: counted, the window restarts, the gap is not integrated
    state = pdr.snapshot()
    assert state.gaps == 1
    assert state.window_fill == len(walk) - 350
    moved = math.hypot(state.x_m, state.y_m)
    assert moved == pytest.approx(speed_eq2_m_s(1.8, 1.70) * (len(walk) - 1 - 50) * 0.02, rel=1e-3)


def test_gimbal_lock_is_kept_and_counted():
    # The phone's top raised to 85 deg on the stand, then a slow yaw: tan and sec of eq. 5 are
    # large; the samples near the singularity are counted (the paper's limitation, section 5).
    pdr = PaperPdr()
    pdr.reset_to_stand(START_NS, 0.0, 0.0, 0.0, tilt_rad=math.radians(85.0))
    c = _rotation(2, -math.pi / 2) @ _rotation(0, math.radians(85.0))
    accel = tuple(c.T @ np.array([0.0, 0.0, G]))
    for i in range(1, 51):
        pdr.step(PhoneSample(START_NS + i * TICK_NS, accel, (0.0, 0.0, 0.0)))
    assert pdr.snapshot().near_gimbal_lock == 50


def test_settings_are_checked_at_start():
    with pytest.raises(ConfigError, match="window_s"):
        PaperPdrSettings(window_s=0.0)
    with pytest.raises(ConfigError, match="cadence_signal"):
        PaperPdrSettings(cadence_signal="sideways")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="height_m"):
        PaperPdr(height_m=170.0)


def test_jittered_timestamps_are_read_on_the_50_hz_grid():
    # Android delivers samples late and unevenly; the paper's 50 Hz timer takes the latest one.
    rng = np.random.default_rng(7)
    pdr = PaperPdr(height_m=1.74)
    pdr.reset_to_stand(START_NS, 0.0, 0.0, 0.0)
    for sample in walk_samples(2.05, 12.0):
        jitter_ns = int(rng.integers(-6_000_000, 6_000_000))
        pdr.step(PhoneSample(sample.time_ns + jitter_ns, sample.accel_ms2, sample.gyro_rads))
    state = pdr.snapshot()
    assert abs(state.cadence_hz - 2.05) <= RESOLUTION_HZ / 2 + 1e-9
    assert (state.gaps, state.backwards) == (0, 0)
