"""Faults with nothing lost, over real Zenoh on loopback: an edge that spools while no hub is up, and
a hub killed (SIGKILL) and restarted from its checkpoint and its recording (docs/faults.md).

Edges run in threads of this process (`run_edge`), hubs in threads (`run_hub`) or as `reckon hub`
subprocesses, each with its own Zenoh session on an explicit tcp endpoint. Waits are on ready
signals (the hub's `ready` event, a source that says how far it got, liveliness, first samples).
"""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import zenoh

from reckon.processes import checkpoint as hub_state
from hub.dedup import Verdict
from protocol import bus as wire
from protocol import keys, messages
from protocol.session_log import LogMessages, read_description
from reckon.transport.bus import Subscription, open_session, zenoh_config
from reckon.processes.edge import mcap_source, run_edge
from reckon.processes.hub import FLUSH_EVERY_S, SNAPSHOT_EVERY_S, run_hub
from reckon.transport.spool import read_records
from support.games import Game

GAME = Game(players=2, duration_s=8.0, seed=5)
RESTARTED_GAME = Game(players=3, duration_s=20.0, seed=6)  # the hub killed and restarted in its middle
WAIT_S = 120.0
INPUT_TYPES = ("ImuBatch", "ClockSample", "BeaconSighting", "EstimatedPose", "ImpactEvent")
CLOCK_SLACK_NS = 5_000_000  # well under a pose interval (20 ms)
QUIET_S = 0.3  # after the kill, this long without a new live pose: the old hub's last ones have all come


class HubThread:
    def __init__(self, endpoint: str, session, output: Path):
        self.stop, self.ready = threading.Event(), threading.Event()
        self.result: dict = {}
        self.thread = threading.Thread(target=lambda: self.result.update(summary=run_hub(
            zenoh_config(listen=[endpoint]), session, self.stop, output=output, ready=self.ready)), daemon=True)
        self.thread.start()
        assert self.ready.wait(WAIT_S)

    def finish(self):
        self.stop.set()
        self.thread.join(WAIT_S)
        assert not self.thread.is_alive()
        return self.result["summary"]


def recorded_inputs(path: Path) -> list[tuple[str, object]]:
    """(topic, message) of the hub's recorded inputs (what it took), in file order."""
    return [(topic, m) for _, topic, m in LogMessages(path) if messages.type_name(m) in INPUT_TYPES
            and not topic.endswith(("/pose/live", "/pose/refined"))]


def identities(inputs) -> Counter:
    """What identifies each input: a batch by sensor and sequence, the rest by key and time."""
    out: Counter = Counter()
    for topic, m in inputs:
        if messages.type_name(m) == "ImuBatch":
            out[(m.sensor_id, m.sequence)] += 1
        else:
            out[(topic, getattr(m, "beacon_id", ""), m.timestamp_ns)] += 1
    return out


def spooled_on_disk(directory: Path) -> int:
    return sum(len(read_records(path.read_bytes(), str(path))[0]) for path in directory.glob("spool-*.seg"))


def source_identities(game: Path, agent_id: str) -> Counter:
    """The raw inputs an edge publishes for the agent with no one asking for its IMU: its sightings."""
    topic = {"BeaconSighting": keys.beacon}
    venue = read_description(game).venue.name
    return identities([(topic[messages.type_name(m)](venue, agent_id, m.sensor_id), m)
                       for m in mcap_source(game, agent_id, 0.0, threading.Event())
                       if messages.type_name(m) in topic])


def raw(inputs) -> list:
    """The sensor messages an edge passes on as they came. Raw IMU batches go out only while someone
    subscribes (reckon/processes/raw_feed.py): a hub without a camera never does, so none are here."""
    return [(t, m) for t, m in inputs if messages.type_name(m) in ("ImuBatch", "BeaconSighting")]


