"""Message schemas as data tables, compiled at import into protobuf classes.

Why protobuf (recorded in docs/protocol.md): Foxglove and the `mcap` CLI both decode protobuf
from the FileDescriptorSet stored in the MCAP schema record, so a session opens in either tool
with no plugin. At the chair load (200 Hz x 3 sensors x 10 chairs, 20-sample batches = 300
batches/s) a batch is about 0.8 KB (JSON: 4.2 KB) and costs about 15 us to encode and decode on
this 2-core x86 machine (field-notes.md), so the whole venue needs well under 1 % of one Pi core.

The layouts live here as tables rather than a `.proto` plus generated code: one file to read, no
protoc step, and the same descriptor goes into every MCAP file. Every message carries
`schema_version` and an integer nanosecond `timestamp_ns`; fields name their unit.
"""

from __future__ import annotations

import enum
from typing import Any

import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

SCHEMA_VERSION = 1
# The wire's units (g, gauss) against the SI ones phones and recorders report (m/s^2, uT).
STANDARD_GRAVITY_MS2 = 9.80665
UT_PER_GAUSS = 100.0
PACKAGE = "reckon.v1"

_F = descriptor_pb2.FieldDescriptorProto
_SCALARS = {
    "double": _F.TYPE_DOUBLE,
    "float": _F.TYPE_FLOAT,
    "int64": _F.TYPE_INT64,
    "uint32": _F.TYPE_UINT32,
    "string": _F.TYPE_STRING,
    "bool": _F.TYPE_BOOL,
}


class CorrectionKind(enum.IntEnum):
    """Why a pose was moved."""

    UNKNOWN = 0
    BEACON = 1
    COLLISION = 2
    VIDEO = 3
    MANUAL = 4


class Track(enum.IntEnum):
    """Which estimate a pose belongs to: published at once, or refined after a lag."""

    UNKNOWN = 0
    LIVE = 1
    REFINED = 2


class ContactKind(enum.IntEnum):
    """How two chairs met (simulator truth)."""

    UNKNOWN = 0
    FRONTAL = 1
    LATERAL = 2


ENUMS: dict[str, type[enum.IntEnum]] = {
    "CorrectionKind": CorrectionKind,
    "Track": Track,
    "ContactKind": ContactKind,
}

