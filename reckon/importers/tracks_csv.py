"""`reckon import tracks FILE.csv (--session SESSION.toml | --into LOG.mcap) -o OUT.mcap`: a camera
tracker's anonymous tracks, MOTChallenge-style CSV -> CameraFrame messages in a session log.

The file (docs/csv-import.md, "Camera tracks"): a header naming the columns with their units, then
one row per track per frame, frames in order:
  frame, id, x_<unit>, y_<unit>   required; frame and id integers from 1, units m, cm or mm
  height_<unit>                   optional: head height, every row
  conf                            optional: a number, checked and not stored (the schema has none)
  time_<unit>                     optional: the frame's time in the tracker's clock (s, ms, us, ns);
                                  without it, --fps and --start give frame n the time start + (n-1)/fps
Any mistake in the file is an InputError naming file:line, the column and the value: the import
is all or nothing, and a failed import writes no file. Frames with no rows are not written (the
tracker saw nobody, or lost the frame: the frame numbers show which).

With --session the log gets the TOML's description and the tracks; with --into it gets another
log's description and every message of it, merged in log time with the tracks (`-o` may name the
same file: it is replaced only when the import succeeds).
"""

from __future__ import annotations

import dataclasses
import math
import re
from array import array
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from protocol import keys, messages
from protocol.errors import ConfigError, InputError
from protocol.session import Session, load_toml
from protocol.session_log import LogMessages, read_description
from reckon.importers.tables import MAX_TIME_NS, NS_PER_TIME_UNIT, csv_rows, parse_time_ns
from reckon.importers.writing import Stamped, write_messages

METRES_PER_UNIT = {"m": 1.0, "cm": 0.01, "mm": 0.001}
DEFAULT_POSITION_SD_M = 0.1  # TRACAB-class court tracking is 0.06 m per axis (docs/simulator-camera.md)
MAX_UINT32 = 0xFFFF_FFFF
MAX_FPS = 1000.0
OUTSIDE_WARNING_M = 5.0  # positions this far outside the venue suggest a unit or origin mistake
_COLUMN = re.compile(r"^(time|x|y|height)(?:_(.+))?$")
_NAMES = {"frame": "frame", "id": "id", "track_id": "id", "conf": "conf"}


@dataclass
class TrackImportReport:
    """What `import_tracks_csv` did; `str(report)` is the summary the CLI prints."""

    output: Path
    camera_id: str
    rows: int = 0
    frames: int = 0
    tracks: int = 0
    first_frame: int = 0
    last_frame: int = 0
    first_s: float = 0.0
    last_s: float = 0.0
    copied_messages: int = 0
    warnings: list[str] = field(default_factory=list)

    def __str__(self) -> str:
        lines = [f"imported {self.rows} track rows of {self.tracks} tracks in {self.frames} frames "
                 f"(camera {self.camera_id}) into {self.output}",
                 f"  frames {self.first_frame}-{self.last_frame}, {self.first_s:.3f}-{self.last_s:.3f} s"]
        if self.copied_messages:
            lines.append(f"  with {self.copied_messages} messages of the existing log")
        if self.warnings:
            lines.append("warnings:")
            lines.extend(f"  - {warning}" for warning in self.warnings)
        return "\n".join(lines)


@dataclass(frozen=True)
class _Layout:
    columns: dict[str, int]  # frame, id, x, y, [height], [conf], [time] -> index
    scale: dict[str, float]  # x, y, height -> metres per unit; time -> ns per unit
    field_count: int


@dataclass
class _Tracks:
    frame: np.ndarray
    track_id: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    height_m: np.ndarray | None
    time_ns: np.ndarray | None  # per row, from the time column


def import_tracks_csv(path: Path, output: Path, *, session_toml: Path | None = None, into: Path | None = None,
                      camera_id: str = "cam1", fps: float | None = None, start_s: str | None = None,
                      position_sd_m: float | None = None) -> TrackImportReport:
    """Import one tracks CSV into the session log `output`. InputError for the file, ConfigError for
    the options and the session description; nothing is written when either is raised."""
    path, output = Path(path), Path(output)
    keys.check_id(camera_id, "--camera-id")
    if (session_toml is None) == (into is None):
        raise ConfigError("reckon import tracks: give --session SESSION.toml or --into LOG.mcap (one of them)")
    report = TrackImportReport(output, camera_id)
    if position_sd_m is None:
        position_sd_m = DEFAULT_POSITION_SD_M
        report.warnings.append(f"--position-sd not given: the tracks say {DEFAULT_POSITION_SD_M} m per axis; give "
                               "your tracker's figure")
    elif not (math.isfinite(position_sd_m) and 0.0 < position_sd_m <= 100.0):
        raise ConfigError(f"--position-sd {position_sd_m}: expected metres in (0, 100]")
    session = load_toml(session_toml) if session_toml is not None else read_description(into)  # type: ignore[arg-type]
    display = str(path)
    with csv_rows(path, display) as (header, rows):
        layout = _layout(header, display, report)
        tracks = _read_rows(rows, layout, display)
    if "time" in layout.columns and (fps is not None or start_s is not None):
        raise ConfigError(f"{display}: the file has a time column; --fps and --start are only for files without one")
    frame_ns = _frame_times(tracks, layout, fps, start_s, display)
    _summarise(tracks, frame_ns, session, report)
    frames = _frame_messages(tracks, frame_ns, session.venue.name, camera_id, float(position_sd_m))
    session = dataclasses.replace(session, source={**session.source, "camera_import": {
        "importer": "reckon import tracks", "file": path.name, "camera_id": camera_id}})
    streams: list[Iterator[Stamped]] = [frames]
    if into is not None:
        streams.append(_existing(Path(into), camera_id, report))
    write_messages(output, session, streams)
    return report


