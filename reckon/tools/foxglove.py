"""`reckon export foxglove IN.mcap -o OUT.mcap`: a session log with Foxglove's 3D scene beside it.

Every original channel, schema, message and the `reckon.session` metadata are copied as they are
(Foxglove's Raw Messages and Plot panels read our protobuf channels from the FileDescriptorSet in
their schema records). Added, with the schemas of the `foxglove-sdk` package (its typed channels
write protobuf under Foxglove's well-known names):

- `/foxglove/court` (foxglove.SceneUpdate, once): the court lines or the floor plan, beacons with
  their reception zone, QR stands, map points; frame `court`.
- `/foxglove/agents` (foxglove.SceneUpdate): one entity per agent and track (live, refined, edge,
  truth) at its latest pose, a disc and a label, at most every DECIMATE_NS of pose time per track.
- `/tf` (foxglove.FrameTransform): `world` -> `court` (identity) once, and `court` ->
  `<agent>/<track>` per pose, at the same rate, so a panel can follow an agent.
- `/foxglove/<agent>/<track>` (foxglove.PoseInFrame): the pose as an arrow in `court`, same rate.

Log times are the source messages' log times; the copies' publish times become their log times
(the SDK's writer takes one time per message).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import foxglove
from foxglove.channels import FrameTransformChannel, PoseInFrameChannel, SceneUpdateChannel
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    FrameTransform,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    PoseInFrame,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    Vector3,
)
from mcap.exceptions import McapError
from mcap.reader import make_reader

from protocol import keys, messages
from protocol.errors import InputError
from protocol.session import Session
from protocol.session_log import read_description

DECIMATE_NS = 100_000_000  # 10 Hz per agent and track: smooth in the 3D panel, a tenth of the 50 Hz poses
AGENT_RADIUS_M = 0.4
TRACK_COLORS = {"live": (0.9, 0.2, 0.2, 1.0), "refined": (0.2, 0.4, 0.9, 1.0), "edge": (0.6, 0.6, 0.6, 0.8),
                "truth": (0.1, 0.7, 0.2, 0.6)}
LINE_COLOR = Color(r=1.0, g=1.0, b=1.0, a=1.0)


@dataclass
class ExportSummary:
    input: str
    output: str
    copied: int = 0
    channels: int = 0
    poses: int = 0  # pose messages seen (EstimatedPose, TruthPose)
    scene_updates: int = 0
    tracks: set[str] = field(default_factory=set)  # "<agent>/<track>"

    def __str__(self) -> str:
        return (f"{self.output}: {self.copied} messages on {self.channels} channels copied from {self.input}; "
                f"added {self.scene_updates} scene updates for {len(self.tracks)} agent tracks "
                f"({self.poses} poses at most every {DECIMATE_NS / 1e9:g} s) and the venue")


def _stamp(time_ns: int) -> Timestamp:
    return Timestamp(sec=time_ns // 1_000_000_000, nsec=time_ns % 1_000_000_000)


def _yaw(heading_rad: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(heading_rad / 2.0), w=math.cos(heading_rad / 2.0))


def _at(x: float, y: float, z: float = 0.0, heading_rad: float = 0.0) -> Pose:
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=_yaw(heading_rad))


def _segments(points: list[tuple[float, float]], closed: bool = True) -> list[Point3]:
    """LINE_LIST points (pairs) along a polyline."""
    ends = points + points[:1] if closed else points
    pairs: list[Point3] = []
    for (x0, y0), (x1, y1) in itertools.pairwise(ends):
        pairs += [Point3(x=x0, y=y0, z=0.0), Point3(x=x1, y=y1, z=0.0)]
    return pairs


def _arc(cx: float, cy: float, radius: float, start: float, end: float, steps: int = 32) -> list[tuple[float, float]]:
    angles = (start + (end - start) * i / steps for i in range(steps + 1))
    return [(cx + radius * math.cos(angle), cy + radius * math.sin(angle)) for angle in angles]


def court_lines(length_m: float, width_m: float) -> list[Point3]:
    """A basketball court's lines (FIBA/IWBF): outline, halfway line, centre circle, keys, 3-point lines."""
    points = _segments([(0, 0), (length_m, 0), (length_m, width_m), (0, width_m)])
    points += _segments([(length_m / 2, 0), (length_m / 2, width_m)], closed=False)
    points += _segments(_arc(length_m / 2, width_m / 2, 1.8, 0, 2 * math.pi), closed=False)
    middle = width_m / 2
    for base, direction in ((0.0, 1.0), (length_m, -1.0)):
        basket = base + direction * 1.575
        key_end = base + direction * 5.8
        points += _segments([(base, middle - 2.45), (key_end, middle - 2.45), (key_end, middle + 2.45),
                             (base, middle + 2.45)])
        side = middle - 0.9  # the 3-point line runs 0.9 m in from the sidelines, then arcs at 6.75 m
        reach = math.sqrt(max(0.0, 6.75**2 - side**2))
        angle = math.atan2(side, reach)
        if direction > 0:
            arc = _arc(basket, middle, 6.75, -angle, angle)
        else:
            arc = _arc(basket, middle, 6.75, math.pi + angle, math.pi - angle)
        points += _segments([(base, middle - side)] + arc + [(base, middle + side)], closed=False)
    return points