# name -> [(field, type, repeated)]; field numbers follow the order, never reorder a row. A type is a
# scalar, an enum of ENUMS or another message of this table. Repeated xyz fields are row-major N x 3
# (x0, y0, z0, x1, ...).
TABLES: dict[str, list[tuple[str, str, bool]]] = {
    # One batch of raw samples from one IMU, in the device's own clock. timestamp_ns is the
    # first sample; sample i is at timestamp_ns + sample_offset_ns[i] (keeps times to ~3 bytes).
    "ImuBatch": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("sensor_id", "string", False),
        ("sequence", "uint32", False),  # batch counter per sensor: gaps reveal lost packets
        ("sample_offset_ns", "uint32", True),
        ("accel_g", "float", True),
        ("gyro_dps", "float", True),
        ("mag_gauss", "float", True),  # empty when the device has no magnetometer
        ("received_ns", "int64", False),  # receiver's (venue host) clock at arrival; 0 = unknown
    ],
    # Edge -> hub: one pair of a sensor's clocks per second, the batch whose (received_ns - timestamp_ns)
    # was the smallest in that second: timestamp_ns the device time of its last sample, received_ns the
    # edge host's clock at its arrival. The hub's clock offsets (hub/clocks.py) keep the lower envelope
    # of that difference, so this one pair a second gives them what every batch would.
    "ClockSample": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("sensor_id", "string", False),
        ("received_ns", "int64", False),
    ],
    "BeaconSighting": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("sensor_id", "string", False),
        ("beacon_id", "string", False),
        ("rssi_dbm", "float", False),
    ],
    "TruthPose": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("x_m", "double", False),
        ("y_m", "double", False),
        ("heading_rad", "double", False),
        ("floor", "int64", False),  # a building's floor (0 where the venue has one); the IPIN score counts it
    ],
    "EstimatedPose": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("x_m", "double", False),
        ("y_m", "double", False),
        ("heading_rad", "double", False),
        ("covariance", "double", True),  # 3 x 3 row-major over (x m, y m, heading rad)
        ("method", "string", False),
        ("track", "Track", False),
        ("correction_sequence", "uint32", False),  # the last Correction of this agent taken into account
        # A pedestrian's pose/live and pose/refined: the floor plan contradicted the dead-reckoned
        # track, and this pose is the edge's own track shifted by the last agreed offset (hub/pedestrian/guard.py).
        ("map_fallback", "bool", False),
        ("floor", "int64", False),  # a pedestrian's floor: the last stand's, plus the changes the barometer saw
    ],
    # Hub -> consumers of every agent (the demo's court table, the load bench's watcher): one track's poses of every
    # agent, as the hub made them in one pass over its inputs, each as it went out on its agent's key.
    # One message for the lot: at 500 chairs a put per pose was a fifth of the hub's CPU.
    "PoseBatch": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),  # the hub's clock when it sent the batch
        ("poses", "EstimatedPose", True),
    ],
    "ImpactEvent": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("sensor_id", "string", False),
        ("peak_g", "float", False),  # peak of | |a| - 1 g |
        # the impact's horizontal specific force (g, chair frame: x forward, y left) at its first sample
        # above the threshold, gravity removed: a contact pushes the chair away from the other one.
        # Both 0: not known (a device that does not say).
        ("forward_g", "float", False),
        ("left_g", "float", False),
    ],
    # Hub -> edge: a measurement of where the agent was at timestamp_ns (venue clock), as an offset
    # (dx, dy) from the pose the hub had for that time, with the measurement's covariance. The
    # edge applies it to its current state as a Kalman update (heading and biases learn from it
    # through their correlation with position); the hub has already gated it.
    "Correction": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("kind", "CorrectionKind", False),
        ("dx_m", "double", False),
        ("dy_m", "double", False),
        ("other_agent_id", "string", False),  # the other chair of a collision
        ("source_id", "string", False),  # beacon id, camera id, operator
        ("sequence", "uint32", False),  # per agent, from 1: poses say which they include
        ("covariance", "double", True),  # 2 x 2 row-major (m^2) of the measurement (dx, dy)
    ],
    # Edge -> hub: the seat magnetometer's field direction where the chair was, for the hub's map of
    # the hall's field (hub/chair/field_map.py). timestamp_ns is the device clock; offset_rad is the
    # field's angle in the chair less the edge's (north - heading), with that difference's variance.
    "FieldReading": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("x_m", "double", False),
        ("y_m", "double", False),
        ("offset_rad", "double", False),
        ("variance_rad2", "double", False),
    ],
    # Hub -> edge: the hall's field as every chair saw it, a grid of `columns` x `rows` square cells
    # from (origin_x_m, origin_y_m), row-major from the origin's row. Per cell the field direction's
    # offset (rad, as FieldReading's) and what is left of the disturbance after it (rad^2);
    # variance 0: nothing known there. timestamp_ns is the venue clock.
    "FieldMap": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("origin_x_m", "double", False),
        ("origin_y_m", "double", False),
        ("cell_m", "double", False),
        ("columns", "uint32", False),
        ("rows", "uint32", False),
        ("offset_rad", "double", True),
        ("variance_rad2", "double", True),
    ],
    # An absolute position from outside the sensors (an operator, a video frame): the agent was
    # at (x, y) at timestamp_ns (venue clock). The hub turns it into a Correction.
    "PositionFix": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("kind", "CorrectionKind", False),
        ("x_m", "double", False),
        ("y_m", "double", False),
        ("covariance", "double", True),  # 2 x 2 row-major (m^2)
        ("source_id", "string", False),
    ],
    # A swimmer's length, published by the edge when the length ends (device clock). timestamp_ns
    # is the wall touch that ended it, start_ns the push-off that began it. Distances are of the
    # swimmer's track, wall to wall: swum (along the path) and lane-parallel (the pool length when
    # the estimate is scaled to it). lateral_deviation_m is the track's offset to the left of the
    # straight line between the length's ends, every profile_step_m along the lane from the start
    # wall (snaking).
    "SwimLength": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("sensor_id", "string", False),
        ("method", "string", False),
        ("index", "uint32", False),  # lengths of this sensor's stream, from 1
        ("start_ns", "int64", False),
        ("swum_distance_m", "double", False),
        ("lane_distance_m", "double", False),
        ("duration_s", "double", False),
        ("stroke_count", "uint32", False),
        ("stroke_rate_per_min", "double", False),
        ("scale", "double", False),  # k: lane length over the integrated lane-parallel distance
        ("heading_error_deg", "double", False),  # integrated heading at the wall minus the route's
        ("lateral_deviation_m", "double", True),
        ("profile_step_m", "double", False),
        ("walls_detected", "bool", False),  # true: from the sensor; false: wall times were given
    ],
    # Simulator truth for one length of a swimmer (true time): push-off to wall touch.
    "TruthLength": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),  # the wall touch
        ("agent_id", "string", False),
        ("index", "uint32", False),
        ("start_ns", "int64", False),  # the push-off start (the feet begin to extend)
        ("swum_distance_m", "double", False),
        ("lane_distance_m", "double", False),
        ("stroke_count", "uint32", False),
        ("stroke", "string", False),  # crawl, breaststroke, backstroke, butterfly, kick
        ("route", "string", False),  # straight, diagonal
    ],
    # One frame of an external camera tracker: every track it reports at that instant, anonymous.
    # timestamp_ns is the frame's time on the tracker's clock, which should be the venue clock
    # (NTP); the hub estimates what offset remains. track_id is the tracker's own id (from 1; 0 is
    # never a track), positions are on the court or floor, height_m is empty when the tracker
    # gives none. position_sd_m is the tracker's stated 1-sigma error per axis.
    "CameraFrame": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("camera_id", "string", False),
        ("frame", "uint32", False),  # per camera, from 1: gaps are lost frames
        ("track_id", "uint32", True),
        ("x_m", "double", True),
        ("y_m", "double", True),
        ("height_m", "float", True),
        ("position_sd_m", "float", False),
    ],
    # Simulator truth for one CameraFrame: who each track really is. person_id[i] belongs to
    # track_id[i]: an agent id, an extra person's id (no sensor), "" for a false track, or ids
    # joined by "+" when the tracker merged several people into one track.
    "TruthTrackLabel": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("camera_id", "string", False),
        ("frame", "uint32", False),
        ("track_id", "uint32", True),
        ("person_id", "string", True),
    ],
    # Hub: which camera track an agent is now (track_id 0: none, the agent is bridged by its own
    # dead reckoning). Published when the identity changes and with every camera fix.
    "TrackIdentity": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("camera_id", "string", False),
        ("track_id", "uint32", False),
        ("method", "string", False),
        ("score", "float", False),  # the assignment's evidence margin over the next best (>= 0)
    ],
    # A phone scanned a QR calibration stand (device clock). The edge checks the code's integrity
    # against the venue's key before it trusts it; `accepted` false keeps a refused scan in the
    # record with the reason (forged, another venue's, unknown stand). The pose is the stand's.
    "StandScan": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("sensor_id", "string", False),
        ("stand_id", "string", False),
        ("x_m", "double", False),
        ("y_m", "double", False),
        ("floor", "int64", False),
        ("heading_rad", "double", False),  # the stand's facing, counter-clockwise from +x
        ("tilt_rad", "double", False),
        ("payload", "string", False),  # the code's text as scanned
        ("accepted", "bool", False),
        ("reason", "string", False),  # why it was refused; empty when accepted
        # 1-sigma of heading_rad; 0: a real stand's (about 3 deg, the paper's calibration). An
        # approximate stand (a surveyed waypoint standing in for one) says how approximate.
        ("heading_sd_rad", "double", False),
    ],
    # Edge -> hub, about once a second per sensor and at once on a change of health: how the
    # device is doing (the live court view's status column, `reckon doctor`). timestamp_ns is the
    # edge host's clock (venue clock). Counters are totals since the edge started; `flags` names
    # what is wrong now, each one of: disconnected, stale, stuck, saturated, clock_jump,
    # out_of_order, duplicate, gap, spooling.
    "DeviceStatus": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("sensor_id", "string", False),
        ("connected", "bool", False),
        ("battery_pct", "float", False),  # -1: unknown
        ("last_sample_age_s", "float", False),  # since the last sample arrived; -1: none yet
        ("samples", "int64", False),
        ("gaps", "uint32", False),  # batches missing by sequence
        ("duplicates", "uint32", False),
        ("out_of_order", "uint32", False),
        ("clock_jumps", "uint32", False),
        ("saturated", "uint32", False),  # samples at a full-scale limit
        ("reconnects", "uint32", False),
        ("spooled", "uint32", False),  # messages waiting in the edge's disk spool for the bus
        ("flags", "string", True),
        ("malformed", "uint32", False),  # batches dropped whole: values not 3 per sample
    ],
    "TruthContact": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("other_agent_id", "string", False),
        ("kind", "ContactKind", False),
        ("closing_speed_mps", "float", False),
    ],
    # One barometer reading (device clock), e.g. a phone's: a floor is about 3 m, 0.36 hPa. Double,
    # not float: recorders write 0.01 Pa (4 decimals of hPa), which a float32 near 1013 hPa rounds.
    "Pressure": [
        ("schema_version", "uint32", False),
        ("timestamp_ns", "int64", False),
        ("agent_id", "string", False),
        ("sensor_id", "string", False),
        ("pressure_hpa", "double", False),
    ],
}


