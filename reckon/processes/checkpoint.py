"""The hub's checkpoint: its whole state in one file, and how a restarted hub catches up from it.

Re-running a game's recorded inputs takes far longer than the 1 s a restart may take, so the hub
(reckon/processes/hub.py) writes a snapshot every few seconds next to its recording: the VenueHub
(every agent's view, the smoother, clocks, pending corrections, the identity engine), the
deduplicator, and where in its recording the snapshot stands (`inputs_recorded`: how many inputs
that recording held when it was taken; the recording is flushed to the OS first, so those are on
disk). A restarted hub loads it, re-applies the recording's inputs after that point (`catch_up`:
at most the few seconds of inputs since the snapshot, without publishing) and then goes on live.

Format: `MAGIC`, a u32 version, then a pickle of `HubState`. Pickle because the state is plain
dataclasses, deques and numpy arrays, and a snapshot is only ever read back by the same code
(the version and a class check refuse anything else with a clear error). It is written to a
temporary file, fsynced, and moved over the old one (os.replace), so a kill at any moment
leaves either the old snapshot or the new one, never half of one.
"""

from __future__ import annotations

import os
import pickle
import struct
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hub.dedup import Deduplicator, Verdict
from hub.venue import VenueHub
from protocol import keys, messages
from protocol.errors import InputError

MAGIC = b"reckon-hub-state\n"
VERSION = 8  # raised whenever the pickled state's fields change: an older snapshot is refused, not half read
_VERSION = struct.Struct("<I")
OUTPUT_STREAMS = ("correction", "identity")  # what the hub itself publishes (and records), with its poses
OUTPUT_TRACKS = ("live", "refined")  # pose/<track> of the hub; pose/edge is an input


@dataclass
class HubState:
    hub: VenueHub
    dedup: Deduplicator
    recording: str  # file name of the recording (in the snapshot's folder) that holds the inputs
    inputs_recorded: int  # inputs in that recording when the snapshot was taken


@dataclass
class CatchUp:
    """What re-applying a recording after a snapshot did."""

    reapplied: int = 0  # inputs given to the hub again
    repeats: int = 0  # inputs the deduplicator dropped on the way
    recorded_inputs: int = 0  # inputs the (intact part of the) recording holds
    unsent: list[Any] = field(default_factory=list)  # corrections made again that the recording never shows sent
    problems: list[str] = field(default_factory=list)


def dumps(state: HubState) -> bytes:
    return MAGIC + _VERSION.pack(VERSION) + pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)


def loads(data: bytes, where: str) -> HubState:
    """The state in `data`; InputError naming `where` if it is not a snapshot of this version."""
    head = len(MAGIC) + _VERSION.size
    if not data.startswith(MAGIC) or len(data) < head:
        raise InputError(f"{where}: not a reckon hub state file (expected it to begin with {MAGIC!r})")
    (version,) = _VERSION.unpack_from(data, len(MAGIC))
    if version != VERSION:
        raise InputError(f"{where}: hub state version {version}, this hub reads version {VERSION} "
                         "(remove the file to start afresh)")
    try:
        state = pickle.loads(data[head:])
    except Exception as error:  # a damaged pickle raises anything from UnpicklingError to EOFError
        raise InputError(f"{where}: hub state is damaged ({type(error).__name__}: {error})") from None
    if not isinstance(state, HubState):
        raise InputError(f"{where}: holds a {type(state).__name__}, expected a HubState")
    return state


def write_atomic(path: Path, data: bytes) -> None:
    """Replace `path` with `data` all at once (temporary file, fsync, os.replace)."""
    temporary = path.with_name(path.name + ".tmp")
    with open(temporary, "wb") as file:
        file.write(data)
        file.flush()
        os.fsync(file.fileno())
    os.replace(temporary, path)


def read(path: Path) -> HubState | None:
    """The snapshot at `path`, None if there is none; InputError if it is unreadable."""
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        return None
    return loads(data, str(path))


def next_recording(path: Path) -> Path:
    """The first free name beside `path`: hub.mcap -> hub.1.mcap, hub.2.mcap, ... (never overwrites)."""
    path = Path(path)
    number = 1
    while (candidate := path.with_name(f"{path.stem}.{number}{path.suffix}")).exists():
        number += 1
    return candidate


def is_input(topic: str) -> bool:
    """Whether a recorded topic is one of the hub's inputs (everything it does not publish itself)."""
    try:
        _, _, stream, rest = keys.parse(topic)
    except ValueError:
        return False
    return stream not in OUTPUT_STREAMS and not (stream == "pose" and rest in OUTPUT_TRACKS)


def catch_up(state: HubState, recorded: Iterable[tuple[int, str, Any]],
             on_input: Any = None) -> CatchUp:
    """Re-apply the inputs of `recorded` (log time, topic, message, in file order) that came after
    the snapshot, through the deduplicator and the hub, publishing nothing. `on_input(log_time,
    topic, message)` sees each input re-applied (the restarted hub records them again).

    The hub is deterministic given its inputs and their arrival times (the log time is the
    arrival), so it ends where the old hub was when its recording ends, corrections numbered as
    they were. Corrections it made that the recording does not show published (the old hub was
    killed between making and sending them) come back in `unsent`, to be sent now; an edge drops
    any it already has (by sequence).
    """
    result = CatchUp()
    published: dict[str, int] = {}  # agent -> last correction sequence the recording shows sent
    made: list[Any] = []
    for log_time, topic, message in recorded:
        if not is_input(topic):
            if messages.type_name(message) == "Correction":
                published[message.agent_id] = max(published.get(message.agent_id, 0), message.sequence)
            continue
        result.recorded_inputs += 1
        if result.recorded_inputs <= state.inputs_recorded:
            continue
        if state.dedup.check(topic, message) is not Verdict.NEW:
            result.repeats += 1
            continue
        if on_input is not None:
            on_input(log_time, topic, message)
        result.reapplied += 1
        if messages.type_name(message) == "SwimLength":
            continue  # shown and totalled by the app, no state in the hub
        try:
            made += [out for out in state.hub.on_message(message, log_time) if messages.type_name(out) == "Correction"]
        except ValueError as error:  # the live hub skipped it too (reckon/processes/hub.py)
            result.problems.append(f"{topic}: {error}")
    result.unsent = [c for c in made if c.sequence > published.get(c.agent_id, 0)]
    if result.recorded_inputs < state.inputs_recorded:
        result.problems.append(f"{state.recording}: holds {result.recorded_inputs} inputs, the snapshot counted "
                               f"{state.inputs_recorded}; the state is the snapshot's")
    return result
