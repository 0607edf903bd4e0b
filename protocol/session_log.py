"""Session logs: one MCAP file per session (protobuf channels + the session description).

Topics are the Zenoh keys of `protocol.keys`, so a recorded live session and a simulated one look
the same. The description (venue, agents) is the metadata record `reckon.session`.

Reading is a single streaming pass, so a truncated file (a logger that lost power) yields every
message before the damage plus a note in `SessionData.problems`, never a traceback.
"""

from __future__ import annotations

import json
import logging
import struct
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
from mcap.exceptions import McapError
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap_protobuf.writer import Writer

from protocol import messages
from protocol.errors import InputError
from protocol.log_index import IndexedLog, open_indexed
from protocol.session import Session, load_toml, session_from_dict, to_json

log = logging.getLogger(__name__)
METADATA_NAME = "reckon.session"
# A chunk is compressed (zstd) and indexed when it fills, on the writer's thread: at mcap's default
# 1 MiB that stalled the hub's recording for 3-4 ms every few seconds, in its live poses' latency
# (the bench's worst 1 % fell on the chunks' ends). 64 KiB stalls an eighth as long; logs grow 4-7 %.
# But each chunk ends with a message index record per channel in it, and a venue's channels grow with
# its agents (a hub's recording: about six an agent): at 500 agents a 64 KiB chunk held about one
# message per channel, and writing cost 9.1 us a message against 4.5 us in 1 MiB chunks (1,500
# channels, round-robin). So a chunk holds CHUNK_BYTES_PER_AGENT an agent (at least 64 KiB, the size up
# to 10 agents), up to 1 MiB, where a stall of a few ms is far inside what a venue that size needs of
# its latency. The writer also keeps every chunk's index (an offset per channel in it) for the file's
# summary until it closes: fewer, larger chunks hold that growth down too.
CHUNK_BYTES = 64 * 1024
CHUNK_BYTES_PER_AGENT = 6 * 1024
CHUNK_BYTES_MAX = 1024 * 1024


def chunk_bytes(agents: int) -> int:
    """The chunk size of a session log of `agents` agents (CHUNK_BYTES above)."""
    return min(CHUNK_BYTES_MAX, max(CHUNK_BYTES, CHUNK_BYTES_PER_AGENT * agents))


class SessionWriter:
    """Write a session MCAP: `with SessionWriter(path, session) as w: w.write(topic, msg, log_time_ns)`."""

    def __init__(self, path: Path | str, session: Session):
        self._file = open(path, "wb")
        self._writer = Writer(self._file, chunk_size=chunk_bytes(len(session.agents)))
        self._writer.add_metadata(METADATA_NAME, {"session_json": to_json(session)})

    def write(self, topic: str, message: Any, log_time_ns: int | None = None) -> None:
        stamp = int(message.timestamp_ns if log_time_ns is None else log_time_ns)
        self._writer.write_message(topic, message, log_time=stamp, publish_time=int(message.timestamp_ns))

    def flush(self) -> None:
        """End the chunk in progress and hand every message so far to the OS, so a reader sees them
        even if this process is killed before `close` (the hub's checkpoints, reckon/processes/checkpoint.py)."""
        self._writer._writer.flush()  # mcap_protobuf's Writer keeps the mcap Writer, whose flush() this is

    def close(self) -> None:
        if not self._file.closed:
            self._writer.finish()
            self._file.close()

    def __enter__(self) -> "SessionWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class ImuSeries:
    """All samples of one IMU in its own clock, sorted by time. Missing magnetometer = None."""

    agent_id: str
    sensor_id: str
    time_ns: np.ndarray  # int64 (N,)
    accel_g: np.ndarray  # float64 (N, 3)
    gyro_dps: np.ndarray  # float64 (N, 3)
    mag_gauss: np.ndarray | None  # float64 (N, 3)
    lost_batches: int = 0  # gaps in the batch sequence numbers


@dataclass
class TruthSeries:
    time_ns: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    heading_rad: np.ndarray
    floor: np.ndarray | None = None  # int64 per pose; None: every pose on floor 0 (a log without floors)


@dataclass
class Sightings:
    time_ns: np.ndarray
    beacon_id: np.ndarray  # str
    rssi_dbm: np.ndarray


@dataclass(frozen=True)
class Contact:
    time_ns: int
    agent_id: str
    other_agent_id: str
    kind: messages.ContactKind
    closing_speed_mps: float