def _build_file() -> descriptor_pb2.FileDescriptorProto:
    file = descriptor_pb2.FileDescriptorProto(name="reckon/v1.proto", package=PACKAGE, syntax="proto3")
    for enum_name, enum_type in ENUMS.items():
        e = file.enum_type.add(name=enum_name)
        for member in enum_type:
            e.value.add(name=f"{enum_name.upper()}_{member.name}", number=int(member))
    for message_name, rows in TABLES.items():
        m = file.message_type.add(name=message_name)
        for number, (field, type_name, repeated) in enumerate(rows, start=1):
            f = m.field.add(name=field, number=number)
            f.label = _F.LABEL_REPEATED if repeated else _F.LABEL_OPTIONAL
            if type_name in ENUMS:
                f.type = _F.TYPE_ENUM
                f.type_name = f".{PACKAGE}.{type_name}"
            elif type_name in TABLES:
                f.type = _F.TYPE_MESSAGE
                f.type_name = f".{PACKAGE}.{type_name}"
            else:
                f.type = _SCALARS[type_name]
    return file


_POOL = descriptor_pool.DescriptorPool()
_FILE = _POOL.Add(_build_file())
CLASSES: dict[str, Any] = {
    name: message_factory.GetMessageClass(_POOL.FindMessageTypeByName(f"{PACKAGE}.{name}")) for name in TABLES
}
ImuBatch = CLASSES["ImuBatch"]
BeaconSighting = CLASSES["BeaconSighting"]
ClockSample = CLASSES["ClockSample"]
TruthPose = CLASSES["TruthPose"]
EstimatedPose = CLASSES["EstimatedPose"]
PoseBatch = CLASSES["PoseBatch"]
ImpactEvent = CLASSES["ImpactEvent"]
Correction = CLASSES["Correction"]
TruthContact = CLASSES["TruthContact"]
PositionFix = CLASSES["PositionFix"]
SwimLength = CLASSES["SwimLength"]
TruthLength = CLASSES["TruthLength"]
CameraFrame = CLASSES["CameraFrame"]
TruthTrackLabel = CLASSES["TruthTrackLabel"]
TrackIdentity = CLASSES["TrackIdentity"]
StandScan = CLASSES["StandScan"]
DeviceStatus = CLASSES["DeviceStatus"]
Pressure = CLASSES["Pressure"]


