"""Some channels of a complete session log read through its index (protocol/log_index.py): the same
messages, in the same order, as the stream reader gives, and the stream's rules on damage."""

from __future__ import annotations

import numpy as np
import pytest

import protocol.session_log as session_log
from protocol import keys, messages
from protocol.messages import imu_batch
from protocol.session import session_from_dict
from protocol.session_log import LogMessages, SessionWriter

AGENTS = ("chair01", "chair02", "chair03")
SESSION = {
    "venue": {"name": "court"},
    "agents": [{"id": a, "sensors": [{"id": f"{a}-seat", "mount": "seat"}]} for a in AGENTS],
}


def write_game(path, batches=1500, foreign=True):
    """Three chairs' batches and sightings interleaved over several chunks, and a channel not ours."""
    rng = np.random.default_rng(1)
    with SessionWriter(path, session_from_dict(SESSION)) as writer:
        if foreign:
            mcap = writer._writer._writer  # mcap_protobuf's Writer keeps the mcap Writer
            schema = mcap.register_schema(name="other.Thing", encoding="jsonschema", data=b"{}")
            other = mcap.register_channel(topic="other/thing", message_encoding="json", schema_id=schema)
        for b in range(batches):
            for a in rng.permutation(AGENTS):
                times = 10**12 + (np.arange(20) + 20 * b) * 5_000_000
                writer.write(keys.imu("court", a, f"{a}-seat"), imu_batch(
                    a, f"{a}-seat", b, times, rng.normal(size=(20, 3)), rng.normal(size=(20, 3)), None), int(times[-1]))
                if rng.random() < 0.3:
                    writer.write(keys.beacon("court", a, f"{a}-seat"), messages.new(
                        "BeaconSighting", timestamp_ns=int(times[0]), agent_id=a, sensor_id=f"{a}-seat",
                        beacon_id="goal-a", rssi_dbm=-70.0))
            if foreign and b % 50 == 0:
                mcap.add_message(other, log_time=10**12 + b, data=b"{}", publish_time=10**12 + b)


def chair02(topic, name):
    return keys.parse(topic)[1] == "chair02"


def serialised(log):
    return [(log_time, topic, message.SerializeToString()) for log_time, topic, message in log]


def test_one_agent_through_the_index_is_what_the_stream_gives(tmp_path, monkeypatch):
    write_game(tmp_path / "g.mcap")
    streamed = LogMessages(tmp_path / "g.mcap")
    expected = [row for row in serialised(streamed) if keys.parse(row[1])[1] == "chair02"]
    def no_stream(*args):
        raise AssertionError("the indexed read parsed the log as a stream")
    monkeypatch.setattr(session_log, "iter_records", no_stream)
    indexed = LogMessages(tmp_path / "g.mcap", chair02)
    got = serialised(indexed)
    assert len(got) > 400 and got == expected
    assert indexed.session == streamed.session and indexed.problems == []
    assert dict(indexed.skipped) == dict(streamed.skipped) == {"other/thing": 30}


def test_a_truncated_log_is_read_as_a_stream_and_keeps_what_came_before(tmp_path):
    write_game(tmp_path / "g.mcap")
    raw = (tmp_path / "g.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(raw[: int(len(raw) * 0.6)])
    log = LogMessages(tmp_path / "cut.mcap", chair02)
    got = serialised(log)
    whole = serialised(LogMessages(tmp_path / "g.mcap", chair02))
    assert 0 < len(got) < len(whole) and got == whole[:len(got)]
    assert "truncated" in log.problems[0]


def test_a_damaged_chunk_in_a_complete_log_keeps_the_chunks_before_it(tmp_path):
    from mcap.reader import make_reader

    write_game(tmp_path / "g.mcap", foreign=False)
    with open(tmp_path / "g.mcap", "rb") as f:
        chunks = sorted(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    assert len(chunks) >= 3
    raw = bytearray((tmp_path / "g.mcap").read_bytes())
    middle = chunks[1].chunk_start_offset + chunks[1].chunk_length // 2
    raw[middle:middle + 64] = bytes(64)  # zeros inside the second chunk's compressed data
    (tmp_path / "bad.mcap").write_bytes(bytes(raw))
    log = LogMessages(tmp_path / "bad.mcap", chair02)
    got = serialised(log)
    whole = serialised(LogMessages(tmp_path / "g.mcap", chair02))
    assert 0 < len(got) < len(whole) and got == whole[:len(got)]
    assert "damaged" in log.problems[0] and str(chunks[1].chunk_start_offset) in log.problems[0]


def test_a_venue_of_many_agents_is_written_in_larger_chunks(tmp_path):
    """Each chunk ends with an index record per channel in it: with 300 agents' channels 64 KiB chunks
    would hold about one message a channel. The log's chunks grow with its agents (up to 1 MiB) and
    it reads back whole, through the index too."""
    from mcap.reader import make_reader

    assert session_log.chunk_bytes(3) == session_log.chunk_bytes(10) == 64 * 1024
    assert session_log.chunk_bytes(300) == session_log.chunk_bytes(5000) == 1024 * 1024
    agents = [f"c{i:03d}" for i in range(300)]
    session = session_from_dict({"venue": {"name": "court"}, "agents": [
        {"id": a, "sensors": [{"id": f"{a}-seat", "mount": "seat"}]} for a in agents]}, where="test")
    path = tmp_path / "venue.mcap"
    with SessionWriter(path, session) as writer:
        for k in range(20):
            for a in agents:
                writer.write(keys.pose("court", a, "live"), messages.new(
                    "EstimatedPose", timestamp_ns=10**12 + k, agent_id=a, x_m=float(k), covariance=[0.1] * 9))
    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    sizes = [chunk.uncompressed_size for chunk in summary.chunk_indexes]
    assert max(sizes) > 64 * 1024 and len(sizes) <= 2
    one = LogMessages(path, lambda topic, name: keys.parse(topic)[1] == "c150")
    assert [message.x_m for _, _, message in one] == [float(k) for k in range(20)]
    assert sum(1 for _ in LogMessages(path)) == 20 * len(agents)
