"""Swimmers live: a simulated set replayed -> `run_edge` per swimmer -> Zenoh on loopback -> `run_hub`.

The edges publish each length as it ends; the hub records and totals them. What arrives at the
hub must be exactly what the same edge code computes offline from the same log.
"""

from __future__ import annotations

import threading

import pytest

from protocol import messages
from protocol.session import Route
from protocol.session_log import LogMessages, read_session
from reckon.transport.bus import zenoh_config
from reckon.processes.edge import mcap_source, run_edge
from reckon.processes.hub import run_hub
from edge.swim.edge import SwimEdge
from sim_devices.swim import simulate_swim

WAIT_S = 120.0


@pytest.fixture(scope="module")
def swim_log(tmp_path_factory):
    path = tmp_path_factory.mktemp("swim") / "swim.mcap"
    simulate_swim(path, seed=2, swimmers=1, lengths=2, strokes=("crawl",), routes=(Route.STRAIGHT,))
    return path


def offline_lengths(path, agent):
    edge = SwimEdge(agent, read_session(path).session.venue.court_length_m)
    out = []
    for _, _, message in LogMessages(path, lambda topic, name: name == "ImuBatch"):
        if message.agent_id == agent.id:
            out += edge.push(message)
    return out + edge.flush()


def test_lengths_reach_the_hub_as_the_edges_computed_them(swim_log, free_endpoint, tmp_path):
    data = read_session(swim_log)
    session = data.session
    endpoint = free_endpoint()
    stop, ready, received = threading.Event(), threading.Event(), []
    hub_result = {}
    hub = threading.Thread(target=lambda: hub_result.update(summary=run_hub(
        zenoh_config(listen=[endpoint]), session, stop, output=tmp_path / "hub.mcap", ready=ready,
        on_output=received.append)), daemon=True)
    hub.start()
    assert ready.wait(WAIT_S)
    results, threads = {}, []
    for agent in session.agents:
        thread = threading.Thread(target=lambda a=agent.id: results.update({a: run_edge(
            zenoh_config(connect=[endpoint]), session, a, mcap_source(swim_log, a, 0.0, threading.Event()),
            threading.Event(), wait_for=1)}), daemon=True)
        thread.start()
        threads.append(thread)
    for thread in threads:
        thread.join(WAIT_S)
        assert not thread.is_alive()
    stop.set()
    hub.join(WAIT_S)
    assert not hub.is_alive()

    lengths = [m for m in received if messages.type_name(m) == "SwimLength"]
    expected = [m for agent in session.agents for m in offline_lengths(swim_log, agent)]
    assert expected, "the edge found no length in the simulated set"
    key = lambda m: (m.sensor_id, m.index)  # noqa: E731
    assert sorted(lengths, key=key) == sorted(expected, key=key)
    summary = hub_result["summary"]
    assert sum(s.lengths for s in summary.swims.values()) == len(expected)
    assert sum(r.lengths for r in results.values()) == len(expected)
    recorded = [m for _, _, m in LogMessages(tmp_path / "hub.mcap", lambda t, n: n == "SwimLength")]
    assert sorted(recorded, key=key) == sorted(expected, key=key)
    # each length is near its truth (the detector found the real walls, not stroke noise)
    for m in expected:
        truth = data.lengths[m.agent_id][m.index - 1]
        assert abs(m.timestamp_ns - truth.timestamp_ns) < 1e9
        assert abs(m.swum_distance_m - truth.swum_distance_m) < 0.05 * truth.swum_distance_m