def _layout(header: list[str], display: str, report: TrackImportReport) -> _Layout:
    columns: dict[str, int] = {}
    scale: dict[str, float] = {}
    ignored = []
    for index, cell in enumerate(header):
        name = cell.strip().lower()
        match = _COLUMN.match(name)
        if name in _NAMES:
            quantity = _NAMES[name]
        elif match:
            quantity, unit = match.group(1), match.group(2)
            table = NS_PER_TIME_UNIT if quantity == "time" else METRES_PER_UNIT
            if unit is None or unit not in table:
                raise InputError(f"{display}: column {cell!r} needs a unit: "
                                 f"{', '.join(f'{quantity}_{u}' for u in table)}")
            scale[quantity] = float(table[unit])
        else:
            ignored.append(cell)
            continue
        if quantity in columns:
            raise InputError(f"{display}: columns {header[columns[quantity]]!r} and {cell!r} both give {quantity}; "
                             "keep one")
        columns[quantity] = index
    for required, spelled in (("frame", "frame"), ("id", "id"), ("x", "x_m"), ("y", "y_m")):
        if required not in columns:
            raise InputError(f"{display}: missing column {spelled}; found columns: {', '.join(header)}")
    if ignored:
        report.warnings.append(f"{display}: ignored columns {', '.join(ignored)}")
    return _Layout(columns, scale, len(header))


def _read_rows(rows: Iterator[tuple[int, list[str]]], layout: _Layout, display: str) -> _Tracks:
    frames, ids = array("q"), array("q")
    values = {name: array("d") for name in ("x", "y", "height") if name in layout.columns}
    times = array("q")
    columns = layout.columns
    previous_frame, previous_line, frame_ids = 0, 0, set()
    for line, row in rows:
        if len(row) != layout.field_count:
            raise InputError(f"{display}:{line}: {len(row)} fields, expected {layout.field_count} as in the header")
        frame = _integer(row, columns["frame"], "frame", line, display)
        track_id = _integer(row, columns["id"], "id", line, display)
        if frame < previous_frame:
            raise InputError(f"{display}:{line}: frame {frame} comes after frame {previous_frame} (line "
                             f"{previous_line}); rows must be in frame order")
        if frame != previous_frame:
            frame_ids = set()
        if track_id in frame_ids:
            raise InputError(f"{display}:{line}: id {track_id} appears twice in frame {frame}")
        frame_ids.add(track_id)
        for name, store in values.items():
            store.append(_number(row, columns[name], name, line, display) * layout.scale[name])
        if "conf" in columns:
            _number(row, columns["conf"], "conf", line, display)
        if "time" in columns:
            text = row[columns["time"]].strip()
            try:
                stamp = parse_time_ns(text, int(layout.scale["time"]))
            except ValueError:
                raise InputError(f"{display}:{line}: column time: {text!r} is not a number") from None
            if not 0 <= stamp <= MAX_TIME_NS:
                raise InputError(f"{display}:{line}: column time: {text} is outside 0 .. {MAX_TIME_NS} ns")
            times.append(stamp)
        frames.append(frame)
        ids.append(track_id)
        previous_frame, previous_line = frame, line
    if not frames:
        raise InputError(f"{display}: no rows after the header (expected one row per track per frame)")

    def column(name: str) -> np.ndarray | None:
        return np.frombuffer(values[name], dtype=np.float64).copy() if name in values else None

    return _Tracks(np.frombuffer(frames, dtype=np.int64).copy(), np.frombuffer(ids, dtype=np.int64).copy(),
                   column("x"), column("y"), column("height"),  # type: ignore[arg-type]
                   np.frombuffer(times, dtype=np.int64).copy() if "time" in columns else None)


def _integer(row: list[str], index: int, name: str, line: int, display: str) -> int:
    text = row[index].strip()
    try:
        value = int(text)
    except ValueError:
        raise InputError(f"{display}:{line}: column {name}: {text!r} is not an integer") from None
    if not 1 <= value <= MAX_UINT32:
        raise InputError(f"{display}:{line}: column {name}: {value} is outside 1 .. {MAX_UINT32} (ids and frames "
                         "count from 1)")
    return value


def _number(row: list[str], index: int, name: str, line: int, display: str) -> float:
    text = row[index].strip()
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{display}:{line}: column {name}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise InputError(f"{display}:{line}: column {name}: {text!r} is not a finite number")
    return value


