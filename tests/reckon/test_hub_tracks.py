"""The hub puts a pose track on the bus only while someone subscribes to it; it records it anyway.

Real Zenoh sessions on loopback: a hub (`run_hub`), and an edge's stand-in that publishes one chair's
poses and watches the hub's live and, from half-way, refined tracks.
"""

from __future__ import annotations

import threading

import pytest

from hub.chair.hub import HubSettings
from protocol import bus as wire
from protocol import keys, messages
from protocol.session import session_from_dict
from protocol.session_log import LogMessages
from reckon.processes import hub as hub_process
from reckon.processes.hub import run_hub
from reckon.transport.matching import Listened
from reckon.transport.bus import Publisher, Subscription, flush, open_session, zenoh_config
from support.waits import wait_until

WAIT_S = 60.0
S = 1_000_000_000
SESSION = session_from_dict({
    "venue": {"name": "court"},
    "agents": [{"id": "c0", "sensors": [{"id": "c0-seat", "mount": "seat"}]}],
}, where="test")


def edge_pose(k: int):
    return messages.new("EstimatedPose", timestamp_ns=10 * S + k * S // 50, agent_id="c0", x_m=0.01 * k, y_m=1.0,
                        covariance=[0.25, 0, 0, 0, 0.25, 0, 0, 0, 0.01], method="reckon", track=messages.Track.LIVE)


@pytest.fixture
def hub_hears(monkeypatch):
    """`hub_hears(key_expr)` returns once the hub's own matching listener on key_expr has seen a
    subscriber: Zenoh tells it on its own thread, so poses the hub makes before that are rightly
    unheard, and a test that subscribes and publishes at once would race it."""
    followed: list[Listened] = []

    class Followed(Listened):
        def __init__(self, session, key_expr):
            super().__init__(session, key_expr)
            followed.append(self)

    monkeypatch.setattr(hub_process, "Listened", Followed)

    def hears(key_expr: str) -> None:
        wait_until(lambda: any(f.key_expr == key_expr and f.matching for f in followed), WAIT_S,
                   f"the hub to see a subscriber to {key_expr}")
    return hears


@pytest.mark.parametrize("recorded", [True, False])
def test_the_refined_track_goes_out_only_once_someone_subscribes_to_it(free_endpoint, tmp_path, recorded, hub_hears):
    """Recorded, every refined pose is made (and recorded); not recorded, those nobody subscribed to are
    not even made, and the summary counts them all the same."""
    endpoint, stop, ready = free_endpoint(), threading.Event(), threading.Event()
    summaries, made = [], []

    def hub() -> None:
        summaries.append(run_hub(zenoh_config(listen=[endpoint]), SESSION, stop, HubSettings(lag_s=1.0),
                                 output=tmp_path / "hub.mcap" if recorded else None, ready=ready,
                                 on_output=made.append if recorded else None))

    thread = threading.Thread(target=hub, daemon=True)
    thread.start()
    assert ready.wait(WAIT_S)
    live_key, refined_key = keys.pose("court", "c0", "live"), keys.pose("court", "c0", "refined")
    try:
        with open_session(zenoh_config(connect=[endpoint])) as bus, Publisher(bus) as edge, \
                Subscription(bus, live_key, capacity=4096) as live:
            edge_key = bus.declare_publisher(keys.pose("court", "c0", "edge"))
            wait_until(lambda: edge_key.matching_status.matching, WAIT_S, "the hub's subscription to edge poses")
            hub_hears(keys.all_agents("court", "pose/live"))
            for k in range(200):  # 4 s of poses: the first 3 s come out refined, and nobody wants them yet
                edge.publish(keys.pose("court", "c0", "edge"), edge_pose(k))
            wait_until(lambda: live.stats.received >= 200, WAIT_S, "the hub's live poses")
            with Subscription(bus, refined_key, capacity=4096) as refined:
                hub_hears(keys.all_agents("court", "pose/refined"))
                for k in range(200, 400):
                    edge.publish(keys.pose("court", "c0", "edge"), edge_pose(k))
                assert flush(bus, wire.alive_selector("court", wire.Role.HUB), WAIT_S)
                wait_until(lambda: live.stats.received >= 400, WAIT_S, "the hub's live poses")
                stop.set()  # the hub's last refined poses come out as it stops
                thread.join(WAIT_S)
                refined.undeclare()
                heard = [item.decode() for item in refined]
            edge_key.undeclare()
    finally:
        stop.set()
        thread.join(WAIT_S)
    assert not thread.is_alive()
    summary = summaries[0]
    assert summary.unheard >= 150  # at least what left the lag before anyone subscribed
    assert f"{summary.unheard} poses of a track nobody subscribed to" in str(summary)
    assert len(heard) == 400 - summary.unheard > 0  # every pose is refined, the last second's at the stop
    if not recorded:  # made: a live pose per pose, the refined ones heard
        assert summary.outputs == 400 + len(heard)
        assert [m.timestamp_ns for m in heard] == [edge_pose(k).timestamp_ns for k in range(400 - len(heard), 400)]
        return
    made_refined = [m for m in made if m.track == messages.Track.REFINED]
    assert len(made_refined) == 400
    assert [m.timestamp_ns for m in heard] == [m.timestamp_ns for m in made_refined[-len(heard):]]
    recording = [m for _, topic, m in LogMessages(tmp_path / "hub.mcap") if topic == refined_key]
    assert len(recording) == 400  # the recording holds the whole track