@dataclass
class CameraTracks:
    """One camera's tracks, one row per (frame, track); labels from TruthTrackLabel when present."""

    camera_id: str
    frame_ns: np.ndarray  # int64 (F,): every frame, including frames that saw nobody
    time_ns: np.ndarray  # int64 (N,): the observation's frame time
    track_id: np.ndarray  # int64 (N,)
    x_m: np.ndarray  # float64 (N,)
    y_m: np.ndarray
    height_m: np.ndarray | None  # float64 (N,), None when the tracker gives no height
    position_sd_m: float
    person_id: np.ndarray | None  # str (N,): "" false track, "a+b" a merge; None without truth


@dataclass
class SessionData:
    session: Session
    imu: dict[str, ImuSeries]
    truth: dict[str, TruthSeries]
    sightings: dict[str, Sightings]
    contacts: list[Contact]
    problems: list[str] = field(default_factory=list)
    lengths: dict[str, list[Any]] = field(default_factory=dict)  # agent id -> TruthLength messages, in time order
    cameras: dict[str, CameraTracks] = field(default_factory=dict)
    scans: dict[str, list[Any]] = field(default_factory=dict)  # agent id -> StandScan messages, in time order

    @property
    def start_ns(self) -> int:
        starts = [int(s.time_ns[0]) for s in self.imu.values() if len(s.time_ns)]
        starts += [int(t.time_ns[0]) for t in self.truth.values() if len(t.time_ns)]
        return min(starts) if starts else 0

    @property
    def end_ns(self) -> int:
        ends = [int(s.time_ns[-1]) for s in self.imu.values() if len(s.time_ns)]
        ends += [int(t.time_ns[-1]) for t in self.truth.values() if len(t.time_ns)]
        return max(ends) if ends else 0


def iter_records(path: Path, problems: list[str]) -> Iterator[Any]:
    """MCAP records in file order; at the first damaged or missing byte, a note in `problems` and stop."""
    try:
        reader = StreamReader(str(path), skip_magic=False)
        for record in reader.records:
            yield record
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (McapError, ValueError, EOFError, OSError) as error:
        # StreamReader raises on the first damaged or missing byte; keep what came before.
        problems.append(f"{path}: log is damaged or truncated ({type(error).__name__}: {error}); "
                        "every message before the damage is kept")


def _parse_description(path: Path, record: Metadata) -> Session:
    try:
        return session_from_dict(json.loads(record.metadata["session_json"]), where=f"{path} metadata")
    except (KeyError, json.JSONDecodeError) as error:
        raise InputError(f"{path}: metadata {METADATA_NAME} is unreadable ({error})") from None


def description_from_records(path: Path, records: Iterator[Any], problems: list[str] | None = None) -> Session:
    """The session description from a record stream; it precedes every message (SessionWriter writes
    it first), so the stream is consumed only up to it. InputError if a message comes first."""
    for record in records:
        if isinstance(record, Metadata) and record.name == METADATA_NAME:
            return _parse_description(path, record)
        if isinstance(record, Message):
            break
    raise InputError(f"{path}: not a reckon session (no '{METADATA_NAME}' metadata before the first message"
                     + (f"; {problems[0]}" if problems else "") + ")")


def read_description(path: Path | str) -> Session:
    """Only the session description of a log. InputError if absent."""
    path = Path(path)
    problems: list[str] = []
    return description_from_records(path, iter_records(path, problems), problems)


def session_description(path: Path | str) -> Session:
    """A session description from a TOML file or from a session log's own record (`.mcap`)."""
    return read_description(path) if Path(path).suffix == ".mcap" else load_toml(path)


