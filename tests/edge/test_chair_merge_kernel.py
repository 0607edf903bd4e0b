"""The compiled merger (edge/chair/merge_kernel.py, fed by edge/chair/merge_layout.py's PackedMerger)
against the readable reference, edge/chair/merger.py's ChairMerger: the same bits in every case the
reference handles, and a fixed size where the reference's queue would grow.

Both are fed the same ImuBatch messages (their float fields are float32, so the same messages, not
the same tuples); the compiled kernel here is the just-in-time one (tests/reckon/test_kernels.py
holds the ahead-of-time build to it)."""

from __future__ import annotations

import itertools
import random

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from edge.chair.kernel import just_in_time
from edge.chair.layout import SAMPLE_WIDTH, pack_samples
from edge.chair.merge_layout import FLOATS_SIZE, INTS_SIZE, PENDING, PackedMerger
from edge.chair.merger import ChairMerger
from protocol import keys
from protocol.messages import imu_batch
from protocol.session_log import LogMessages, read_description
from support.chair_streams import AGENT, DT, pivoting, shifted, streams, yawing_streams
from support.games import Game

GAME = Game(players=2, duration_s=30.0, seed=7)
MERGE = just_in_time().merge_batch


def batches(order, most: int = 20) -> list:
    """`order`'s samples as ImuBatch messages: each run of one sensor's consecutive samples, cut at `most`."""
    out = []
    for sensor, run in itertools.groupby(order, key=lambda item: item[0]):
        run = list(run)
        for start in range(0, len(run), most):
            part = run[start:start + most]
            mags = None if part[0][4] is None else np.array([item[4] for item in part])
            out.append(imu_batch(AGENT.id, sensor, len(out), np.array([item[1] for item in part], dtype=np.int64),
                                 np.array([item[2] for item in part]), np.array([item[3] for item in part]), mags))
    return out


def both(messages, agent=AGENT, max_wait_s: float = 100.0):
    """(reference rows, compiled rows, reference merger, compiled merger) for the same messages."""
    reference, compiled = ChairMerger(agent, max_wait_s=max_wait_s), PackedMerger(agent, MERGE, max_wait_s=max_wait_s)
    samples = [s for message in messages for s in reference.push_batch(message)] + reference.flush()
    made = [compiled.push_batch(message) for message in messages] + [compiled.flush()]
    times = np.concatenate([np.zeros(0, dtype=np.int64)] + [t for t, _ in made])
    rows = np.concatenate([np.zeros((0, SAMPLE_WIDTH))] + [v for _, v in made])
    return pack_samples(samples), (times, rows), reference, compiled


def assert_same(reference, compiled, reference_merger, compiled_merger) -> None:
    np.testing.assert_array_equal(compiled[0], reference[0])
    np.testing.assert_array_equal(compiled[1], reference[1])  # NaNs (bridges, no mag) in the same places
    assert compiled_merger.counters == reference_merger.counters
    clocks = reference_merger.clocks
    assert compiled_merger.clock_offsets_ns == (clocks["left"].offset_ns, clocks["right"].offset_ns)


def test_a_pivoting_chair_with_offset_clocks_bridged_gaps_and_stale_samples():
    seat, left, right = yawing_streams(3000, pivoting)
    left, right = shifted(left, 60_000_000), shifted(right, -30_000_000)
    del seat[400:470]  # 0.35 s of seat lost: bridged
    del seat[900:960], left[880:950], right[900:960]  # all three silent together: one step across
    del left[1500:1530]  # a wheel silent inside...
    del seat[1490:1540]  # ...a bridge
    messages = batches(sorted(seat + left + right, key=lambda item: item[1]))
    messages[2000:2000] = batches([seat[100]]) + batches([left[300]])  # stale samples of the seat and of a wheel
    reference, compiled, reference_merger, compiled_merger = both(messages, max_wait_s=2.0)
    assert_same(reference, compiled, reference_merger, compiled_merger)
    counters = reference_merger.counters
    assert counters.bridged > 30 and counters.seat_out_of_order == 1 and counters.wheel_out_of_order == {"left": 1}
    assert reference_merger.clocks["left"].updates > 0  # the clocks moved, so their learning is compared too


def test_a_silent_wheel_extrapolated_after_the_wait_and_a_seat_far_behind():
    seat, left, right = streams(400)
    late = batches(sorted(seat + left[:100] + right, key=lambda item: item[1]))
    assert_same(*both(late, max_wait_s=0.2))
    assert both(late, max_wait_s=0.2)[2].counters.extrapolated > 250
    seat, left, right = streams(1500)
    behind = batches(left + right) + batches(seat)  # the wheels 7.5 s ahead before the seat says anything
    result = both(behind)
    assert_same(*result)
    assert result[2].counters.wheel_overrun > 0


def test_the_games_batches_as_the_edge_gets_them(game):
    for agent in read_description(game).agents:
        messages = [m for _, topic, m in LogMessages(game, lambda topic, name: name == "ImuBatch"
                                                     and keys.parse(topic)[1] == agent.id)]
        result = both(messages, agent, max_wait_s=2.0)
        assert len(result[0][0]) > 5000
        assert_same(*result)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 40))
def test_any_interleaving_and_batching(seed, most):
    seat, left, right = yawing_streams(300, pivoting)
    del seat[100:150]
    shuffle = random.Random(seed)
    queues, order = [list(seat), list(left), list(right)], []
    while any(queues):  # each sensor keeps its own order; the sensors interleave at random
        queue = shuffle.choice([q for q in queues if q])
        order.append(queue.pop(0))
    assert_same(*both(batches(order, most), max_wait_s=0.3))


def test_a_seat_queue_beyond_its_ring_releases_the_oldest_and_the_state_keeps_its_size():
    seat, _, _ = streams(PENDING + 500)  # the wheels never report, and the wait is longer than the stream
    merger = PackedMerger(AGENT, MERGE, max_wait_s=1e3)
    sizes = (merger.ints.shape, merger.floats.shape)
    released = sum(len(merger.push_batch(message)[0]) for message in batches(seat))
    assert released == 500 + 1  # the ring holds PENDING - 1 after each push: the rest went out, oldest first
    assert merger.counters.extrapolated == released
    assert (merger.ints.shape, merger.floats.shape) == sizes == ((INTS_SIZE,), (FLOATS_SIZE,))
    times, _ = merger.flush()
    assert len(times) == PENDING - 1 and merger.counters.samples == len(seat)


def test_another_agents_sensor_and_an_empty_batch_give_nothing():
    merger = PackedMerger(AGENT, MERGE)
    seat, left, right = streams(10)
    stranger = imu_batch("chair09", "elsewhere", 0, np.array([DT]), np.zeros((1, 3)), np.zeros((1, 3)), None)
    assert len(merger.push_batch(stranger)[0]) == 0 and len(merger.push_batch(None)[0]) == 0
    assert merger.counters.samples == 0


def test_a_malformed_batch_is_refused_naming_the_sensor_and_the_counts():
    seat, _, _ = streams(4)
    broken = batches(seat)[0]
    del broken.gyro_dps[-2:]
    with pytest.raises(ValueError, match=r"ImuBatch of seat \(sequence 0\): 12 accel and 10 gyro values for 4 "):
        PackedMerger(AGENT, MERGE).push_batch(broken)


def test_missing_sensor_is_refused():
    from protocol.session import Agent, Mount, Sensor
    with pytest.raises(ValueError, match="needs seat, left_wheel and right_wheel"):
        PackedMerger(Agent("chair02", sensors=(Sensor("seat", Mount.SEAT),)), MERGE)
