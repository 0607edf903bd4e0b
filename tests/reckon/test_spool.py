"""The edge's disk spool (reckon/transport/spool.py): order, the size limit, a power cut's truncated record, a restart."""

from __future__ import annotations

import logging
from collections import deque

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.errors import ConfigError
from reckon.transport.spool import Entry, Spool, encode_record, read_records


def entry(i: int, size: int = 100) -> Entry:
    return Entry(f"reckon/v/a{i % 3}/imu/s{i % 2}", "application/protobuf;reckon.v1.ImuBatch", bytes([i % 256]) * size)


def segments(directory):
    return sorted(directory.glob("spool-*.seg"))


def test_entries_come_back_in_order_across_segments_which_are_deleted_once_replayed(tmp_path):
    with Spool(tmp_path, segment_bytes=1000) as spool:
        for i in range(50):
            assert spool.append(entry(i))
        assert spool.pending == 50
        per_segment = 1000 // len(encode_record(entry(0)))
        assert len(segments(tmp_path)) == -(-50 // per_segment)  # rolled at 1000 bytes
        got = [e for e in spool.replay()]
        assert got == [entry(i) for i in range(50)]
        assert spool.pending == 0 and not segments(tmp_path)


def test_appends_while_replaying_keep_the_order(tmp_path):
    with Spool(tmp_path, segment_bytes=1000) as spool:
        for i in range(10):
            spool.append(entry(i))
        got, following = [], 10
        while (head := spool.peek()) is not None:
            got.append(head)
            spool.pop()
            if following < 30:  # the edge's new messages go to the tail while it drains
                spool.append(entry(following))
                following += 1
        assert got == [entry(i) for i in range(30)]


def test_at_the_limit_new_entries_are_refused_counted_and_warned_about_once(tmp_path, caplog):
    record = len(encode_record(entry(0)))
    with Spool(tmp_path, limit_bytes=10 * record, segment_bytes=4 * record) as spool, \
            caplog.at_level(logging.WARNING, logger="reckon.transport.spool"):
        accepted = [spool.append(entry(i)) for i in range(25)]
        assert accepted == [True] * 10 + [False] * 15
        assert spool.refused == 15 and spool.pending == 10
        assert spool.size_bytes <= 10 * record
        full = [r for r in caplog.records if "is full" in r.getMessage()]
        assert len(full) == 1  # rate-limited: one warning for 15 refusals within WARN_EVERY_S
        assert "refused 1 messages" in full[0].getMessage() and str(10 * record) in full[0].getMessage()
        assert [e for e in spool.replay()] == [entry(i) for i in range(10)]  # what it had is kept
        assert spool.append(entry(99))  # room again once replayed


def test_a_spool_left_on_disk_is_taken_over_by_the_next_start(tmp_path):
    with Spool(tmp_path, segment_bytes=1000) as spool:
        for i in range(20):
            spool.append(entry(i))
        for _ in range(5):  # replayed before the edge stopped
            spool.pop()
    with Spool(tmp_path, segment_bytes=1000) as spool:
        # the 5 replayed entries are gone only if their segment was used up; the rest is all there
        assert spool.recovered == spool.pending >= 15
        spool.append(entry(20))
        got = list(spool.replay())
    assert got[-16:] == [entry(i) for i in range(5, 21)]


def test_a_record_cut_short_by_a_power_cut_is_skipped_and_earlier_ones_kept(tmp_path, caplog):
    with Spool(tmp_path) as spool:
        for i in range(10):
            spool.append(entry(i))
    (path,) = segments(tmp_path)
    whole = path.stat().st_size
    with open(path, "r+b") as file:
        file.truncate(whole - 30)  # the last record loses its last 30 bytes
    with caplog.at_level(logging.WARNING, logger="reckon.transport.spool"), Spool(tmp_path) as spool:
        assert spool.pending == 9 and spool.damaged == 1
        assert path.stat().st_size == whole - len(encode_record(entry(9)))  # cut back to the last whole record
        spool.append(entry(10))  # appends continue cleanly after the cut
        assert list(spool.replay()) == [entry(i) for i in range(9)] + [entry(10)]
    assert any("cut short" in r.getMessage() and "kept the 9 records" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("damage", ["crc", "length", "header"])
def test_each_kind_of_damage_keeps_the_records_before_it(damage):
    data = b"".join(encode_record(entry(i)) for i in range(3))
    size = len(encode_record(entry(0)))
    if damage == "crc":
        data = data[:2 * size + 20] + b"\xff" + data[2 * size + 21:]
    elif damage == "length":
        data = data[:2 * size] + (2**31).to_bytes(4, "little") + data[2 * size + 4:]
    else:
        data = data[:2 * size + 5]
    records, intact, problem = read_records(data, "seg")
    assert [e for _, e in records] == [entry(0), entry(1)]
    assert intact == 2 * size
    assert problem is not None and f"at byte {2 * size}" in problem


def test_requeued_entries_come_before_the_rest(tmp_path):
    with Spool(tmp_path, segment_bytes=1000) as spool:
        for i in range(5, 15):
            spool.append(entry(i))
        spool.requeue([entry(i) for i in range(5)])
        assert spool.pending == 15
        assert list(spool.replay()) == [entry(i) for i in range(15)]


def test_bad_settings_fail_naming_the_value(tmp_path):
    with pytest.raises(ConfigError, match="limit 0 B"):
        Spool(tmp_path, limit_bytes=0)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.sampled_from(["append", "pop", "reopen"]), max_size=80))
def test_the_spool_behaves_as_a_queue_whatever_the_operations(tmp_path_factory, operations):
    directory = tmp_path_factory.mktemp("spool")
    model: deque[Entry] = deque()
    spool = Spool(directory, segment_bytes=600)
    number = 0
    for operation in operations:
        if operation == "append":
            spool.append(entry(number))
            model.append(entry(number))
            number += 1
        elif operation == "pop" and model:
            assert spool.peek() == model.popleft()
            spool.pop()
        elif operation == "reopen":
            spool.close()
            spool = Spool(directory, segment_bytes=600)
            # a reopened spool replays its oldest segment from its start (at least once): skip what the model had popped
            while spool.pending > len(model):
                spool.pop()
        assert spool.pending == len(model)
    assert list(spool.replay()) == list(model)
    spool.close()
