"""The hub's deduplication (hub/dedup.py): repeats dropped, late and restarted streams kept, memory fixed."""

from __future__ import annotations

import sys

import pytest

from hub.dedup import Deduplicator, DedupSettings, Verdict
from protocol import keys, messages
from protocol.session_log import LogMessages
from support.games import Game

NEW, DUPLICATE, STALE = Verdict.NEW, Verdict.DUPLICATE, Verdict.STALE


def batch(sequence: int, sensor: str = "s1", agent: str = "a1") -> messages.ImuBatch:
    return messages.new("ImuBatch", timestamp_ns=sequence * 100_000_000, agent_id=agent, sensor_id=sensor,
                        sequence=sequence)


def pose(time_s: float, agent: str = "a1") -> messages.EstimatedPose:
    return messages.new("EstimatedPose", timestamp_ns=int(time_s * 1e9), agent_id=agent)


def sighting(time_s: float, beacon: str) -> messages.BeaconSighting:
    return messages.new("BeaconSighting", timestamp_ns=int(time_s * 1e9), agent_id="a1", sensor_id="rx",
                        beacon_id=beacon, rssi_dbm=-60.0)


def check_all(dedup: Deduplicator, key: str, items) -> list[Verdict]:
    return [dedup.check(key, item) for item in items]


def test_imu_batches_repeated_are_dropped_late_ones_kept():
    dedup = Deduplicator()
    key = keys.imu("v", "a1", "s1")
    assert check_all(dedup, key, [batch(i) for i in (1, 2, 3, 5)]) == [NEW] * 4
    assert check_all(dedup, key, [batch(i) for i in (2, 3, 5)]) == [DUPLICATE] * 3
    assert dedup.check(key, batch(4)) is NEW  # late, never seen: kept
    assert dedup.check(key, batch(4)) is DUPLICATE
    assert dedup.check(key, batch(3, sensor="s2")) is NEW  # another sensor's stream
    assert dedup.counters.duplicates == 4 and dedup.counters.stale == 0


def test_a_sequence_far_behind_is_a_restarted_device_and_taken():
    dedup = Deduplicator(DedupSettings(window=64))
    key = keys.imu("v", "a1", "s1")
    check_all(dedup, key, [batch(i) for i in range(100, 200)])
    assert dedup.check(key, batch(199 - 63)) is DUPLICATE  # still inside the window
    assert dedup.check(key, batch(0)) is NEW and dedup.counters.resets == 1
    assert dedup.check(key, batch(1)) is NEW and dedup.check(key, batch(0)) is DUPLICATE


def test_timed_streams_tell_a_repeat_from_an_out_of_order_message():
    dedup = Deduplicator()
    key = keys.pose("v", "a1", "edge")
    assert check_all(dedup, key, [pose(t) for t in (1.0, 1.02, 1.04)]) == [NEW] * 3
    assert dedup.check(key, pose(1.04)) is DUPLICATE
    assert dedup.check(key, pose(1.02)) is STALE
    assert (dedup.counters.duplicates, dedup.counters.stale) == (1, 1)
    assert dedup.check(key, pose(1.06)) is NEW
    assert dedup.check(key, pose(0.5 - 60)) is NEW and dedup.counters.resets == 1  # a clock that started over


def test_sightings_of_two_beacons_at_one_time_are_both_new():
    dedup = Deduplicator()
    key = keys.beacon("v", "a1", "rx")
    assert check_all(dedup, key, [sighting(2.0, "left"), sighting(2.0, "right")]) == [NEW, NEW]
    assert check_all(dedup, key, [sighting(2.0, "left"), sighting(2.0, "right")]) == [DUPLICATE, DUPLICATE]


def test_memory_is_fixed_however_long_the_stream_and_however_many_streams():
    dedup = Deduplicator(DedupSettings(window=256, max_streams=8))
    key = keys.imu("v", "a1", "s1")

    def size() -> int:
        return sys.getsizeof(dedup._counted[("ImuBatch", "a1", "s1")].seen)

    check_all(dedup, key, [batch(i) for i in range(300)])
    after_300 = size()
    check_all(dedup, key, [batch(i) for i in range(300, 100_000, 7)])  # gaps as well
    assert size() <= after_300
    for agent in range(100):  # made-up streams: the oldest are forgotten
        dedup.check(keys.pose("v", f"x{agent}", "edge"), pose(1.0, f"x{agent}"))
    assert len(dedup._timed) == 8


def test_bad_settings_name_the_value():
    with pytest.raises(ValueError, match="window 0"):
        DedupSettings(window=0)


def test_a_simulated_game_with_a_replayed_window_loses_nothing_and_repeats_nothing(games):
    path = games.path(Game(players=2, duration_s=6.0, seed=4))
    inputs = [(topic, message) for _, topic, message in LogMessages(path)
              if messages.type_name(message) in ("ImuBatch", "BeaconSighting")]
    cut = len(inputs) // 2
    # what an edge does after a hub loss: the last 100 sent go again, then the rest
    arriving = inputs[:cut] + inputs[cut - 100:]
    dedup = Deduplicator()
    verdicts = [dedup.check(topic, message) for topic, message in arriving]
    assert verdicts.count(NEW) == len(inputs)
    # a timed stream's repeat older than its newest message is told apart from a new one, not from an out-of-order one
    assert dedup.counters.duplicates + dedup.counters.stale == 100
    assert NEW not in verdicts[cut:cut + 100]
    assert all(v is DUPLICATE for (_, m), v in zip(arriving[cut:cut + 100], verdicts[cut:cut + 100])
               if messages.type_name(m) == "ImuBatch")