def venue_entities(session: Session, time_ns: int) -> list[SceneEntity]:
    venue = session.venue
    stamp = _stamp(time_ns)
    if venue.floor_plan:
        lines = [point for polygon in venue.floor_plan for ring in polygon
                 for point in _segments([(float(x), float(y)) for x, y in ring])]
    else:
        lines = court_lines(venue.court_length_m, venue.court_width_m)
    entities = [SceneEntity(timestamp=stamp, frame_id="court", id="venue/lines", lines=[LinePrimitive(
        type=LinePrimitiveLineType.LineList, pose=_at(0, 0), thickness=0.08, points=lines, color=LINE_COLOR)])]
    for beacon in venue.beacons:
        entities.append(SceneEntity(
            timestamp=stamp, frame_id="court", id=f"beacon/{beacon.id}",
            spheres=[SpherePrimitive(pose=_at(beacon.x_m, beacon.y_m, beacon.height_m), size=Vector3(x=0.3, y=0.3, z=0.3),
                                     color=Color(r=0.1, g=0.4, b=0.8, a=1.0))],
            cylinders=[CylinderPrimitive(pose=_at(beacon.x_m, beacon.y_m, 0.01),
                                         size=Vector3(x=2 * beacon.radius_m, y=2 * beacon.radius_m, z=0.02),
                                         bottom_scale=1.0, top_scale=1.0, color=Color(r=0.1, g=0.4, b=0.8, a=0.25))],
            texts=[TextPrimitive(pose=_at(beacon.x_m, beacon.y_m, beacon.height_m + 0.4), billboard=True, font_size=14,
                                 scale_invariant=True, color=LINE_COLOR, text=beacon.id)]))
    for stand in venue.stands:
        entities.append(SceneEntity(
            timestamp=stamp, frame_id="court", id=f"stand/{stand.id}",
            cubes=[CubePrimitive(pose=_at(stand.x_m, stand.y_m, 0.6, math.radians(stand.heading_deg)),
                                 size=Vector3(x=0.3, y=0.3, z=1.2), color=Color(r=0.4, g=0.1, b=0.6, a=1.0))],
            texts=[TextPrimitive(pose=_at(stand.x_m, stand.y_m, 1.5), billboard=True, font_size=14, scale_invariant=True,
                                 color=LINE_COLOR, text=f"QR {stand.id}")]))
    for point in venue.map_points:
        entities.append(SceneEntity(
            timestamp=stamp, frame_id="court", id=f"map/{point.id}",
            spheres=[SpherePrimitive(pose=_at(point.x_m, point.y_m), size=Vector3(x=0.2, y=0.2, z=0.2),
                                     color=Color(r=0.3, g=0.3, b=0.3, a=1.0))]))
    return entities


def agent_entity(agent_id: str, track: str, time_ns: int, x: float, y: float, heading_rad: float) -> SceneEntity:
    r, g, b, a = TRACK_COLORS.get(track, (0.5, 0.5, 0.5, 1.0))
    pose = _at(x, y, 0.25, heading_rad)
    return SceneEntity(
        timestamp=_stamp(time_ns), frame_id="court", id=f"{agent_id}/{track}",
        cylinders=[CylinderPrimitive(pose=pose, size=Vector3(x=2 * AGENT_RADIUS_M, y=2 * AGENT_RADIUS_M, z=0.5),
                                     bottom_scale=1.0, top_scale=1.0, color=Color(r=r, g=g, b=b, a=a))],
        texts=[TextPrimitive(pose=_at(x, y, 0.9), billboard=True, font_size=14, scale_invariant=True,
                             color=LINE_COLOR, text=agent_id if track == "live" else f"{agent_id} {track}")])


