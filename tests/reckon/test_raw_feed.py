"""Raw IMU batches on the bus only while someone subscribes; each sensor's clock always (reckon/processes/raw_feed.py).

Real Zenoh sessions on loopback: an edge (`run_edge`) replaying a game, a watcher that may or may
not subscribe to the raw stream, and a hub that asks for it once a camera's frames arrive.
"""

from __future__ import annotations

import threading
from collections import Counter

import numpy as np

from hub.clocks import ClockOffsets
from protocol import bus as wire
from protocol import keys, messages
from protocol.messages import imu_batch
from protocol.session import session_from_dict
from protocol.session_log import read_description
from reckon.processes.edge import mcap_source, run_edge
from reckon.processes.hub import run_hub
from reckon.transport.bus import Alive, Publisher, Subscription, open_session, zenoh_config
from support.games import Game
from support.waits import wait_until

GAME = Game(players=2, duration_s=8.0, seed=5)
WAIT_S = 120.0


def replay(game, endpoint: str, agent_id: str):
    session = read_description(game)
    return run_edge(zenoh_config(connect=[endpoint]), session, agent_id,
                    mcap_source(game, agent_id, 0.0, threading.Event()), threading.Event(), wait_for=1)


def source_batches(game, agent_id: str) -> list:
    return [m for m in mcap_source(game, agent_id, 0.0, threading.Event()) if messages.type_name(m) == "ImuBatch"]


def watch(game, free_endpoint, streams: list[str]):
    """What a recorder subscribed to `streams` of every agent receives while agent 0's edge replays the game."""
    session = read_description(game)
    agent_id, endpoint, venue = session.agents[0].id, free_endpoint(), session.venue.name
    with open_session(zenoh_config(listen=[endpoint])) as bus, \
            Subscription(bus, [keys.all_agents(venue, s) for s in streams], capacity=1 << 16) as subscription:
        with Alive(bus, venue, wire.Role.RECORDER):  # the edge waits for it: its subscriptions are known by then
            summary = replay(game, endpoint, agent_id)
        subscription.undeclare()
        received = [item.decode() for item in subscription]
    return agent_id, summary, received


def test_nobody_subscribed_to_raw_imu_gets_only_the_clock_samples(game, free_endpoint):
    agent_id, summary, received = watch(game, free_endpoint, ["clock/*"])
    batches = source_batches(game, agent_id)
    assert summary.raw_sent == 0 and summary.raw_unasked == len(batches)
    clocks = [m for m in received if messages.type_name(m) == "ClockSample"]
    assert len(clocks) == summary.clock_samples and {m.sensor_id for m in clocks} == {b.sensor_id for b in batches}
    assert len({(m.sensor_id, m.timestamp_ns) for m in clocks}) == len(clocks)  # none sent twice (the hub counts repeats)
    # the lower envelope the hub keeps is the same from one sample a second as from every batch
    from_batches, from_samples = ClockOffsets(), ClockOffsets()
    for b in batches:
        from_batches.observe(b.sensor_id, b.timestamp_ns + b.sample_offset_ns[-1], b.received_ns)
    for m in clocks:
        from_samples.observe(m.sensor_id, m.timestamp_ns, m.received_ns)
    for sensor in {b.sensor_id for b in batches}:
        assert from_samples.offset_ns(sensor) == from_batches.offset_ns(sensor) != 0
    # one a second per sensor, and each sensor's first batch at once
    duration_s = (batches[-1].received_ns - batches[0].received_ns) * 1e-9
    assert len(clocks) <= 3 * (duration_s + 2)
    first = {}
    for b in batches:
        first.setdefault(b.sensor_id, (b.timestamp_ns + b.sample_offset_ns[-1], b.received_ns))
    seen = {}
    for m in clocks:
        seen.setdefault(m.sensor_id, (m.timestamp_ns, m.received_ns))
    assert seen == first


def test_a_subscriber_to_raw_imu_gets_every_batch_once(game, free_endpoint):
    agent_id, summary, received = watch(game, free_endpoint, ["imu/*", "clock/*"])
    batches = source_batches(game, agent_id)
    assert summary.raw_sent == len(batches) and summary.raw_unasked == 0
    raw = Counter((m.sensor_id, m.sequence) for m in received if messages.type_name(m) == "ImuBatch")
    assert raw == Counter((b.sensor_id, b.sequence) for b in batches)
    assert sum(messages.type_name(m) == "ClockSample" for m in received) == summary.clock_samples > 0