def new(name: str, **fields: Any) -> Any:
    """Build message `name` with the current schema version filled in."""
    return CLASSES[name](schema_version=SCHEMA_VERSION, **fields)


def type_name(message: Any) -> str:
    """Short message name (`ImuBatch`) of a message instance."""
    return str(message.DESCRIPTOR.name)


def imu_batch(agent_id: str, sensor_id: str, sequence: int, time_ns: np.ndarray, accel_g: np.ndarray,
              gyro_dps: np.ndarray, mag_gauss: np.ndarray | None) -> Any:
    """Build one ImuBatch from arrays (times int64 ns, xyz arrays N x 3)."""
    offsets = time_ns - time_ns[0]
    if len(offsets) and int(offsets[-1]) > 0xFFFFFFFF:
        raise ValueError(f"batch spans {int(offsets[-1])} ns, more than the 4.29 s a uint32 offset holds")
    return new(
        "ImuBatch", timestamp_ns=int(time_ns[0]), agent_id=agent_id, sensor_id=sensor_id, sequence=sequence,
        sample_offset_ns=offsets.astype(np.uint32).tolist(), accel_g=np.ravel(accel_g).tolist(),
        gyro_dps=np.ravel(gyro_dps).tolist(), mag_gauss=[] if mag_gauss is None else np.ravel(mag_gauss).tolist())
