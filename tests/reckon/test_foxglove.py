"""Recordings open in Foxglove: every schema of a simulator session and of a hub recording is a
self-contained FileDescriptorSet that decodes every message in a fresh descriptor pool built only
from the file (what Foxglove does), and `reckon export foxglove` adds Foxglove's own scene schemas
(SceneUpdate, FrameTransform, PoseInFrame) beside the untouched original channels."""

from __future__ import annotations

import itertools
import threading
from collections import defaultdict
from pathlib import Path

import foxglove.messages
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

from protocol import bus as wire
from protocol import keys, messages
from protocol.session_log import read_description
from reckon.transport.bus import Publisher, flush, open_session, wait_for_peers, zenoh_config
from reckon.cli import main
from reckon.tools.foxglove import DECIMATE_NS, export_foxglove
from reckon.processes.hub import run_hub
from support.court import CHAIRS, STEP_NS, T0_NS, chair_xy, pose, session
from support.games import Game

GAME = Game(players=2, duration_s=5.0, seed=3)
WAIT_S = 30.0
FOXGLOVE_SCHEMAS = {f"foxglove.{name}" for name in dir(foxglove.messages) if name[0].isupper()}


class FreshPools:
    """Message classes built from each schema record's own bytes, one pool per schema, as a viewer would."""

    def __init__(self):
        self.classes: dict[int, type] = {}

    def decode(self, schema, data: bytes):
        cls = self.classes.get(schema.id)
        if cls is None:
            assert schema.encoding == "protobuf", schema.name
            files = descriptor_pb2.FileDescriptorSet.FromString(schema.data).file
            names = {file.name for file in files}
            for file in files:  # self-contained: every import is in the set
                assert set(file.dependency) <= names, (schema.name, file.name, set(file.dependency) - names)
            pool = descriptor_pool.DescriptorPool()
            pending = list(files)
            while pending:  # dependencies first, in whatever order the set lists them
                ready = [f for f in pending if all(d not in {p.name for p in pending} for d in f.dependency)]
                assert ready, f"{schema.name}: circular imports"
                for file in ready:
                    pool.Add(file)
                    pending.remove(file)
            cls = self.classes[schema.id] = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
        message = cls.FromString(data)
        assert message.SerializeToString() == cls.FromString(message.SerializeToString()).SerializeToString()
        return message


def decode_all(path: Path) -> dict[str, list]:
    """{topic: [(log_time, schema name, decoded message), ...]}; every channel protobuf with a schema."""
    pools = FreshPools()
    out: dict[str, list] = defaultdict(list)
    with open(path, "rb") as stream:
        for schema, channel, record in make_reader(stream).iter_messages(log_time_order=False):
            assert schema is not None and channel.message_encoding == "protobuf", channel.topic
            out[channel.topic].append((record.log_time, schema.name, pools.decode(schema, record.data)))
    return out


@pytest.fixture(scope="module")
def hub_recording(tmp_path_factory, free_endpoint) -> Path:
    """A real hub's recording: three chairs' edge poses and an operator's fix in, live and refined out."""
    path = tmp_path_factory.mktemp("fox") / "hub.mcap"
    endpoint, stop, ready = free_endpoint(), threading.Event(), threading.Event()
    hub = threading.Thread(target=run_hub, args=(zenoh_config(listen=[endpoint]), session(), stop),
                           kwargs={"output": path, "ready": ready}, daemon=True)
    hub.start()
    assert ready.wait(WAIT_S)
    with open_session(zenoh_config(connect=[endpoint])) as bus, Publisher(bus) as publisher:
        wait_for_peers(bus, wire.alive_selector("court", wire.Role.HUB), 1, WAIT_S)
        for step in range(60):
            for agent in CHAIRS:
                publisher.publish(keys.pose("court", agent, "edge"), pose(agent, T0_NS + step * STEP_NS, *chair_xy(agent, step)))
            if step == 10:
                x, y = chair_xy("c2", step)
                publisher.publish(keys.fix("court", "c2"), messages.new(
                    "PositionFix", timestamp_ns=T0_NS + step * STEP_NS, agent_id="c2", kind=messages.CorrectionKind.MANUAL,
                    x_m=x + 0.5, y_m=y, covariance=[0.25, 0.0, 0.0, 0.25], source_id="operator"))
        assert flush(bus, wire.alive_selector("court", wire.Role.HUB), WAIT_S)
    stop.set()
    hub.join(WAIT_S)
    assert not hub.is_alive()
    return path


