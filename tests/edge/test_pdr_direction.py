"""The walking direction from the acceleration (edge/pedestrian/direction.py), on crafted walks: the
centre of mass vaults like an inverted pendulum (slowest at its highest: forward acceleration
opposite to the vertical velocity), a thigh-like swing at stride frequency whose fore-aft and
vertical motions are in phase, a lateral sway; and through PdrEstimator for a pocket phone whose
walking axis is the opposite of the session's forward axis."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from edge.pedestrian import direction as pdr_direction
from edge.pedestrian.estimator import PdrEstimator, PdrSettings, PhoneSample

RATE_HZ = 50.0
CADENCE_HZ = 1.8  # steps per second
T0_NS = 1_700_000_000_000_000_000
GRAVITY_MS2 = 9.80665


def walk_accel(time_s: float, walking_rad: float) -> tuple[float, float, float]:
    """Linear acceleration (earth frame, m/s^2) of a point on a walker heading `walking_rad`."""
    step = 2.0 * math.pi * CADENCE_HZ * time_s
    stride = step / 2.0
    omega, omega_stride = 2.0 * math.pi * CADENCE_HZ, math.pi * CADENCE_HZ
    # Centre of mass: height B cos(step) (highest at mid-stance, step = 0), forward position
    # -S sin(step) (slowest there): a_f = S w^2 sin, v_z = -B w sin, so a_f opposes v_z.
    bounce_m, surge_m = 0.02, 0.013
    forward = surge_m * omega ** 2 * math.sin(step)
    vertical = -bounce_m * omega ** 2 * math.cos(step)
    # A thigh-like swing at stride frequency: fore-aft and vertical in phase (no sign information).
    forward += -0.18 * 0.38 * omega_stride ** 2 * math.sin(stride)
    vertical += -0.07 * 0.38 * omega_stride ** 2 * math.sin(stride)
    lateral = -0.02 * omega_stride ** 2 * math.cos(stride)
    cos_w, sin_w = math.cos(walking_rad), math.sin(walking_rad)
    return (forward * cos_w - lateral * sin_w, forward * sin_w + lateral * cos_w, vertical)


def run(walking_rad: float, seconds: float, reference_rad: float = 0.0,
        state: pdr_direction.DirectionState | None = None, start_s: float = 0.0) -> pdr_direction.DirectionState:
    settings = pdr_direction.DirectionSettings()
    state = state or pdr_direction.DirectionState()
    for i in range(int(seconds * RATE_HZ)):
        t = start_s + i / RATE_HZ
        state = pdr_direction.step(settings, state, T0_NS + int(round(t * 1e9)), walk_accel(t, walking_rad),
                                   reference_rad)
    return state


def angle_error_deg(a_rad: float, b_rad: float) -> float:
    return abs(math.degrees((a_rad - b_rad + math.pi) % (2.0 * math.pi) - math.pi))


@pytest.mark.parametrize("walking_deg", [0.0, 37.0, 100.0, 180.0, -143.0, -60.0])
def test_direction_and_sign_in_the_earth_frame(walking_deg: float) -> None:
    state = run(math.radians(walking_deg), 10.0)
    heading = pdr_direction.heading_rad(pdr_direction.DirectionSettings(), state)
    assert heading is not None
    assert angle_error_deg(heading, math.radians(walking_deg)) < 3.0
    assert pdr_direction.elongation(state) > 0.5


@pytest.mark.parametrize("phone_yaw_deg", [0.0, 45.0, 170.0, -95.0])
@pytest.mark.parametrize("walking_deg", [20.0, 200.0])
def test_offset_relative_to_a_yawed_phone(phone_yaw_deg: float, walking_deg: float) -> None:
    """In a frame turning with the phone: the offset is the walking direction relative to the phone."""
    reference = math.radians(walking_deg + phone_yaw_deg)
    state = run(math.radians(walking_deg), 10.0, reference)
    settings = pdr_direction.DirectionSettings()
    offset = pdr_direction.offset_rad(settings, state)
    assert offset is not None
    assert angle_error_deg(offset, -math.radians(phone_yaw_deg)) < 3.0
    assert angle_error_deg(pdr_direction.heading_rad(settings, state), math.radians(walking_deg)) < 3.0


def test_reversed_walk_flips_the_sign_within_a_few_strides() -> None:
    state = run(0.3, 10.0)
    state = run(0.3 + math.pi, 12.0, state=state, start_s=10.0)
    heading = pdr_direction.heading_rad(pdr_direction.DirectionSettings(), state)
    assert heading is not None and angle_error_deg(heading, 0.3 + math.pi) < 3.0


def test_no_direction_while_still_and_gaps_counted() -> None:
    settings = pdr_direction.DirectionSettings()
    state = pdr_direction.DirectionState()
    for i in range(100):
        state = pdr_direction.step(settings, state, T0_NS + i * 20_000_000, (0.0, 0.0, 0.0))
    assert pdr_direction.heading_rad(settings, state) is None
    state = pdr_direction.step(settings, state, state.time_ns + 2_000_000_000, (0.0, 0.0, 0.0))
    assert state.gaps == 1
    assert pdr_direction.step(settings, state, state.time_ns, (1.0, 0.0, 0.0)) is state  # not advancing


def test_memory_does_not_grow() -> None:
    """The state is the same fixed set of scalar fields after 10 and after 10^5 samples."""
    short, long = run(1.0, 10 / RATE_HZ), run(1.0, 100_000 / RATE_HZ)
    assert dataclasses.fields(short) == dataclasses.fields(long)
    for state in (short, long):
        assert all(isinstance(value, (int, float)) for value in dataclasses.astuple(state))


def pocket_rows(seconds: float, walking_rad: float, phone_z_rad: float) -> list[PhoneSample]:
    """A phone standing in a pocket: its top (+y) up, its screen normal (+z) horizontal at earth
    heading `phone_z_rad`, while the walker heads `walking_rad` (gyro zero: a straight walk)."""
    z_axis = np.array([math.cos(phone_z_rad), math.sin(phone_z_rad), 0.0])
    y_axis = np.array([0.0, 0.0, 1.0])
    rotation = np.column_stack([np.cross(y_axis, z_axis), y_axis, z_axis])  # phone-to-earth
    rows = []
    for i in range(int(seconds * RATE_HZ)):
        t = i / RATE_HZ
        specific = rotation.T @ (np.array(walk_accel(t, walking_rad)) + np.array([0.0, 0.0, GRAVITY_MS2]))
        rows.append(PhoneSample(T0_NS + int(round(t * 1e9)), tuple(specific.tolist()), (0.0, 0.0, 0.0)))
    return rows


@pytest.mark.parametrize("phone_z_deg", [0.0, 180.0, 30.0])
def test_pocket_steps_follow_the_walk_not_the_session_axis(phone_z_deg: float) -> None:
    """The session says +z is forward; the walker goes along +z (0 deg), -z (180 deg) or 30 deg off it."""
    walking_rad = 0.0
    estimator = PdrEstimator(PdrSettings(forward_axis=(0.0, 0.0, 1.0), direction_from_acceleration=True))
    rows = pocket_rows(20.0, walking_rad, math.radians(phone_z_deg))
    steps = [step for row in rows for step in estimator.step(row)]
    assert len(steps) > 20
    # Fusion's frame starts at an arbitrary yaw: compare with the heading the walk has in it
    rotation_phone = np.column_stack([np.cross([0.0, 0.0, 1.0], [math.cos(math.radians(phone_z_deg)),
                                                                 math.sin(math.radians(phone_z_deg)), 0.0]),
                                      [0.0, 0.0, 1.0],
                                      [math.cos(math.radians(phone_z_deg)), math.sin(math.radians(phone_z_deg)), 0.0]])
    walk_in_phone = rotation_phone.T @ np.array([math.cos(walking_rad), math.sin(walking_rad), 0.0])
    expected = estimator.axis_heading_rad(walk_in_phone)
    late = steps[len(steps) // 2:]
    assert all(angle_error_deg(step.heading_rad, expected) < 5.0 for step in late)
    assert late[-1].covariance[2, 2] > steps[0].covariance[2, 2]  # the extra per-step heading noise
