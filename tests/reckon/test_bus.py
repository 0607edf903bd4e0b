"""Zenoh bus end to end on loopback: wire format, every message type, replay -> record, back-pressure, start order.

Real sessions, explicit tcp endpoints on a free port per test, scouting off. Every wait is on a
ready signal (liveliness, events, queue gets, thread joins) and bounded, so a failure cannot hang.
"""

from __future__ import annotations

import json
import queue
import subprocess
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader

from protocol import bus as wire
from protocol import keys, messages
from protocol.errors import ConfigError, InputError
from protocol.session_log import read_session
from reckon.transport.bus import (Alive, Answer, BusError, CallbackSubscription, DirectSubscription, PolledSubscription,
                                  Publisher, Subscription, TokenWatch, flush, open_session, query, wait_for_peers,
                                  zenoh_config)
from reckon.transport.config import free_endpoint
from reckon.transport.record import RecordSummary, record
from reckon.transport.replay import ReplayProgress, ReplaySummary, replay
from sim_devices.wheelchair import simulate

VENUE = "court"
WAIT_S = 15.0  # upper bound of every wait: generous, only reached when something is broken

SAMPLES: dict[str, dict[str, Any]] = {
    "ImuBatch": dict(timestamp_ns=1, agent_id="a", sensor_id="a-seat", sequence=3, sample_offset_ns=[0, 5],
                     accel_g=[0.0, 0.5, 1.0] * 2, gyro_dps=[1.5] * 6, mag_gauss=[0.25] * 6),
    "BeaconSighting": dict(timestamp_ns=2, agent_id="a", sensor_id="a-seat", beacon_id="goal-a", rssi_dbm=-71.5),
    "TruthPose": dict(timestamp_ns=3, agent_id="a", x_m=1.25, y_m=-2.5, heading_rad=0.5),
    "EstimatedPose": dict(timestamp_ns=4, agent_id="a", x_m=1.0, y_m=2.0, covariance=[0.1] * 9, method="paper",
                          track=int(messages.Track.LIVE)),
    "ImpactEvent": dict(timestamp_ns=5, agent_id="a", sensor_id="a-seat", peak_g=9.5),
    "Correction": dict(timestamp_ns=6, agent_id="a", kind=int(messages.CorrectionKind.COLLISION), dx_m=0.5,
                       other_agent_id="b"),
    "TruthContact": dict(timestamp_ns=7, agent_id="a", other_agent_id="b", kind=int(messages.ContactKind.LATERAL),
                         closing_speed_mps=1.5),
    "PositionFix": dict(timestamp_ns=8, agent_id="a", kind=int(messages.CorrectionKind.MANUAL), x_m=1.0, y_m=2.0,
                        covariance=[0.25, 0.0, 0.0, 0.25], source_id="operator"),
}
KEYS = {
    "ImuBatch": keys.imu(VENUE, "a", "a-seat"), "BeaconSighting": keys.beacon(VENUE, "a", "a-seat"),
    "TruthPose": keys.truth(VENUE, "a"), "EstimatedPose": keys.pose(VENUE, "a"),
    "ImpactEvent": keys.impact(VENUE, "a"), "Correction": keys.correction(VENUE, "a"),
    "TruthContact": keys.contact(VENUE, "a"), "PositionFix": keys.fix(VENUE, "a"),
}

# The publishing side of the round trip, in its own interpreter: it must also exit without hanging.
PUBLISHER_SCRIPT = """
import json, sys
from protocol import bus as wire, messages
from reckon.transport.bus import Publisher, flush, open_session, wait_for_peers, zenoh_config
endpoint, venue, keys, samples = sys.argv[1], sys.argv[2], json.loads(sys.argv[3]), json.loads(sys.argv[4])
with open_session(zenoh_config(connect=[endpoint])) as session:
    wait_for_peers(session, wire.alive_selector(venue, wire.Role.HUB), 1, 15.0)
    with Publisher(session) as publisher:
        for name, fields in samples.items():
            publisher.publish(keys[name], messages.new(name, **fields))
    print(len(flush(session, wire.alive_selector(venue), 15.0)))
"""