class LogMessages:
    """Iterate a session log's reckon messages as (log_time_ns, topic, message), in file order.

    `session` is the description once its record has been read (it precedes every message);
    `problems` notes damage (iteration stops there, keeping what came before); `skipped` counts
    messages per topic that are not ours or come from a newer schema.
    """

    def __init__(self, path: Path | str, wanted: Callable[[str, str], bool] | None = None):
        """`wanted(topic, type name)`: decode only the messages it accepts (the rest are not counted)."""
        self.path = Path(path)
        self.wanted = wanted
        self.problems: list[str] = []
        self.skipped: dict[str, int] = defaultdict(int)
        self.session: Session | None = None

    def __iter__(self) -> Iterator[tuple[int, str, Any]]:
        if self.wanted is not None:  # some channels only: through the log's index when it is complete
            opened = open_indexed(self.path) if self.path.exists() else None
            if opened is not None:
                with opened[0]:
                    yield from self._indexed(opened[1])
                return
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, Any]] = {}
        for record in iter_records(self.path, self.problems):
            if isinstance(record, Schema):
                schemas[record.id] = record.name
            elif isinstance(record, Channel):
                name = schemas.get(record.schema_id, "")
                short = name.removeprefix(messages.PACKAGE + ".")
                channels[record.id] = (record.topic, messages.CLASSES.get(short) if name.startswith(messages.PACKAGE) else None)
            elif isinstance(record, Metadata) and record.name == METADATA_NAME:
                self.session = _parse_description(self.path, record)
            elif isinstance(record, Message):
                topic, cls = channels.get(record.channel_id, ("?", None))
                if cls is None:
                    self.skipped[topic] += 1
                    continue
                if self.wanted is not None and not self.wanted(topic, cls.DESCRIPTOR.name):
                    continue
                msg = cls.FromString(record.data)
                if msg.schema_version > messages.SCHEMA_VERSION:
                    self.skipped[f"{topic} (schema_version {msg.schema_version} > {messages.SCHEMA_VERSION})"] += 1
                    continue
                yield record.log_time, topic, msg

    def _indexed(self, indexed: IndexedLog) -> Iterator[tuple[int, str, Any]]:
        description = indexed.metadata(METADATA_NAME)
        if description is not None:
            self.session = _parse_description(self.path, description)
        channels: dict[int, tuple[str, Any]] = {}
        for channel_id, channel in indexed.channels.items():
            schema = indexed.schemas.get(channel.schema_id)
            name = schema.name if schema is not None else ""
            cls = messages.CLASSES.get(name.removeprefix(messages.PACKAGE + ".")) if name.startswith(messages.PACKAGE) else None
            channels[channel_id] = (channel.topic, cls)
            if cls is None and indexed.message_counts.get(channel_id):
                self.skipped[channel.topic] += indexed.message_counts[channel_id]
        chosen = {channel_id for channel_id, (topic, cls) in channels.items()
                  if cls is not None and self.wanted(topic, cls.DESCRIPTOR.name)}
        try:
            for log_time, channel_id, payload in indexed.messages(chosen.__contains__):
                topic, cls = channels[channel_id]
                msg = cls.FromString(payload)
                if msg.schema_version > messages.SCHEMA_VERSION:
                    self.skipped[f"{topic} (schema_version {msg.schema_version} > {messages.SCHEMA_VERSION})"] += 1
                    continue
                yield log_time, topic, msg
        except (McapError, ValueError, EOFError, OSError, struct.error) as error:
            self.problems.append(f"{self.path}: log is damaged ({type(error).__name__}: {error}); "
                                 "every message before the damage is kept")


def read_session(path: Path | str) -> SessionData:
    """Load a whole session log into numpy arrays. InputError if it is not a reckon session."""
    path = Path(path)
    log_messages = LogMessages(path)
    problems = log_messages.problems
    batches: dict[str, list[Any]] = defaultdict(list)
    truth_rows: dict[str, list[tuple[int, float, float, float]]] = defaultdict(list)
    sighting_rows: dict[str, list[tuple[int, str, float]]] = defaultdict(list)
    contacts: list[Contact] = []
    lengths: dict[str, list[Any]] = defaultdict(list)
    frames: dict[str, list[Any]] = defaultdict(list)
    labels: dict[str, dict[int, Any]] = defaultdict(dict)
    scans: dict[str, list[Any]] = defaultdict(list)
    for _, _, msg in log_messages:
        kind = msg.DESCRIPTOR.name
        if kind == "ImuBatch":
            batches[msg.sensor_id].append(msg)
        elif kind == "TruthPose":
            truth_rows[msg.agent_id].append((msg.timestamp_ns, msg.x_m, msg.y_m, msg.heading_rad, msg.floor))
        elif kind == "BeaconSighting":
            sighting_rows[msg.agent_id].append((msg.timestamp_ns, msg.beacon_id, msg.rssi_dbm))
        elif kind == "TruthContact":
            contacts.append(Contact(msg.timestamp_ns, msg.agent_id, msg.other_agent_id,
                                    messages.ContactKind(msg.kind), msg.closing_speed_mps))
        elif kind == "TruthLength":
            lengths[msg.agent_id].append(msg)
        elif kind == "CameraFrame":
            frames[msg.camera_id].append(msg)
        elif kind == "TruthTrackLabel":
            labels[msg.camera_id][msg.frame] = msg
        elif kind == "StandScan":
            scans[msg.agent_id].append(msg)
    session, skipped = log_messages.session, log_messages.skipped
    if session is None:
        raise InputError(f"{path}: not a reckon session (no '{METADATA_NAME}' metadata record"
                         + (f"; {problems[0]}" if problems else "") + ")")
    for topic, count in skipped.items():
        problems.append(f"{path}: skipped {count} messages on {topic} (not a reckon schema)")
    owners = session.sensor_owner()
    imu = {sensor_id: _imu_series(owners[sensor_id].id if sensor_id in owners else rows[0].agent_id, sensor_id, rows)
           for sensor_id, rows in batches.items()}
    truth = {}
    for agent_id, rows in truth_rows.items():
        rows.sort()
        arr = np.array(rows, dtype=np.float64)
        floors = np.array([r[4] for r in rows], dtype=np.int64)
        truth[agent_id] = TruthSeries(np.array([r[0] for r in rows], dtype=np.int64), arr[:, 1], arr[:, 2], arr[:, 3],
                                      floors if floors.any() else None)
    sightings = {}
    for agent_id, rows in sighting_rows.items():
        rows.sort(key=lambda r: r[0])
        sightings[agent_id] = Sightings(np.array([r[0] for r in rows], dtype=np.int64),
                                        np.array([r[1] for r in rows]), np.array([r[2] for r in rows]))
    contacts.sort(key=lambda c: c.time_ns)
    for problem in problems:
        log.warning("%s", problem)
    for rows in (*lengths.values(), *scans.values()):
        rows.sort(key=lambda m: m.timestamp_ns)
    cameras = {camera_id: _camera_tracks(camera_id, rows, labels.get(camera_id)) for camera_id, rows in frames.items()}
    return SessionData(session, imu, truth, sightings, contacts, problems, dict(lengths), cameras, dict(scans))