def test_the_hub_asks_for_raw_imu_once_a_camera_is_on(game, free_endpoint, tmp_path):
    session = read_description(game)
    venue, agent_id, endpoint = session.venue.name, session.agents[0].id, free_endpoint()
    stop, ready = threading.Event(), threading.Event()
    hub = threading.Thread(target=run_hub, args=(zenoh_config(listen=[endpoint]), session, stop),
                           kwargs={"ready": ready}, daemon=True)
    hub.start()
    assert ready.wait(WAIT_S)
    try:
        with open_session(zenoh_config(connect=[endpoint])) as bus, Publisher(bus) as camera:
            raw = bus.declare_publisher(keys.imu(venue, agent_id, f"{agent_id}-seat"))
            clock = bus.declare_publisher(keys.clock(venue, agent_id, f"{agent_id}-seat"))
            wait_until(lambda: clock.matching_status.matching, WAIT_S, "the hub's subscription to the clocks")
            assert not raw.matching_status.matching  # no camera yet: no one wants the raw stream
            frame = messages.new("CameraFrame", timestamp_ns=1, camera_id="cam1", frame=0, track_id=[1],
                                 x_m=[1.0], y_m=[2.0], height_m=[1.2], position_sd_m=0.05)
            camera.publish(keys.camera_tracks(venue, "cam1"), frame)
            wait_until(lambda: raw.matching_status.matching, WAIT_S, "the hub to subscribe to the raw IMU")
            raw.undeclare()
            clock.undeclare()
    finally:
        stop.set()
        hub.join(WAIT_S)
    assert not hub.is_alive()


def test_an_agent_whose_poses_come_without_clock_samples_gets_its_raw_imu_asked_for(free_endpoint):
    """An edge older than the hub (or a recording from before ClockSample, replayed): the hub takes the
    raw IMU for its clock offset, and that agent's live poses move to venue time from then on."""
    session = session_from_dict({"venue": {"name": "court"},
                                 "agents": [{"id": "c0", "sensors": [{"id": "c0-seat", "mount": "seat"}]},
                                            {"id": "c1", "sensors": [{"id": "c1-seat", "mount": "seat"}]}]}, where="test")
    endpoint, stop, ready, live = free_endpoint(), threading.Event(), threading.Event(), []
    hub = threading.Thread(target=run_hub, args=(zenoh_config(listen=[endpoint]), session, stop),
                           kwargs={"ready": ready, "on_output": live.append}, daemon=True)
    hub.start()
    assert ready.wait(WAIT_S)
    second, offset = 1_000_000_000, 5_000_000_000

    def pose(agent_id: str, k: int):
        return messages.new("EstimatedPose", timestamp_ns=10 * second + k * second // 50, agent_id=agent_id, x_m=1.0,
                            y_m=1.0, covariance=[0.25, 0, 0, 0, 0.25, 0, 0, 0, 0.01], track=messages.Track.LIVE)

    try:
        with open_session(zenoh_config(connect=[endpoint])) as bus, Publisher(bus) as edge:
            raw = {a: bus.declare_publisher(keys.imu("court", a, f"{a}-seat")) for a in ("c0", "c1")}
            clock_c1 = messages.new("ClockSample", timestamp_ns=10 * second, agent_id="c1", sensor_id="c1-seat",
                                    received_ns=10 * second + offset)
            edge.publish(keys.clock("court", "c1", "c1-seat"), clock_c1)  # c1's edge sends its clock
            k = 0

            def asked() -> bool:  # a pose of each at every look: the hub looks once a second, on its next batch
                nonlocal k
                for agent_id in ("c0", "c1"):
                    edge.publish(keys.pose("court", agent_id, "edge"), pose(agent_id, k))
                k += 1
                return raw["c0"].matching_status.matching

            wait_until(asked, WAIT_S, "the hub to ask for c0's raw IMU")
            assert k >= 100  # one subscription to every agent's raw IMU: c1's too, though it sends clock samples
            batch = imu_batch("c0", "c0-seat", 0, np.array([10 * second + k * second // 50]), np.zeros((1, 3)),
                              np.zeros((1, 3)), None)
            batch.received_ns = batch.timestamp_ns + offset
            edge.publish(keys.imu("court", "c0", "c0-seat"), batch)
            last = k + 50
            for k in range(k, last + 1):
                edge.publish(keys.pose("court", "c0", "edge"), pose("c0", k))
            wait_until(lambda: any(m.agent_id == "c0" and m.timestamp_ns == pose("c0", last).timestamp_ns + offset
                                   for m in list(live)), WAIT_S, "c0's live poses in venue time")
            for publisher in raw.values():
                publisher.undeclare()
    finally:
        stop.set()
        hub.join(WAIT_S)
    assert not hub.is_alive()
    c0 = [m.timestamp_ns for m in live if m.agent_id == "c0" and m.track == messages.Track.LIVE]
    assert c0[0] == pose("c0", 0).timestamp_ns  # device time until the hub had an offset
    assert all(m.timestamp_ns >= 10 * second + offset for m in live if m.agent_id == "c1")  # c1's clock from the start
