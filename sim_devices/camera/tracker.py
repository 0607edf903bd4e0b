"""A simulated external tracker over any set of true paths: `simulate_tracks`, and `camera_items` to log it.

Frames are captured on a regular grid of true time over the people's span; each frame is stamped
in the tracker's clock (capture + `camera.clock_offset_ms` + jitter) and carries the tracks that
`identity.IdentityModel` says the tracker reports then. A track's position is the truth plus a
per-person Gauss-Markov error and white noise per axis (a merged track: the centroid of its people;
a split track: the person plus a fixed offset; a false track: its random walk). Lost frames are
left out, keeping the frame numbers of the others (gaps reveal them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from protocol import keys, messages
from protocol.errors import ConfigError
from sim_devices.camera.identity import FrameTracks, IdentityModel
from sim_devices.camera.params import TrackerParams
from sim_devices.camera.paths import PersonPath, check_path
from sim_devices.common import Item

FRAME_ORDER, LABEL_ORDER = 4, 5  # stream order among a venue's simulated streams (wheelchair uses 0-3)
MAX_JITTER_SHARE = 0.45  # stamps stay within +-45 % of a frame of the capture, so they always increase


@dataclass
class CameraFrameData:
    """One frame as the tracker reports it, with the truth label of each track (`person_id`)."""

    time_ns: int  # tracker clock
    frame: int  # from 1; lost frames leave gaps
    track_id: np.ndarray  # uint32-range int64, from 1
    x_m: np.ndarray
    y_m: np.ndarray
    height_m: np.ndarray | None  # None when the tracker reports no height
    person_id: list[str]  # "" false track, "a+b" a merge


@dataclass
class CameraRecording:
    camera_id: str
    position_sd_m: float  # stated 1-sigma per axis (white and correlated parts together)
    frames: list[CameraFrameData]
    counters: dict[str, int] = field(default_factory=dict)  # tracks, gaps, exits, switches, merges, splits, ...
    capture_ns: np.ndarray | None = None  # true capture time of every frame, lost ones included (truth)


def simulate_tracks(people: list[PersonPath], area_m: tuple[float, float], params: TrackerParams,
                    rng: np.random.Generator, camera_id: str = "cam1") -> CameraRecording:
    """Simulate the tracker over `people` in an area of `area_m` = (length along x, width along y) m,
    origin at a corner. ConfigError for a bad area, no people, a duplicate id or a malformed path."""
    keys.check_id(camera_id, "camera_id")
    if not all(math.isfinite(side) and side > 0.0 for side in area_m):
        raise ConfigError(f"simulate_tracks: area_m {area_m} must be two positive lengths (m)")
    if not people:
        raise ConfigError("simulate_tracks: no people")
    for person in people:
        check_path(person)
    ids = [p.person_id for p in people]
    if len(set(ids)) != len(ids):
        raise ConfigError(f"simulate_tracks: duplicate person id in {ids}")
    camera, noise = params.camera, params.noise
    period_ns = 1e9 / camera.frame_rate_hz
    dt = 1.0 / camera.frame_rate_hz
    start_ns = min(int(p.time_ns[0]) for p in people)
    end_ns = max(int(p.time_ns[-1]) for p in people)
    frames = int((end_ns - start_ns) // period_ns) + 1
    capture_ns = start_ns + np.round(np.arange(frames) * period_ns).astype(np.int64)
    position, valid = _positions(people, capture_ns)
    margin = camera.fov_margin_m
    fov = (-margin, -margin, area_m[0] + margin, area_m[1] + margin)
    in_view = valid & (position[..., 0] >= fov[0]) & (position[..., 0] <= fov[2]) \
        & (position[..., 1] >= fov[1]) & (position[..., 1] <= fov[3])
    speed = np.hypot(*np.moveaxis(np.gradient(position, dt, axis=0), -1, 0)) if frames > 1 \
        else np.zeros((frames, len(people)))
    limit_ns = MAX_JITTER_SHARE * period_ns
    jitter_ns = np.clip(rng.normal(0.0, camera.frame_jitter_ms * 1e6, frames), -limit_ns, limit_ns)
    stamps = capture_ns + int(round(camera.clock_offset_ms * 1e6)) + np.round(jitter_ns).astype(np.int64)
    lost = rng.random(frames) < camera.frame_loss_rate
    observed = position + _gauss_markov(rng, frames, len(people), noise.correlated_sd_m, noise.correlation_s, dt) \
        + rng.normal(0.0, noise.white_sd_m, position.shape)
    heights = _heights(people, capture_ns)
    model = IdentityModel(params, rng, len(people), dt, fov)
    out: list[CameraFrameData] = []
    for index in range(frames):
        distance = np.linalg.norm(position[index, :, None, :] - position[index, None, :, :], axis=-1)
        tracks = model.step(in_view[index], distance, speed[index])
        if not lost[index]:
            out.append(_frame(int(stamps[index]), index + 1, tracks, observed[index], heights[index], ids, params, rng))
    counters = dict(model.counters)
    counters.update(frames=len(out), lost_frames=int(lost.sum()),
                    observations=sum(len(f.track_id) for f in out))
    return CameraRecording(camera_id, math.hypot(noise.white_sd_m, noise.correlated_sd_m), out, counters,
                           capture_ns)


def _positions(people: list[PersonPath], capture_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F, P, 2) true positions at the capture times (linear interpolation) and (F, P) presence."""
    position = np.zeros((len(capture_ns), len(people), 2))
    valid = np.zeros((len(capture_ns), len(people)), dtype=bool)
    for column, person in enumerate(people):
        times = np.asarray(person.time_ns, dtype=np.int64)
        valid[:, column] = (capture_ns >= times[0]) & (capture_ns <= times[-1])
        relative = (capture_ns - times[0]).astype(np.float64)  # float64 keeps ns over days
        grid = (times - times[0]).astype(np.float64)
        position[:, column, 0] = np.interp(relative, grid, np.asarray(person.x_m, dtype=np.float64))
        position[:, column, 1] = np.interp(relative, grid, np.asarray(person.y_m, dtype=np.float64))
    return position, valid


