"""Camera track rows grouped into fragments (one per track id), and people's values on the frame grid.

The camera-identity paper's unit is the path (fragment): the rows of one track id, which a tracker
never reuses. Each fragment gets its horizontal speed per row here (`track_speed`), once, so the
permutation search only ever looks things up. Also `training_pairs`, the labelled (speed,
vertical) pairs that `fit_model` measures the regression and eq. 1's Ave and SD on.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Protocol

import numpy as np

from hub.identity.paper.features import check_length, check_times, track_speed


class TrackArrays(Protocol):
    """What `protocol.session_log.CameraTracks` holds (that module is not imported: it reads MCAP)."""

    frame_ns: np.ndarray
    time_ns: np.ndarray
    track_id: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray


@dataclass(frozen=True)
class Fragments:
    """Rows grouped by track id: fragment k owns rows[offsets[k]:offsets[k + 1]], in time order."""

    track_id: np.ndarray  # (K,)
    start_frame: np.ndarray  # (K,) index into frame_ns of the first row
    end_frame: np.ndarray  # (K,) of the last row
    offsets: np.ndarray  # (K + 1,)
    rows: np.ndarray  # (N,) row indices into the track arrays
    frame_index: np.ndarray  # (N,) for each entry of rows
    speed_mps: np.ndarray  # (N,) track_speed, per entry of rows


def split_fragments(tracks: TrackArrays, window_s: float) -> Fragments:
    """Group the track rows by id and compute each fragment's speed. ValueError on bad arrays."""
    frames = check_times("frame_ns", tracks.frame_ns)
    times = check_times("tracks time_ns", tracks.time_ns, strictly=False)
    ids = np.asarray(tracks.track_id)
    x, y = np.asarray(tracks.x_m, dtype=float), np.asarray(tracks.y_m, dtype=float)
    for name, values in (("track_id", ids), ("x_m", x), ("y_m", y)):
        check_length(f"tracks {name}", values, len(times))
    if np.any(ids == 0):
        raise ValueError(f"track_id 0 at row {int(np.flatnonzero(ids == 0)[0])}: 0 is reserved for 'no track'")
    frame_index = np.searchsorted(frames, times)
    off_grid = (frame_index >= len(frames)) | (frames[np.minimum(frame_index, len(frames) - 1)] != times)
    if off_grid.any():
        k = int(np.flatnonzero(off_grid)[0])
        raise ValueError(f"tracks time_ns[{k}] = {int(times[k])} is not one of frame_ns")
    rows = np.lexsort((times, ids))
    grouped = ids[rows]
    starts = np.flatnonzero(np.r_[True, grouped[1:] != grouped[:-1]]) if len(rows) else np.zeros(0, np.int64)
    offsets = np.r_[starts, len(rows)].astype(np.int64)
    repeated = (grouped[1:] == grouped[:-1]) & (times[rows][1:] == times[rows][:-1])
    if repeated.any():
        k = int(rows[np.flatnonzero(repeated)[0] + 1])
        raise ValueError(f"track_id {int(ids[k])} has two rows at time_ns {int(times[k])}")
    speed = np.empty(len(rows))
    for a, b in zip(offsets[:-1], offsets[1:]):
        chosen = rows[a:b]
        speed[a:b] = track_speed(times[chosen], x[chosen], y[chosen], window_s)
    return Fragments(grouped[starts].astype(np.int64), frame_index[rows][starts],
                     frame_index[rows][offsets[1:] - 1], offsets, rows, frame_index[rows], speed)


def on_frame_grid(frame_ns: np.ndarray, name: str, time_ns: np.ndarray, values: np.ndarray) -> np.ndarray:
    """A person's per-frame values moved onto frame_ns (nearest within half a frame, else NaN)."""
    times = check_times(f"people[{name!r}] time_ns", time_ns)
    values = np.asarray(values, dtype=float)
    check_length(f"people[{name!r}] vertical", values, len(times))
    out = np.full(len(frame_ns), np.nan)
    if times.size == 0 or len(frame_ns) == 0:
        return out
    half_frame = np.median(np.diff(frame_ns)) / 2 if len(frame_ns) > 1 else 0
    after = np.searchsorted(times, frame_ns)
    left, right = np.clip(after - 1, 0, len(times) - 1), np.clip(after, 0, len(times) - 1)
    nearest = np.where(np.abs(times[left] - frame_ns) <= np.abs(times[right] - frame_ns), left, right)
    close = np.abs(times[nearest] - frame_ns) <= half_frame
    out[close] = values[nearest[close]]
    return out


def frame_period_s(frame_ns: np.ndarray) -> float:
    """The median frame period (s): robust to the odd dropped frame."""
    return float(np.median(np.diff(frame_ns))) * 1e-9 if len(frame_ns) > 1 else 0.0


def training_pairs(tracks: TrackArrays, row_person: np.ndarray,
                   people: Mapping[str, tuple[np.ndarray, np.ndarray]],
                   window_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Labelled (speed, vertical, track id) per row for `fit_model`: rows whose label names one
    person with a sensor ("" false tracks and "a+b" merges are skipped)."""
    fragments = split_fragments(tracks, window_s)
    labels = np.asarray(row_person, dtype=object)
    check_length("row_person", labels, len(np.asarray(tracks.time_ns)))
    frames = np.asarray(tracks.frame_ns, dtype=np.int64)
    speeds, verticals, ids = [], [], []
    for name, (time_ns, vertical) in people.items():
        grid = on_frame_grid(frames, name, time_ns, vertical)
        mine = labels[fragments.rows] == name
        speeds.append(fragments.speed_mps[mine])
        verticals.append(grid[fragments.frame_index[mine]])
        ids.append(np.asarray(tracks.track_id)[fragments.rows[mine]])
    if not speeds:
        return np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64)
    return np.concatenate(speeds), np.concatenate(verticals), np.concatenate(ids)