def _track(topic: str, message: Any) -> str | None:
    """The track a pose message belongs to: live, refined, edge, truth; None when not a pose."""
    name = messages.type_name(message)
    if name == "TruthPose":
        return "truth"
    if name != "EstimatedPose":
        return None
    try:
        _, _, stream, sub = keys.parse(topic)
    except ValueError:
        return None
    return sub if stream == "pose" and sub else None


def export_foxglove(source: Path, output: Path, progress: Callable[[str], None] | None = None) -> ExportSummary:
    """Copy `source` into `output` with the Foxglove scene channels; InputError for an unreadable log."""
    session = read_description(source)
    summary = ExportSummary(str(source), str(output))
    context = foxglove.Context()  # not the SDK's global one: two exports never share channels
    writer = foxglove.open_mcap(output, allow_overwrite=True, context=context)
    try:
        with open(source, "rb") as stream:
            reader = make_reader(stream)
            for record in reader.iter_metadata():
                writer.write_metadata(record.name, dict(record.metadata))
            stream.seek(0)
            _copy_and_add(make_reader(stream), session, context, summary, progress)
    except (McapError, ValueError, EOFError) as error:
        raise InputError(f"{source}: cannot read the log ({type(error).__name__}: {error})") from None
    finally:
        writer.close()
    return summary


def _copy_and_add(reader: Any, session: Session, context: foxglove.Context, summary: ExportSummary,
                  progress: Callable[[str], None] | None) -> None:
    copies: dict[int, foxglove.Channel] = {}
    scene = SceneUpdateChannel("/foxglove/court", context=context)
    agents = SceneUpdateChannel("/foxglove/agents", context=context)
    transforms = FrameTransformChannel("/tf", context=context)
    arrows: dict[str, PoseInFrameChannel] = {}
    last_ns: dict[str, int] = {}
    started = False
    for schema, channel, record in reader.iter_messages(log_time_order=False):
        if not started:  # the venue and the world frame at the first message's time
            started = True
            scene.log(SceneUpdate(entities=venue_entities(session, record.log_time)), log_time=record.log_time)
            transforms.log(FrameTransform(timestamp=_stamp(record.log_time), parent_frame_id="world", child_frame_id="court",
                                          translation=Vector3(x=0, y=0, z=0), rotation=_yaw(0.0)), log_time=record.log_time)
        copy = copies.get(channel.id)
        if copy is None:
            raw = None if schema is None else foxglove.Schema(name=schema.name, encoding=schema.encoding, data=schema.data)
            copy = copies[channel.id] = foxglove.Channel(channel.topic, schema=raw, message_encoding=channel.message_encoding,
                                                         context=context, metadata=dict(channel.metadata))
        copy.log(record.data, log_time=record.log_time)
        summary.copied += 1
        if progress is not None and summary.copied % 10000 == 0:
            progress(f"export: {summary.copied} messages")
        short = schema.name.removeprefix(messages.PACKAGE + ".") if schema is not None else ""
        if short not in ("EstimatedPose", "TruthPose") or channel.message_encoding != "protobuf":
            continue
        message = messages.CLASSES[short].FromString(record.data)
        track = _track(channel.topic, message)
        if track is None:
            continue
        summary.poses += 1
        name = f"{message.agent_id}/{track}"
        # The pose's own time decides, not the log time: a hub fed from a fast replay logs seconds in a blink.
        if name in last_ns and 0 <= message.timestamp_ns - last_ns[name] < DECIMATE_NS:
            continue
        last_ns[name] = message.timestamp_ns
        summary.tracks.add(name)
        x, y, heading = message.x_m, message.y_m, message.heading_rad
        agents.log(SceneUpdate(entities=[agent_entity(message.agent_id, track, message.timestamp_ns, x, y, heading)]),
                   log_time=record.log_time)
        summary.scene_updates += 1
        transforms.log(FrameTransform(timestamp=_stamp(message.timestamp_ns), parent_frame_id="court", child_frame_id=name,
                                      translation=Vector3(x=x, y=y, z=0.0), rotation=_yaw(heading)), log_time=record.log_time)
        arrow = arrows.get(name)
        if arrow is None:
            arrow = arrows[name] = PoseInFrameChannel(f"/foxglove/{name}", context=context)
        arrow.log(PoseInFrame(timestamp=_stamp(message.timestamp_ns), frame_id="court", pose=_at(x, y, 0.0, heading)),
                  log_time=record.log_time)
    summary.channels = len(copies)