def _heights(people: list[PersonPath], capture_ns: np.ndarray) -> np.ndarray:
    """(F, P) head-top heights at the capture times: each person's `head_m` interpolated, else `height_m`."""
    heights = np.tile(np.array([p.height_m for p in people], dtype=np.float64), (len(capture_ns), 1))
    for column, person in enumerate(people):
        if person.head_m is not None:
            times = np.asarray(person.time_ns, dtype=np.int64)
            heights[:, column] = np.interp((capture_ns - times[0]).astype(np.float64),
                                           (times - times[0]).astype(np.float64), np.asarray(person.head_m, np.float64))
    return heights


def _gauss_markov(rng: np.random.Generator, frames: int, people: int, sd_m: float, tau_s: float,
                  dt: float) -> np.ndarray:
    """(F, P, 2) first-order Gauss-Markov error, stationary SD `sd_m`, time constant `tau_s`."""
    drive = rng.normal(0.0, 1.0, (frames, people, 2))
    keep = math.exp(-dt / tau_s)
    out = np.empty_like(drive)
    out[0] = sd_m * drive[0]
    scale = sd_m * math.sqrt(1.0 - keep * keep)
    for index in range(1, frames):
        out[index] = keep * out[index - 1] + scale * drive[index]
    return out


def _frame(stamp: int, number: int, tracks: FrameTracks, observed: np.ndarray, heights: np.ndarray,
           ids: list[str], params: TrackerParams, rng: np.random.Generator) -> CameraFrameData:
    rows: list[tuple[int, float, float, float, str]] = []
    points, tall = observed.tolist(), heights.tolist()
    for track_id, members in tracks.groups:
        share = 1.0 / len(members)  # a merged track sits at its people's centroid
        x = sum(points[m][0] for m in members) * share
        y = sum(points[m][1] for m in members) * share
        label = "+".join(sorted(ids[m] for m in members))
        rows.append((track_id, x, y, sum(tall[m] for m in members) * share, label))
    white = params.noise.white_sd_m
    for track_id, person, (dx, dy) in tracks.splits:
        x, y = observed[person] + (dx, dy) + rng.normal(0.0, white, 2)
        rows.append((track_id, float(x), float(y), float(heights[person]), ids[person]))
    for track_id, x, y, height in tracks.false_tracks:
        rows.append((track_id, x + float(rng.normal(0.0, white)), y + float(rng.normal(0.0, white)), height, ""))
    rows.sort()
    count = len(rows)
    height = None
    if params.camera.reports_height:
        height = np.array([r[3] for r in rows]) + rng.normal(0.0, params.noise.height_sd_m, count)
    return CameraFrameData(stamp, number, np.array([r[0] for r in rows], dtype=np.int64),
                           np.array([r[1] for r in rows]), np.array([r[2] for r in rows]), height,
                           [r[4] for r in rows])


def camera_items(recording: CameraRecording, venue: str) -> Iterator[Item]:
    """CameraFrame and TruthTrackLabel items of every frame, log time = the frame's stamp (tracker clock)."""
    frame_topic = keys.camera_tracks(venue, recording.camera_id)
    label_topic = keys.camera_truth(venue, recording.camera_id)
    sd = float(recording.position_sd_m)
    for frame in recording.frames:
        track_ids = frame.track_id.tolist()
        yield frame.time_ns, FRAME_ORDER, frame_topic, messages.new(
            "CameraFrame", timestamp_ns=frame.time_ns, camera_id=recording.camera_id, frame=frame.frame,
            track_id=track_ids, x_m=frame.x_m.tolist(), y_m=frame.y_m.tolist(),
            height_m=[] if frame.height_m is None else frame.height_m.tolist(), position_sd_m=sd)
        yield frame.time_ns, LABEL_ORDER, label_topic, messages.new(
            "TruthTrackLabel", timestamp_ns=frame.time_ns, camera_id=recording.camera_id, frame=frame.frame,
            track_id=track_ids, person_id=frame.person_id)