def test_a_consumer_of_every_agent_takes_the_poses_batched(free_endpoint, hub_hears):
    """Subscribed to `reckon/<venue>/hub/poses/<track>` only: every live and refined pose of both chairs
    comes exactly once, in each chair's order, several to a message, and no pose counts as unheard."""
    session = session_from_dict({"venue": {"name": "court"}, "agents": [
        {"id": agent, "sensors": [{"id": f"{agent}-seat", "mount": "seat"}]} for agent in ("c0", "c1")]},
        where="test")
    endpoint, stop, ready = free_endpoint(), threading.Event(), threading.Event()
    summaries = []
    hub = threading.Thread(target=lambda: summaries.append(run_hub(
        zenoh_config(listen=[endpoint]), session, stop, HubSettings(lag_s=1.0), ready=ready)), daemon=True)
    hub.start()
    assert ready.wait(WAIT_S)
    poses = 300
    try:
        with open_session(zenoh_config(connect=[endpoint])) as bus, Publisher(bus) as edge, \
                Subscription(bus, keys.pose_batch("court", "live"), capacity=4096) as live, \
                Subscription(bus, keys.pose_batch("court", "refined"), capacity=4096) as refined:
            edge_key = bus.declare_publisher(keys.pose("court", "c1", "edge"))
            wait_until(lambda: edge_key.matching_status.matching, WAIT_S, "the hub's subscription to edge poses")
            hub_hears(keys.pose_batch("court", "live"))
            hub_hears(keys.pose_batch("court", "refined"))
            for k in range(poses):
                for agent in ("c0", "c1"):
                    pose = edge_pose(k)
                    pose.agent_id = agent
                    edge.publish(keys.pose("court", agent, "edge"), pose)
            assert flush(bus, wire.alive_selector("court", wire.Role.HUB), WAIT_S)
            stop.set()  # the refined poses still in the lag come out as the hub stops
            hub.join(WAIT_S)
            live.undeclare()
            refined.undeclare()
            live_batches, refined_batches = [item.decode() for item in live], [item.decode() for item in refined]
            edge_key.undeclare()
    finally:
        stop.set()
        hub.join(WAIT_S)
    assert not hub.is_alive()
    assert summaries[0].unheard == 0
    expected = [edge_pose(k).timestamp_ns for k in range(poses)]
    for batches, track in ((live_batches, messages.Track.LIVE), (refined_batches, messages.Track.REFINED)):
        assert all(messages.type_name(batch) == "PoseBatch" for batch in batches)
        got = [pose for batch in batches for pose in batch.poses]
        assert {pose.track for pose in got} == {track}
        for agent in ("c0", "c1"):
            assert [pose.timestamp_ns for pose in got if pose.agent_id == agent] == expected, (track, agent)
    assert len(live_batches) < 2 * poses  # several poses to a message
