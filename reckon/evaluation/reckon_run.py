"""Our method offline: the live edge and hub code, driven in lockstep from a session log.

Every message of the log goes, in arrival (log time) order, where it would go live: an ImuBatch
to its chair's edge (edge/chair/edge.py) and to the hub (hub/chair/hub.py, for clock offsets),
the edge's poses, impacts and field readings to the hub, a beacon sighting to the hub, and the
hub's corrections and field maps back to the edge at once. So `reckon eval` scores exactly what `reckon edge` +
`reckon hub` compute, minus the bus's delay and reordering.

`live`: at each scoring frame, the newest live pose the hub had published by then. `refined`:
the hub's fixed-lag track, interpolated at the frames.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from edge.chair.edge import ChairEdge
from edge.chair.merger import ChairMerger
from edge.chair.state import ChairSample
from hub.chair.hub import HubSettings
from hub.venue import VenueHub
from protocol import messages
from protocol.session import AgentKind, Session
from protocol.session_log import LogMessages
from reckon.evaluation.inputs import AgentInputs
from reckon.kernels import chair_kernels

RECKON_CORRECTIONS = ("beacon", "collision")
INPUT_TYPES = ("ImuBatch", "BeaconSighting", "CameraFrame")


@dataclass
class ReckonEstimate:
    x_m: np.ndarray  # (agents, frames)
    y_m: np.ndarray
    corrections_applied: int
    covariance_m2: np.ndarray | None = None  # (agents, frames, 3): xx, xy, yy of the pose's stated covariance
    contacts: tuple[tuple[int, str, str], ...] = ()  # the hub's contacts, (venue time, agent, other) per pair


def log_inputs(path: Path | str) -> list[tuple[int, Any]]:
    """(log_time_ns, message) of every sensor message, with the arrival stamped as `received_ns`."""
    out = []
    for log_time, _, message in LogMessages(path):
        if messages.type_name(message) in INPUT_TYPES:
            if messages.type_name(message) == "ImuBatch" and not message.received_ns:
                message.received_ns = log_time
            out.append((log_time, message))
    return out


def run_lockstep(session: Session, inputs: list[tuple[int, Any]], settings: HubSettings,
                 identities: list[Any] | None = None,
                 contacts: list[tuple[int, str, str]] | None = None) -> tuple[VenueHub, dict, dict]:
    """(hub, live, refined): per agent, arrays (time_ns, x, y, cov xx, cov xy, cov yy) of the hub's two tracks.

    `identities`, if given, receives the hub's TrackIdentity messages in order; `contacts` the
    contacts it took, (venue time, agent, other) once per pair."""
    hub = VenueHub(session, settings, clock=time.perf_counter)  # times the identity engine's hops
    kernels = chair_kernels()[0]
    edges = {agent.id: ChairEdge(agent, settings.pose_rate_hz, kernels=kernels) for agent in session.agents
             if agent.kind is AgentKind.WHEELCHAIR}
    tracks: dict[int, dict[str, list]] = {messages.Track.LIVE: {}, messages.Track.REFINED: {}}

    def to_hub(message: Any, arrival_ns: int) -> None:
        for out in hub.on_message(message, arrival_ns):
            if messages.type_name(out) == "Correction":
                edges[out.agent_id].correct(out)
                if contacts is not None and out.kind == messages.CorrectionKind.COLLISION and out.agent_id < out.other_agent_id:
                    contacts.append((out.timestamp_ns, out.agent_id, out.other_agent_id))
            elif messages.type_name(out) == "FieldMap":
                edges[out.agent_id].field_map(out)
            elif messages.type_name(out) == "TrackIdentity":
                if identities is not None:
                    identities.append(out)
            else:
                tracks[out.track].setdefault(out.agent_id, []).append(_row(out))

    arrival_ns = 0
    for arrival_ns, message in inputs:
        to_hub(message, arrival_ns)
        edge = edges.get(message.agent_id) if messages.type_name(message) == "ImuBatch" else None
        if edge is not None:
            for out in edge.push(message):
                to_hub(out, arrival_ns)
    for edge in edges.values():
        for out in edge.flush():
            to_hub(out, arrival_ns)
    for out in hub.flush():
        tracks[out.track].setdefault(out.agent_id, []).append(_row(out))
    as_arrays = {track: {agent: np.array(rows) for agent, rows in by_agent.items()} for track, by_agent in tracks.items()}
    return hub, as_arrays[messages.Track.LIVE], as_arrays[messages.Track.REFINED]


def _row(pose: Any) -> tuple[float, ...]:
    """(time, x, y, cov xx, xy, yy) of an EstimatedPose; NaN covariance when it states none."""
    cov = pose.covariance[:]
    xx, xy, yy = (cov[0], cov[1], cov[4]) if len(cov) == 9 else (math.nan,) * 3
    return pose.timestamp_ns, pose.x_m, pose.y_m, xx, xy, yy


def run_reckon(session: Session, inputs: list[tuple[int, Any]], frame_ns: np.ndarray, corrections: frozenset[str],
               lag_s: float = HubSettings.lag_s) -> tuple[ReckonEstimate, ReckonEstimate]:
    """(live, refined) estimates of every agent of `session` at `frame_ns`; the live one with its covariance."""
    contacts: list[tuple[int, str, str]] = []
    hub, live, refined = run_lockstep(session, inputs, HubSettings(corrections=corrections, lag_s=lag_s),
                                      contacts=contacts)
    applied = sum(sum(view.applied.values()) for view in hub.agents.values())
    ids = [agent.id for agent in session.agents]
    live_rows = np.array([_newest_at(live.get(agent_id), frame_ns) for agent_id in ids])  # (agents, frames, 5)
    refined_xy = [_interpolated(refined.get(agent_id), frame_ns) for agent_id in ids]
    # The refined pose's covariance: the one stated by the refined pose at or before each frame.
    refined_covariance = np.array([_newest_at(refined.get(agent_id), frame_ns) for agent_id in ids])[:, :, 2:]
    return (ReckonEstimate(live_rows[:, :, 0], live_rows[:, :, 1], applied, live_rows[:, :, 2:], tuple(contacts)),
            ReckonEstimate(np.array([xy[0] for xy in refined_xy]), np.array([xy[1] for xy in refined_xy]), applied,
                           refined_covariance, tuple(contacts)))


def without_magnetometer(inputs: list[tuple[int, Any]]) -> list[tuple[int, Any]]:
    """The same arrivals with every ImuBatch's magnetometer readings removed (the gyro-only ablation)."""
    out = []
    for arrival_ns, message in inputs:
        if messages.type_name(message) == "ImuBatch" and len(message.mag_gauss):
            gyro_only = messages.ImuBatch()
            gyro_only.CopyFrom(message)  # the arrivals are shared with the other runs: never edit them
            del gyro_only.mag_gauss[:]
            message = gyro_only
        out.append((arrival_ns, message))
    return out