def test_simulator_session_schemas_decode_in_a_fresh_pool(game: Path):
    topics = decode_all(game)
    names = {name for rows in topics.values() for _, name, _ in rows}
    assert {"reckon.v1.ImuBatch", "reckon.v1.TruthPose", "reckon.v1.BeaconSighting"} <= names
    assert all(message.schema_version == messages.SCHEMA_VERSION for rows in topics.values() for _, _, message in rows)


def test_hub_recording_schemas_decode_in_a_fresh_pool(hub_recording: Path):
    topics = decode_all(hub_recording)
    names = {name for rows in topics.values() for _, name, _ in rows}
    assert {"reckon.v1.EstimatedPose", "reckon.v1.Correction", "reckon.v1.PositionFix"} <= names
    assert len(topics[keys.pose("court", "c1", "live")]) == 60 and topics[keys.pose("court", "c1", "refined")]
    kinds = [m.kind for _, _, m in topics[keys.correction("court", "c2")]]
    assert kinds == [messages.CorrectionKind.MANUAL]


def test_export_adds_foxglove_scene_beside_the_untouched_channels(game: Path, tmp_path: Path):
    out = tmp_path / "game-foxglove.mcap"
    summary = export_foxglove(game, out)
    source, exported = decode_all(game), decode_all(out)
    for topic, rows in source.items():  # every original message, same bytes, same times
        assert [(t, n, m.SerializeToString()) for t, n, m in rows] == \
               [(t, n, m.SerializeToString()) for t, n, m in exported[topic]], topic
    assert read_description(out) == read_description(game)
    added = {topic: rows for topic, rows in exported.items() if topic not in source}
    assert {name for rows in added.values() for _, name, _ in rows} == \
           {"foxglove.SceneUpdate", "foxglove.FrameTransform", "foxglove.PoseInFrame"} <= FOXGLOVE_SCHEMAS
    venue = read_description(game).venue
    (_, _, court), = added["/foxglove/court"]
    ids = {entity.id for entity in court.entities}
    assert ids == {"venue/lines"} | {f"beacon/{beacon.id}" for beacon in venue.beacons}
    lines = next(e for e in court.entities if e.id == "venue/lines").lines[0]
    xs = [point.x for point in lines.points]
    assert len(lines.points) % 2 == 0 and min(xs) == 0.0 and max(xs) == venue.court_length_m
    frames = {(m.parent_frame_id, m.child_frame_id) for _, _, m in added["/tf"]}
    agents = [agent.id for agent in read_description(game).agents]
    assert frames == {("world", "court")} | {("court", f"{agent}/truth") for agent in agents}
    for agent in agents:  # the arrows are the truth poses, at most every DECIMATE_NS
        truth = {m.timestamp_ns: m for _, _, m in source[keys.truth(venue.name, agent)]}
        arrows = [m for _, _, m in added[f"/foxglove/{agent}/truth"]]
        times = [m.timestamp.ToNanoseconds() for m in arrows]
        assert all(b - a >= DECIMATE_NS for a, b in itertools.pairwise(times))
        assert len(arrows) >= (max(truth) - min(truth)) // DECIMATE_NS
        for t, arrow in zip(times, arrows):
            assert (arrow.frame_id, arrow.pose.position.x, arrow.pose.position.y) == ("court", truth[t].x_m, truth[t].y_m)
    entity_ids = {e.id for _, _, m in added["/foxglove/agents"] for e in m.entities}
    assert entity_ids == {f"{agent}/truth" for agent in agents}
    assert summary.copied == sum(len(rows) for rows in source.values())


def test_export_of_a_hub_recording_from_the_command_line(hub_recording: Path, tmp_path: Path, capsys):
    out = tmp_path / "hub-foxglove.mcap"
    assert main(["-q", "export", "foxglove", str(hub_recording), "-o", str(out)]) == 0
    assert "scene updates" in capsys.readouterr().out
    exported = decode_all(out)
    frames = {m.child_frame_id for _, _, m in exported["/tf"]}
    assert {f"{agent}/{track}" for agent in CHAIRS for track in ("edge", "live", "refined")} <= frames
    assert exported["/foxglove/c3/live"][-1][2].pose.position.x == pytest.approx(chair_xy("c3", 59)[0], abs=0.15)


def test_export_refuses_a_file_that_is_not_a_session(tmp_path: Path, capsys):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file")
    assert main(["-q", "export", "foxglove", str(bad), "-o", str(tmp_path / "out.mcap")]) == 2
    assert str(bad) in capsys.readouterr().err
