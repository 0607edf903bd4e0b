"""The compiled batch path (edge/chair/kernel.py) against the readable reference, chair_estimator.step.

Correctness only: how fast the kernel runs is `reckon bench`'s business, never a test's.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from edge.chair.estimator import start, step
from edge.chair.kernel import (COV, FLAGS, GRAVITY, IMPACT_WIDTH, MEAN, SAMPLE_WIDTH, STATE_SIZE, V_ACCEL, V_HAS_MAG,
                               V_LEFT, V_MAG, V_RIGHT, V_WHEEL_YAW, V_YAW_RATE, pack_samples, pack_settings, pack_state,
                               run_batch, run_poses, step_batch, unpack_state)
from edge.chair.state import DEG, ChairSample, ChairSettings, ChairState, Flag, N
from protocol.session_log import read_session
from reckon.evaluation.inputs import build_inputs
from reckon.evaluation.reckon_run import merged_samples
from support.games import Game

# a magnetometer aid that trusts its fit early and gates hard: rejections and re-learning north
STRICT_MAG = dict(mag_fit_min_points=10, mag_fit_min_spread=0.3, mag_gate_chi2=0.01, mag_recover_rejections=3)
GAME = Game(players=2, duration_s=30.0, seed=7)


@pytest.fixture(scope="module")
def chairs(game):
    """Per chair of the 2-player 30 s simulated game: (settings, start state, merged samples after the first)."""
    chairs = []
    for agent in build_inputs(read_session(game)).agents:
        samples = merged_samples(agent)
        chair = ChairSettings(wheel_diameter_m=agent.agent.wheel_diameter_m, camber_deg=agent.agent.camber_deg)
        first = start(chair, samples[0], agent.agent.start_x_m, agent.agent.start_y_m, agent.agent.start_heading_rad)
        chairs.append((chair, first, samples[1:]))
    return chairs


def with_mishaps(samples: list[ChairSample]) -> list[ChairSample]:
    """The game's samples plus what the live path also meets: lost seat packets, time going back,
    a hard impact, a stretch without magnetometer, a silence of the seat bridged by the wheels."""
    out = list(samples[:1500])
    # 40 seat samples (0.2 s) lost: the wheels' rotation meanwhile arrives with the next one
    lost = samples[1500:1540]
    after = samples[1540]
    out.append(replace(after, left_rotation_deg=after.left_rotation_deg + sum(s.left_rotation_deg for s in lost),
                       right_rotation_deg=after.right_rotation_deg + sum(s.right_rotation_deg for s in lost)))
    out += samples[1541:2500]
    out.append(samples[2490])  # a stale sample from the past
    out.append(replace(samples[2499], yaw_rate_dps=55.0))  # the same timestamp again
    out += samples[2500:3500]
    for s in samples[3500:3504]:  # a 6 g contact spanning four samples: one shove
        out.append(replace(s, accel_g=(6.0, 2.0, 1.0)))
    out += samples[3504:4000]
    out += [replace(s, mag_gauss=None) for s in samples[4000:4800]]
    out += samples[4800:5000]
    # the seat silent for 0.2 s, bridged by the merger: wheel-only samples every 10 ms
    for k in range(5000, 5040, 2):
        pair = samples[k:k + 2]
        out.append(replace(pair[1], yaw_rate_dps=math.nan, accel_g=(math.nan,) * 3, mag_gauss=None,
                           left_rotation_deg=sum(s.left_rotation_deg for s in pair),
                           right_rotation_deg=sum(s.right_rotation_deg for s in pair),
                           wheel_yaw_deg=sum(s.wheel_yaw_deg for s in pair)))
    out += samples[5040:]
    return out


def reference(chair: ChairSettings, state: ChairState,
              samples: list[ChairSample]) -> tuple[ChairState, np.ndarray, int]:
    """`step` in turn: (final state, each sample's flags, how often north was re-learned)."""
    flags, relearned = [], 0
    for sample in samples:
        before = state.mag.rejections
        state = step(chair, state, sample)
        flags.append(int(state.flags))
        relearned += (before >= chair.mag_recover_rejections and state.mag.rejections == 0
                      and not state.flags & Flag.MAG_USED)
    return state, np.array(flags), relearned


def assert_same_state(kernel: ChairState, expected: ChairState) -> None:
    """Equal to 1e-9 relative (bit for bit where numpy's BLAS sums as the kernel does, see its
    docstring); covariances relative to each entry's scale sqrt(P_ii P_jj), as an entry near zero
    has no relative precision of its own."""
    assert kernel.time_ns == expected.time_ns
    assert kernel.flags == expected.flags
    assert kernel.in_impact == expected.in_impact
    assert (kernel.mag.ready, kernel.mag.rejections) == (expected.mag.ready, expected.mag.rejections)
    close = dict(rtol=1e-9, atol=1e-300)
    np.testing.assert_allclose(kernel.mean, expected.mean, **close)
    scale = np.sqrt(np.outer(np.diag(expected.cov), np.diag(expected.cov)))
    assert np.all(np.abs(kernel.cov - expected.cov) <= 1e-9 * scale)
    scalars = ("yaw_rate_dps", "left_bias_dps", "right_bias_dps", "still_s", "accel_mean_g", "travel_m", "turn_xy",
               "turn_xx", "axis_xy", "axis_xx")
    for name in scalars:
        np.testing.assert_allclose(getattr(kernel, name), getattr(expected, name), err_msg=name, equal_nan=True,
                                   **close)
    np.testing.assert_allclose(kernel.gravity, expected.gravity, **close)
    np.testing.assert_allclose(kernel.mag.fit, expected.mag.fit, **close)
    np.testing.assert_allclose(kernel.mag.due_s, expected.mag.due_s, **close)
    np.testing.assert_allclose(kernel.mag.innovation_deg, expected.mag.innovation_deg, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(kernel.mag.stats, expected.mag.stats, **close)
    for name in ("since_read_m", "since_update_m", "anchor_angle", "turn_gyro_rad", "turn_s", "turn_m", "map_offset_rad",
                 "map_var_rad2", "field_x_m", "field_y_m", "field_offset_rad", "field_var_rad2"):
        np.testing.assert_allclose(getattr(kernel.mag, name), getattr(expected.mag, name), err_msg=name, equal_nan=True,
                                   **close)
    assert (kernel.mag.field_count, kernel.mag.field_time_ns) == (expected.mag.field_count, expected.mag.field_time_ns)


@pytest.mark.parametrize("overrides", [{}, STRICT_MAG], ids=["default", "strict-mag"])
def test_kernel_steps_as_the_reference_does(chairs, overrides):
    seen, relearned_north = Flag.NONE, 0
    for chair, first, samples in chairs:
        chair = replace(chair, **overrides)
        samples = with_mishaps(samples)
        expected, expected_flags, relearned = reference(chair, first, samples)
        state, flags = step_batch(chair, first, samples)
        np.testing.assert_array_equal(flags, expected_flags)
        assert_same_state(state, expected)
        # and part way, where the magnetometer has been absent for a while
        middle, _ = step_batch(chair, first, samples[:4500])
        assert_same_state(middle, reference(chair, first, samples[:4500])[0])

        # the mishaps and the filter's branches did happen
        seen |= Flag(int(np.bitwise_or.reduce(expected_flags)))
        relearned_north += relearned
    assert seen & Flag.STILL and seen & Flag.GAP and seen & Flag.BACKWARDS and seen & Flag.IMPACT
    assert seen & Flag.MAG_USED
    if overrides:
        assert seen & Flag.MAG_REJECTED and relearned_north > 0


def test_kernel_reads_the_hub_field_map_as_the_reference_does(chairs):
    """With the hub's map set (an offset out of every reading, a smaller variance left), the two still
    agree, and both offer the same readings to the map."""
    offered = 0
    for chair, first, samples in chairs:
        mapped = replace(first, mag=replace(first.mag, map_offset_rad=0.12, map_var_rad2=(2.5 * DEG) ** 2))
        expected, expected_flags, _ = reference(chair, mapped, samples)
        state, flags = step_batch(chair, mapped, samples)
        np.testing.assert_array_equal(flags, expected_flags)
        assert_same_state(state, expected)
        unmapped, _ = step_batch(chair, first, samples)
        assert not np.allclose(unmapped.mean, state.mean)  # the map did change the filter
        offered += expected.mag.field_count
        if expected.mag.field_count:
            assert expected.mag.field_time_ns <= expected.time_ns and expected.mag.field_var_rad2 > 0.0
    assert offered > 0


@settings(max_examples=30, deadline=None)
@given(st.lists(st.integers(0, 6000), max_size=6))
def test_any_split_into_batches_gives_the_same_result(chairs, cuts):
    chair, first, samples = chairs[1]
    times, values = pack_samples(with_mishaps(samples))
    settings_vector = pack_settings(chair)
    whole, whole_flags = run_batch(settings_vector, pack_state(first), times, values)
    state, flags = pack_state(first), []
    bounds = [0, *sorted(min(c, len(times)) for c in cuts), len(times)]
    for lo, hi in zip(bounds, bounds[1:]):
        state, part = run_batch(settings_vector, state, times[lo:hi], values[lo:hi])
        flags.append(part)
    np.testing.assert_array_equal(state, whole)
    np.testing.assert_array_equal(np.concatenate(flags), whole_flags)


@settings(max_examples=20, deadline=None)
@given(st.lists(st.integers(0, 6000), max_size=5), st.sampled_from([10_000_000, 20_000_000, 100_000_000]))
def test_run_poses_is_run_batch_cut_at_each_pose(chairs, cuts, period_ns):
    """run_poses per batch against run_batch run up to each pose time and each batch's end, as a
    Python loop would: the same states, poses, impacts (with gravity at the end of their run) and
    schedule, however the samples come in batches."""
    chair, first, samples = chairs[0]
    times, values = pack_samples(with_mishaps(samples))
    settings_vector = pack_settings(chair)
    bounds = [0, *sorted(min(c, len(times)) for c in cuts), len(times)]
    expected_state, expected_next, expected_poses, expected_impacts = pack_state(first), 0, [], []
    state, next_pose_ns, poses, impacts, seen = pack_state(first), 0, [], [], 0
    for lo, hi in zip(bounds, bounds[1:]):
        begin = lo
        for i in range(lo, hi):  # the loop run_poses stands for
            if times[i] < expected_next and i < hi - 1:
                continue
            expected_state, flags = run_batch(settings_vector, expected_state, times[begin:i + 1], values[begin:i + 1])
            expected_impacts += [(times[begin + j], *values[begin + j, V_ACCEL:V_ACCEL + 3],
                                  *expected_state[GRAVITY:GRAVITY + 3]) for j in np.flatnonzero(flags & Flag.IMPACT)]
            begin = i + 1
            if times[i] >= expected_next:
                expected_next = max(expected_next + period_ns, int(times[i]) - period_ns // 2)
                expected_poses.append((times[i], *expected_state[MEAN:MEAN + 3],
                                       *expected_state[COV:COV + N * N].reshape(N, N)[:3, :3].ravel()))
        flags, next_pose_ns, posed, out_times, rows = run_poses(
            settings_vector, state, times[lo:hi], values[lo:hi], next_pose_ns, period_ns)
        assert not rows[posed:, IMPACT_WIDTH:].any()
        poses += [(t, *row) for t, row in zip(out_times[:posed], rows[:posed])]
        impacts += [(t, *row[:IMPACT_WIDTH]) for t, row in zip(out_times[posed:], rows[posed:])]
        seen |= flags
    np.testing.assert_array_equal(state, expected_state)
    assert next_pose_ns == expected_next
    np.testing.assert_array_equal(np.array(poses), np.array(expected_poses))
    assert len(impacts) >= 1
    np.testing.assert_array_equal(np.array(impacts), np.array(expected_impacts))
    assert seen & Flag.IMPACT and seen & Flag.GAP


def test_packing_keeps_every_field(chairs):
    chair, first, samples = chairs[0]
    state = reference(chair, first, samples)[0]
    assert state.mag.ready and state.mag.fit.any()  # a state with everything in use
    for original in (state, replace(state, time_ns=-(2**62) + 12345, flags=Flag.GAP | Flag.IMPACT, in_impact=True)):
        vector = pack_state(original)
        assert vector.shape == (STATE_SIZE,) and vector.dtype == np.float64
        back = unpack_state(vector)
        assert back.time_ns == original.time_ns and isinstance(back.time_ns, int)
        assert back.flags == original.flags and back.in_impact == original.in_impact
        assert back.gravity == original.gravity
        np.testing.assert_array_equal(back.mean, original.mean)
        np.testing.assert_array_equal(back.cov, original.cov)
        np.testing.assert_array_equal(back.mag.fit, original.mag.fit)
        assert (back.mag.due_s, back.mag.ready, back.mag.rejections, back.mag.innovation_deg) == (
            original.mag.due_s, original.mag.ready, original.mag.rejections, original.mag.innovation_deg)
        for name in ("yaw_rate_dps", "left_bias_dps", "right_bias_dps", "still_s", "accel_mean_g", "travel_m",
                     "turn_xy", "turn_xx", "axis_xy", "axis_xx"):
            assert getattr(back, name) == getattr(original, name)
        np.testing.assert_array_equal(back.mag.stats, original.mag.stats)
        assert original.mag.stats[0] > 0  # the disturbance statistics were in use
        for name in ("since_read_m", "since_update_m", "anchor_angle", "turn_gyro_rad", "turn_s", "turn_m"):
            assert getattr(back.mag, name) == getattr(original.mag, name) or (
                math.isnan(getattr(back.mag, name)) and math.isnan(getattr(original.mag, name)))


def test_samples_without_magnetometer_pack_as_absent():
    times, values = pack_samples([ChairSample(5, 1.0, 2.0, 3.0, (0.0, 0.1, 1.0), None),
                                  ChairSample(10, 1.5, 2.5, 3.5, (0.0, 0.0, 1.0), (0.2, 0.1, -0.3))])
    assert times.dtype == np.int64 and values.shape == (2, SAMPLE_WIDTH)
    assert values[0, V_HAS_MAG] == 0.0 and values[1, V_HAS_MAG] == 1.0
    assert values[1, V_MAG:V_MAG + 3].tolist() == [0.2, 0.1, -0.3]
    assert values[0, [V_YAW_RATE, V_LEFT, V_RIGHT]].tolist() == [1.0, 2.0, 3.0]
    assert values[0, V_ACCEL:V_ACCEL + 3].tolist() == [0.0, 0.1, 1.0]
    assert math.isnan(values[0, V_WHEEL_YAW])  # no axle IMU yaw given
    assert pack_samples([])[1].shape == (0, SAMPLE_WIDTH)


def test_an_empty_batch_or_a_backwards_one_changes_nothing_but_the_flag(chairs):
    chair, first, samples = chairs[0]
    vector = pack_state(first)
    settings_vector = pack_settings(chair)
    same, flags = run_batch(settings_vector, vector, np.zeros(0, np.int64), np.zeros((0, SAMPLE_WIDTH)))
    np.testing.assert_array_equal(same, vector)
    assert flags.shape == (0,)
    times, values = pack_samples([samples[0]])
    stale = times - 10 ** 9
    after, flags = run_batch(settings_vector, vector, stale, values)
    assert flags.tolist() == [Flag.BACKWARDS]
    assert unpack_state(after).flags == Flag.BACKWARDS
    np.testing.assert_array_equal(np.delete(after, FLAGS), np.delete(vector, FLAGS))
    np.testing.assert_array_equal(vector, pack_state(first))  # the input was not written to


def test_state_size_is_fixed_over_a_million_steps():
    """10^6 synthetic samples (83 min at 200 Hz) with gaps, bridged silences of the seat, impacts, a
    backwards timestamp, a magnetometer that comes and goes and axles that check the seat's scale: the
    state is the same fixed-size vector, all finite."""
    n = 1_000_000
    rng = np.random.default_rng(1)
    i = np.arange(n)
    times = 1_704_067_200_000_000_000 + i * 5_000_000
    times[i % 50_000 == 49_999] += 300_000_000  # a lost stretch every 250 s
    times[123_456] = times[123_455]
    values = np.zeros((n, SAMPLE_WIDTH))
    moving = np.sin(i / 20_000.0) > -0.3  # rolling and pivoting, then still spells of ~30 s
    pivot = np.sin(i / 400.0) * moving
    values[:, V_YAW_RATE] = 90.0 * pivot
    values[:, V_LEFT] = 1.2 * moving - 0.4 * pivot
    values[:, V_RIGHT] = 1.2 * moving + 0.4 * pivot
    values[:, V_ACCEL:V_ACCEL + 3] = (0.0, 0.0, 1.0) + rng.normal(0.0, 0.002, (n, 3))
    values[i % 7_919 == 0, V_ACCEL] = 7.0
    values[:, V_WHEEL_YAW] = values[:, V_YAW_RATE] * 0.005 * math.cos(math.radians(17.0))
    heading = np.cumsum(values[:, V_YAW_RATE]) * 0.005 * math.pi / 180.0
    disturbance = 1.5 * ((i // 40_000) % 5 == 4)  # a steel structure turns the field for 200 s
    values[:, V_MAG] = 0.3 * np.cos(0.7 + disturbance - heading) + 0.05
    values[:, V_MAG + 1] = 0.3 * np.sin(0.7 + disturbance - heading) - 0.02
    values[:, V_MAG + 2] = -0.35
    values[:, V_HAS_MAG] = (i // 30_000) % 3 != 2
    values[values[:, V_HAS_MAG] == 0.0, V_MAG:V_MAG + 3] = np.nan
    bridged = i % 20_000 < 30  # 0.15 s of wheel-only samples every 100 s
    values[bridged, V_YAW_RATE] = np.nan
    values[bridged, V_ACCEL:V_ACCEL + 3] = np.nan
    values[bridged, V_HAS_MAG] = 0.0
    chair = ChairSettings()
    first = start(chair, ChairSample(int(times[0]) - 5_000_000, 0.0, 0.0, 0.0, (0.0, 0.0, 1.0)), 0.0, 0.0, 0.0)
    vector, flags = run_batch(pack_settings(chair), pack_state(first), times, values)
    assert vector.shape == (STATE_SIZE,) and flags.shape == (n,)
    assert np.all(np.isfinite(vector))
    assert len(pack_state(unpack_state(vector))) == STATE_SIZE
    assert unpack_state(vector).time_ns == int(times[-1])
    seen = Flag(int(np.bitwise_or.reduce(flags)))
    assert seen == (Flag.STILL | Flag.GAP | Flag.BACKWARDS | Flag.IMPACT | Flag.MAG_USED | Flag.MAG_REJECTED
                    | Flag.AXLE_SCALE_USED)
