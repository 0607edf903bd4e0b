"""Edges and hub over real Zenoh sessions on loopback: simulated devices -> edges -> hub.

Each test runs the hub (`run_hub`) and one edge per chair (`run_edge`) in threads of this process,
each with its own Zenoh session on an explicit tcp endpoint. They wait on ready signals (the
hub's `ready` event, liveliness tokens), never on sleeps.
"""

from __future__ import annotations

import threading
from collections import defaultdict

import numpy as np
import pytest

from hub.chair.field_map import FieldMapSettings
from hub.chair.hub import HubSettings
from protocol import messages
from protocol import bus as wire
from protocol.session_log import read_session
from reckon.transport.bus import open_session, wait_for_peers, zenoh_config
from reckon.processes.edge import mcap_source, run_edge
from reckon.evaluation.reckon_run import log_inputs, run_lockstep
from reckon.processes.hub import run_hub
from support.games import Game

GAME = Game(players=4, duration_s=30.0, seed=3)
WAIT_S = 120.0


@pytest.fixture(scope="module")
def data(game):
    return read_session(game)


class Hub:
    """The hub in a thread; every output it publishes is also kept here."""

    def __init__(self, endpoint: str, session, output=None, settings: HubSettings = HubSettings()):
        self.stop, self.ready = threading.Event(), threading.Event()
        self.outputs: list = []
        self.result: dict = {}
        self.thread = threading.Thread(target=lambda: self.result.update(summary=run_hub(
            zenoh_config(listen=[endpoint]), session, self.stop, settings, output, self.ready, self.outputs.append)),
            daemon=True)
        self.thread.start()

    def finish(self):
        self.stop.set()
        self.thread.join(WAIT_S)
        assert not self.thread.is_alive()
        return self.result["summary"]

    def live(self) -> dict[str, np.ndarray]:
        rows = defaultdict(list)
        for out in self.outputs:
            if messages.type_name(out) == "EstimatedPose" and out.track == messages.Track.LIVE:
                rows[out.agent_id].append((out.timestamp_ns, out.x_m, out.y_m))
        return {agent: np.array(r) for agent, r in rows.items()}

    def collisions(self) -> list[tuple[int, frozenset]]:
        return [(c.timestamp_ns, frozenset((c.agent_id, c.other_agent_id))) for c in self.outputs
                if messages.type_name(c) == "Correction" and c.kind == messages.CorrectionKind.COLLISION]


def start_edges(endpoint: str, session, game, wait_for: int, source=None, speed: float = 0.0):
    results, threads = {}, []
    for agent in session.agents:
        messages_in = source(agent.id) if source else mcap_source(game, agent.id, speed, threading.Event())
        thread = threading.Thread(target=lambda a=agent.id, m=messages_in: results.update({a: run_edge(
            zenoh_config(connect=[endpoint]), session, a, m, threading.Event(), wait_for=wait_for)}), daemon=True)
        thread.start()
        threads.append(thread)
    return threads, results


def join(threads):
    for thread in threads:
        thread.join(WAIT_S)
        assert not thread.is_alive()


def errors_against_truth(data, live: dict[str, np.ndarray]) -> dict[str, float]:
    out = {}
    for agent, track in live.items():
        truth = data.truth[agent]
        tx = np.interp(track[:, 0], truth.time_ns, truth.x_m)
        ty = np.interp(track[:, 0], truth.time_ns, truth.y_m)
        out[agent] = float(np.mean(np.hypot(track[:, 1] - tx, track[:, 2] - ty)))
    return out


def test_edges_into_hub_corrected_poses_and_collision_pairs(game, data, free_endpoint, tmp_path):
    endpoint = free_endpoint()
    session = data.session
    hub = Hub(endpoint, session, output=tmp_path / "hub.mcap")
    assert hub.ready.wait(WAIT_S)
    # paced (4 x real time) as devices are, so corrections reach the edges while they still run
    threads, edges = start_edges(endpoint, session, game, wait_for=1, speed=4.0)
    join(threads)
    summary = hub.finish()

    live = hub.live()
    assert set(live) == {a.id for a in session.agents}
    for agent in session.agents:  # every pose the edge published came out corrected
        assert len(live[agent.id]) == edges[agent.id].poses
    errors = errors_against_truth(data, live)
    assert max(errors.values()) < 1.5, errors  # 30 s of play: dead reckoning plus corrections

    # the same code in lockstep pairs the same collisions (the bus may reorder, the pairs hold)
    taken: list[tuple[int, str, str]] = []
    reference, _, _ = run_lockstep(session, log_inputs(game), HubSettings(), contacts=taken)
    assert summary.pairs == reference.counters.pairs == len(taken) >= 1  # `reckon eval` scores these pairs
    assert sorted((a, b) for _, a, b in taken) == sorted(tuple(sorted(pair)) for _, pair in set(hub.collisions()))
    contacts = [(c.time_ns, frozenset((c.agent_id, c.other_agent_id))) for c in data.contacts]
    for time_ns, pair in hub.collisions():  # each applied pair was a real contact, found within the window
        assert any(pair == truth_pair and abs(time_ns - truth_ns) < 0.5e9 for truth_ns, truth_pair in contacts)
    # and the edges took them: every correction sent was applied by its edge, but for one sent as
    # its replay ended
    sent = defaultdict(int)
    for out in hub.outputs:
        if messages.type_name(out) == "Correction":
            sent[out.agent_id] += 1
    assert sent
    for agent, count in sent.items():
        assert count - 1 <= edges[agent].corrections <= count
    assert (tmp_path / "hub.mcap").stat().st_size > 0