def test_an_edge_with_no_hub_spools_and_a_hub_started_later_gets_every_message_once(game, free_endpoint, tmp_path):
    session = read_description(game)
    agent_id = session.agents[0].id
    endpoint, spool = free_endpoint(), tmp_path / "spool"
    half, go = threading.Event(), threading.Event()
    every = list(mcap_source(game, agent_id, 0.0, threading.Event()))

    def source():
        yield from every[:len(every) // 2]
        half.set()  # asked for the next one: all before it were handed to the spool
        assert go.wait(WAIT_S)
        yield from every[len(every) // 2:]

    result = {}
    edge = threading.Thread(target=lambda: result.update(summary=run_edge(
        zenoh_config(connect=[endpoint]), session, agent_id, source(), threading.Event(), spool=spool,
        spool_wait_s=WAIT_S)), daemon=True)
    edge.start()
    assert half.wait(WAIT_S)
    held = spooled_on_disk(spool)
    assert held >= len(every) // 2  # every raw message so far, and the poses made from them
    hub = HubThread(endpoint, session, tmp_path / "hub.mcap")
    go.set()
    edge.join(WAIT_S)
    assert not edge.is_alive()
    summary, edge_summary = hub.finish(), result["summary"]

    assert edge_summary.spooled == 0 and spooled_on_disk(spool) == 0 and not list(spool.glob("*.seg"))
    taken = recorded_inputs(tmp_path / "hub.mcap")
    assert identities(raw(taken)) == source_identities(game, agent_id)  # every sighting, each once
    assert edge_summary.raw_sent == 0 and edge_summary.raw_unasked > 0  # no one asked for the raw IMU
    clocks = Counter((m.sensor_id, m.timestamp_ns) for _, m in taken if messages.type_name(m) == "ClockSample")
    assert len({sensor for sensor, _ in clocks}) == 3 and set(clocks.values()) == {1}  # each sensor's, each once
    assert sum(clocks.values()) == edge_summary.clock_samples
    poses = [m for _, m in taken if messages.type_name(m) == "EstimatedPose"]
    assert len(poses) == edge_summary.poses and len({m.timestamp_ns for m in poses}) == len(poses)
    impacts = [m for _, m in taken if messages.type_name(m) == "ImpactEvent"]
    assert len(impacts) == edge_summary.impacts
    assert summary.duplicates == 0 and summary.stale == 0  # nothing was sent twice here
    # and the hub's streams kept their order: each key's times only go forward
    last: dict = {}
    for topic, m in taken:
        stream = (topic, getattr(m, "beacon_id", ""))
        assert m.timestamp_ns > last.get(stream, -1)
        last[stream] = m.timestamp_ns


def test_a_spool_left_by_an_edge_that_stopped_is_replayed_by_its_next_start(game, free_endpoint, tmp_path):
    session = read_description(game)
    agent_id = session.agents[1].id
    endpoint, spool = free_endpoint(), tmp_path / "spool"
    config = zenoh_config(connect=[endpoint])
    first = run_edge(config, session, agent_id, mcap_source(game, agent_id, 0.0, threading.Event()),
                     threading.Event(), spool=spool, spool_wait_s=0.0)
    assert first.spooled == spooled_on_disk(spool) > 0  # no hub ever came: all of it is on disk
    hub = HubThread(endpoint, session, tmp_path / "hub.mcap")
    second = run_edge(config, session, agent_id, iter(()), threading.Event(), spool=spool, spool_wait_s=WAIT_S)
    hub.finish()
    assert second.spooled == 0 and spooled_on_disk(spool) == 0
    taken = recorded_inputs(tmp_path / "hub.mcap")
    assert identities(raw(taken)) == source_identities(game, agent_id)
    assert sum(messages.type_name(m) == "EstimatedPose" for _, m in taken) == first.poses


class Watcher:
    """Every live pose and correction on the bus, as a court-side screen sees them (a thread drains them)."""

    def __init__(self, endpoint: str, venue: str):
        self._bus_context = open_session(zenoh_config(connect=[endpoint]))
        bus = self._bus_context.__enter__()
        self.subscription = Subscription(bus, [keys.all_agents(venue, "pose/live"), keys.all_agents(venue, "correction")])
        self.items: list = []
        self.hub_up: list[float] = []  # when a hub's liveliness token showed up here
        self.changed = threading.Condition()
        self.tokens = bus.liveliness().declare_subscriber(
            wire.alive_selector(venue, wire.Role.HUB),
            lambda sample: self.hub_up.append(time.monotonic()) if sample.kind == zenoh.SampleKind.PUT else None)
        self.thread = threading.Thread(target=self._drain, daemon=True)
        self.thread.start()

    def _drain(self) -> None:
        for item in self.subscription:
            with self.changed:
                self.items.append((time.monotonic(), item.decode()))
                self.changed.notify_all()

    def wait_for(self, predicate, what: str, process: subprocess.Popen | None = None) -> None:
        """Until `predicate()` holds, checked at each new item and twice a second (a process may end)."""
        deadline = time.monotonic() + WAIT_S
        with self.changed:
            while not predicate():
                assert process is None or process.poll() is None, f"{what}: the hub exited ({process.returncode})"
                assert time.monotonic() < deadline, f"waited {WAIT_S} s for {what}"
                self.changed.wait(0.5)

    def wait_quiet(self, quiet_s: float) -> None:
        """Until no item has come for `quiet_s` (each arrival wakes the wait)."""
        with self.changed:
            while self.changed.wait(quiet_s):
                pass

    def close(self) -> None:
        self.tokens.undeclare()
        self.subscription.close()
        self._bus_context.__exit__(None, None, None)


def live(items) -> list:
    return [m for _, m in items if messages.type_name(m) == "EstimatedPose"]


def test_a_hub_killed_and_restarted_rebuilds_its_state_and_contradicts_nothing(games, free_endpoint, tmp_path, capsys):
    game = games.path(RESTARTED_GAME)
    session = read_description(game)
    venue = session.venue.name
    endpoint = free_endpoint()
    hub_command = [str(Path(sys.executable).with_name("reckon")), "-q", "hub", "--venue", str(game),
                   "-o", str(tmp_path / "hub.mcap"), "--state", str(tmp_path / "hub.state"), "--listen", endpoint]
    watcher = Watcher(endpoint, venue)
    logs = {name: open(tmp_path / name, "w+") for name in ("hub0.out", "hub0.err", "hub1.out", "hub1.err")}
    first_hub = subprocess.Popen(hub_command, stdout=logs["hub0.out"], stderr=logs["hub0.err"])
    results: dict = {}
    edges = [threading.Thread(target=lambda a=agent.id: results.update({a: run_edge(
        zenoh_config(connect=[endpoint]), session, a, mcap_source(game, a, 2.0, threading.Event()), threading.Event(),
        spool=tmp_path / f"spool-{a}", spool_wait_s=WAIT_S)}), daemon=True) for agent in session.agents]
    for edge in edges:
        edge.start()
    try:
        # kill it between two checkpoints: a snapshot is on disk and the hub has gone on since
        state = tmp_path / "hub.state"
        watcher.wait_for(lambda: state.exists() and len(watcher.items) > 0, "a first snapshot", first_hub)
        first_snapshot = state.stat().st_mtime_ns
        watcher.wait_for(lambda: state.stat().st_mtime_ns != first_snapshot, "a second snapshot", first_hub)
        seen, recording = len(watcher.items), tmp_path / "hub.mcap"
        # and past a whole flush of its recording after it (a loaded machine may be late to one): it grew twice
        for flush in ("a flush after the snapshot", "a second flush"):
            flushed = recording.stat().st_size
            watcher.wait_for(lambda: recording.stat().st_size > flushed, flush, first_hub)
        watcher.wait_for(lambda: len(watcher.items) > seen + 200, "poses after the snapshot", first_hub)
        first_hub.send_signal(signal.SIGKILL)
        first_hub.wait(WAIT_S)
        # what the old hub published before it died may still be on its way here: a quiet spell says it
        # has all come (nothing else publishes until the restart); the restarted hub is judged against it
        watcher.wait_quiet(QUIET_S)
        killed_at = len(watcher.items)
        old_size = (tmp_path / "hub.mcap").stat().st_size
        checkpoint = hub_state.read(state)  # the one the restart starts from
        started = time.monotonic()
        second_hub = subprocess.Popen(hub_command, stdout=logs["hub1.out"], stderr=logs["hub1.err"])
        watcher.wait_for(lambda: any(messages.type_name(m) == "EstimatedPose" for _, m in watcher.items[killed_at:]),
                         f"a live pose from the restarted hub (its log: {tmp_path / 'hub1.err'})", second_hub)
        first_pose_s = next(t for t, m in watcher.items[killed_at:] if messages.type_name(m) == "EstimatedPose") - started
        for edge in edges:
            edge.join(WAIT_S)
            assert not edge.is_alive()
        second_hub.send_signal(signal.SIGTERM)
        second_hub.wait(WAIT_S)
    finally:
        for process in (first_hub, locals().get("second_hub")):
            if process is not None and process.poll() is None:
                process.kill()
        watcher.close()
        for file in logs.values():
            file.close()
    out, err = (tmp_path / "hub1.out").read_text(), (tmp_path / "hub1.err").read_text()
    assert second_hub.returncode == 0, err
    before, after = watcher.items[:killed_at], watcher.items[killed_at:]

    # the old recording is kept as the kill left it; the restarted hub recorded beside it
    assert (tmp_path / "hub.mcap").stat().st_size == old_size and (tmp_path / "hub.1.mcap").exists()
    assert "hub restored from" in err
    reapplied = int(re.search(r"(\d+) inputs re-applied \(", err).group(1))
    assert reapplied > 0 and f"{reapplied} inputs re-applied after a restart" in out, err  # the catch-up ran
    old_inputs = recorded_inputs(tmp_path / "hub.mcap")
    new_inputs = recorded_inputs(tmp_path / "hub.1.mcap")
    # the bound: what is re-applied is what the old hub took after its last checkpoint, not the game so far
    assert checkpoint.recording == "hub.mcap" and reapplied == len(old_inputs) - checkpoint.inputs_recorded
    assert reapplied < len(old_inputs) / 3
    # ... which is what it took in under one checkpoint interval plus a flush: its outputs after the
    # checkpoint's inputs are stamped with the hub's clock as it made them
    counted, output_times = 0, []
    for log_time, topic, m in LogMessages(tmp_path / "hub.mcap"):
        if hub_state.is_input(topic):
            counted += 1
        elif counted >= checkpoint.inputs_recorded:
            output_times.append(log_time)
    assert (max(output_times) - min(output_times)) * 1e-9 <= SNAPSHOT_EVERY_S + FLUSH_EVERY_S
    # nothing lost, nothing twice: the old hub's intact record plus what the new one took live
    taken = identities(raw(old_inputs)) + identities(raw(new_inputs[reapplied:]))
    expected = sum((source_identities(game, a.id) for a in session.agents), Counter())
    assert taken == expected
    # correction numbers carry on: one number, one correction, from 1 up without a gap
    corrections: dict = {}
    for _, m in watcher.items:
        if messages.type_name(m) == "Correction":
            assert corrections.setdefault((m.agent_id, m.sequence), (m.dx_m, m.dy_m)) == (m.dx_m, m.dy_m)
    for agent in session.agents:
        numbers = sorted(seq for a, seq in corrections if a == agent.id)
        assert numbers == list(range(1, len(numbers) + 1))
    # no published pose contradicted without a correction message: the same time gives the same place
    # unless a correction came between (the replayed streams interleave across chairs differently, so
    # a collision may be paired a pose earlier or later), and then by no more than that correction
    def explained(agent_id: str, one, other) -> float:
        low, high = sorted((one.correction_sequence, other.correction_sequence))
        return sum(np.hypot(dx, dy) for (a, seq), (dx, dy) in corrections.items() if a == agent_id and low < seq <= high)

    # A pose is known again by its heading (the hub copies the edge's) at nearly the same venue time:
    # venue time is device time plus the hub's clock offset, which the restarted hub may have lowered
    # a fraction of a millisecond sooner or later than the old one did (the clock samples come on a key
    # of their own, and a burst of resent messages interleaves the keys differently).
    old_by_heading = {(m.agent_id, m.heading_rad): m for m in live(before)}
    compared = 0
    for m in live(after):
        was = old_by_heading.get((m.agent_id, m.heading_rad))
        if was is not None and abs(m.timestamp_ns - was.timestamp_ns) <= CLOCK_SLACK_NS:
            assert np.hypot(m.x_m - was.x_m, m.y_m - was.y_m) <= explained(m.agent_id, m, was) + 1e-6, (m, was)
            compared += 1
    # The poses the old hub published but never recorded (those after its last flush) come again in the
    # edges' resend window, and the restarted hub publishes them again: those are compared above. When
    # the kill came right after a flush there are none, and then nothing old may be published again.
    recorded = {(m.agent_id, m.heading_rad) for _, m in old_inputs if messages.type_name(m) == "EstimatedPose"}
    if any((m.agent_id, m.heading_rad) not in recorded for m in live(before)):
        assert compared > 0
    else:
        assert not any(abs(m.timestamp_ns - old_by_heading[(m.agent_id, m.heading_rad)].timestamp_ns) <= CLOCK_SLACK_NS
                       for m in live(after) if (m.agent_id, m.heading_rad) in old_by_heading)
    # and the first new pose follows on from the last old one (at most sprint speed, plus corrections)
    for agent in session.agents:
        last = [m for m in live(before) if m.agent_id == agent.id][-1]
        first = [m for m in live(after) if m.agent_id == agent.id][0]
        gap_s = abs(first.timestamp_ns - last.timestamp_ns) * 1e-9
        assert np.hypot(first.x_m - last.x_m, first.y_m - last.y_m) <= 6.0 * gap_s + explained(agent.id, first, last) + 1e-6
    with capsys.disabled():
        catch_up_s = float(re.search(r"inputs re-applied \(\d+ repeats dropped\) in ([0-9.]+) s", err).group(1))
        token_s = watcher.hub_up[-1] - started
        print(f"\nhub restart: {reapplied} inputs re-applied (of {len(old_inputs)} recorded) in {catch_up_s:.3f} s; "
              f"hub token seen {token_s:.2f} s and first live pose {first_pose_s:.2f} s after the restart began; "
              f"{len(corrections)} corrections; "
              f"{sum(r.poses for r in results.values())} edge poses")


def test_a_snapshot_plus_the_recording_after_it_gives_the_state_the_hub_had(game, tmp_path):
    """In lockstep, no bus: the hub takes a game's inputs, a snapshot at a third of them, then the rest;
    a hub restored from the snapshot and caught up from the recording is the same hub."""
    from hub.dedup import Deduplicator
    from hub.venue import VenueHub
    from protocol.session_log import SessionWriter
    from reckon.evaluation.reckon_run import log_inputs

    session = read_description(game)
    inputs = log_inputs(game)
    hub, dedup = VenueHub(session), Deduplicator()
    recording, state_path = tmp_path / "hub.mcap", tmp_path / "hub.state"
    topic = {"ImuBatch": lambda m: keys.imu(session.venue.name, m.agent_id, m.sensor_id),
             "BeaconSighting": lambda m: keys.beacon(session.venue.name, m.agent_id, m.sensor_id)}
    with SessionWriter(recording, session) as writer:
        for number, (arrival_ns, message) in enumerate(inputs):
            if number == len(inputs) // 3:
                writer.flush()
                hub_state.write_atomic(state_path, hub_state.dumps(hub_state.HubState(hub, dedup, recording.name, number)))
            key = topic[messages.type_name(message)](message)
            assert dedup.check(key, message) is Verdict.NEW
            writer.write(key, message, arrival_ns)
            hub.on_message(message, arrival_ns)
    assert not list(tmp_path.glob("*.tmp"))  # replaced at once
    restored = hub_state.read(state_path)
    result = hub_state.catch_up(restored, LogMessages(recording))
    assert result.reapplied == len(inputs) - len(inputs) // 3 and result.repeats == 0
    for agent_id, view in hub.agents.items():
        again = restored.hub.agents[agent_id]
        assert again.latest_ns == view.latest_ns and again.sequence == view.sequence
    assert hub_state.dumps(restored) == hub_state.dumps(hub_state.HubState(hub, dedup, recording.name,
                                                                           len(inputs) // 3))


def test_a_bad_state_file_fails_naming_it(tmp_path):
    from protocol.errors import InputError

    path = tmp_path / "hub.state"
    path.write_bytes(b"not a snapshot")
    with pytest.raises(InputError, match=f"{path}: not a reckon hub state file"):
        hub_state.read(path)
    path.write_bytes(hub_state.MAGIC + (99).to_bytes(4, "little"))
    with pytest.raises(InputError, match=f"version 99, this hub reads version {hub_state.VERSION}"):
        hub_state.read(path)
    assert hub_state.read(tmp_path / "absent.state") is None


def test_the_restarted_hub_never_overwrites_a_recording(tmp_path):
    (tmp_path / "hub.mcap").write_bytes(b"old")
    assert hub_state.next_recording(tmp_path / "hub.mcap") == tmp_path / "hub.1.mcap"
    (tmp_path / "hub.1.mcap").write_bytes(b"older")
    assert hub_state.next_recording(tmp_path / "hub.mcap") == tmp_path / "hub.2.mcap"


def test_a_state_file_needs_a_recording(game, free_endpoint, tmp_path):
    from protocol.errors import ConfigError

    with pytest.raises(ConfigError, match="needs a recording"):
        run_hub(zenoh_config(listen=[free_endpoint()]), read_description(game), threading.Event(),
                state=tmp_path / "hub.state")