def _frame_times(tracks: _Tracks, layout: _Layout, fps: float | None, start_s: str | None,
                 display: str) -> dict[int, int]:
    """Frame number -> time ns, from the time column (same in every row of a frame, increasing) or
    from --fps and --start."""
    starts = np.flatnonzero(np.concatenate([[True], np.diff(tracks.frame) != 0]))
    numbers = tracks.frame[starts]
    if tracks.time_ns is not None:
        out: dict[int, int] = {}
        previous: tuple[int, int] | None = None
        for first, end in zip(starts.tolist(), np.append(starts[1:], len(tracks.frame)).tolist()):
            stamps = tracks.time_ns[first:end]
            frame = int(tracks.frame[first])
            if np.any(stamps != stamps[0]):
                raise InputError(f"{display}: frame {frame}: rows give different times ({int(stamps.min())} and "
                                 f"{int(stamps.max())} ns); one frame has one time")
            if previous is not None and stamps[0] <= previous[1]:
                raise InputError(f"{display}: frame {frame}: time {int(stamps[0])} ns is not after frame "
                                 f"{previous[0]}'s {previous[1]} ns")
            out[frame] = int(stamps[0])
            previous = (frame, int(stamps[0]))
        return out
    if fps is None or start_s is None:
        raise ConfigError(f"{display}: no time column: give --fps and --start (the time of frame 1, seconds)")
    if not (math.isfinite(fps) and 0.0 < fps <= MAX_FPS):
        raise ConfigError(f"--fps {fps}: expected a frame rate in (0, {MAX_FPS:g}]")
    try:
        start_ns = parse_time_ns(start_s, 1_000_000_000)
    except ValueError:
        raise ConfigError(f"--start {start_s!r}: not a number of seconds") from None
    last_ns = start_ns + round((int(numbers[-1]) - 1) * 1e9 / fps)
    if start_ns < 0 or last_ns > MAX_TIME_NS:
        raise ConfigError(f"--start {start_s}: frame times must stay within 0 .. {MAX_TIME_NS} ns")
    return {int(n): start_ns + round((int(n) - 1) * 1e9 / fps) for n in numbers.tolist()}


def _summarise(tracks: _Tracks, frame_ns: dict[int, int], session: Session, report: TrackImportReport) -> None:
    report.rows, report.frames = len(tracks.frame), len(frame_ns)
    report.tracks = len(np.unique(tracks.track_id))
    report.first_frame, report.last_frame = int(tracks.frame[0]), int(tracks.frame[-1])
    report.first_s, report.last_s = frame_ns[report.first_frame] * 1e-9, frame_ns[report.last_frame] * 1e-9
    venue = session.venue
    outside = ((tracks.x_m < -OUTSIDE_WARNING_M) | (tracks.x_m > venue.court_length_m + OUTSIDE_WARNING_M)
               | (tracks.y_m < -OUTSIDE_WARNING_M) | (tracks.y_m > venue.court_width_m + OUTSIDE_WARNING_M))
    if outside.any():
        report.warnings.append(f"{int(outside.sum())} rows lie more than {OUTSIDE_WARNING_M:g} m outside the "
                               f"{venue.court_length_m:g} m x {venue.court_width_m:g} m venue (a unit or origin "
                               "mistake?)")


def _frame_messages(tracks: _Tracks, frame_ns: dict[int, int], venue: str, camera_id: str,
                    position_sd_m: float) -> Iterator[Stamped]:
    topic = keys.camera_tracks(venue, camera_id)
    starts = np.flatnonzero(np.concatenate([[True], np.diff(tracks.frame) != 0]))
    for first, end in zip(starts.tolist(), np.append(starts[1:], len(tracks.frame)).tolist()):
        frame = int(tracks.frame[first])
        stamp = frame_ns[frame]
        rows = slice(first, end)
        height = [] if tracks.height_m is None else tracks.height_m[rows].tolist()
        yield stamp, topic, messages.new(
            "CameraFrame", timestamp_ns=stamp, camera_id=camera_id, frame=frame,
            track_id=tracks.track_id[rows].tolist(), x_m=tracks.x_m[rows].tolist(), y_m=tracks.y_m[rows].tolist(),
            height_m=height, position_sd_m=position_sd_m)


def _existing(path: Path, camera_id: str, report: TrackImportReport) -> Iterator[Stamped]:
    """Every message of the log at `path`; InputError if it already has frames from `camera_id`."""
    log_messages = LogMessages(path)
    for log_ns, topic, message in log_messages:
        if messages.type_name(message) == "CameraFrame" and message.camera_id == camera_id:
            raise InputError(f"{path}: already holds frames of camera {camera_id!r}; choose another --camera-id")
        report.copied_messages += 1
        yield log_ns, topic, message
    report.warnings.extend(log_messages.problems)
    report.warnings.extend(f"{path}: {count} messages on {topic} not copied (not a reckon schema)"
                           for topic, count in log_messages.skipped.items())
