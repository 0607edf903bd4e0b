"""Write imported streams as one session MCAP, every stream merged in time order.

Messages are merged by timestamp (log time = the message's timestamp, as `SessionWriter` does by
default), so a replay that reads the file front to back sees the streams interleaved as they
happened. The file is written under a temporary name and renamed at the end: a failed import
never leaves a half-written session behind.
"""

from __future__ import annotations

import heapq
import os
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from protocol import keys, messages
from protocol.errors import InputError
from protocol.session import Session
from protocol.messages import imu_batch
from protocol.session_log import SessionWriter
from reckon.importers.report import SensorCount
from reckon.importers.tables import ImuArrays

BATCH_SAMPLES = 20  # samples per ImuBatch, as the live devices send them (protocol/messages.py)
MAX_BATCH_SPAN_NS = 0xFFFF_FFFF  # sample offsets are uint32 ns: a batch spans at most 4.29 s

Stamped = tuple[int, str, Any]  # (timestamp ns, topic, message)


def batch_bounds(time_ns: np.ndarray) -> Iterator[tuple[int, int]]:
    """(start, end) index pairs: up to BATCH_SAMPLES samples, cut early before a gap over 4.29 s."""
    start = 0
    while start < len(time_ns):
        limit = int(np.searchsorted(time_ns, time_ns[start] + MAX_BATCH_SPAN_NS, side="right"))
        end = min(start + BATCH_SAMPLES, limit)
        yield start, end
        start = end


def imu_messages(venue: str, agent_id: str, sensor_id: str, data: ImuArrays, count: SensorCount) -> Iterator[Stamped]:
    """ImuBatch messages of one sensor, sequence numbers 0, 1, 2, ...; counts batches in `count`."""
    topic = keys.imu(venue, agent_id, sensor_id)
    for sequence, (start, end) in enumerate(batch_bounds(data.time_ns)):
        window = slice(start, end)
        message = imu_batch(agent_id, sensor_id, sequence, data.time_ns[window], data.accel_g[window],
                            data.gyro_dps[window], None if data.mag_gauss is None else data.mag_gauss[window])
        count.batches += 1
        yield int(data.time_ns[start]), topic, message


def sensor_count(agent_id: str, data: ImuArrays) -> SensorCount:
    return SensorCount(agent_id, samples=len(data.time_ns), first_s=float(data.time_ns[0]) * 1e-9,
                       last_s=float(data.time_ns[-1]) * 1e-9)


def sighting_message(venue: str, agent_id: str, sensor_id: str, beacon_id: str, time_ns: int,
                     rssi_dbm: float) -> Stamped:
    message = messages.new("BeaconSighting", timestamp_ns=time_ns, agent_id=agent_id, sensor_id=sensor_id,
                           beacon_id=beacon_id, rssi_dbm=rssi_dbm)
    return time_ns, keys.beacon(venue, agent_id, sensor_id), message


def truth_message(venue: str, agent_id: str, time_ns: int, x_m: float, y_m: float, heading_rad: float,
                  floor: int = 0) -> Stamped:
    message = messages.new("TruthPose", timestamp_ns=time_ns, agent_id=agent_id, x_m=x_m, y_m=y_m,
                           heading_rad=heading_rad, floor=floor)
    return time_ns, keys.truth(venue, agent_id), message


def write_messages(output: Path, session: Session, streams: Iterable[Iterable[Stamped]]) -> None:
    """Merge time-sorted streams into a session MCAP at `output`; InputError if it cannot be written."""
    output = Path(output)
    if not output.parent.is_dir():
        raise InputError(f"{output}: cannot write, folder {output.parent} does not exist")
    partial = output.with_name(f".{output.name}.partial")
    try:
        with SessionWriter(partial, session) as writer:
            for time_ns, topic, message in heapq.merge(*streams, key=lambda stamped: stamped[0]):
                writer.write(topic, message, time_ns)
        os.replace(partial, output)
    except OSError as error:
        raise InputError(f"{output}: cannot write ({error.strerror or error})") from None
    finally:
        if partial.exists():
            partial.unlink()