def run_in_thread(target: Any, *args: Any, **kwargs: Any) -> tuple[threading.Thread, dict[str, Any]]:
    """Start `target` on a thread; the dict gets its 'result' or 'error'."""
    outcome: dict[str, Any] = {}

    def body() -> None:
        try:
            outcome["result"] = target(*args, **kwargs)
        except BaseException as error:  # handed to the test, which re-raises it
            outcome["error"] = error

    thread = threading.Thread(target=body, daemon=True)
    thread.start()
    return thread, outcome


def joined(thread: threading.Thread, outcome: dict[str, Any]) -> Any:
    thread.join(WAIT_S)
    assert not thread.is_alive(), "thread did not finish in time"
    if "error" in outcome:
        raise outcome["error"]
    return outcome["result"]


def messages_per_topic(path: Path) -> dict[str, list[Any]]:
    """Every message of a log, decoded, in file order per topic."""
    topics: dict[str, list[Any]] = defaultdict(list)
    with open(path, "rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            cls = messages.CLASSES[schema.name.removeprefix(messages.PACKAGE + ".")]
            topics[channel.topic].append(cls.FromString(message.data))
    return dict(topics)


@pytest.fixture(scope="module")
def game(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("bus") / "game.mcap"
    simulate(players=2, duration_s=5, seed=1, output=path)
    return path


# ---------------------------------------------------------------------------------------------
# Wire format and config (no network)


def test_wire_format_names_the_type_in_the_encoding():
    message = messages.new("ImuBatch", **SAMPLES["ImuBatch"])
    payload, encoding = wire.encode(message)
    assert encoding == "application/protobuf;reckon.v1.ImuBatch"
    assert payload == message.SerializeToString()
    assert wire.decode(encoding, payload) == message
    with pytest.raises(InputError, match="application/json"):
        wire.decode("application/json", payload)
    with pytest.raises(InputError, match="reckon.v1.Nope"):
        wire.decode("application/protobuf;reckon.v1.Nope", payload)
    with pytest.raises(InputError, match="not a valid reckon.v1.TruthPose"):
        wire.decode(wire.encoding_for("TruthPose"), b"\xff\xff\xff")


def test_control_keys():
    assert wire.session_key(VENUE) == "reckon/court/session"
    key = wire.alive(VENUE, wire.Role.RECORDER, "r1")
    assert key == "reckon/court/alive/recorder/r1"
    assert wire.parse_alive(key) == (VENUE, wire.Role.RECORDER, "r1")
    assert wire.alive_selector(VENUE) == "reckon/court/alive/*/*"
    assert wire.alive_selector(VENUE, wire.Role.HUB) == "reckon/court/alive/hub/*"
    with pytest.raises(ConfigError, match="r/1"):
        wire.alive(VENUE, wire.Role.HUB, "r/1")
    with pytest.raises(ValueError, match="role 'boss'"):
        wire.parse_alive("reckon/court/alive/boss/x")


def test_zenoh_config_rejects_what_cannot_work():
    with pytest.raises(ConfigError, match="no listen and no connect"):
        zenoh_config()
    with pytest.raises(ConfigError, match="'127.0.0.1:7447' is not <protocol>/<address>"):
        zenoh_config(connect=["127.0.0.1:7447"])
    with pytest.raises(ConfigError, match="mode 'hub'"):
        zenoh_config(mode="hub", listen=["tcp/127.0.0.1:7447"])
    with pytest.raises(ConfigError, match="replay speed -1"):
        replay("missing.mcap", zenoh_config(connect=["tcp/127.0.0.1:7447"]), speed=-1)


# ---------------------------------------------------------------------------------------------
# On the bus


def test_every_message_type_round_trips(tmp_path):
    endpoint = free_endpoint()
    with open_session(zenoh_config(listen=[endpoint])) as session, \
            Subscription(session, f"reckon/{VENUE}/**") as subscription, Alive(session, VENUE, wire.Role.HUB):
        child = subprocess.run([sys.executable, "-c", PUBLISHER_SCRIPT, endpoint, VENUE, json.dumps(KEYS),
                                json.dumps(SAMPLES)], capture_output=True, text=True, timeout=WAIT_S)
        assert child.returncode == 0, child.stderr
        assert child.stdout.split() == ["1"]  # this hub confirmed the flush barrier
        received = {}
        for _ in SAMPLES:
            item = subscription.get(timeout=WAIT_S)
            received[item.key] = item
    for name, fields in SAMPLES.items():
        item = received[KEYS[name]]
        assert item.encoding == wire.encoding_for(name)
        assert item.decode() == messages.new(name, **fields)
        assert item.source_ns is not None  # the publisher stamps its samples (timestamping on)


def test_replay_into_record_reproduces_the_session(game, tmp_path):
    endpoint, output = free_endpoint(), tmp_path / "recorded.mcap"
    stop, ready = threading.Event(), threading.Event()
    thread, outcome = run_in_thread(record, zenoh_config(listen=[endpoint]), VENUE, output, stop, ready,
                                    until_end=True)
    try:
        summary: ReplaySummary = replay(game, zenoh_config(connect=[endpoint]), speed=0, wait_for=1,
                                        wait_timeout_s=WAIT_S)
        recorded: RecordSummary = joined(thread, outcome)
    finally:
        stop.set()
    assert ready.is_set() and recorded.end_seen and not recorded.skipped
    assert len(summary.confirmed) == 1 and not summary.problems
    assert recorded.written == summary.published == sum(len(v) for v in messages_per_topic(game).values())
    assert messages_per_topic(output) == messages_per_topic(game)
    original, copy = read_session(game), read_session(output)
    assert copy.session == original.session and not copy.problems
    assert copy.imu.keys() == original.imu.keys() and copy.truth.keys() == original.truth.keys()
    for sensor, series in original.imu.items():
        for name in ("time_ns", "accel_g", "gyro_dps", "mag_gauss"):
            np.testing.assert_array_equal(getattr(copy.imu[sensor], name), getattr(series, name))
        assert copy.imu[sensor].lost_batches == series.lost_batches
    for agent, truth in original.truth.items():
        for name in ("time_ns", "x_m", "y_m", "heading_rad"):
            np.testing.assert_array_equal(getattr(copy.truth[agent], name), getattr(truth, name))
    for agent, seen in original.sightings.items():
        np.testing.assert_array_equal(copy.sightings[agent].rssi_dbm, seen.rssi_dbm)
        np.testing.assert_array_equal(copy.sightings[agent].beacon_id, seen.beacon_id)
    assert copy.contacts == original.contacts


def test_slow_subscriber_loses_nothing():
    endpoint, count = free_endpoint(), 3000
    key = keys.imu(VENUE, "a", "a-seat")
    with open_session(zenoh_config(listen=[endpoint])) as hub, open_session(zenoh_config(connect=[endpoint])) as edge:
        with Subscription(hub, key, capacity=4, fifo_capacity=4) as subscription, Alive(hub, VENUE, wire.Role.HUB):
            wait_for_peers(edge, wire.alive_selector(VENUE, wire.Role.HUB), 1, WAIT_S)

            def publish_all() -> int:
                with Publisher(edge) as publisher:
                    for sequence in range(count):
                        publisher.publish(key, messages.new("ImuBatch", **{**SAMPLES["ImuBatch"], "sequence": sequence}))
                    return publisher.sent

            thread, outcome = run_in_thread(publish_all)
            # the consumer does not read until the full queue has held the publisher back
            assert subscription.held_back.wait(WAIT_S)
            sequences = [subscription.get(timeout=WAIT_S).decode().sequence for _ in range(count)]
            assert joined(thread, outcome) == count
            with Publisher(edge) as publisher:  # a marker after the rest: in FIFO order, nothing came between
                publisher.publish(key, messages.new("ImuBatch", **{**SAMPLES["ImuBatch"], "sequence": count}))
            assert subscription.get(timeout=WAIT_S).decode().sequence == count
    assert sequences == list(range(count))
    assert subscription.stats.full_waits > 0  # the queue did fill: the publisher was held back, not dropped
    assert subscription.stats.discarded == 0 and subscription.stats.received == count + 1


def test_polled_subscription_holds_the_publisher_back_and_loses_nothing():
    """The hub's subscription (no drain thread): while nobody takes, its small FIFO fills and the
    publisher is held back (2,000 samples of 12 kB, 24 MB, cannot all sit in Zenoh's and TCP's
    buffers); then every sample comes out once, in order, across two selectors, in batches."""
    endpoint, count = free_endpoint(), 2000
    imu, beacon = keys.imu(VENUE, "a", "a-seat"), keys.beacon(VENUE, "a", "a-seat")
    big = {**SAMPLES["ImuBatch"], "accel_g": [0.5] * 1000, "gyro_dps": [1.5] * 1000, "mag_gauss": [0.25] * 1000}
    with open_session(zenoh_config(listen=[endpoint])) as hub, open_session(zenoh_config(connect=[endpoint])) as edge:
        with PolledSubscription(hub, [imu, beacon], fifo_capacity=4) as subscription, \
                Alive(hub, VENUE, wire.Role.HUB):
            wait_for_peers(edge, wire.alive_selector(VENUE, wire.Role.HUB), 1, WAIT_S)

            fifos_full = threading.Event()

            def publish_all() -> int:
                with Publisher(edge) as publisher:
                    for sequence in range(count + 1):  # the last pair: markers, sent after the rest
                        # 4 of each are in the FIFOs of 4, which nobody takes from: full
                        if sequence == 4 and flush(edge, wire.alive_selector(VENUE, wire.Role.HUB), WAIT_S):
                            fifos_full.set()
                        publisher.publish(imu, messages.new("ImuBatch", **{**big, "sequence": sequence}))
                        publisher.publish(beacon, messages.new("BeaconSighting", **{**SAMPLES["BeaconSighting"],
                                                                                    "timestamp_ns": sequence + 1}))
                    return publisher.sent

            thread, outcome = run_in_thread(publish_all)
            assert fifos_full.wait(WAIT_S)  # from here on every put waits for the consumer: held back
            taken: dict[str, list[int]] = {imu: [], beacon: []}
            batches = 0
            while not (taken[imu][-1:] == taken[beacon][-1:] == [count]):  # until both markers
                for item in subscription.take(limit=64, timeout=WAIT_S):
                    message = item.decode()
                    taken[item.key].append(message.sequence if item.key == imu else message.timestamp_ns - 1)
                    assert item.source_ns is not None and item.received_ns > 0
                batches += 1
            assert joined(thread, outcome) == 2 * (count + 1)
            subscription.undeclare()
            assert subscription.take(timeout=WAIT_S) is None and subscription.get(timeout=WAIT_S) is None
    # each selector in FIFO order: nothing beyond what was sent came before its marker
    assert taken[imu] == list(range(count + 1)) and taken[beacon] == list(range(count + 1))
    assert batches < 2 * count  # taken many at a time
    assert subscription.stats.full_waits > 0 and subscription.stats.discarded == 0
    assert subscription.stats.received == subscription.stats.delivered == 2 * (count + 1)


def test_polled_subscription_delivers_what_came_before_undeclare_and_close_discards_the_rest():
    endpoint = free_endpoint()
    key = keys.pose(VENUE, "a", "edge")
    pose = messages.new("EstimatedPose", **SAMPLES["EstimatedPose"])
    with open_session(zenoh_config(listen=[endpoint])) as hub, open_session(zenoh_config(connect=[endpoint])) as edge:
        first = PolledSubscription(hub, key, fifo_capacity=64)
        second = PolledSubscription(hub, key, fifo_capacity=64)
        with Alive(hub, VENUE, wire.Role.HUB):
            wait_for_peers(edge, wire.alive_selector(VENUE, wire.Role.HUB), 1, WAIT_S)
            with Publisher(edge) as publisher:
                for _ in range(10):
                    publisher.publish(key, pose)
            assert flush(edge, wire.alive_selector(VENUE, wire.Role.HUB), WAIT_S)  # all 10 are in both FIFOs
            assert first.get(timeout=WAIT_S).decode() == pose  # one handed out, nine held
            first.undeclare()
            rest = []
            while (batch := first.take(timeout=WAIT_S)) is not None:
                rest += batch
            assert len(rest) == 9 and first.stats.delivered == 10 and first.stats.discarded == 0
            assert len(second.take(limit=3, timeout=WAIT_S)) >= 1
            second.close()
            assert second.stats.received == 10 and second.stats.discarded == 10 - second.stats.delivered > 0
            assert second.take(timeout=0.1) is None
        first.close()


def test_polled_subscription_by_source_time_gives_the_order_of_the_puts_across_selectors():
    """The hub's order: a sweep of several FIFOs comes out as the samples were published, not
    stream by stream (the FIFOs are read a chunk at a time)."""
    endpoint, count = free_endpoint(), 300
    pose_key, beacon = keys.pose(VENUE, "a", "edge"), keys.beacon(VENUE, "a", "a-seat")
    with open_session(zenoh_config(listen=[endpoint])) as hub, open_session(zenoh_config(connect=[endpoint])) as edge:
        with PolledSubscription(hub, [pose_key, beacon], fifo_capacity=4 * count, by_source_time=True) as subscription, \
                Alive(hub, VENUE, wire.Role.HUB):
            wait_for_peers(edge, wire.alive_selector(VENUE, wire.Role.HUB), 1, WAIT_S)
            with Publisher(edge) as publisher:
                for n in range(count):
                    publisher.publish(pose_key, messages.new("EstimatedPose", **{**SAMPLES["EstimatedPose"],
                                                                                 "timestamp_ns": n}))
                    publisher.publish(beacon, messages.new("BeaconSighting", **{**SAMPLES["BeaconSighting"],
                                                                                "timestamp_ns": n}))
            assert flush(edge, wire.alive_selector(VENUE, wire.Role.HUB), WAIT_S)  # all in the FIFOs
            batch = subscription.take(limit=4 * count, timeout=WAIT_S)
    assert [(item.key, item.decode().timestamp_ns) for item in batch] == [
        (key, n) for n in range(count) for key in (pose_key, beacon)]
    assert all(item.received_ns == batch[0].received_ns for item in batch)  # one sweep, one clock reading


def test_direct_subscriptions_ring_drops_the_oldest_and_fifo_keeps_every_sample():
    endpoint = free_endpoint()
    ring_key, fifo_key = keys.status(VENUE, "a", "a-seat"), keys.correction(VENUE, "a")
    with open_session(zenoh_config(listen=[endpoint])) as hub, open_session(zenoh_config(connect=[endpoint])) as edge:
        ring = DirectSubscription.ring(hub, ring_key, 2)
        fifo = DirectSubscription.fifo(hub, fifo_key, 8)
        with Alive(hub, VENUE, wire.Role.HUB):
            wait_for_peers(edge, wire.alive_selector(VENUE, wire.Role.HUB), 1, WAIT_S)
            with Publisher(edge) as publisher:
                for n in range(5):
                    publisher.publish(ring_key, messages.new("DeviceStatus", timestamp_ns=n, agent_id="a"))
                    publisher.publish(fifo_key, messages.new("Correction", **{**SAMPLES["Correction"], "timestamp_ns": n}))
            assert flush(edge, wire.alive_selector(VENUE, wire.Role.HUB), WAIT_S)  # all 10 are in the handlers
            assert ring.try_get().decode().timestamp_ns == 3  # a ring of 2: the three oldest went
            assert ring.try_get().decode().timestamp_ns == 4 and ring.try_get() is None
            assert [fifo.try_get().decode().timestamp_ns for _ in range(5)] == list(range(5))
            assert fifo.try_get() is None
            ring.close()
            assert ring.try_get() is None  # undeclared: nothing more, no error
            reader, read = run_in_thread(lambda: [item.decode().timestamp_ns for item in fifo])
            with Publisher(edge) as publisher:
                for n in range(5, 8):
                    publisher.publish(fifo_key, messages.new("Correction", **{**SAMPLES["Correction"], "timestamp_ns": n}))
            assert flush(edge, wire.alive_selector(VENUE, wire.Role.HUB), WAIT_S)
            fifo.undeclare()  # the iterating thread gets what the FIFO holds, then its loop ends
            assert joined(reader, read) == [5, 6, 7]


def test_callback_subscription_answer_query_and_token_watch():
    endpoint = free_endpoint()
    key, answer_key = keys.correction(VENUE, "a"), wire.session_key(VENUE)
    got: queue.Queue[Any] = queue.Queue()
    tokens: queue.Queue[tuple[str, bool]] = queue.Queue()
    with open_session(zenoh_config(listen=[endpoint])) as hub, open_session(zenoh_config(connect=[endpoint])) as edge:
        alive = Alive(hub, VENUE, wire.Role.HUB, "h1")
        with CallbackSubscription(hub, key, got.put), Answer(hub, answer_key, b"description", wire.SESSION_ENCODING), \
                TokenWatch(edge, wire.alive_selector(VENUE, wire.Role.HUB), lambda k, up: tokens.put((k, up))):
            assert tokens.get(timeout=WAIT_S) == (alive.key, True)  # already present: reported from history
            with Publisher(edge) as publisher:
                # The hub's token reaching the edge does not mean its subscription has: until it
                # has, a put finds no subscriber and goes nowhere. Probes until one comes through.
                deadline = time.monotonic() + WAIT_S
                while True:
                    publisher.publish(key, messages.new("Correction", **{**SAMPLES["Correction"], "timestamp_ns": -1}))
                    try:
                        got.get(timeout=0.05)
                        break
                    except queue.Empty:
                        assert time.monotonic() < deadline, "the hub's subscription never reached the edge"
                for n in range(3):
                    publisher.publish(key, messages.new("Correction", **{**SAMPLES["Correction"], "timestamp_ns": n}))
            stamps: list[int] = []
            while len(stamps) < 3:
                stamp = got.get(timeout=WAIT_S).decode().timestamp_ns
                if stamp != -1:  # a probe still on its way
                    stamps.append(stamp)
            assert stamps == [0, 1, 2]
            replies = list(query(edge, answer_key, WAIT_S))
            assert [(r.key, r.payload, r.encoding) for r in replies] == [(answer_key, b"description", wire.SESSION_ENCODING)]
            alive.close()
            assert tokens.get(timeout=WAIT_S) == (alive.key, False)


def test_recorder_started_after_the_replayer_waits_gets_everything(game, tmp_path):
    endpoint, output = free_endpoint(), tmp_path / "late.mcap"
    waiting, stop = threading.Event(), threading.Event()

    def progress(report: ReplayProgress) -> None:
        if report.phase == "waiting":
            waiting.set()

    speed = 10.0  # also checks pacing: 5 s of log in about 0.5 s
    replayer, replayed = run_in_thread(replay, game, zenoh_config(connect=[endpoint]), speed, progress,
                                       wait_for=1, wait_timeout_s=WAIT_S)
    try:
        assert waiting.wait(WAIT_S)
        recorder, recorded = run_in_thread(record, zenoh_config(listen=[endpoint]), VENUE, output, stop,
                                           until_end=True)
        summary: ReplaySummary = joined(replayer, replayed)
        written: RecordSummary = joined(recorder, recorded)
    finally:
        stop.set()
    expected = {topic: len(items) for topic, items in messages_per_topic(game).items()}
    assert written.topics == expected and written.end_seen
    assert summary.published == sum(expected.values()) and len(summary.confirmed) == 1
    assert summary.publish_s >= 0.9 * summary.log_span_s / speed


def test_waiting_for_peers_gives_up_after_its_timeout():
    with open_session(zenoh_config(listen=[free_endpoint()])) as session:
        thread, outcome = run_in_thread(wait_for_peers, session, wire.alive_selector(VENUE), 1, 0.2)
        with pytest.raises(BusError, match=r"waited 0\.2 s for 1 live peer\(s\) on reckon/court/alive/\*/\*; saw 0: none"):
            joined(thread, outcome)  # it returns (raising) by itself: nobody else ends the wait


def test_recorder_stopped_before_a_description_writes_nothing(tmp_path):
    stop = threading.Event()
    stop.set()
    summary = record(zenoh_config(listen=[free_endpoint()]), VENUE, tmp_path / "none.mcap", stop)
    assert summary.written == 0 and "nothing written" in summary.problems[0]
    assert not (tmp_path / "none.mcap").exists()


def test_a_recorder_takes_each_pose_on_its_own_key_never_the_hubs_batches(game, tmp_path):
    """The hub sends a pose both on its agent's key and in a PoseBatch: the recording holds it once."""
    endpoint, output, stop, ready = free_endpoint(), tmp_path / "venue.mcap", threading.Event(), threading.Event()
    pose = messages.new("EstimatedPose", timestamp_ns=5, agent_id="chair01", x_m=1.0, track=messages.Track.LIVE)
    recorder, recorded = run_in_thread(record, zenoh_config(listen=[endpoint]), VENUE, output, stop, ready,
                                       description=read_session(game).session)
    try:
        assert ready.wait(WAIT_S)
        with open_session(zenoh_config(connect=[endpoint])) as session, Publisher(session) as publisher:
            publisher.publish(keys.pose(VENUE, "chair01", "live"), pose)
            publisher.publish(keys.pose_batch(VENUE, "live"), messages.new("PoseBatch", timestamp_ns=6, poses=[pose]))
            assert flush(session, wire.alive_selector(VENUE, wire.Role.RECORDER), WAIT_S)
        stop.set()
        written: RecordSummary = joined(recorder, recorded)
    finally:
        stop.set()
    assert written.topics == {keys.pose(VENUE, "chair01", "live"): 1}