def _newest_at(track: np.ndarray | None, frame_ns: np.ndarray) -> np.ndarray:
    """(frames, 5): x, y and covariance xx, xy, yy of the newest pose at or before each frame (the first pose
    before there is one)."""
    if track is None or len(track) == 0:
        return np.full((len(frame_ns), 5), np.nan)
    index = np.clip(np.searchsorted(track[:, 0], frame_ns, side="right") - 1, 0, len(track) - 1)
    return track[index, 1:6]


def _interpolated(track: np.ndarray | None, frame_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if track is None or len(track) == 0:
        return np.full(len(frame_ns), np.nan), np.full(len(frame_ns), np.nan)
    return np.interp(frame_ns, track[:, 0], track[:, 1]), np.interp(frame_ns, track[:, 0], track[:, 2])


def merged_samples(agent: AgentInputs) -> list[ChairSample]:
    """The agent's logged samples pushed through the live path's merger, in time order (tests, bench)."""
    merger = ChairMerger(agent.agent)
    streams = [(sensor_id, series) for sensor_id, series in agent.raw.items()]
    times = np.concatenate([series.time_ns for _, series in streams])
    which = np.concatenate([np.full(len(series.time_ns), i) for i, (_, series) in enumerate(streams)])
    index = np.concatenate([np.arange(len(series.time_ns)) for _, series in streams])
    samples: list[ChairSample] = []
    for k in np.argsort(times, kind="stable"):
        sensor_id, series = streams[which[k]]
        i = index[k]
        mag = None if series.mag_gauss is None else tuple(series.mag_gauss[i].tolist())
        samples += merger.push(sensor_id, int(series.time_ns[i]), tuple(series.accel_g[i].tolist()),
                               tuple(series.gyro_dps[i].tolist()), mag)
    return samples + merger.flush()