def _camera_tracks(camera_id: str, rows: list[Any], labels: dict[int, Any] | None) -> CameraTracks:
    rows.sort(key=lambda m: (m.timestamp_ns, m.frame))
    counts = [len(m.track_id) for m in rows]
    with_height = all(len(m.height_m) == len(m.track_id) for m in rows) and any(counts)
    person = None
    if labels:
        person = []
        for m in rows:
            label = labels.get(m.frame)
            names = dict(zip(label.track_id, label.person_id)) if label is not None else {}
            person += [names.get(t, "") for t in m.track_id]
        person = np.array(person, dtype=object)
    return CameraTracks(
        camera_id, np.array([m.timestamp_ns for m in rows], dtype=np.int64),
        np.repeat(np.array([m.timestamp_ns for m in rows], dtype=np.int64), counts),
        np.concatenate([np.asarray(m.track_id, dtype=np.int64) for m in rows]) if rows else np.zeros(0, np.int64),
        np.concatenate([np.asarray(m.x_m, dtype=np.float64) for m in rows]) if rows else np.zeros(0),
        np.concatenate([np.asarray(m.y_m, dtype=np.float64) for m in rows]) if rows else np.zeros(0),
        np.concatenate([np.asarray(m.height_m, dtype=np.float64) for m in rows]) if with_height else None,
        float(rows[0].position_sd_m) if rows else 0.0, person)


def _imu_series(agent_id: str, sensor_id: str, rows: list[Any]) -> ImuSeries:
    rows.sort(key=lambda m: (m.timestamp_ns, m.sequence))
    sequences = np.array([m.sequence for m in rows], dtype=np.int64)
    lost = int(np.sum(np.clip(np.diff(sequences) - 1, 0, None))) if len(rows) > 1 else 0
    times = np.concatenate([m.timestamp_ns + np.asarray(m.sample_offset_ns, dtype=np.int64) for m in rows])
    accel = np.concatenate([np.asarray(m.accel_g, dtype=np.float64) for m in rows]).reshape(-1, 3)
    gyro = np.concatenate([np.asarray(m.gyro_dps, dtype=np.float64) for m in rows]).reshape(-1, 3)
    has_mag = all(len(m.mag_gauss) for m in rows)
    mag = np.concatenate([np.asarray(m.mag_gauss, dtype=np.float64) for m in rows]).reshape(-1, 3) if has_mag else None
    order = np.argsort(times, kind="stable")
    keep = order[np.concatenate([[True], np.diff(times[order]) > 0])]  # drop repeated samples
    return ImuSeries(agent_id, sensor_id, times[keep], accel[keep], gyro[keep],
                     None if mag is None else mag[keep], lost)