def test_hub_started_after_the_edges_picks_them_up(game, data, free_endpoint):
    endpoint = free_endpoint()
    session = data.session
    # paced, so the game is still going when the hub joins; the edges do not wait for a hub
    threads, edges = start_edges(endpoint, session, game, wait_for=0, speed=3.0)
    with open_session(zenoh_config(listen=[endpoint])) as watcher:
        wait_for_peers(watcher, wire.alive_selector(session.venue.name, wire.Role.EDGE), len(session.agents), WAIT_S)
    hub = Hub(endpoint, session)
    assert hub.ready.wait(WAIT_S)
    join(threads)
    hub.finish()
    live = hub.live()
    assert set(live) == {a.id for a in session.agents}
    game_end = max(int(t.time_ns[-1]) for t in data.truth.values())
    for agent, track in live.items():
        assert track[-1, 0] > game_end - 1e9  # it followed every chair to the end
    assert max(errors_against_truth(data, live).values()) < 1.5


def test_a_device_that_drops_out_and_returns_resumes_without_a_restart(game, data, free_endpoint):
    endpoint = free_endpoint()
    session = data.session
    gone = session.agents[0].id
    start_ns = min(int(t.time_ns[0]) for t in data.truth.values())
    gap = (start_ns + int(10e9), start_ns + int(16e9))  # six seconds with nothing from its three sensors

    def source(agent_id):
        for message in mcap_source(game, agent_id, 0.0, threading.Event()):
            if agent_id == gone and gap[0] <= message.timestamp_ns < gap[1]:
                continue
            yield message

    hub = Hub(endpoint, session)
    assert hub.ready.wait(WAIT_S)
    threads, edges = start_edges(endpoint, session, game, wait_for=1, source=source)
    join(threads)
    hub.finish()
    track = hub.live()[gone]
    inside = (track[:, 0] > gap[0] + 0.5e9) & (track[:, 0] < gap[1] - 0.5e9)
    assert not inside.any()  # silent while away ...
    after = track[track[:, 0] >= gap[1]]
    assert len(after) > 100  # ... and back afterwards, from the same edge and hub
    assert edges[gone].samples < edges[session.agents[1].id].samples
    # carried on from where it was (no restart at the start pose): the first pose after the gap
    # is where the one before it plus the wheels' guess across the gap put it
    before = track[track[:, 0] < gap[0]]
    start = session.agents[0]
    assert np.hypot(after[0, 1] - start.start_x_m, after[0, 2] - start.start_y_m) > 0.5
    assert np.hypot(after[0, 1] - before[-1, 1], after[0, 2] - before[-1, 2]) < 6 * 5.0  # at most sprint speed


def test_the_hall_field_map_goes_round_edges_and_hub(game, data, free_endpoint):
    """Each edge's magnetometer readings reach the hub's field map, and the map comes back to each
    edge on its own key (sent every second here, and whatever it predicts: the map's own check
    needs more than a 30 s game, tests/hub/test_field_map.py holds that)."""
    endpoint = free_endpoint()
    session = data.session
    eager = FieldMapSettings(check_min=0, explained_share=1e9, period_s=1.0)
    hub = Hub(endpoint, session, settings=HubSettings(field_map=eager))
    assert hub.ready.wait(WAIT_S)
    threads, edges = start_edges(endpoint, session, game, wait_for=1, speed=4.0)
    join(threads)
    summary = hub.finish()
    sent = defaultdict(int)
    for out in hub.outputs:
        if messages.type_name(out) == "FieldMap":
            sent[out.agent_id] += 1
            assert out.columns * out.rows == len(out.offset_rad) == len(out.variance_rad2) > 0
    assert summary.field_map.startswith(f"field map: {len(session.agents)} chairs")
    for agent in session.agents:
        assert edges[agent.id].field_readings >= 1  # north is learnt some 20 s in (the hard-iron fit)
        # every map sent was taken, but for those sent as its replay ended (a chair whose first
        # reading came in the game's last second may have had none)
        assert sent[agent.id] - 2 <= edges[agent.id].field_maps <= sent[agent.id]
    assert sum(sent.values()) >= len(session.agents) and sum(e.field_maps for e in edges.values()) >= len(session.agents)
