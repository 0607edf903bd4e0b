"""Camera identity live: a scene's IMU batches, edge poses and camera frames over Zenoh on loopback
into `run_hub`; the hub names the tracks and turns identified positions into video corrections."""

from __future__ import annotations

import threading

import numpy as np

from protocol import keys, messages
from protocol.bus import Role
from reckon.transport.bus import Publisher, flush, open_session, wait_for_peers, zenoh_config
from reckon.transport.config import free_endpoint
from reckon.processes.hub import run_hub
from support.identity_scenes import CROSSING, camera_frames, edge_poses, imu_batches, session
from support.waits import wait_until

WAIT_S = 60.0


def test_identified_tracks_reach_the_hub_and_become_video_corrections():
    chairs = session(list(CROSSING), chairs=True)
    venue = chairs.venue.name
    rng = np.random.default_rng(3)
    events = []
    for agent, (times, xy) in CROSSING.items():
        events += [(t, keys.imu(venue, agent, m.sensor_id), m) for t, m in imu_batches(agent, times, xy, rng, chairs=True)]
        events += [(t, keys.pose(venue, agent, "edge"), m) for t, m in edge_poses(agent, times, xy, (0.8, -0.4))]
    tracks = [(1, "a", 0, 6), (2, "b", 0, 6), (3, "c", 0, 30), (4, "b", 6, 30), (5, "a", 6, 30)]
    events += [(t, keys.camera_tracks(venue, "cam1"), m) for t, m in camera_frames(CROSSING, tracks, rng, end_s=30)]
    events.sort(key=lambda e: e[0])

    endpoint = free_endpoint()
    stop, ready, received = threading.Event(), threading.Event(), []
    hub = threading.Thread(target=lambda: run_hub(zenoh_config(listen=[endpoint]), chairs, stop, ready=ready,
                                                  on_output=received.append), daemon=True)
    hub.start()
    assert ready.wait(WAIT_S)
    with open_session(zenoh_config(connect=[endpoint])) as bus, Publisher(bus) as publisher:
        wait_for_peers(bus, f"reckon/{venue}/alive/{Role.HUB.value}/*", 1, WAIT_S)
        # published in one burst, as fast as the bus takes it (30 s of the scene in about a second): the hub
        # polls its streams in batches, so camera frames may run ahead of a chair's poses by seconds of
        # scene time, as when a device's link stalls. Before the hub's pose of a chair grew doubtful
        # with its age (hub/venue.py), about half the runs named a wrongly for b's track 4 after the
        # crossing: the position cue compared the tracks with poses seconds old.
        # The hub asks for the raw IMU once a camera's frames arrive (reckon/processes/raw_feed.py): an
        # edge sends it while the hub subscribes. So the first frame goes first, and the rest once the
        # hub's subscription is seen here (the first frame again with it: the hub drops the repeat).
        frame_key = keys.camera_tracks(venue, "cam1")
        publisher.publish(frame_key, next(m for _, key, m in events if key == frame_key))
        asked = bus.declare_publisher(next(key for _, key, _ in events if "/imu/" in key))
        wait_until(lambda: asked.matching_status.matching, WAIT_S, "the hub to subscribe to the raw IMU")
        asked.undeclare()
        for _, key, message in events:
            publisher.publish(key, message)
        assert flush(bus, f"reckon/{venue}/alive/{Role.HUB.value}/*", WAIT_S)
    stop.set()
    hub.join(WAIT_S)
    assert not hub.is_alive()

    identities = [m for m in received if messages.type_name(m) == "TrackIdentity"]
    truth = {1: "a", 2: "b", 3: "c", 4: "b", 5: "a"}
    assert {(m.agent_id, m.track_id) for m in identities if m.track_id} >= {("c", 3), ("a", 5), ("b", 4)}
    assert all(m.track_id == 0 or truth[m.track_id] == m.agent_id for m in identities), [(m.timestamp_ns // 10**8 / 10, m.agent_id, m.track_id) for m in identities]
    video = [m for m in received if messages.type_name(m) == "Correction" and m.kind == messages.CorrectionKind.VIDEO]
    assert {m.agent_id for m in video} == {"a", "b", "c"}
    # the edges drifted by (0.8, -0.4) m: each agent's first camera correction pulls it back (later ones
    # measure from the hub's pose, which already expects that shift)
    for agent in "abc":
        first = next(m for m in video if m.agent_id == agent)
        assert abs(first.dx_m + 0.8) < 0.25 and abs(first.dy_m - 0.4) < 0.25
